"""Tests of imu_allan.history."""

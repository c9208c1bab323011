"""Tests of imu_allan.core."""

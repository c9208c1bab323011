"""Tests of imu_allan.device."""

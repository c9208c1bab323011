"""Tests of imu_allan.formats."""

"""Tests of imu_allan.report."""

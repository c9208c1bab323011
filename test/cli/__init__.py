"""Tests of imu_allan.cli."""

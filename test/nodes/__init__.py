"""Tests of imu_allan.nodes."""

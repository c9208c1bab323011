"""Thin rclpy nodes: parameters, QoS, timers and publishing; the numerics live in core/."""

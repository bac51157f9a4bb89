"""Thin rclpy nodes: parameters, topics, timers, and a call into the pure core."""

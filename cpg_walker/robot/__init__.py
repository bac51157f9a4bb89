"""The simulated HOAP-2: MJCF model, simulation class, PID law, recorded gait data (no rclpy)."""

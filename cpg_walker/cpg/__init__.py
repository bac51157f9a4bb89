"""The programmable CPG (pure numpy; never imports rclpy)."""

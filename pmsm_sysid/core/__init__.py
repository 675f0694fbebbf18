"""Numerical core: pure numpy/scipy. Never imports rclpy, rosbags or matplotlib."""

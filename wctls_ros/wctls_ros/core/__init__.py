"""Estimation core: plain numpy, no ROS imports."""

"""Numerical core of sma_wrist. Nothing under this package imports ROS."""

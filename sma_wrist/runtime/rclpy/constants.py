"""Constants as in rclpy/constants.py."""

S_TO_NS = 1000 * 1000 * 1000

"""sma_wrist: an artificial wrist actuated by an antagonistic pair of Nitinol muscles.

Layout
------
core/      pure numerics (numpy/scipy, no ROS imports): hysteresis, heat balance, joint, plant, controllers
runtime/   the embedded single-process rclpy subset used where ROS 2 is not installed
nodes/     thin rclpy node adapters over core/
"""

__version__ = '0.1.0'

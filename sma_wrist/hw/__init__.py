"""Hardware side of sma_wrist: the serial line protocol (protocol.py), the device emulator
(emulator.py), the bridge's serial link (link.py), calibration/estimation helpers and the
streaming benchmark (bench.py). The ROS node is sma_wrist/nodes/hardware_bridge.py."""

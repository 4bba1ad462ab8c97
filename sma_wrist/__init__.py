"""sma_wrist: an artificial wrist actuated by an antagonistic pair of Nitinol muscles.

Layout
------
core/      pure numerics (numpy/scipy, no ROS imports): hysteresis, heat balance, joint, plant, controllers
runtime/   the embedded single-process rclpy subset used where ROS 2 is not installed
nodes/     thin rclpy node adapters over core/
"""

import os

__version__ = '0.1.0'

# Every dense problem here is small (<= a few hundred unknowns) and runs beside the simulation, other
# nodes or sweep workers: OpenBLAS's worker threads only spin against them (test_identification took
# 160 s with them and 13 s without on a loaded 2-core machine). Set before numpy loads; a user's own
# setting wins.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_var, '1')
del _var

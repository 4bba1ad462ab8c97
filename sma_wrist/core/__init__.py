"""Numerical core of sma_wrist. Nothing under this package imports ROS.

Grouped by physical idea; each group keeps its numpy reference and its compiled kernel side by side
(``kernel.py`` / ``*_kernel.py``, numba when installed, see :mod:`sma_wrist.core.jit`):

- :mod:`~sma_wrist.core.hysteresis`: the wire. Play operators, SD-GPI (Eqs. 3.19-3.25, 4.1-4.6),
  the muscle's load solve, identification (Ch. 4.1-4.2), inverse compensation (Eqs. 5.5-5.15).
- :mod:`~sma_wrist.core.thermal`: the TEM + Nitinol heat balance (Eqs. 4.7-4.15, Table 4.9) and its
  identification (Sec. 4.3.2).
- :mod:`~sma_wrist.core.joint`: chain/sprocket kinematics and joint dynamics (Eqs. 4.16-4.18).
- :mod:`~sma_wrist.core.plant`: the coupled wrist (thermal -> wires -> joint) and the parametric
  extensions ``diagnose`` names.
- :mod:`~sma_wrist.core.control`: the laws of Chapter 5-6: adaptive back-stepping (Eqs. 5.22-5.37),
  PID (Sec. 6.1), TEM feedback linearisation (Eqs. 5.38-5.47), trajectories.

Shared: :mod:`~sma_wrist.core.errors` (typed errors), :mod:`~sma_wrist.core.metrics` (Table 6.2),
:mod:`~sma_wrist.core.jit` (the optional-numba switch).
"""

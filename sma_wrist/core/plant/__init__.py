"""The coupled wrist: TEM drive -> temperatures -> wire loads -> joint angle.

- ``wrist``: :class:`~sma_wrist.core.plant.wrist.WristPlant` (numpy path); ``kernel``: the same step,
  compiled, over N wrists (thermal, hysteresis and joint kernels composed).
- ``extensions``: parametric effects beyond the nominal model, the ones ``sma-wrist diagnose`` names.
"""

"""The TEM + Nitinol heat balance of the two-layer wrist.

- ``heat_balance``: Eqs. 4.7-4.15, Table 4.9 (numpy reference, N scenarios); ``kernel``: its RK4 step,
  compiled (shared by the plant and the TEM law).
- ``params_file``: an identified heat balance (Table 4.9 layout) the wrist loads.
- ``identification``: the heat balance from measured runs (Sec. 4.3.2, Tables 4.9-4.10).
"""

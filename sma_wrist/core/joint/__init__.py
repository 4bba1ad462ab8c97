"""The wrist joint: chain/sprocket kinematics and rigid-body dynamics.

- ``dynamics``: Eqs. 4.16-4.18 (numpy reference); ``kernel``: the compiled joint step every plant calls.
"""

"""``sma-wrist commission``: a wrist the package has never seen, from first power-on to a params file.

This is the first stage, the bring-up (sma_wrist/commission/bringup.py): link, sensors, which TEM moves which
muscle and which way, which way the angle turns; wiring faults found and named with their fix before any closed
loop runs, the TEMs at 0 V on anything unsafe. doc/howto/commission.md says how to run it and what it measured.

* :mod:`sma_wrist.commission.detect`: the numerical decisions (pure functions);
* :mod:`sma_wrist.commission.device`: the serial port (the bridge's link) or the emulated device in lockstep;
* :mod:`sma_wrist.commission.run`: the command (params, report, JSON, exit codes).
"""

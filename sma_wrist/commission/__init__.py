"""``sma-wrist commission``: a wrist the package has never seen, from first power-on to a params file.

First the bring-up (sma_wrist/commission/bringup.py): link, sensors, which TEM moves which muscle and which way,
which way the angle turns; wiring faults found and named with their fix before any closed loop runs, the TEMs at
0 V on anything unsafe. Then an excitation (excite.py) through the same checks, from which the heat balance, the
wire's shift, the payload, friction and pre-load are identified and validated on a held-out cycle
(identification.py). Then the verification (verify.py): the closed loop with the params file handed over against
the defaults. doc/howto/commission.md says how to run it, doc/explanation/commissioning.md what it
was measured against.

* :mod:`sma_wrist.commission.detect`: the numerical decisions (pure functions);
* :mod:`sma_wrist.commission.device`: the serial port (the bridge's link) or the emulated device in lockstep;
* :mod:`sma_wrist.commission.verify`: the Sec. 6.1 sine in closed loop, defaults against commissioned, diagnosed;
* :mod:`sma_wrist.commission.run`: the command (params, report, JSON, exit codes).
"""

"""``sma-wrist sweep``: many closed loops over plants that are not the controllers' model.

:mod:`sma_wrist.sweep.simulate` runs N loops as one vectorised simulation (the node graph's
computation, wrists in lockstep), :mod:`sma_wrist.sweep.laws` holds the N-wrist paths of the
per-wrist compositions (joint controller, TEM loop), :mod:`sma_wrist.sweep.run` the sampling,
chunks (locally or on a Dask cluster), outputs and plots. doc/howto/sweep.md.
"""

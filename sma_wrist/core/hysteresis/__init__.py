"""The Nitinol wire: hysteresis model, its identification and its inverse.

- ``play``: play / stop operators, the memory of the Prandtl-Ishlinskii family (Eqs. 3.16-3.19).
- ``sdgpi``: GPI and stress-dependent GPI (Eqs. 3.19-3.25, 4.1-4.6), numpy reference, N scenarios.
- ``muscle``: a bundle of wires whose load follows from its elongation; ``kernel``: that load solve
  with the SD-GPI, compiled (the plant kernel calls it per muscle and step).
- ``default_params``: the default SD-GPI set (Nitinol #6); ``seed_params``: the seed's printed
  Tables 4.1-4.3 and 4.5-4.6 under named conventions; ``params_file``: ``hysteresis.yaml``.
- ``identification`` / ``identification_kernel``: GPI / SD-GPI fit from measured loops
  (Secs. 4.1.1, 4.2.2) and its exact-Jacobian play recursion, compiled.
- ``inverse``: inverse compensation (Eqs. 5.5-5.15); ``compensation``: the same in the wrist's
  coordinates (bundle strain + wire stress -> temperature). Both compile their inner searches in place.
"""

"""Acceptance studies: each measures a method against its reference on the scenes of its
acceptance criteria and returns the numbers quoted in ``docs/<method>.md``.

:mod:`~prefilter.studies.leadr` (point light, environment, convergence and flicker of LEADR),
:mod:`~prefilter.studies.colormap` (the four colour-map cases near and far),
:mod:`~prefilter.studies.ltc_aniso` (the anisotropic table against Monte Carlo quad integrals).
``prefilter demo``, the acceptance tests and ``benchmarks/`` run them; no library module imports
them.
"""

"""Experiments: the seed's evaluation rerun in the simulated tank, and the demo's building blocks.

Each experiment is a module of this package that defines ``NAME`` (its command-line name),
``SUMMARY`` (one line), optionally ``add_arguments(parser)`` for its own options, and
``run(config: ExperimentConfig) -> ExperimentReport``. ``registry`` discovers them, so a new
experiment plugs in by adding its module, without editing any other file. Shared pieces:
``config`` (the run's settings), ``runner`` (parallel trials with per-trial seeds), ``report``
(results.json, report.md, figures), ``geometry`` (sonar placement), ``truth`` (what a localiser
should report), ``gating`` (the record window), ``labels`` (naming echoes from the ground truth),
``edge_scene``, ``position_measurement``, ``sweep_detectors``, ``noise_free_bias``, ``sweep_summary``
(the edge-target measurements of the range and angle sweeps).

Importing this package imports nothing heavy.
"""

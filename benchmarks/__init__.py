"""Benchmarks: timing of emulator, simulator and inference, reported as measurements (p50/p99/max
and counts, judged against the goals the docs state) with the machine, through
:mod:`benchmarks.report`. Run one with ``python -m benchmarks.<name>`` or all with
``python -m benchmarks``."""

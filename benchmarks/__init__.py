"""Benchmarks: timing of emulator, simulator and inference, reported as p50/p99/max with the
machine. Run one with ``python -m benchmarks.<name>`` or all with ``python -m benchmarks``."""

"""Run every benchmark in turn with its defaults: ``python -m benchmarks`` (or ``make bench``).

Each prints p50/p99/max and the machine. The emulator benchmark streams for 60 s.
"""

from __future__ import annotations

import subprocess
import sys

BENCHMARKS = ("bench_sim", "bench_recording_io", "bench_inference", "bench_emulator")


def main() -> int:
    failed = []
    for name in BENCHMARKS:
        print(f"\n=== benchmarks.{name} ===", flush=True)
        if subprocess.call([sys.executable, "-m", f"benchmarks.{name}"]) != 0:
            failed.append(name)
    if failed:
        print(f"\nfailed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

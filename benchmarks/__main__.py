"""Run every benchmark in turn with its defaults: ``python -m benchmarks`` (or ``make bench``;
``python -m benchmarks bench_sim bench_inference`` runs only those, in that order).

Each prints its measurements and the machine (:mod:`benchmarks.report`); the emulator
benchmark streams for 60 s and the pipeline benchmark for 600 s, so the whole run takes about
15 minutes. At the end, every measurement that missed its goal is listed again.
``--json FILE`` writes ``{"benchmarks": [<each benchmark's --json document>, ...]}``. The exit
status is 1 only when a benchmark broke (a missed goal is not a failure).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.report import description, json_file, run_main, write_json
from exohil.formats.measurement import Limit

BENCHMARKS = ("bench_sim", "bench_recording_io", "bench_inference", "bench_emulator",
              "bench_robot", "bench_pipeline")


def missed(documents: list[dict[str, Any]]) -> list[str]:
    """``bench: name = value unit (limit ...)`` for each FAIL measurement of ``documents``."""
    return [f"{doc['benchmark']}: {m['name']} = "
            f"{'—' if m['value'] is None else format(m['value'], '.4g')} {m['unit']} "
            f"(limit {Limit(**m['limit']).describe()})"
            for doc in documents for m in doc["measurements"] if m["verdict"] == "fail"]


def main() -> int:
    ap = argparse.ArgumentParser(description=description(__doc__))
    ap.add_argument("--json", type=json_file, metavar="FILE",
                    help="write every benchmark's measurements and machine to FILE (JSON)")
    ap.add_argument("names", nargs="*", metavar="NAME",
                    help=f"run only these, in this order (default: all: {' '.join(BENCHMARKS)})")
    args = ap.parse_args()
    unknown = [name for name in args.names if name not in BENCHMARKS]
    if unknown:
        ap.error(f"unknown benchmark {unknown[0]}: choose from {', '.join(BENCHMARKS)}")
    failed: list[str] = []
    documents: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as folder:
        for name in args.names or BENCHMARKS:
            print(f"\n=== benchmarks.{name} ===", flush=True)
            out = Path(folder) / f"{name}.json"
            if subprocess.call([sys.executable, "-m", f"benchmarks.{name}", "--json",
                                str(out)]) != 0:
                failed.append(name)
                continue
            documents.append(json.loads(out.read_text(encoding="utf-8")))
    lines = missed(documents)
    print(f"\n=== goals missed: {len(lines) or 'none'} ===")
    for line in lines:
        print(line)
    if args.json is not None:
        write_json(args.json, {"benchmarks": documents})
    if failed:
        print(f"\nfailed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    run_main(main, interrupted="the benchmarks run so far are not reported")

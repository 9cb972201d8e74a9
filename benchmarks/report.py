"""How every benchmark reports: its figures are :class:`~exohil.formats.measurement.Measurement`
objects, printed as one aligned table under the machine line and, with ``--json FILE``, written
as::

    {"benchmark": name, "machine": str,
     "measurements": [{"name", "value", "unit", "limit", "verdict", "note"}, ...]}

A figure with a goal stated in the docs carries it as its limit; a missed goal is reported as
FAIL and is never an error: a benchmark exits 0 unless its arguments are bad or it breaks.
"""

from __future__ import annotations

import argparse
import json
import math
import os
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from exohil.formats.atomic import write_text
from exohil.formats.measurement import Measurement
from exohil.harness.machine import machine

EPILOG = ("Every figure is a measurement (name, value, unit, limit, verdict): a figure with a "
          "goal stated in the docs is judged PASS or FAIL against it, the others are INFO. "
          "A missed goal does not change the exit status (0); bad arguments or errors do. "
          "--json FILE writes {\"benchmark\", \"machine\", \"measurements\": [...]} "
          "(written to a temporary name, then renamed).")


def json_file(value: str) -> Path:
    """argparse type for ``--json FILE``: refused at once when FILE's folder does not exist
    (rather than after the benchmark ran)."""
    path = Path(value)
    if not path.parent.is_dir():
        raise argparse.ArgumentTypeError(f"no such folder: {path.parent}")
    return path


def positive_int(value: str) -> int:
    """argparse type: an integer ≥ 1."""
    number = int(value)
    if number < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return number


def positive_float(value: str) -> float:
    """argparse type: a finite number > 0."""
    number = float(value)
    if not (math.isfinite(number) and number > 0):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {value}")
    return number


def parser(doc: str) -> argparse.ArgumentParser:
    """An argument parser described by the first paragraph of ``doc`` (a benchmark's module
    docstring), with ``--json FILE`` and the epilog on measurements and exit status."""
    ap = argparse.ArgumentParser(description=" ".join(doc.split("\n\n")[0].split()),
                                 epilog=EPILOG)
    ap.add_argument("--json", type=json_file, metavar="FILE",
                    help="also write the measurements and the machine to FILE (JSON)")
    return ap


def load_average() -> str:
    """The 1/5/15-minute load averages (the machine may be shared; tails depend on them)."""
    return "/".join(f"{v:.2f}" for v in os.getloadavg())


def _value(m: Measurement) -> str:
    """Whole counts (frames, bytes) in full, other values to 6 significant digits."""
    if math.isnan(m.value):
        return "—"
    if m.unit == "count" and m.value.is_integer():
        return f"{m.value:.0f}"
    return f"{m.value:.6g}"


def table(measurements: Sequence[Measurement]) -> list[str]:
    """The measurements as aligned lines: name, value, unit, limit, verdict, note."""
    rows = [("measurement", "value", "unit", "limit", "verdict", "note")]
    rows += [(m.name, _value(m), m.unit, m.limit.describe() if m.limit else "",
              m.verdict.value.upper(), m.note) for m in measurements]
    widths = [max(len(row[i]) for row in rows) for i in range(5)]
    return [f"{name:<{widths[0]}}  {value:>{widths[1]}}  {unit:<{widths[2]}}  "
            f"{limit:<{widths[3]}}  {verdict:<{widths[4]}}  {note}".rstrip()
            for name, value, unit, limit, verdict, note in rows]


def verdict_line(measurements: Sequence[Measurement]) -> str:
    """``verdicts: 2 pass, 1 fail, 12 info`` (only the verdicts that occur)."""
    counts = Counter(m.verdict.value for m in measurements)
    return "verdicts: " + ", ".join(f"{n} {v}" for v, n in counts.items())


def document(benchmark: str, measurements: Sequence[Measurement]) -> dict[str, Any]:
    """The JSON document of one benchmark's report (module doc)."""
    return {"benchmark": benchmark, "machine": machine(),
            "measurements": [m.to_dict() for m in measurements]}


def write_json(path: Path, content: Any) -> None:
    """``content`` as JSON in ``path``, written to a temporary name and renamed into place."""
    write_text(path, json.dumps(content, indent=2) + "\n")


def report(benchmark: str, measurements: Sequence[Measurement],
           json_path: Path | None = None) -> None:
    """Print the machine line, the table and the verdict counts; write ``json_path`` if given."""
    print(f"machine: {machine()}")
    for line in table(measurements):
        print(line)
    print(verdict_line(measurements))
    if json_path is not None:
        write_json(json_path, document(benchmark, measurements))

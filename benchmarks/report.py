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
import signal
import sys
import threading
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import InvalidStateError
from pathlib import Path
from types import FrameType, TracebackType
from typing import Any, NoReturn

from exohil.formats.atomic import same_file, write_text
from exohil.formats.errors import InputError
from exohil.formats.measurement import Measurement
from exohil.harness.cli_types import cannot_write_in
from exohil.harness.machine import machine

EPILOG = ("Every figure is a measurement (name, value, unit, limit, verdict): a figure with a "
          "goal stated in the docs is judged PASS or FAIL against it, the others are INFO. "
          "A missed goal does not change the exit status (0); bad arguments or errors do. "
          "--json FILE writes {\"benchmark\", \"machine\", \"measurements\": [...]} "
          "(written to a temporary name, then renamed).")


class BenchmarkError(InputError):
    """Bad input a benchmark finds only once it runs (too short a run to measure, ...); its
    message is printed as one ``error:`` line by :func:`run_main`."""


#: this process's id: a process forked from it (a pool worker) has another
_MAIN_PID = os.getpid()


def file_name(value: str) -> Path:
    """argparse type for an output file whose folder may not exist yet: refused at once when
    the name is empty or names an existing folder."""
    if not value.strip():
        raise argparse.ArgumentTypeError("empty file name")
    path = Path(value)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{path} is a folder, not a file")
    return path


def json_file(value: str) -> Path:
    """argparse type for ``--json FILE`` (and other output files): refused at once, rather
    than after the benchmark ran, when the name is empty or an existing folder, or when its
    folder does not exist or takes no files."""
    path = file_name(value)
    if not path.parent.is_dir():
        raise argparse.ArgumentTypeError(f"no such folder: {path.parent}")
    problem = cannot_write_in(path.parent)
    if problem:
        raise argparse.ArgumentTypeError(f"cannot write in folder {path.parent}: {problem}")
    return path


def gif_file(value: str) -> Path:
    """argparse type for ``--gif FILE``: a :func:`json_file` whose name ends in ``.gif``
    (the animation is GIF data whatever the name says)."""
    path = json_file(value)
    if path.suffix.lower() != ".gif":
        raise argparse.ArgumentTypeError(f"{path}: the animation is a GIF, name it *.gif")
    return path


def out_folder(value: str) -> Path:
    """argparse type for an output folder (created later): refused at once when the name is
    empty or names an existing file."""
    if not value.strip():
        raise argparse.ArgumentTypeError("empty folder name")
    path = Path(value)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{path} exists and is not a folder")
    return path


def refuse_overwrite(ap: argparse.ArgumentParser, option: str, output: Path | None,
                     inputs: Iterable[str | Path]) -> None:
    """Refuse (``ap.error``: one line, exit 2, before anything runs) an ``output`` that names
    one of the ``inputs`` the benchmark reads."""
    if output is None:
        return
    hit = same_file(output, inputs)
    if hit is not None:
        ap.error(f"{option} {output} would overwrite the input {hit}")


def _exit_quietly(_signum: int, _frame: FrameType | None) -> None:
    """SIGINT in a worker (forked or spawned): end at once without a traceback; the main
    process reports the interruption."""
    os._exit(130)


def _interrupt(signum: int, frame: FrameType | None) -> None:
    if os.getpid() != _MAIN_PID:  # inherited by a forked worker
        _exit_quietly(signum, frame)
    raise KeyboardInterrupt


def _raised_in_terminate_broken(tb: TracebackType | None) -> bool:
    """Whether the traceback ``tb`` passes through the process pool's ``terminate_broken``
    (``concurrent/futures/process.py``)."""
    while tb is not None:
        code = tb.tb_frame.f_code
        if code.co_name == "terminate_broken" and Path(code.co_filename).parts[-3:] == (
                "concurrent", "futures", "process.py"):
            return True
        tb = tb.tb_next
    return False


def _quiet_cancelled_future_race(hook: Callable[[threading.ExceptHookArgs], object]
                                 ) -> Callable[[threading.ExceptHookArgs], None]:
    """``threading.excepthook`` that drops the one error Python 3.11's process pool raises in
    its manager thread on Ctrl-C, and hands any other to ``hook``.

    On Ctrl-C the pool's map cancels its pending futures while the workers end; the manager
    thread, finding the pool broken, then sets an exception on the futures just cancelled
    and raises ``InvalidStateError`` (CPython gh-107219, fixed in 3.12): a traceback after
    the one line this process means to print, now and then (a CI run of the Ctrl-C test)."""
    def excepthook(args: threading.ExceptHookArgs) -> None:
        if args.exc_type is InvalidStateError and _raised_in_terminate_broken(
                args.exc_traceback):
            return
        hook(args)
    excepthook.quiets_cancelled_future_race = True  # type: ignore[attr-defined]
    return excepthook


def run_main(main: Callable[[], object], interrupted: str = "nothing written") -> NoReturn:
    """Run a benchmark's ``main`` and exit: with the status it returns (0 for None), 2 with
    one line ``error: ...`` for bad input it found (the project's
    :class:`~exohil.formats.errors.InputError`: a checkpoint, a recording, a session; an
    operating-system error), 130 with
    ``interrupted; <interrupted>`` on Ctrl-C. Other exceptions are bugs and keep their
    traceback. Worker processes end silently on Ctrl-C, so that pools stop at once. Started
    with SIGINT ignored (a command a script starts in the background), the benchmark and its
    workers ignore it."""
    if threading.current_thread() is threading.main_thread() and _sigint_handled():
        signal.signal(signal.SIGINT, _interrupt)
    if sys.version_info < (3, 12) and not getattr(threading.excepthook,
                                                  "quiets_cancelled_future_race", False):
        threading.excepthook = _quiet_cancelled_future_race(threading.excepthook)
    try:
        status = main()
    except KeyboardInterrupt:
        print(f"interrupted; {interrupted}", file=sys.stderr)
        sys.exit(130)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}", file=sys.stderr)
        sys.exit(2)
    sys.exit(status if isinstance(status, int) else 0)


def _sigint_handled() -> bool:
    """Whether SIGINT is not ignored in this process (a process started with it ignored
    leaves it ignored, and so do the processes it spawns)."""
    return signal.getsignal(signal.SIGINT) is not signal.SIG_IGN


if "--multiprocessing-fork" in sys.orig_argv and _sigint_handled():  # a spawned worker
    signal.signal(signal.SIGINT, _exit_quietly)


def positive_int(value: str) -> int:
    """argparse type: an integer ≥ 1."""
    number = int(value)
    if number < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return number


def non_negative_int(value: str) -> int:
    """argparse type: an integer ≥ 0."""
    number = int(value)
    if number < 0:
        raise argparse.ArgumentTypeError(f"must be at least 0, got {value}")
    return number


def positive_float(value: str) -> float:
    """argparse type: a finite number > 0."""
    number = float(value)
    if not (math.isfinite(number) and number > 0):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {value}")
    return number


def description(doc: str) -> str:
    """The first paragraph of ``doc`` (a module docstring) on one line, for ``--help``."""
    return " ".join(doc.strip().split("\n\n")[0].split())


def generator_parser(doc: str) -> argparse.ArgumentParser:
    """The command line of a blind generator that writes its recordings and ``truth.json``
    to ``--out`` (``--without-effect``: the clean twins; ``--only N ...``: some of them),
    described by the first paragraph of its module docstring ``doc``."""
    parser = argparse.ArgumentParser(description=description(doc))
    parser.add_argument("--out", required=True, help="folder for the recordings and truth.json")
    parser.add_argument("--without-effect", action="store_true",
                        help="write each recording's clean twin (the effect computed, not "
                             "applied)")
    parser.add_argument("--only", type=int, nargs="*", metavar="N",
                        help="only these recordings (then no truth.json is written)")
    return parser


def finite_float(value: str) -> float:
    """argparse type: a finite number."""
    number = float(value)
    if not math.isfinite(number):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {value}")
    return number


def non_negative_float(value: str) -> float:
    """argparse type: a finite number ≥ 0."""
    number = float(value)
    if not (math.isfinite(number) and number >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number ≥ 0, got {value}")
    return number


def parser(doc: str, json_type: Callable[[str], Path] = json_file
           ) -> argparse.ArgumentParser:
    """An argument parser described by the first paragraph of ``doc`` (a benchmark's module
    docstring), with ``--json FILE`` (checked by ``json_type``) and the epilog on
    measurements and exit status."""
    ap = argparse.ArgumentParser(description=description(doc), epilog=EPILOG)
    ap.add_argument("--json", type=json_type, metavar="FILE",
                    help="also write the measurements and the machine to FILE (JSON)")
    return ap


def load_average() -> str:
    """The 1/5/15-minute load averages (the machine may be shared; tails depend on them)."""
    return "/".join(f"{v:.2f}" for v in os.getloadavg())


def _value(m: Measurement) -> str:
    """Whole counts (frames, bytes) in full, other values to 6 significant digits."""
    if math.isnan(m.value):
        return "—"
    if m.unit in ("count", "B") and m.value.is_integer():
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

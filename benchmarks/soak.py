"""Soak: the whole pipeline for half an hour at 250 Hz, faults on and recording; memory and
latency must hold steady.

``python -m benchmarks.soak [--minutes 30] --out DIR [--robot simulated|mujoco]
[--faults SPEC] [--json FILE]``: the emulator replays the held-out fixture cyclically on a
pty with the demo's fault schedule, and the session (acquisition, reference ENNet,
teleoperation, robot, recorder writing ``DIR/soak.mcap``) runs exactly as ``exohil demo``
does. A script for a quiet machine, not part of ``python -m benchmarks`` nor of the tests.

Goals (issue 13), as limits: zero host-side loss beyond the injected faults
(``link.lost_on_host``, ``link.dropped_unexplained``, ``link.bad_frames_delivered``,
``link.overflow`` all 0); resident memory growth after the first minute ≤ 5 %
(``soak.rss_growth``, from ``/proc/self/status`` VmRSS sampled every few seconds); the
end-to-end latency p99 of the last five minutes within 1.2× that of the first five
(``soak.latency_p99_ratio``). A run shorter than 10 minutes compares its first and last
halves, and measures growth from the middle when shorter than 2 minutes; ``--minutes 2`` is
the quick check.

End to end is device write → robot command of every frame, from the pipeline's status each
second (``Status.recent_latency_ms``) into 10-second histograms: the first window's are
merged, the last window's kept in a ring, so the script's memory is bounded too. Writes
``DIR/soak.mcap`` (every frame received), ``DIR/rss.csv`` (seconds, MiB) and
``DIR/soak.json`` (the report's JSON).
"""

from __future__ import annotations

import math
import time
from collections import deque

from benchmarks.bench_pipeline import HOST_LOSS_LIMITS
from benchmarks.report import (
    document,
    file_name,
    load_average,
    out_folder,
    parser,
    positive_float,
    refuse_overwrite,
    report,
    run_main,
    write_json,
)
from exohil.formats.atomic import write_text
from exohil.formats.measurement import Limit, Measurement
from exohil.harness.bench import BenchConfig, EmulatorDevice
from exohil.harness.cmd_demo import DEFAULT_FAULTS, DEFAULT_MODEL, DEFAULT_RECORDING
from exohil.harness.pipeline import LATENCY_HIGH_MS, LATENCY_LOW_MS, Status
from exohil.harness.robot_stats import LogHistogram
from exohil.harness.session import (
    histogram_distribution,
    latency_measurements,
    link_measurements,
    run_session,
    session_accuracy,
)

#: issue 13's goals
LIMITS = {
    **HOST_LOSS_LIMITS,
    "soak.rss_growth": Limit(high=5.0, unit="%", inclusive=True),
    "soak.latency_p99_ratio": Limit(high=1.2, unit="x", inclusive=True),
}
#: latency windows are made of slices this long, s
SLICE_S = 10.0
#: the windows compared, and when memory growth is measured from, s (at most)
WINDOW_S, RSS_FROM_S = 300.0, 60.0


def rss_mib() -> float | None:
    """This process's resident memory (VmRSS), MiB; psutil where /proc is missing."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    try:
        import psutil  # type: ignore[import-untyped]
    except ImportError:
        return None
    return float(psutil.Process().memory_info().rss) / 2**20


def _histogram() -> LogHistogram:
    return LogHistogram(LATENCY_LOW_MS, LATENCY_HIGH_MS)


class Monitor:
    """The session's progress callback: end-to-end latency into the first window's histogram
    and a ring of the last window's slices; RSS every ``rss_every_s``; a line a minute."""

    def __init__(self, window_s: float, rss_every_s: float) -> None:
        self.window_s = window_s
        self.rss_every_s = rss_every_s
        self.first = _histogram()
        self.last: deque[tuple[float, LogHistogram]] = deque(
            maxlen=max(1, math.ceil(window_s / SLICE_S)) + 1)
        self.rss: list[tuple[float, float]] = []
        self.start: float | None = None
        self._next_rss = 0.0
        self._next_line = 60.0
        self._minute = _histogram()

    def __call__(self, status: Status) -> None:
        now = time.perf_counter()
        if self.start is None:
            self.start = now
        t = now - self.start
        ms = status.recent_latency_ms.clip(min=0.0)
        if t < self.window_s:
            self.first.add_many(ms)
        begin = SLICE_S * math.floor(t / SLICE_S)
        if not self.last or self.last[-1][0] != begin:
            self.last.append((begin, _histogram()))
        self.last[-1][1].add_many(ms)
        self._minute.add_many(ms)
        if t >= self._next_rss:
            rss = rss_mib()
            if rss is not None:
                self.rss.append((t, rss))
            self._next_rss += self.rss_every_s
        if t >= self._next_line:
            memory = f"{self.rss[-1][1]:.1f} MiB" if self.rss else "?"
            p99 = self._minute.quantile(0.99)
            print(f"  {t / 60:5.1f} min  {status.frames} frames  dropped "
                  f"{status.link.dropped}  overflow {status.link.overflow}  p99 (last minute) "
                  f"{'—' if p99 is None else f'{p99:.3f}'} ms  RSS {memory}", flush=True)
            self._minute = _histogram()
            self._next_line += 60.0

    def last_window(self, end_s: float) -> tuple[LogHistogram, float]:
        """The slices of the last ``window_s`` before ``end_s`` merged, and where they begin."""
        merged = _histogram()
        begin = end_s
        for start, hist in self.last:
            if start >= end_s - self.window_s - 1e-9:
                merged.merge(hist)
                begin = min(begin, start)
        return merged, begin

    def rss_at(self, t: float) -> tuple[float, float] | None:
        """The first sample at or after ``t`` s (the last one if none)."""
        return next(((s, v) for s, v in self.rss if s >= t), self.rss[-1] if self.rss else None)


def soak_measurements(monitor: Monitor, run_s: float) -> list[Measurement]:
    """Memory growth and latency drift (module doc) with their limits."""
    out: list[Measurement] = []
    ref_s = min(RSS_FROM_S, run_s / 2)
    ref, end = monitor.rss_at(ref_s), (monitor.rss[-1] if monitor.rss else None)
    if ref is None or end is None:
        out.append(Measurement.skipped("soak.rss_growth", "%", "no RSS (no /proc, no psutil)",
                                       LIMITS["soak.rss_growth"]))
    else:
        samples = [v for _, v in monitor.rss]
        out += [
            Measurement.judge("soak.rss_start", ref[1], "MiB",
                              note=f"resident at {ref[0]:.0f} s"),
            Measurement.judge("soak.rss_end", end[1], "MiB",
                              note=f"resident at {end[0]:.0f} s"),
            Measurement.judge("soak.rss_max", max(samples), "MiB",
                              note=f"largest of {len(samples)} samples"),
            Measurement.judge("soak.rss_growth", 100.0 * (end[1] - ref[1]) / ref[1], "%",
                              LIMITS["soak.rss_growth"],
                              f"{end[1] - ref[1]:+.1f} MiB from {ref[0]:.0f} s to "
                              f"{end[0]:.0f} s"),
        ]
    last, begin = monitor.last_window(run_s)
    first_note = f"end to end, 0..{min(monitor.window_s, run_s):.0f} s"
    last_note = f"end to end, {begin:.0f}..{run_s:.0f} s"
    out += histogram_distribution("soak.latency_first", monitor.first, "ms", note=first_note)
    out += histogram_distribution("soak.latency_last", last, "ms", note=last_note)
    p_first, p_last = monitor.first.quantile(0.99), last.quantile(0.99)
    if p_first is None or p_last is None:
        out.append(Measurement.skipped("soak.latency_p99_ratio", "x", "no frames in a window",
                                       LIMITS["soak.latency_p99_ratio"]))
    else:
        out.append(Measurement.judge("soak.latency_p99_ratio", p_last / p_first, "x",
                                     LIMITS["soak.latency_p99_ratio"],
                                     f"p99 last {p_last:.3f} ms / first {p_first:.3f} ms"))
    return out


def main() -> None:
    ap = parser(__doc__, json_type=file_name)  # its folder may be --out, created below
    ap.add_argument("--minutes", type=positive_float, default=30.0,
                    help="device time to stream, minutes (default: 30; 2 for a quick check)")
    ap.add_argument("--out", type=out_folder, required=True,
                    help="folder for soak.mcap, rss.csv and soak.json (created)")
    ap.add_argument("--robot", default="simulated", help="robot target (simulated, mujoco)")
    ap.add_argument("--faults", default=DEFAULT_FAULTS, help="emulator fault spec")
    ap.add_argument("--rss-every", type=positive_float, default=5.0, metavar="S",
                    help="seconds between RSS samples (default: 5)")
    args = ap.parse_args()
    if args.json is not None and not (args.json.parent.is_dir()
                                      or args.json.parent.resolve() == args.out.resolve()):
        ap.error(f"argument --json: no such folder: {args.json.parent}")
    refuse_overwrite(ap, "--json", args.json, [DEFAULT_RECORDING, DEFAULT_MODEL])
    args.out.mkdir(parents=True, exist_ok=True)
    seconds = 60.0 * args.minutes
    window_s = min(WINDOW_S, seconds / 2)
    print(f"load average before: {load_average()}")
    config = BenchConfig(device=EmulatorDevice(DEFAULT_RECORDING, args.faults or None, 0,
                                               loop=True),
                         model=DEFAULT_MODEL, robots=(args.robot,),
                         record=args.out / "soak.mcap")
    print(f"soak: {args.minutes:g} min of {DEFAULT_RECORDING.name} (looped) at 250 Hz, faults "
          f"{args.faults!r}, robot {args.robot}, recording {config.record}", flush=True)
    monitor = Monitor(window_s, args.rss_every)
    result = run_session(config, seconds, progress=monitor)
    run_s = 0.0 if monitor.start is None else time.perf_counter() - monitor.start
    print(f"load average after: {load_average()}")
    print(f"device log: {result.fault_counts}")
    rss_csv = args.out / "rss.csv"
    write_text(rss_csv, "seconds,rss_mib\n" + "".join(f"{t:.1f},{v:.2f}\n"
                                                      for t, v in monitor.rss))
    measurements = (link_measurements(result, LIMITS) + soak_measurements(monitor, run_s)
                    + latency_measurements(result.run) + session_accuracy(result))
    report("soak", measurements, args.json)
    write_json(args.out / "soak.json", document("soak", measurements))


if __name__ == "__main__":
    run_main(main)

"""Emulator pacing and link latency (``python -m benchmarks.bench_emulator [--seconds 60]``).

The emulator runs in its own process (as ``exohil emulate`` would), streaming 250 Hz frames
over its pty; this process reads them with the harness's acquisition thread. Reported as
measurements through :mod:`benchmarks.report`, after the options and the load average, with
the targets of docs/emulator.md ("Benchmarks") as limits:

* ``frames.*`` and ``link.*``: frames generated, written and delivered, the emulator's fault
  log and the link's dropped / CRC error / overflow counts;
* ``rate.send|host`` (Hz): mean frame rate, 1 / least-squares slope of time against sequence
  number, at the send side (the emulator's ``perf_counter_ns`` right after each write) and at
  the host side (receive time); ``rate_error.send|host`` (%): its error against the nominal
  rate, target within ±0.05 %;
* ``period_jitter.send|host`` p50/p99/max (ms): |period − 1/rate| between consecutive frames,
  target p99 ≤ 0.5 ms;
* ``write_to_delivered`` p50/p99/max (ms): emulator write → frame delivered to the host buffer
  (same CLOCK_MONOTONIC in both processes), target p99 ≤ 1 ms.

``--realtime`` puts the emulator and reader threads under SCHED_FIFO (opt-in, needs
CAP_SYS_NICE), which is what keeps the timing on a machine shared with other work.
"""

from __future__ import annotations

import multiprocessing as mp
from collections import Counter
from multiprocessing.connection import Connection

import numpy as np

from benchmarks.report import (
    BenchmarkError,
    load_average,
    non_negative_float,
    parser,
    positive_float,
    report,
    run_main,
)
from exohil.formats.measurement import Limit, Measurement, distribution
from exohil.harness.acquisition import SerialFrameSource

SENSORS = 4

#: docs/emulator.md, "Benchmarks": the targets of the figures this benchmark reports
RATE_ERROR_LIMIT = Limit(low=-0.05, high=0.05, unit="%", inclusive=True)
JITTER_LIMITS = {"p99": Limit(high=0.5, unit="ms", inclusive=True)}
LATENCY_LIMITS = {"p99": Limit(high=1.0, unit="ms", inclusive=True)}


def run_emulator(rate_hz: float, seconds: float, realtime: bool, spin_s: float,
                 conn: Connection) -> None:
    """Child process: stream for ``seconds``, then report the send times and the fault log."""
    from exohil.emulators.arduino import ArduinoEmulator

    k = np.arange(1000)[:, None]
    values = 300.0 + 50.0 * np.sin(2 * np.pi * k / 1000.0 + np.arange(SENSORS)[None, :])
    emulator = ArduinoEmulator(values, rate_hz=rate_hz, loop=True, duration_s=seconds,
                               autostart=False, record_send_times=True, realtime=realtime,
                               spin_s=spin_s)
    with emulator:
        conn.send(emulator.port)
        conn.recv()  # the host is attached
        emulator.begin()
        emulator.wait_finished()
        conn.send((emulator.send_times, Counter(r.kind for r in emulator.fault_log),
                   emulator.frames_generated, emulator.realtime_error))


def rate_measurements(side: str, seq: np.ndarray, t_ns: np.ndarray,
                      nominal_hz: float) -> list[Measurement]:
    """Mean rate (Hz) as 1 / (least-squares slope of time against sequence number), and its
    error against ``nominal_hz`` (%, judged against :data:`RATE_ERROR_LIMIT`)."""
    slope_s = np.polyfit(seq - seq[0], (t_ns - t_ns[0]) / 1e9, 1)[0]
    rate = 1.0 / slope_s
    return [Measurement.judge(f"rate.{side}", rate, "Hz", note=f"{seq.size} frames"),
            Measurement.judge(f"rate_error.{side}", (rate / nominal_hz - 1) * 100, "%",
                              RATE_ERROR_LIMIT, note=f"vs {nominal_hz:g} Hz")]


def jitter_ms(seq: np.ndarray, t_ns: np.ndarray, nominal_hz: float) -> np.ndarray:
    """|period − 1/nominal_hz| between frames of consecutive sequence numbers, ms."""
    consecutive = np.diff(seq) == 1
    periods_ms = np.diff(t_ns)[consecutive] / 1e6
    return np.abs(periods_ms - 1000.0 / nominal_hz)


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--seconds", type=positive_float, default=60.0, help="streaming time (s)")
    ap.add_argument("--rate", type=positive_float, default=250.0, help="frame rate (Hz)")
    ap.add_argument("--spin-ms", type=non_negative_float, default=0.3,
                    help="emulator's spin before each deadline (ms; at most one period)")
    ap.add_argument("--read-timeout-ms", type=positive_float, default=1.0,
                    help="reader's longest blocking read (ms); each return re-polls the tty")
    ap.add_argument("--realtime", action="store_true",
                    help="emulator and reader threads under SCHED_FIFO (CAP_SYS_NICE)")
    args = ap.parse_args()
    if args.spin_ms > 1000.0 / args.rate:
        ap.error(f"--spin-ms {args.spin_ms:g}: longer than the {1000.0 / args.rate:g} ms "
                 f"period of --rate {args.rate:g}")
    print(f"options: {args.seconds:g} s at {args.rate:g} Hz, spin {args.spin_ms:g} ms, read "
          f"timeout {args.read_timeout_ms:g} ms, SCHED_FIFO "
          f"{'requested' if args.realtime else 'no'}")
    print(f"load average before: {load_average()}")

    parent, child = mp.get_context("spawn").Pipe()
    # a daemon, and terminated on any error here: the child must never outlive this process
    # (it would wait for "go" forever and multiprocessing would wait for it)
    process = mp.get_context("spawn").Process(target=run_emulator,
                                              args=(args.rate, args.seconds, args.realtime,
                                                    args.spin_ms / 1000.0, child), daemon=True)
    process.start()
    try:
        port = parent.recv()
        received: list[tuple[int, int]] = []
        with SerialFrameSource(port, buffer_frames=1 << 16, realtime=args.realtime,
                               read_timeout_s=args.read_timeout_ms / 1000.0) as source:
            if not source.wait_connected(30):
                raise BenchmarkError(f"could not open {port}: {source.last_error}")
            parent.send("go")
            # Block (no GIL held) until the emulator is done: the buffer holds every frame, so
            # no consumer thread competes with the reader thread while it is being measured.
            send_times, faults, generated, emulator_rt_error = parent.recv()
            while (frame := source.get(timeout=0.5)) is not None:
                received.append((frame.seq, frame.host_ns))
            link = source.stats()
            reader_rt_error = source.realtime_error
        process.join(10)
    finally:
        if process.is_alive():
            process.terminate()
            process.join(5)
    if args.realtime:
        print(f"SCHED_FIFO: emulator {emulator_rt_error or 'yes'}, "
              f"reader {reader_rt_error or 'yes'}")
    print(f"load average after: {load_average()}")

    if min(len(send_times), len(received)) < 2:
        raise BenchmarkError(f"{len(send_times)} frames written, {len(received)} delivered: "
                             "too few frames to measure a rate (stream longer: --seconds)")
    sent = np.array(send_times, dtype=np.int64)
    got = np.array(received, dtype=np.int64)
    measurements = [
        Measurement.judge("frames.generated", generated, "count"),
        Measurement.judge("frames.written", len(sent), "count"),
        Measurement.judge("frames.delivered", len(got), "count"),
        *(Measurement.judge(f"emulator_log.{kind}", n, "count")
          for kind, n in sorted(faults.items())),
        Measurement.judge("link.dropped", link.dropped, "count"),
        Measurement.judge("link.crc_errors", link.crc_errors, "count"),
        Measurement.judge("link.overflow", link.overflow, "count"),
        *rate_measurements("send", sent[:, 0], sent[:, 1], args.rate),
        *rate_measurements("host", got[:, 0], got[:, 1], args.rate),
        *distribution("period_jitter.send", jitter_ms(sent[:, 0], sent[:, 1], args.rate), "ms",
                      JITTER_LIMITS),
        *distribution("period_jitter.host", jitter_ms(got[:, 0], got[:, 1], args.rate), "ms",
                      JITTER_LIMITS),
    ]
    send_ns = dict(zip(sent[:, 0].tolist(), sent[:, 1].tolist(), strict=True))
    latency_ms = [(ns - send_ns[seq]) / 1e6 for seq, ns in got.tolist() if seq in send_ns]
    measurements += distribution("write_to_delivered", latency_ms, "ms", LATENCY_LIMITS)
    report("bench_emulator", measurements, args.json)


if __name__ == "__main__":
    run_main(main)

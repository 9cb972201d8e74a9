"""Emulator pacing and link latency (``python -m benchmarks.bench_emulator [--seconds 60]``).

The emulator runs in its own process (as ``exohil emulate`` would), streaming 250 Hz frames
over its pty; this process reads them with the harness's acquisition thread. Reported, as
p50/p99/max with the machine and its load average:

* mean frame rate (1 / least-squares slope of time against sequence number) and its error
  against the nominal rate, at the send side (the emulator's ``perf_counter_ns`` right after
  each write) and at the host side (receive time);
* period jitter |period − 1/rate| between consecutive frames, both sides, ms;
* emulator write → frame delivered to the host buffer, ms (same CLOCK_MONOTONIC in both
  processes).

``--realtime`` puts the emulator and reader threads under SCHED_FIFO (opt-in, needs
CAP_SYS_NICE), which is what keeps the timing on a machine shared with other work.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
from collections import Counter

import numpy as np

from exohil.harness.acquisition import SerialFrameSource
from exohil.harness.machine import machine

SENSORS = 4


def run_emulator(rate_hz: float, seconds: float, realtime: bool, spin_s: float, conn) -> None:
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


def stats_ms(samples_ms: np.ndarray) -> str:
    p50, p99 = np.percentile(samples_ms, [50, 99])
    return f"p50 {p50:.3f}  p99 {p99:.3f}  max {samples_ms.max():.3f} ms  (n={samples_ms.size})"


def rate_line(seq: np.ndarray, t_ns: np.ndarray, nominal_hz: float) -> str:
    """Mean rate as 1 / (least-squares slope of time against sequence number)."""
    slope_s = np.polyfit(seq - seq[0], (t_ns - t_ns[0]) / 1e9, 1)[0]
    rate = 1.0 / slope_s
    return f"{rate:.4f} Hz ({(rate / nominal_hz - 1) * 100:+.4f} % vs {nominal_hz:g} Hz)"


def jitter_ms(seq: np.ndarray, t_ns: np.ndarray, nominal_hz: float) -> np.ndarray:
    consecutive = np.diff(seq) == 1
    periods_ms = np.diff(t_ns)[consecutive] / 1e6
    return np.abs(periods_ms - 1000.0 / nominal_hz)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="streaming time (s)")
    parser.add_argument("--rate", type=float, default=250.0, help="frame rate (Hz)")
    parser.add_argument("--spin-ms", type=float, default=0.3,
                        help="emulator's spin before each deadline (ms)")
    parser.add_argument("--read-timeout-ms", type=float, default=1.0,
                        help="reader's longest blocking read (ms); each return re-polls the tty")
    parser.add_argument("--realtime", action="store_true",
                        help="emulator and reader threads under SCHED_FIFO (CAP_SYS_NICE)")
    args = parser.parse_args()
    print(f"machine: {machine()}")
    print(f"options: rate {args.rate:g} Hz, spin {args.spin_ms:g} ms, read timeout "
          f"{args.read_timeout_ms:g} ms, SCHED_FIFO {'requested' if args.realtime else 'no'}")
    print(f"load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")

    parent, child = mp.get_context("spawn").Pipe()
    process = mp.get_context("spawn").Process(target=run_emulator,
                                              args=(args.rate, args.seconds, args.realtime,
                                                    args.spin_ms / 1000.0, child))
    process.start()
    port = parent.recv()
    received: list[tuple[int, int]] = []
    with SerialFrameSource(port, buffer_frames=1 << 16, realtime=args.realtime,
                           read_timeout_s=args.read_timeout_ms / 1000.0) as source:
        if not source.wait_connected(30):
            raise SystemExit(f"could not open {port}: {source.last_error}")
        parent.send("go")
        # Block (no GIL held) until the emulator is done: the buffer holds every frame, so no
        # consumer thread competes with the reader thread while it is being measured.
        send_times, faults, generated, emulator_rt_error = parent.recv()
        while (frame := source.get(timeout=0.5)) is not None:
            received.append((frame.seq, frame.host_ns))
        link = source.stats()
        reader_rt_error = source.realtime_error
    process.join(10)
    if args.realtime:
        print(f"SCHED_FIFO: emulator {emulator_rt_error or 'yes'}, "
              f"reader {reader_rt_error or 'yes'}")

    sent = np.array(send_times, dtype=np.int64)
    got = np.array(received, dtype=np.int64)
    print(f"streamed {args.seconds:g} s at {args.rate:g} Hz: {generated} frames generated, "
          f"{len(sent)} written, {len(got)} delivered; emulator log {dict(faults)}; "
          f"link dropped {link.dropped}, crc {link.crc_errors}, overflow {link.overflow}")
    print(f"send-side mean rate:  {rate_line(sent[:, 0], sent[:, 1], args.rate)}")
    print(f"host-side mean rate:  {rate_line(got[:, 0], got[:, 1], args.rate)}")
    print(f"send-side period jitter: {stats_ms(jitter_ms(sent[:, 0], sent[:, 1], args.rate))}")
    print(f"host-side period jitter: {stats_ms(jitter_ms(got[:, 0], got[:, 1], args.rate))}")
    send_ns = dict(zip(sent[:, 0].tolist(), sent[:, 1].tolist(), strict=True))
    latency_ms = np.array([(ns - send_ns[seq]) / 1e6 for seq, ns in got.tolist()
                           if seq in send_ns])
    print(f"write -> delivered latency: {stats_ms(latency_ms)}")
    print(f"load average after: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()

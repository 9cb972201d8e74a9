"""The reference sketch (firmware/exohil_due/exohil_due.ino) run on the host against a small
model of the Arduino Due core: a simulated micros() clock, and SerialUSB / USB registers that
cost what ArduinoCore-sam's cost (cores/arduino/USB/CDC.cpp: ``operator bool`` calls
``delay(10)``; ``availableForWrite`` always 511; ``write`` spins while the IN bank is busy).
Compiled with the host C++ compiler; skipped when there is none."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from exohil.formats.wire import decode_packet

REPO = Path(__file__).resolve().parents[1]
SKETCH_DIR = REPO / "firmware" / "exohil_due"
PERIOD_US = 4000

# argv: seconds [stall_at_s stall_s [busy_from_s busy_to_s]], times since boot; environment:
# T0_US (micros() at setup, 0.6 s after boot; default 600000), NO_HOST="FROM_S TO_S" (DTR
# low). Prints "seq t_us HEX" per frame sent (HEX: the bytes written, delimiter included).
DRIVER = r"""
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
static uint64_t start_us(void) {  /* T0_US in the environment, else 0.6 s after boot */
    const char *t0 = getenv("T0_US"); return t0 ? strtoull(t0, NULL, 10) : 600000u;
}
static uint64_t g_now = start_us();
static const uint64_t g_start = g_now;
static double g_stall_at = -1, g_stall_s = 0, g_busy_from = -1, g_busy_to = -1;
/* seconds since boot: setup() runs 0.6 s after boot, at micros() = T0_US (mod 2^32) */
static double since_boot_s(void) { return 0.6 + (g_now - g_start) / 1e6; }
static double g_no_host[2] = {-1, -1};  /* NO_HOST="FROM_S TO_S": DTR low then (main) */
static int no_host(void) {
    double t = since_boot_s(); return t >= g_no_host[0] && t < g_no_host[1];
}
static uint32_t micros(void) { return (uint32_t)(g_now++); }   /* each call costs 1 us */
static void delay(uint32_t ms) { g_now += 1000u * (uint64_t)ms; }
static int bank_busy(void) {
    double t = since_boot_s(); return t >= g_busy_from && t < g_busy_to;
}
enum { A0 = 54, A1, A2, A3 };
static void analogReadResolution(int) {}
static int analogRead(int pin) { g_now += 40; return (pin * 97) % 4096; }
struct Uotghs { uint32_t UOTGHS_DEVEPTISR[10]; };
static Uotghs g_uotghs;
static Uotghs *uotghs(void) {
    g_uotghs.UOTGHS_DEVEPTISR[3] = bank_busy() ? 0u : 1u; return &g_uotghs;
}
#define UOTGHS (uotghs())
#define UOTGHS_DEVEPTISR_TXINI 1u
#define CDC_TX 3
struct Serial_ {
    void begin(uint32_t) {}
    bool dtr() { return !no_host(); }
    int availableForWrite() { return 511; }
    operator bool() { bool r = g_now >= 500000; delay(10); return r; }
    size_t write(const uint8_t *buf, size_t n) {
        while (bank_busy()) g_now += 10;                  /* UDD_Send: no timeout */
        if (g_stall_at >= 0 && since_boot_s() >= g_stall_at) {  /* one long stall */
            g_now += (uint64_t)(g_stall_s * 1e6); g_stall_at = -1;
        }
        uint8_t body[64]; size_t k = 0, i = 0;            /* decode seq and t_us */
        while (i < n - 1) {                               /* COBS decode */
            uint8_t code = buf[i++];
            for (uint8_t j = 1; j < code; ++j) body[k++] = buf[i++];
            if (code < 0xFF && i < n - 1) body[k++] = 0;
        }
        unsigned seq = body[1] | (body[2] << 8);
        uint32_t t = body[3] | (body[4] << 8) | (body[5] << 16) | ((uint32_t)body[6] << 24);
        printf("%u %lu ", seq, (unsigned long)t);
        for (size_t b = 0; b < n; ++b) printf("%02x", buf[b]);  /* the frame as sent */
        printf("\n");
        g_now += 30;
        return n;
    }
};
static Serial_ SerialUSB;
#include "exohil_due.ino"
int main(int argc, char **argv) {
    double seconds = atof(argv[1]);
    if (getenv("NO_HOST")) sscanf(getenv("NO_HOST"), "%lf %lf", &g_no_host[0], &g_no_host[1]);
    if (argc > 3) { g_stall_at = atof(argv[2]); g_stall_s = atof(argv[3]); }
    if (argc > 5) { g_busy_from = atof(argv[4]); g_busy_to = atof(argv[5]); }
    setup();
    uint64_t end = g_now + (uint64_t)(seconds * 1e6);
    unsigned long loops = 0;
    while (g_now < end) { loop(); ++loops; }
    fprintf(stderr, "%lu\n", loops);
    return 0;
}
"""


@pytest.fixture(scope="module")
def sketch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    compiler = shutil.which("c++") or shutil.which("g++") or shutil.which("clang++")
    if compiler is None:
        pytest.skip("no host C++ compiler")
    build = tmp_path_factory.mktemp("sketch")
    source = build / "driver.cpp"
    source.write_text(DRIVER)
    exe = build / "driver"
    subprocess.run([compiler, "-std=c++11", "-Wall", "-Werror", "-Wno-unused-function",
                    "-x", "c++", "-I", str(SKETCH_DIR), str(source), "-o", str(exe)],
                   check=True, capture_output=True, timeout=120)
    return exe


def _run(exe: Path, *args: float) -> list[tuple[int, int]]:
    return _run_loops(exe, *args)[0]


def _run_loops(exe: Path, *args: float, env: dict[str, str] | None = None
               ) -> tuple[list[tuple[int, int]], int]:
    """(seq, t_us) of each frame sent, and how many times loop() ran."""
    frames, loops = _run_bytes(exe, *args, env=env)
    return [(seq, t_us) for seq, t_us, _ in frames], loops


def _run_bytes(exe: Path, *args: float, env: dict[str, str] | None = None
               ) -> tuple[list[tuple[int, int, bytes]], int]:
    """(seq, t_us, bytes written) of each frame sent, and how many times loop() ran;
    ``env``: T0_US, NO_HOST (see DRIVER)."""
    done = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True,
                          check=True, timeout=60, env={**os.environ, **(env or {})})
    lines = (line.split() for line in done.stdout.splitlines())
    return [(int(a), int(b), bytes.fromhex(c)) for a, b, c in lines], int(done.stderr)


def test_sketch_sends_at_250_hz(sketch: Path) -> None:
    frames = _run(sketch, 4.0)
    assert 995 <= len(frames) <= 1001  # 250 Hz over 4 s, not ~99 Hz
    seqs = [s for s, _ in frames]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    steps = [b - a for (_, a), (_, b) in zip(frames, frames[1:], strict=False)]
    assert max(abs(s - PERIOD_US) for s in steps) < PERIOD_US // 4


def test_overrun_skips_ahead_and_counts_the_skipped_periods(sketch: Path) -> None:
    frames = _run(sketch, 3.0, 1.0, 0.1)  # one 100 ms stall in a write
    (gap_at,) = [k for k in range(1, len(frames)) if frames[k][0] != frames[k - 1][0] + 1]
    (s0, t0), (s1, t1) = frames[gap_at - 1], frames[gap_at]
    assert t1 - t0 >= 100_000 and abs((t1 - t0) - (s1 - s0) * PERIOD_US) < PERIOD_US
    after = frames[gap_at:gap_at + 10]  # back at the period at once: no catch-up burst
    assert all(b - a > PERIOD_US // 2 for (_, a), (_, b) in zip(after, after[1:], strict=False))
    assert 720 <= len(frames) <= 726


def test_stall_past_half_the_micros_range_costs_only_the_stall(sketch: Path) -> None:
    frames = _run(sketch, 2500.0, 1.0, 2200.0)  # 36.7 min stall (> 2^31 us)
    last_t = frames[-1][1]
    sim_end_us = (600_000 + 2_500_000_000) % 2**32
    assert abs(last_t - sim_end_us) < 2 * PERIOD_US  # it ran to the end of the simulation
    after = [t for _, t in frames if t > 2_200_000_000]
    assert len(after) >= 70_000  # ~300 s at 250 Hz after the stall, not a 36-min wait


def test_host_not_reading_drops_frames_instead_of_blocking(sketch: Path) -> None:
    frames, loops = _run_loops(sketch, 3.0, -1, 0, 1.0, 1.5)  # IN bank busy for 0.5 s
    assert loops == pytest.approx(750, abs=2)  # sampling went on: write() never spun
    seqs = [s for s, _ in frames]
    assert seqs[-1] - seqs[0] + 1 == pytest.approx(750, abs=2)  # periods still counted
    assert len(frames) == pytest.approx(750 - 125, abs=3)  # the busy 0.5 s is one gap
    times = [t for _, t in frames]
    assert max(b - a for a, b in zip(times, times[1:], strict=False)) < 510_000


def test_frames_decode_with_the_calibrated_values_across_the_micros_wrap(sketch: Path) -> None:
    """What the sketch writes, read by formats/wire.py (COBS, CRC): one frame per write,
    the header the driver read, the four pins' counts through the sketch's calibration
    (placeholders: 100 mm + counts * 500 mm / 4095, in 0.01 mm), and the period kept as
    micros() wraps at 2^32 µs one second in."""
    t0 = 2**32 - 1_000_000
    frames, _ = _run_bytes(sketch, 3.0, env={"T0_US": str(t0)})
    counts = [(pin * 97) % 4096 for pin in (54, 55, 56, 57)]  # the model's analogRead
    calibrated = [10000 + c * 50000 // 4095 for c in counts]
    assert 745 <= len(frames) <= 751
    for seq, t_us, data in frames:
        assert data[-1] == 0 and data.count(0) == 1
        frame = decode_packet(data[:-1], expected_sensors=4)
        assert (frame.seq, frame.t_us, list(frame.raw)) == (seq, t_us, calibrated)
    seqs = [seq for seq, _, _ in frames]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    steps = [(b - a) % 2**32 for (_, a, _), (_, b, _) in zip(frames, frames[1:], strict=False)]
    assert max(abs(s - PERIOD_US) for s in steps) < PERIOD_US // 4
    assert any(b < a for (_, a, _), (_, b, _) in zip(frames, frames[1:], strict=False))


def test_no_host_on_the_port_means_nothing_written_and_seq_counting_on(sketch: Path) -> None:
    """DTR low (no host has the port open) for 0.5 s: no write in it, sampling and the
    period count go on, so the host sees one gap of 125 frames when it opens again."""
    frames, loops = _run_loops(sketch, 3.0, env={"NO_HOST": "1.0 1.5"})
    assert loops == pytest.approx(750, abs=2)
    seqs = [s for s, _ in frames]
    gaps = [b - a for a, b in zip(seqs, seqs[1:], strict=False) if b - a != 1]
    assert len(gaps) == 1 and gaps[0] - 1 == pytest.approx(125, abs=1)

"""The firmware's C encoder (firmware/exohil_due/exohil_wire.h) sends the same bytes as
formats/wire.py: compiled with the host C compiler; skipped when there is none."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_wire_protocol import VECTORS, frames

from exohil.formats.wire import WireFrame, cobs_encode, encode_frame

REPO = Path(__file__).resolve().parents[1]
HEADER_DIR = REPO / "firmware" / "exohil_due"

# Reads lines "crc HEX" | "cobs HEX" | "frame SEQ T_US V1 V2 ..."; prints the result in hex.
DRIVER = r"""
#include <stdio.h>
#include <string.h>
#include "exohil_wire.h"

static size_t read_hex(const char *hex, uint8_t *out) {
    size_t n = 0; unsigned v;
    while (sscanf(hex, "%2x", &v) == 1) { out[n++] = (uint8_t)v; hex += 2; }
    return n;
}

int main(void) {
    char line[4096], word[16];
    uint8_t in[1024], out[1100];
    while (fgets(line, sizeof line, stdin)) {
        int used = 0;
        if (sscanf(line, "%15s %n", word, &used) != 1) continue;
        size_t n = 0;
        if (strcmp(word, "crc") == 0) {
            char hex[4096] = "";
            sscanf(line + used, "%4095s", hex);
            printf("%04x\n", exohil_crc16(in, read_hex(hex, in)));
            continue;
        } else if (strcmp(word, "cobs") == 0) {
            char hex[4096] = "";
            sscanf(line + used, "%4095s", hex);
            n = exohil_cobs_encode(in, read_hex(hex, in), out);
        } else {
            unsigned long seq, t_us; uint16_t values[32]; unsigned long v; int k = 0, c = 0;
            const char *p = line + used;
            sscanf(p, "%lu %lu %n", &seq, &t_us, &c); p += c;
            while (sscanf(p, "%lu %n", &v, &c) == 1) { values[k++] = (uint16_t)v; p += c; }
            n = exohil_frame_encode((uint16_t)seq, (uint32_t)t_us, values, (uint8_t)k, out);
        }
        for (size_t i = 0; i < n; ++i) printf("%02x", out[i]);
        printf("\n");
    }
    return 0;
}
"""

@pytest.fixture(scope="module")
def driver(tmp_path_factory: pytest.TempPathFactory) -> Path:
    compiler = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if compiler is None:
        pytest.skip("no host C compiler")
    build = tmp_path_factory.mktemp("wire_c")
    source = build / "driver.c"
    source.write_text(DRIVER)
    exe = build / "driver"
    subprocess.run([compiler, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic",
                    "-I", str(HEADER_DIR), str(source), "-o", str(exe)],
                   check=True, capture_output=True, timeout=60)
    return exe


def _run(driver: Path, lines: list[str]) -> list[str]:
    done = subprocess.run([str(driver)], input="\n".join(lines) + "\n", text=True,
                          capture_output=True, check=True, timeout=30)
    return done.stdout.split()


def _frame_line(frame: WireFrame) -> str:
    return " ".join(["frame", str(frame.seq), str(frame.t_us), *map(str, frame.raw)])


def test_c_crc_check_value(driver: Path) -> None:
    assert _run(driver, ["crc " + b"123456789".hex()]) == ["29b1"]


def test_c_encoder_matches_documented_vectors(driver: Path) -> None:
    out = _run(driver, [_frame_line(frame) for frame, _ in VECTORS])
    assert out == [wire.replace(" ", "") for _, wire in VECTORS]


@settings(max_examples=40)
@given(st.lists(frames, min_size=1, max_size=50))
def test_c_encoder_matches_python_for_random_frames(driver: Path, batch: list[WireFrame]) -> None:
    assert _run(driver, [_frame_line(f) for f in batch]) == [encode_frame(f).hex() for f in batch]


@settings(max_examples=40)
@given(st.lists(st.binary(min_size=1, max_size=600), min_size=1, max_size=5))
def test_c_cobs_matches_python(driver: Path, blobs: list[bytes]) -> None:
    assert _run(driver, ["cobs " + b.hex() for b in blobs]) == [cobs_encode(b).hex() for b in blobs]

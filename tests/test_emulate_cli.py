"""``exohil emulate`` end to end, read by an INDEPENDENT decoder written from
docs/wire-protocol.md (its own COBS and CRC; nothing from exohil.formats.wire)."""

from __future__ import annotations

import json
import os
import select
import struct
import subprocess
import sys
import termios
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from shared_data import SHARED_DIR

from exohil.formats.recording import Recording, SensorStream
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import write_recording
from exohil.formats.wire import off_the_wire
from exohil.harness.cli import main

REPO = Path(__file__).resolve().parents[1]
FOREIGN = SHARED_DIR / "samples" / "foreign-recording-v1.mcap"


# ---- the independent reader (from the documentation only) ----------------------------------


def _crc_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = (crc << 1) ^ 0x1021 if crc & 0x8000 else crc << 1
        table.append(crc & 0xFFFF)
    return table


CRC_TABLE = _crc_table()


def doc_crc(data: bytes) -> int:
    crc = 0xFFFF
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ CRC_TABLE[(crc >> 8) ^ byte]
    return crc


def doc_unstuff(packet: bytes) -> bytes | None:
    out, i = bytearray(), 0
    while i < len(packet):
        code = packet[i]
        if code == 0 or i + code > len(packet):
            return None
        out += packet[i + 1:i + code]
        i += code
        if code < 0xFF and i < len(packet):
            out.append(0)
    return bytes(out)


def doc_parse(packet: bytes) -> tuple[int, int, list[int]] | None:
    """(seq, t_us, values in 0.01 mm) or None when the packet is not a valid frame."""
    body = doc_unstuff(packet)
    if body is None or len(body) < 12 or body[0] != 0x11:
        return None
    count = body[7]
    if len(body) != 10 + 2 * count or doc_crc(body[:-2]) != int.from_bytes(body[-2:], "little"):
        return None
    seq, t_us = struct.unpack_from("<HI", body, 1)
    return seq, t_us, list(struct.unpack_from(f"<{count}H", body, 8))


def test_independent_reader_agrees_with_the_documented_check_value() -> None:
    assert doc_crc(b"123456789") == 0x29B1
    assert doc_parse(bytes.fromhex("02 11 01 01 01 01 01 0a 04 10 27 da 61 49 75 5f ea 02 4a")) \
        == (0, 0, [10000, 25050, 30025, 59999])


# ---- streaming ------------------------------------------------------------------------------


def _synthetic_recording(path: Path) -> Path:
    n = 3000
    k = np.arange(n)
    values = 300.0 + 150.0 * np.sin(2 * np.pi * k[:, None] / 500.0 + np.arange(4)[None, :])
    rec = Recording(("F", "SF", "SR", "R"), SensorStream(k, k / 250.0, values))
    write_recording(path, rec)
    return path


@pytest.fixture(params=["synthetic", "foreign"])
def recording_path(request, tmp_path: Path) -> Path:
    if request.param == "foreign":
        if not FOREIGN.is_file():
            pytest.skip("shared/samples/foreign-recording-v1.mcap is absent")
        return FOREIGN
    return _synthetic_recording(tmp_path / "synthetic.mcap")


def _emulate(*args: str, stderr: list[str] | None = None) -> list[tuple[int, int, list[int]]]:
    """Run `exohil emulate ARGS`, read its port until it exits; the frames decoded (and its
    stderr lines appended to ``stderr``)."""
    proc = subprocess.Popen([str(Path(sys.executable).parent / "exohil"), "emulate", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = proc.stdout.readline().strip()
        assert port, proc.stderr.read()
        fd = os.open(port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        termios.tcflush(fd, termios.TCIFLUSH)  # like pyserial's open(): "ready, from now on"
        stream = bytearray()
        while True:  # until the emulator exits and its port vanishes (EIO)
            select.select([fd], [], [], 5.0)
            try:
                chunk = os.read(fd, 65536)
            except BlockingIOError:
                assert proc.poll() is None, "emulator exited but the port did not vanish"
                continue
            except OSError:
                break
            if not chunk:
                break
            stream += chunk
        os.close(fd)
        assert proc.wait(timeout=30) == 0
        if stderr is not None:
            stderr += proc.stderr.read().splitlines()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    packets = bytes(stream).split(b"\x00")[:-1]
    frames = [f for f in map(doc_parse, packets) if f is not None]
    assert frames, "no valid frame"
    assert len(frames) == len(packets)  # no invalid packet at all without faults
    return frames


#: the fault kinds of frames a host never receives intact, as docs/emulator.md lists them
LOSING = {"drop", "corrupt", "truncate", "disconnect", "not_read"}


def test_emulate_streams_frames_an_independent_reader_decodes(recording_path: Path,
                                                              tmp_path: Path) -> None:
    rate, duration = 2000, 2.0
    generated = int(rate * duration)
    fault_log = tmp_path / "faults.jsonl"
    stderr: list[str] = []
    frames = _emulate(str(recording_path), "--rate", str(rate), "--duration", str(duration),
                      "--loop", "--fault-log", str(fault_log), stderr=stderr)
    assert stderr[-1].startswith(f"done: {generated} frames generated, ")
    assert f", {len(frames)} read by it; " in stderr[-1]  # the frames this reader decoded
    seqs = [seq for seq, _, _ in frames]
    # the emulator replays the recording's own numbering: sequence numbers the recording lacks
    # (the foreign sample has gaps) are never sent, looped over its seq span
    recorded = read_recording(recording_path).sensors.seq
    offsets = recorded - recorded[0]
    present = np.zeros(int(offsets[-1]) + 1, dtype=bool)
    present[offsets] = True
    assert seqs == sorted(seqs)
    # every frame generated is decoded or in the fault log, never both; how many the reader
    # decodes depends on it being scheduled at 2 kHz (benchmarks/bench_emulator.py measures it)
    log = [json.loads(line) for line in fault_log.read_text().splitlines()]
    lost = [r["seq"] for r in log if r["kind"] in LOSING]
    assert sorted(seqs + lost) == [int(recorded[0]) + k for k in range(generated)]
    absent = {int(recorded[0]) + k for k in range(generated) if not present[k % present.size]}
    assert absent == {r["seq"] for r in log
                      if r["details"].get("reason") == "absent from the recording"}
    rec = read_recording(recording_path)
    row_of = {int(offset): row for row, offset in enumerate(offsets)}
    expected = np.rint(rec.sensors.values / 0.01).astype(int)
    t_us0 = round(float(rec.sensors.t[0]) * 1e6)  # the device keeps the recording's clock
    for seq, t_us, values in frames:
        k = seq - int(recorded[0])
        assert t_us == t_us0 + k * 500  # 2 kHz device clock, µs
        assert values == expected[row_of[k % present.size]].tolist()


def test_emulate_streams_at_the_recordings_own_rate_by_default(tmp_path: Path) -> None:
    k = np.arange(200)
    values = 300.0 + 50.0 * np.sin(k[:, None] / 20.0 + np.arange(4)[None, :])
    path = tmp_path / "slow.mcap"
    write_recording(path, Recording(("F", "SF", "SR", "R"), SensorStream(k, k / 100.0, values),
                                    sensor_rate_hz=100.0))
    frames = _emulate(str(path))
    steps = np.diff([t_us for _, t_us, _ in frames])
    assert len(frames) > 100 and set(steps.tolist()) == {10_000}  # 100 Hz, in µs


def test_emulate_a_recording_whose_sequence_jumps_far_streams_its_start(tmp_path: Path) -> None:
    """The sequence grid spanned the whole recording whatever --duration said: a recording
    (format v1 allows it) whose seq jumps by 10**12 was an 'unexpected MemoryError' (and by
    10**9, 7.45 GiB per column allocated) before its first second could be streamed."""
    from exohil.emulators.arduino import _on_sequence_grid

    k = np.arange(400)
    seq = np.where(k < 200, k, k + 10**12)
    values = 300.0 + 50.0 * np.sin(k[:, None] / 20.0 + np.arange(4)[None, :])
    path = tmp_path / "jump.mcap"
    write_recording(path, Recording(("F", "SF", "SR", "R"), SensorStream(seq, k / 250.0, values)))
    result = CliRunner().invoke(main, ["emulate", str(path), "--duration", "0.2"])
    assert result.exit_code == 0, result.output
    assert "done: 50 frames generated" in result.stderr
    # the grid cut at a limit is the start of the whole grid, interpolated alike
    small = np.where(k < 200, k, k + 100)[::3]
    whole, present = _on_sequence_grid(small, values[::3])
    for limit in (1, 150, 199, 250, 300, 301, 1000):
        cut, cut_present = _on_sequence_grid(small, values[::3], limit)
        np.testing.assert_array_equal(cut, whole[:limit])
        np.testing.assert_array_equal(cut_present, present[:limit])


# ---- bad input -------------------------------------------------------------------------------


def test_emulate_rejects_bad_input_with_one_line(tmp_path: Path) -> None:
    runner = CliRunner()
    good = _synthetic_recording(tmp_path / "ok.mcap")
    not_mcap = tmp_path / "junk.mcap"
    not_mcap.write_bytes(b"not an mcap file")
    cases = [
        ["emulate", str(tmp_path / "missing.mcap")],
        ["emulate", str(not_mcap)],
        ["emulate", str(good), "--faults", "warp:speed=9"],
        ["emulate", str(good), "--faults", "drop:rate=7"],
        ["emulate", str(good), "--rate", "0"],
    ]
    for args in cases:
        result = runner.invoke(main, args)
        assert result.exit_code != 0, args
        assert result.exception is None or isinstance(result.exception, SystemExit), args
        lines = [line for line in result.output.splitlines() if line.startswith("Error")]
        assert len(lines) == 1, (args, result.output)


def test_emulate_refuses_readings_the_wire_cannot_carry_in_the_wording_of_every_refusal(
        tmp_path: Path) -> None:
    """A recording in V: the wire carries mm. The emulator, `run` and `demo` refused it in
    three wordings; all now say it as `off_the_wire` does."""
    rec = read_recording(_synthetic_recording(tmp_path / "mm.mcap"))
    rec.sensor_units = "V"
    volts = tmp_path / "volts.mcap"
    write_recording(volts, rec)
    result = CliRunner().invoke(main, ["emulate", str(volts), "--duration", "0.1"])
    assert result.exit_code == 1, result.output
    assert result.output.strip().splitlines()[-1] == (
        f"Error: {volts}: sensor values are in 'V'; wire protocol v1 carries mm")
    assert off_the_wire("V") == "sensor values are in 'V'; wire protocol v1 carries mm"
    assert off_the_wire("mm") is None


def test_emulate_refuses_a_fault_log_that_is_its_fault_file(tmp_path: Path) -> None:
    """`--faults f.toml --fault-log f.toml` streamed, then replaced the fault file with the
    log: the user's fault schedule was lost."""
    recording = _synthetic_recording(tmp_path / "ok.mcap")
    faults = tmp_path / "faults.toml"
    text = '[[fault]]\nkind = "drop"\nrate = 0.01\n'
    faults.write_text(text, encoding="utf-8")
    result = CliRunner().invoke(main, ["emulate", str(recording), "--duration", "0.1",
                                       "--faults", str(faults), "--fault-log", str(faults)])
    assert result.exit_code == 2, result.output
    assert "--fault-log" in result.output and "refusing to overwrite" in result.output
    assert "/dev/" not in result.output and "ttyEXOHIL" not in result.output
    assert faults.read_text(encoding="utf-8") == text


@pytest.mark.parametrize(("spec", "problem"), [
    ("noise:sigma_mm=1/1", "noise: sigma_mm lists 2 values for 4 sensors"),
    ("drift:rate_mm_per_s=1/2/3/4/5", "drift: rate_mm_per_s lists 5 values for 4 sensors"),
    ("drop:rate=0.1/0.2", "drop: rate takes one number, got [0.1, 0.2]"),
    ("stall:every_s=1/2", "stall: every_s takes one number"),
    ("disconnect:at_s=1/2", "disconnect: at_s takes one number"),
])
def test_emulate_refuses_faults_that_do_not_fit_before_streaming(spec: str,
                                                                  problem: str) -> None:
    """`noise:sigma_mm=1/1` started the emulator, printed its device path, then failed
    (exit 1); `drop:rate=0.1/0.2` gave a raw TypeError text."""
    recording = Path(__file__).resolve().parents[1] / "fixtures" / "paper_protocol.mcap"
    result = CliRunner().invoke(main, ["emulate", str(recording), "--duration", "0.2",
                                       "--faults", spec])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error") and problem in lines[0], lines
    assert "/dev/" not in result.output and "not supported" not in result.output



def test_emulate_warns_when_the_timestamps_disagree_with_the_nominal_rate(tmp_path: Path) -> None:
    """Another lab's recording says sensor_rate_hz=250 while its frames come at 100 Hz:
    `emulate` streamed it 2.5 times too fast without a word."""
    k = np.arange(200)
    values = 300.0 + 50.0 * np.sin(k[:, None] / 20.0 + np.arange(4)[None, :])
    path = tmp_path / "wrong.mcap"
    write_recording(path, Recording(("F", "SF", "SR", "R"), SensorStream(k, k / 100.0, values),
                                    sensor_rate_hz=250.0))
    result = CliRunner().invoke(main, ["emulate", str(path), "--duration", "0.1"])
    assert result.exit_code == 0, result.output
    assert (f"warning: {path}: metadata sensor_rate_hz=250 but its timestamps give 100 Hz; "
            "streaming at 250 Hz (--rate to choose)") in result.stderr
    chosen = CliRunner().invoke(main, ["emulate", str(path), "--duration", "0.1",
                                       "--rate", "100"])
    assert chosen.exit_code == 0 and "timestamps give" not in chosen.stderr


_TERM_WHILE_READING = """
import os, signal, sys
import exohil.harness.cmd_emulate as cmd
read = cmd._load_recording
def reading(path):  # a SIGTERM arrives while the recording is read (the slow start-up)
    os.kill(os.getpid(), signal.SIGTERM)
    return read(path)
cmd._load_recording = reading
from exohil.harness.cli import main
main(sys.argv[1:], prog_name="exohil")
"""


def test_a_sigterm_while_emulate_starts_up_ends_it_as_a_later_one_does(tmp_path: Path) -> None:
    """SIGTERM in emulate's first seconds (reading the recording, before its handler was
    installed) ended it with status 143 and no word; it ends as a later SIGTERM does: the
    done line (nothing generated), status 0, and the fault log written."""
    recording = _synthetic_recording(tmp_path / "r.mcap")
    log = tmp_path / "faults.jsonl"
    proc = subprocess.run([sys.executable, "-c", _TERM_WHILE_READING, "emulate", str(recording),
                           "--fault-log", str(log)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, (proc.returncode, proc.stderr)
    assert proc.stdout == ""  # no port was made
    assert proc.stderr.strip().splitlines()[-1] == \
        "done: 0 frames generated, 0 handed to the host, 0 read by it; faults: none", \
        proc.stderr
    assert log.read_text() == ""


def test_emulate_gives_back_the_sigterm_handler_it_found(tmp_path: Path) -> None:
    """Run in-process (click's runner), emulate left its SIGTERM handler behind it, also
    when it failed (it is installed before the recording is read)."""
    import signal

    before = signal.getsignal(signal.SIGTERM)
    recording = _synthetic_recording(tmp_path / "r.mcap")
    result = CliRunner().invoke(main, ["emulate", str(recording), "--duration", "0.1"])
    assert result.exit_code == 0, result.output
    assert signal.getsignal(signal.SIGTERM) is before
    failed = CliRunner().invoke(main, ["emulate", str(tmp_path / "missing.mcap")])
    assert failed.exit_code != 0 and signal.getsignal(signal.SIGTERM) is before

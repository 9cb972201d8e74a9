"""OpenSim ``.mot`` / ``.sto`` motion files (e.g. inverse-kinematics results).

Layout: a free-text header of ``key=value`` lines and prose, terminated by a line that reads
``endheader``; then one line of column labels (the first is ``time``) and one row per sample,
separated by tabs (any whitespace is accepted). ``inDegrees=yes`` means rotational coordinates
are in degrees (``no``: radians); translations are always metres. Values are returned exactly as
stored: this module does not convert units.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from exohil.formats.errors import InputError


class MotError(InputError, ValueError):
    """A ``.mot`` file that cannot be parsed; the message names the file and the problem."""


@dataclass
class MotData:
    """The contents of one ``.mot`` file.

    Attributes:
        time: (N,) float64 sample times, seconds, as stored (non-decreasing).
        columns: label → (N,) float64 values for every column except ``time``, in file order.
            Rotations are in degrees when ``in_degrees`` is true, else radians.
        in_degrees: the header's ``inDegrees`` flag (True when absent: OpenSim IK writes degrees).
        header: the header's ``key=value`` pairs as str → str (e.g. ``nRows``, ``version``).
    """

    time: np.ndarray
    columns: dict[str, np.ndarray]
    in_degrees: bool
    header: dict[str, str]

    @property
    def rate_hz(self) -> float:
        """Mean sample rate, Hz (NaN with fewer than two samples)."""
        if self.time.shape[0] < 2:
            return float("nan")
        return float((self.time.shape[0] - 1) / (self.time[-1] - self.time[0]))


def read_mot(path: str | Path) -> MotData:
    """Parse an OpenSim ``.mot`` file.

    Raises:
        MotError: missing ``endheader``, no ``time`` column, ragged or non-numeric rows,
            fewer than two rows, times that do not increase, or a row count that contradicts
            the header's ``nRows``.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise MotError(f"{path}: cannot read: {exc}") from exc
    lines = text.splitlines()
    end = next((i for i, line in enumerate(lines) if line.strip().lower() == "endheader"), None)
    if end is None:
        raise MotError(f"{path}: not an OpenSim .mot file: no 'endheader' line")
    header = _parse_header(lines[:end])
    body = [line for line in lines[end + 1 :] if line.strip()]
    if not body:
        raise MotError(f"{path}: no column labels after 'endheader'")
    labels = body[0].split()
    if not labels or labels[0].lower() != "time":
        raise MotError(f"{path}: first column must be 'time', found {labels[:1]}")
    if len(set(labels)) != len(labels):
        raise MotError(f"{path}: duplicate column labels")
    data = _parse_rows(path, body[1:], len(labels))
    expected_rows = header.get("nRows")
    if expected_rows is not None and expected_rows.isdigit() and int(expected_rows) != len(data):
        raise MotError(f"{path}: header says nRows={expected_rows} but {len(data)} rows follow")
    if len(data) < 2:
        raise MotError(f"{path}: {len(data)} data row(s); a motion needs at least two, "
                       "to give its times a rate")
    time = data[:, 0]
    steps = np.diff(time)
    if np.any(steps <= 0):
        row = int(np.argmax(steps <= 0)) + 2  # the later of the two rows, counted from 1
        how = "repeats" if steps[row - 2] == 0 else "goes back from"
        raise MotError(f"{path}: data row {row}: time {time[row - 1]:g} s {how} the row "
                       f"before's {time[row - 2]:g} s; times must increase")
    in_degrees = header.get("inDegrees", "yes").strip().lower() != "no"
    columns = {label: data[:, k].copy() for k, label in enumerate(labels) if k > 0}
    return MotData(time=time.copy(), columns=columns, in_degrees=in_degrees, header=header)


def _parse_header(lines: list[str]) -> dict[str, str]:
    header: dict[str, str] = {}
    for line in lines:
        key, sep, value = line.partition("=")
        if sep and key.strip() and " " not in key.strip():
            header[key.strip()] = value.strip()
    return header


def _parse_rows(path: Path, rows: list[str], width: int) -> np.ndarray:
    data = np.empty((len(rows), width), dtype=np.float64)
    for i, row in enumerate(rows):
        fields = row.split()
        if len(fields) != width:
            raise MotError(f"{path}: data row {i + 1} has {len(fields)} values, expected {width}")
        try:
            data[i] = [float(f) for f in fields]
        except ValueError as exc:
            raise MotError(f"{path}: data row {i + 1}: {exc}") from exc
    return data

"""Numeric CSV tables → recordings (importing other tools' data into recording format v1).

A table has one row per sample at a fixed rate; chosen columns become the sensor stream
(``seq`` = row index, ``t`` = row / rate) and chosen columns become one mocap joint's angles
(degrees) at the same times. Columns are 0-based. A UTF-8 byte-order mark and an optional
header row (detected: a first row whose selected cells are not all numbers) are handled.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from exohil.formats.errors import InputError
from exohil.formats.recording import AngleStream, Recording, SensorStream


class TableError(InputError, ValueError):
    """A CSV table or column specification that cannot be used; the message says why."""


#: The highest column index a spec may name (0-based).
MAX_COLUMN = 9999


def parse_columns(spec: str) -> list[int]:
    """0-based column indices from ``"1-5"``, ``"0"``, ``"1,3,6-8"`` (order kept, no repeats)."""
    columns: list[int] = []
    for part in spec.split(","):
        part = part.strip()
        low, dash, high = part.partition("-")
        try:
            first = int(low)
            last = int(high) if dash else first
        except ValueError:
            raise TableError(f"bad column spec {spec!r}: {part!r} is not N or N-M") from None
        if first < 0 or last < first or last > MAX_COLUMN:
            raise TableError(f"bad column spec {spec!r}: {part!r} must be "
                             f"0 <= N <= M <= {MAX_COLUMN}")
        columns.extend(range(first, last + 1))
    if len(set(columns)) != len(columns):
        raise TableError(f"bad column spec {spec!r}: a column appears twice")
    return columns


@dataclass
class Table:
    """A parsed numeric table: ``header`` labels (None when the file has none) and ``data``
    (R, C) float64 of the selected columns, in the order they were asked for."""

    header: list[str] | None
    data: np.ndarray


def read_table(
    path: str | Path, columns: Sequence[int], *, delimiter: str = ",", skip_rows: int = 0
) -> Table:
    """Read the selected ``columns`` of a delimited text file.

    Args:
        path: the file (UTF-8, optional BOM).
        columns: 0-based column indices to keep.
        delimiter: field separator.
        skip_rows: lines to drop before the header/data (e.g. a preamble).

    Raises:
        TableError: unreadable file, missing columns, non-numeric or non-finite data cells
            (NaN, inf), no data rows.
    """
    path = Path(path)
    try:
        with open(path, encoding="utf-8-sig", newline="") as stream:
            rows = [row for row in csv.reader(stream, delimiter=delimiter) if any(row)]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise TableError(f"{path}: cannot read: {exc}") from exc
    rows = rows[skip_rows:]
    if not rows:
        raise TableError(f"{path}: no rows after skipping {skip_rows}")
    width = max(columns) + 1
    header: list[str] | None = None
    if len(rows[0]) >= width and not all(_is_number(rows[0][c]) for c in columns):
        header = [rows[0][c].strip() for c in columns]
        rows = rows[1:]
    if not rows:
        raise TableError(f"{path}: header but no data rows")
    data = np.empty((len(rows), len(columns)), dtype=np.float64)
    for r, row in enumerate(rows):
        if len(row) < width:
            raise TableError(
                f"{path}: data row {r + 1} has {len(row)} columns; column {width - 1} is needed"
            )
        try:
            data[r] = [float(row[c]) for c in columns]
        except ValueError as exc:
            raise TableError(f"{path}: data row {r + 1}: {exc}") from exc
        if not np.isfinite(data[r]).all():
            c = columns[int(np.flatnonzero(~np.isfinite(data[r]))[0])]
            raise TableError(f"{path}: data row {r + 1}, column {c}: {row[c].strip()!r} is not a "
                             "finite number (a recording holds finite values only)")
    return Table(header=header, data=data)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def recording_from_table(
    data: np.ndarray,
    *,
    rate_hz: float,
    sensor_names: Sequence[str],
    angle_names: Sequence[str],
    joint: str,
    sensor_units: str,
    metadata: dict[str, str],
) -> Recording:
    """Build a recording from (R, S + A) rows: the first S columns are sensors, the rest are
    angles (degrees) of ``joint``; row k is at k / rate_hz seconds with seq k."""
    sensor_count = len(sensor_names)
    t = np.arange(data.shape[0], dtype=np.float64) / rate_hz
    mocap = {}
    if angle_names:
        mocap[joint] = AngleStream(t=t, names=tuple(angle_names), angles=data[:, sensor_count:])
    return Recording(
        sensor_names=tuple(sensor_names),
        sensors=SensorStream(
            seq=np.arange(data.shape[0], dtype=np.int64), t=t, values=data[:, :sensor_count]
        ),
        mocap=mocap,
        sensor_units=sensor_units,
        sensor_rate_hz=rate_hz,
        mocap_rate_hz=rate_hz,
        metadata=metadata,
    )

"""OpenSim .mot parsing: synthetic files for each rule, one real IK file when present."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from shared_data import SHARED_DIR

from exohil.formats.opensim_mot import MotError, read_mot

SHARED = SHARED_DIR
REAL_MOT = SHARED / "realdata" / "shoulder-ik" / "ABD01.mot"

HEADER = (
    "Coordinates\nversion=1\nnRows={n}\nnColumns=3\ninDegrees={deg}\n\n"
    "Units are S.I.\nendheader\n"
)


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "trial.mot"
    path.write_text(text, encoding="utf-8")
    return path


def test_synthetic_file_parses_columns_and_flags(tmp_path: Path) -> None:
    rows = "time\tplane_elv\tshoulder_elv\n  0.00\t 1.5\t 20.0\n  0.01\t-2.5\t 21.0\n"
    data = read_mot(_write(tmp_path, HEADER.format(n=2, deg="no") + rows))
    np.testing.assert_array_equal(data.time, [0.0, 0.01])
    assert list(data.columns) == ["plane_elv", "shoulder_elv"]
    np.testing.assert_array_equal(data.columns["plane_elv"], [1.5, -2.5])
    assert data.in_degrees is False
    assert data.header["nRows"] == "2"
    assert data.rate_hz == pytest.approx(100.0)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("time\ta\n0\t1\n", "endheader"),
        (HEADER.format(n=1, deg="yes") + "t\ta\n0\t1\n", "first column must be 'time'"),
        (HEADER.format(n=1, deg="yes") + "time\ta\n0\t1\t2\n", "row 1 has 3 values"),
        (HEADER.format(n=1, deg="yes") + "time\ta\n0\tx\n", "data row 1"),
        (HEADER.format(n=3, deg="yes") + "time\ta\n0\t1\n", "nRows=3"),
        (HEADER.format(n=2, deg="yes") + "time\ta\n1\t1\n0\t1\n",
         "data row 2: time 0 s goes back from the row before's 1 s"),
        # a repeated time: accepted by import mot, then refused by simulate naming no file
        (HEADER.format(n=3, deg="yes") + "time\ta\n0\t1\n0.01\t1\n0.01\t2\n",
         "data row 3: time 0.01 s repeats the row before's 0.01 s"),
        # no data row, one row: import mot wrote "0 samples at 100 Hz", simulate crashed
        (HEADER.format(n=0, deg="yes") + "time\ta\n", "0 data row"),
        (HEADER.format(n=1, deg="yes") + "time\ta\n0\t1\n", "1 data row"),
    ],
)
def test_malformed_files_raise_named_error(tmp_path: Path, text: str, problem: str) -> None:
    with pytest.raises(MotError, match=problem) as info:
        read_mot(_write(tmp_path, text))
    assert "trial.mot" in str(info.value)


@pytest.mark.skipif(not REAL_MOT.exists(), reason="shared/realdata/shoulder-ik absent")
def test_real_ik_file_parses() -> None:
    data = read_mot(REAL_MOT)
    assert data.in_degrees is True
    assert data.time.shape == (1091,)
    assert data.rate_hz == pytest.approx(100.0, rel=1e-6)
    for name in ("plane_elv", "shoulder_elv", "axial_rot"):
        assert data.columns[name].shape == (1091,)
    assert data.columns["plane_elv"][0] == pytest.approx(-18.55139173)
    assert 10.0 < float(np.max(data.columns["shoulder_elv"])) < 120.0

"""docs/conventions.md's example-pose table must match what the code computes."""

from pathlib import Path

import numpy as np
import pytest

from exohil.kinematics import humerus_to_nao, ms_to_isb, ms_to_quat, rotation_angle_between

DOC = Path(__file__).resolve().parents[1] / "docs" / "conventions.md"


def _table_rows():
    lines = DOC.read_text(encoding="utf-8").splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| θ elv_angle"))
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip("|").split("|")])
    return rows


def _triple(cell: str) -> np.ndarray:
    return np.array([float(v) for v in cell.replace("clamped", "").strip(" ()").split(",")])


@pytest.mark.parametrize("row", _table_rows(), ids=lambda r: "/".join(r[:3]))
def test_example_pose_row_matches_code(row):
    theta, phi, psi = np.deg2rad([float(v) for v in row[:3]])
    coupled = ms_to_quat(theta, phi, psi)
    paper = ms_to_quat(theta, phi, psi, convention="paper")
    assert np.allclose(np.rad2deg(ms_to_isb(theta, phi, psi)), _triple(row[3]), atol=0.051)
    paper_isb = np.rad2deg(ms_to_isb(theta, phi, psi, convention="paper"))
    assert np.allclose(paper_isb, _triple(row[4]), atol=0.051)
    gap = np.rad2deg(rotation_angle_between(coupled, paper))
    assert gap == pytest.approx(float(row[5].rstrip("°")), abs=0.051)
    for cell, q in ((row[6], coupled), (row[7], paper)):
        arm = humerus_to_nao(q)
        assert np.allclose(np.rad2deg(arm.angles), _triple(cell), atol=0.051)
        assert bool(arm.any_clamped) == ("clamped" in cell)

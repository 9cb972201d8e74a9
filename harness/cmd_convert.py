"""``exohil convert``: one shoulder pose from one convention to another, printed as JSON.

Angles are degrees at the command line and in the output; quaternions are (x, y, z, w).
"""

from __future__ import annotations

import json

import click
import numpy as np

from exohil.harness.cli_types import Finite
from exohil.kinematics import (
    NAO_JOINTS,
    humerus_to_nao,
    isb_to_quat,
    ms_to_quat,
    quat_to_isb,
    quat_to_ms,
    quat_to_zyx,
)
from exohil.kinematics.robot import Side
from exohil.kinematics.rotations import normalize_quat
from exohil.kinematics.shoulder import Axes, Convention

_SOURCES = {
    "ms": ("elv_angle", "shoulder_elv", "shoulder_rot"),
    "isb": ("plane_of_elevation", "elevation", "axial_rotation"),
    "quat": ("x", "y", "z", "w"),
}
#: The largest magnitude of an input value (degrees, or a quaternion component): far beyond
#: any angle, small enough that no conversion step overflows.
MAX_VALUE = 1e6
#: Decimal places in the JSON output (1e-9 deg, far below any physical meaning).
_DECIMALS = 9


def _clean(values: np.ndarray, half_open: dict[int, float] | None = None) -> list[float]:
    """Round for display and turn −0.0 into 0.0. ``half_open`` maps an index to the bound its
    range excludes (180 for [−180, 180), −180 for (−180, 180]): an angle a hair inside it
    would round onto it, and is printed as the other end, the same angle."""
    rounded = np.round(values, _DECIMALS) + 0.0
    for index, excluded in (half_open or {}).items():
        if rounded[index] == excluded:
            rounded[index] = -excluded
    return rounded.tolist()


#: Angles documented in a half-open range (docs/conventions.md): index → the excluded end.
_HALF_OPEN = {"ms": {0: 180.0, 2: 180.0}, "isb": {0: 180.0, 2: 180.0}}
#: NAO's exact (unclamped) pitch lies in (−180, 180].
_NAO_UNCLAMPED_HALF_OPEN = {0: -180.0}


class _Value(Finite):
    """A number of VALUES. ``ignore_unknown_options`` lets negative numbers through as
    arguments, and with them a mistyped option: name it as one, not as a bad number."""

    def convert(self, value, param, ctx):
        if isinstance(value, str) and value.startswith("-"):
            try:
                float(value)
            except ValueError:
                options = [] if ctx is None else [
                    opt for p in ctx.command.params for opt in p.opts if opt.startswith("--")]
                raise click.NoSuchOption(value.split("=", 1)[0], possibilities=options,
                                         ctx=ctx) from None
        return super().convert(value, param, ctx)


_TARGET_FIELDS = {
    "ms": _SOURCES["ms"],
    "isb": _SOURCES["isb"],
    "quat": _SOURCES["quat"],
    "zyx": ("z", "y_prime", "x_double_prime"),
    "nao": NAO_JOINTS,
}


def _to_quat(source: str, values: np.ndarray, convention: Convention, axes: Axes) -> np.ndarray:
    if source == "quat":
        return normalize_quat(values)
    radians = np.deg2rad(values)
    if source == "ms":
        return ms_to_quat(radians, axes=axes, convention=convention)
    return isb_to_quat(radians)


def _from_quat(target: str, q: np.ndarray, convention: Convention, side: Side,
               hint_deg: float) -> dict:
    hint = np.deg2rad(hint_deg)
    if target == "quat":
        return {"values": dict(zip(_TARGET_FIELDS["quat"], _clean(q), strict=True))}
    if target == "nao":
        arm = humerus_to_nao(q, side=side, hint=np.array([hint, 0.0, 0.0]))
        names = [f"{'R' if side == 'right' else 'L'}{n}" for n in NAO_JOINTS]
        return {
            "values": dict(zip(names, _clean(np.rad2deg(arm.angles)), strict=True)),
            "clamped": dict(zip(names, arm.clamped.tolist(), strict=True)),
            "any_clamped": bool(arm.any_clamped),
            "unclamped": dict(zip(names, _clean(np.rad2deg(arm.unclamped),
                                                _NAO_UNCLAMPED_HALF_OPEN), strict=True)),
        }
    if target == "ms":
        angles = quat_to_ms(q, plane_hint=hint, convention=convention)
    elif target == "isb":
        angles = quat_to_isb(q, plane_hint=hint)
    else:
        angles = quat_to_zyx(q, yaw_hint=hint)
    return {"values": dict(zip(_TARGET_FIELDS[target],
                               _clean(np.rad2deg(angles), _HALF_OPEN.get(target)), strict=True))}


@click.command(context_settings={"ignore_unknown_options": True})
@click.option("--from", "source", type=click.Choice(sorted(_SOURCES)), required=True,
              help="Input convention: ms (MoBL-ARMS θ φ ψ), isb (Y-X'-Y'' α β γ), quat (x y z w).")
@click.option("--to", "target", type=click.Choice(sorted(_TARGET_FIELDS)), required=True,
              help="Output: ms, isb, quat, zyx (intrinsic Z-Y'-X'', V-REP) or nao (arm joints).")
@click.option("--convention", type=click.Choice(["coupled", "paper"]), default="coupled",
              show_default=True,
              help="MS↔ISB step: 'coupled' (ISB γ = ψ − θ, the model's coupler) or the paper's.")
@click.option("--axes", type=click.Choice(["ideal", "mobl"]), default="ideal", show_default=True,
              help="--from ms only: MS → rotation with ideal ISB axes or the MoBL-ARMS model "
                   "file's axes (up to 8.3° apart); --to ms/isb always read ideal axes.")
@click.option("--side", type=click.Choice(["right", "left"]), default="right", show_default=True,
              help="Arm side for --to nao.")
@click.option("--hint", type=Finite(-360.0, 360.0), default=0.0, show_default=True,
              help="Degrees for the angle a singular pose leaves free: plane of elevation "
                   "(ms/isb), yaw (zyx), pitch (nao; also picks the pitch limit nearer the hint "
                   "where both are equally near, as for an arm horizontal behind the "
                   "shoulder).")
@click.argument("values", nargs=-1, required=True, type=_Value(-MAX_VALUE, MAX_VALUE))
def convert(source: str, target: str, convention: Convention, axes: Axes, side: Side,
            hint: float,
            values: tuple[float, ...]) -> None:
    """Convert one pose. VALUES are degrees (3 for ms/isb) or a quaternion (4: x y z w, of any
    length from 1e-12: it is normalised), each finite and within ±1e6. Prints JSON: the output
    angles in degrees (a quaternion for --to quat) under "values".

    Example: exohil convert --from ms --to nao 90 90 0
    """
    if axes == "mobl" and source != "ms":
        raise click.BadParameter(f"mobl applies to --from ms only; --from {source} would ignore "
                                 "it", param_hint="'--axes'")
    if axes == "mobl" and convention == "paper":
        raise click.BadParameter("paper cannot go with --axes mobl: the model file's coupler is "
                                 "the coupled form", param_hint="'--convention'")
    expected = len(_SOURCES[source])
    numbers = np.array(values, dtype=np.float64)
    if numbers.size != expected:
        raise click.BadParameter(
            f"--from {source} takes {expected} numbers "
            f"({' '.join(_SOURCES[source])}), got {len(values)}",
            param_hint="VALUES",
        )
    try:
        q = _to_quat(source, numbers, convention, axes)
    except ValueError as err:
        raise click.BadParameter(str(err), param_hint="VALUES") from None
    result = {
        "from": source,
        "to": target,
        "units": "deg" if target != "quat" else "unitless",
        "input": dict(zip(_SOURCES[source], numbers.tolist(), strict=True)),
        "convention": convention,
        "axes": axes,
    }
    result.update(_from_quat(target, q, convention, side, hint))
    click.echo(json.dumps(result, indent=2))


COMMANDS = [convert]

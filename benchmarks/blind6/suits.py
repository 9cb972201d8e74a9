"""The garments of the blind6 lab: where each textile sensor's strain comes from, and how a
sensor turns strain into a reading.

Four families:

* ``shoulder-res`` / ``shoulder-cap``: 3–6 stretch patches over the deltoid, each running from
  an anchor on the acromion / clavicle / scapular spine (thorax frame) to a point on the skin
  over the humerus, 35–55 mm off its long axis (so axial rotation ψ moves it). The patch lies
  on the skin, which wraps around the humeral head: its length is a polyline whose inner
  points are pushed out onto a sphere of 45–62 mm about the joint centre. The patch sits in
  series with the garment's fabric and takes a share of 25–50 % of the path's strain.
  Resistive patches
  read R = R_lead + R₀(1 + G ε + c G ε²) (ohm or kohm); capacitive ones C = C_p + C₀(1 + ε)^p
  (pF).
* ``elbow-sleeve``: 2–4 knitted resistive bands around the elbow at azimuth γ (0 posterior,
  over the olecranon); the skin stretches over the olecranon once flexion passes an onset
  angle (a softplus wrap) and folds in front: ΔL = r cos γ · wrap(θ) behind, and
  0.3 r cos γ · wrap(θ) − κ θ² on the anterior side. Reading R = R₀ exp(k ε) (kohm).
* ``wrist-band``: 2–4 knitted bands around the wrist at azimuth γ (0 dorsal, 90° radial);
  ΔL = r (cos γ · flexion + sin γ · deviation + c · flexion · deviation), compressed skin
  folding (ΔL < 0 counts about half). Knitted piezoresistive yarn: resistance falls with
  strain, R = R₀ / (1 + k ε + k₂ ε²), reported in ohm or as dR/R0.

Strain is ε = ΔL / L₀ + pretension, the pretension set so that the sensor stays taut over
the whole session (at least 1.5 % strain).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from benchmarks.blind6.motion import JointRange
from exohil.kinematics.shoulder import ms_to_matrix

Transfer = Callable[[np.ndarray], np.ndarray]


@dataclass
class Suit:
    """One garment on one joint.

    Attributes:
        family: short name (``shoulder-res``, ``shoulder-cap``, ``elbow-sleeve``, ``wrist-band``).
        joint: the mocap joint (``/mocap/<joint>``).
        motion: the joint's angle names, limits and rest pose.
        names: sensor names in column order.
        units: unit of the readings.
        raw_strain: angles (N, D) in degrees → strain without pretension (S, N).
        transfers: one strain → reading function per sensor.
        params: what was drawn, for the answer key.
    """

    family: str
    joint: str
    motion: JointRange
    names: tuple[str, ...]
    units: str
    raw_strain: Callable[[np.ndarray], np.ndarray]
    transfers: list[Transfer]
    params: dict[str, object] = field(default_factory=dict)


SHOULDER = JointRange(
    ("elv_angle", "shoulder_elv", "shoulder_rot"),
    np.array([-30.0, 5.0, -75.0]),
    np.array([110.0, 150.0, 25.0]),
    np.array([20.0, 12.0, -15.0]),
)
ELBOW = JointRange(("flexion",), np.array([5.0]), np.array([140.0]), np.array([15.0]))
WRIST = JointRange(
    ("flexion", "deviation"), np.array([-60.0, -25.0]), np.array([60.0, 30.0]),
    np.array([0.0, 0.0]),
)

# Deltoid patch sites: name, humerus azimuth (deg, 0 lateral, +90 anterior), anchor azimuth.
_DELTOID_SITES = [
    ("AD", 70.0, 115.0), ("AL", 35.0, 60.0), ("ML", 0.0, 0.0), ("PL", -35.0, -70.0),
    ("PD", -70.0, -125.0), ("SUP", 10.0, -30.0),
]


def _wrapped_length(anchor: np.ndarray, insertion: np.ndarray, radius: float) -> np.ndarray:
    """Length of a skin path from ``anchor`` (3,) to ``insertion`` (N, 3) that cannot enter a
    sphere of ``radius`` about the origin: 8 inner points on the straight line, each pushed
    out radially to the sphere when inside it."""
    s = np.linspace(0.0, 1.0, 10)[:, None, None]
    points = anchor[None, None] + s * (insertion[None] - anchor[None, None])
    norm = np.linalg.norm(points, axis=-1, keepdims=True)
    points = points * np.maximum(1.0, radius / np.maximum(norm, 1e-9))
    return np.linalg.norm(np.diff(points, axis=0), axis=-1).sum(axis=0)


def shoulder_suit(rng: np.random.Generator, capacitive: bool) -> Suit:
    """A deltoid patch garment with 3–6 resistive or capacitive stretch sensors."""
    count = int(rng.integers(3, 7))
    picks = np.sort(rng.choice(len(_DELTOID_SITES), size=count, replace=False))
    sites = [_DELTOID_SITES[k] for k in picks]
    radius = rng.uniform(0.045, 0.062)
    geometry = []
    for _, hum_az, anc_az in sites:
        b_az = np.radians(hum_az + rng.uniform(-10, 10))
        offset = rng.uniform(0.035, 0.055)
        insertion = np.array([offset * np.sin(b_az), -rng.uniform(0.07, 0.15),
                              offset * np.cos(b_az)])
        a_az = np.radians(anc_az + rng.uniform(-10, 10))
        reach = rng.uniform(0.04, 0.09)
        anchor = np.array([reach * np.sin(a_az), rng.uniform(0.0, 0.04), reach * np.cos(a_az)])
        geometry.append((anchor, insertion))
    rest = _wrapped_rest(geometry, radius)
    shares = rng.uniform(0.25, 0.5, size=count)

    def raw_strain(angles: np.ndarray) -> np.ndarray:
        rot = ms_to_matrix(*np.radians(angles).T)
        rows = []
        for (anchor, insertion), length0, share in zip(geometry, rest, shares, strict=True):
            moved = rot @ insertion
            rows.append(share * (_wrapped_length(anchor, moved, radius) / length0 - 1.0))
        return np.array(rows)

    transfers: list[Transfer] = []
    described = []
    if capacitive:
        units = "pF"
        for _ in sites:
            c0, cp, p = rng.uniform(20, 200), rng.uniform(5, 50), rng.uniform(0.85, 1.25)
            transfers.append(lambda e, c0=c0, cp=cp, p=p: cp + c0 * (1 + e) ** p)
            described.append({"C0_pF": round(c0, 2), "Cp_pF": round(cp, 2), "p": round(p, 3)})
    else:
        units = str(rng.choice(["ohm", "kohm"]))
        scale = 1.0 if units == "ohm" else 1e-3
        for _ in sites:
            r0, lead = rng.uniform(150, 4000), rng.uniform(2, 30)
            gauge, curve = rng.uniform(1.5, 8.0), rng.uniform(-0.8, 3.0)
            transfers.append(
                lambda e, r0=r0, lead=lead, g=gauge, c=curve, k=scale:
                k * (lead + r0 * (1 + g * e + c * g * e**2))
            )
            described.append({"R0_ohm": round(r0, 1), "gauge": round(gauge, 3),
                              "curvature": round(curve, 3), "lead_ohm": round(lead, 2)})
    return Suit(
        family="shoulder-cap" if capacitive else "shoulder-res",
        joint="shoulder",
        motion=SHOULDER,
        names=tuple(name for name, _, _ in sites),
        units=units,
        raw_strain=raw_strain,
        transfers=transfers,
        params={"wrap_radius_m": round(radius, 4), "strain_share": np.round(shares, 3).tolist(),
                "transfer": described},
    )


def _wrapped_rest(geometry: list[tuple[np.ndarray, np.ndarray]], radius: float) -> list[float]:
    """Each patch's length in the arm-hanging pose (θ = φ = ψ = 0), the strain reference."""
    return [float(_wrapped_length(anchor, insertion[None], radius)[0])
            for anchor, insertion in geometry]


def elbow_suit(rng: np.random.Generator) -> Suit:
    """A knitted sleeve with 2–4 resistive bands around the elbow."""
    count = int(rng.integers(2, 5))
    names = ["OLC", "LAT", "MED", "ANT"]
    azimuths = [0.0, 60.0, -60.0, 180.0]
    picks = np.sort(rng.choice(4, size=count, replace=False))
    bands = []
    for k in picks:
        bands.append({
            "azimuth": azimuths[k] + rng.uniform(-15, 15),
            "arm_m": rng.uniform(0.010, 0.020),
            "length_m": rng.uniform(0.06, 0.12),
            "onset_deg": rng.uniform(10, 40),
            "fold": rng.uniform(0.0008, 0.002),
        })

    def raw_strain(angles: np.ndarray) -> np.ndarray:
        theta = np.radians(angles[:, 0])
        rows = []
        for band in bands:
            onset, width = np.radians(band["onset_deg"]), np.radians(12.0)
            wrap = width * (np.logaddexp(0, (theta - onset) / width)
                            - np.logaddexp(0, -onset / width))
            cos_g = np.cos(np.radians(band["azimuth"]))
            side = 1.0 if cos_g > 0 else 0.3  # the front of the elbow folds rather than wraps
            delta = (band["arm_m"] * side * cos_g * wrap
                     - band["fold"] * max(-cos_g, 0.0) * theta**2)
            rows.append(delta / band["length_m"])
        return np.array(rows)

    transfers: list[Transfer] = []
    for band in bands:
        r0, k = rng.uniform(0.5, 20.0), rng.uniform(1.5, 5.0)
        band.update({"R0_kohm": r0, "k": k})
        transfers.append(lambda e, r0=r0, k=k: r0 * np.exp(k * e))
    return Suit(
        family="elbow-sleeve", joint="elbow", motion=ELBOW,
        names=tuple(names[k] for k in picks), units="kohm",
        raw_strain=raw_strain, transfers=transfers,
        params={"bands": [{key: round(v, 4) for key, v in b.items()} for b in bands]},
    )


def wrist_suit(rng: np.random.Generator) -> Suit:
    """A knitted wrist band with 2–4 piezoresistive yarns whose resistance falls with strain."""
    count = int(rng.integers(2, 5))
    names = ["DOR", "RAD", "VOL", "ULN"]
    picks = np.sort(rng.choice(4, size=count, replace=False))
    bands = [{
        "azimuth": 90.0 * k + rng.uniform(-20, 20),
        "arm_m": rng.uniform(0.018, 0.03),
        "length_m": rng.uniform(0.05, 0.09),
        "coupling": rng.uniform(-0.3, 0.3),
    } for k in picks]
    relative = rng.random() < 0.5
    units = "dR/R0" if relative else "ohm"

    def raw_strain(angles: np.ndarray) -> np.ndarray:
        flex, dev = np.radians(angles[:, 0]), np.radians(angles[:, 1])
        rows = []
        for band in bands:
            g = np.radians(band["azimuth"])
            delta = band["arm_m"] * (np.cos(g) * flex + np.sin(g) * dev
                                     + band["coupling"] * flex * dev)
            folded = delta * (0.75 + 0.25 * np.tanh(delta / 0.004))
            rows.append(folded / band["length_m"])
        return np.array(rows)

    transfers: list[Transfer] = []
    for band in bands:
        r0, k, k2 = rng.uniform(80, 3000), rng.uniform(1.0, 4.0), rng.uniform(0.0, 6.0)
        band.update({"R0_ohm": r0, "k": k, "k2": k2})
        if relative:
            transfers.append(lambda e, k=k, k2=k2: 1.0 / (1 + k * e + k2 * e**2) - 1.0)
        else:
            transfers.append(lambda e, r0=r0, k=k, k2=k2: r0 / (1 + k * e + k2 * e**2))
    return Suit(
        family="wrist-band", joint="wrist", motion=WRIST,
        names=tuple(names[k] for k in picks), units=units,
        raw_strain=raw_strain, transfers=transfers,
        params={"bands": [{key: round(v, 4) for key, v in b.items()} for b in bands]},
    )


def make_suit(family: str, rng: np.random.Generator) -> Suit:
    """The garment of ``family`` with freshly drawn geometry and transfers."""
    if family in ("shoulder-res", "shoulder-cap"):
        return shoulder_suit(rng, capacitive=family == "shoulder-cap")
    if family == "elbow-sleeve":
        return elbow_suit(rng)
    if family == "wrist-band":
        return wrist_suit(rng)
    raise ValueError(f"unknown garment family {family!r}")

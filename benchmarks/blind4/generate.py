#!/usr/bin/env python3
"""blind4gen: an independent test-data generator for the sim-to-real discrepancy tool.

Suit: elastic fabric strain bands glued on a shoulder sleeve. The skin under each band is
deformed by linear-blend skinning of three rigid bodies (thorax, scapula/clavicle following a
scapulohumeral rhythm, humerus) plus a deltoid bulge that grows with the gravity torque of the
arm. A band's reading is a transfer of its engineering strain: knitted piezoresistive fabric
(kOhm, exponential gauge law), elastomer capacitor (pF, C = Cp + C0(1+e)) or a strain board
that reports Hencky strain in percent.

Exactly one hidden effect per recording (or none). ``--without-effect`` writes each
recording's clean twin: identical random draws, the effect computed but not applied.

Run from the repository root:
    python -m benchmarks.blind4.generate --out /tmp/blind4
    python -m benchmarks.blind4.generate --out /tmp/blind4-twins --without-effect
"""

from __future__ import annotations

import json
import math
import os
import time

import numpy as np
from scipy import signal
from scipy.interpolate import CubicSpline, PchipInterpolator

from exohil.formats.atomic import write_text
from exohil.formats.recording import AngleStream, Recording, SensorStream
from exohil.formats.recording_writer import write_recording

GENERATOR = "blind4gen v1"
MASTER_SEED = 4404
N_REC = 40
CLASS_COUNTS = {"clean": 7, "hysteresis": 7, "creep": 7, "saturation": 7, "lag": 6, "drift": 6}
FAMILIES = {
    "clean": ["none"],
    "hysteresis": ["coleman_hodgdon", "bouc_wen_baber_noori_asym_pinched",
                   "preisach_lognormal_lorentzian", "armstrong_frederick_kinematic_hardening",
                   "masing_hyperbolic_pose_scaled"],
    "creep": ["schapery_nonlinear", "kww_stretched_exponential", "thixotropic_stretch_history",
              "hygro_viscoelastic_moisture", "eyring_sinh_kelvin"],
    "saturation": ["jamming_gain_collapse", "log_compression", "piecewise_cubic_plateau",
                   "two_sided_algebraic", "gent_series_compliance"],
    "lag": ["cic_sinc3", "usb_jitter_delay", "fractional_lowpass", "alpha_beta_tracker",
            "causal_running_median"],
    "drift": ["gauge_factor_thermal_gain", "flicker_1_over_f", "knock_step_recovery",
              "wear_cycle_baseline", "sweat_gompertz"],
}
DEG = math.pi / 180.0
LIMITS = np.array([[-40.0, 125.0], [5.0, 150.0], [-88.0, 22.0]])  # theta, phi, psi (deg)

# ============================================================================ plan


def make_plan():
    rng = np.random.default_rng([MASTER_SEED, 999])
    labels = []
    for cls, n in CLASS_COUNTS.items():
        labels += [cls] * n
    labels = list(rng.permutation(labels))
    fam_iter = {}
    for cls, fams in FAMILIES.items():
        order = list(rng.permutation(fams))
        fam_iter[cls] = (order + list(rng.permutation(fams))) * 8
    used = {c: 0 for c in FAMILIES}
    plan = []
    for i, cls in enumerate(labels):
        fam = fam_iter[cls][used[cls]]
        used[cls] += 1
        target = float(np.exp(rng.uniform(np.log(2.0), np.log(10.0)))) if cls != "clean" else 0.0
        plan.append((i, str(cls), str(fam), target))
    return plan


# ============================================================================ motion

FS_MOTION = 1000.0


def min_jerk(a, b, dur):
    n = max(int(round(dur * FS_MOTION)), 1)
    s = np.arange(1, n + 1) / n
    w = 10 * s**3 - 15 * s**4 + 6 * s**5
    return a[None, :] + (b - a)[None, :] * w[:, None]


def smooth_noise(rng, n, knot_s, amp):
    """Smooth zero-mean noise (n, 3), cubic through random knots every knot_s seconds."""
    nk = int(n / (knot_s * FS_MOTION)) + 3
    knots = rng.normal(0, amp, (nk, 3))
    tk = np.arange(nk) * knot_s
    return CubicSpline(tk, knots, axis=0)(np.arange(n) / FS_MOTION)


def rand_pose(rng, th, ph, ps):
    return np.array([rng.uniform(*th), rng.uniform(*ph), rng.uniform(*ps)])


def seg_rest(rng, cur):
    p = rand_pose(rng, (10, 60), (8, 20), (-35, -5))
    a = min_jerk(cur, p, rng.uniform(1.0, 2.0))
    n = int(rng.uniform(2, 6) * FS_MOTION)
    b = p[None, :] + smooth_noise(rng, n, 0.8, 0.5)
    return np.vstack([a, b])


def seg_reach_shelf(rng, cur):
    out = []
    for _ in range(rng.integers(2, 5)):
        shelf = rand_pose(rng, (55, 100), (85, 140), (-45, 0))
        low = rand_pose(rng, (20, 60), (15, 35), (-30, -5))
        out.append(min_jerk(cur, shelf, rng.uniform(0.8, 1.6)))
        n = int(rng.uniform(0.3, 2.5) * FS_MOTION)
        out.append(shelf[None, :] + smooth_noise(rng, n, 0.6, 0.4))
        cur = out[-1][-1]
        out.append(min_jerk(cur, low, rng.uniform(0.8, 1.6)))
        n = int(rng.uniform(0.2, 1.0) * FS_MOTION)
        out.append(low[None, :] + smooth_noise(rng, n, 0.6, 0.3))
        cur = out[-1][-1]
    return np.vstack(out)


def seg_comb_hair(rng, cur):
    c = rand_pose(rng, (70, 110), (105, 140), (-15, 15))
    a = min_jerk(cur, c, rng.uniform(1.2, 2.0))
    dur = rng.uniform(5, 12)
    n = int(dur * FS_MOTION)
    t = np.arange(n) / FS_MOTION
    f = rng.uniform(0.7, 1.4)
    amp = np.array([rng.uniform(5, 15), rng.uniform(3, 8), rng.uniform(10, 25)])
    ph = np.array([math.pi / 3, rng.uniform(0, 2 * math.pi), 0.0])
    env = np.clip(np.minimum(t, dur - t) / 0.5, 0, 1)
    b = c[None, :] + (env[:, None] * amp[None, :]
                      * np.sin(2 * math.pi * f * t[:, None] + ph[None, :]))
    back = min_jerk(b[-1], rand_pose(rng, (20, 60), (10, 25), (-30, -5)), rng.uniform(1.2, 2.0))
    return np.vstack([a, b, back])


def seg_circumduction(rng, cur):
    c = rand_pose(rng, (30, 70), (45, 75), (-30, -5))
    a = min_jerk(cur, c, rng.uniform(1.0, 2.0))
    per = rng.uniform(2.5, 6.0)
    cyc = int(rng.integers(2, 5))
    dur = per * cyc
    n = int(dur * FS_MOTION)
    t = np.arange(n) / FS_MOTION
    r = np.clip(np.minimum(t, dur - t) / (0.5 * per), 0, 1)
    r = r * r * (3 - 2 * r)
    sgn = rng.choice([-1.0, 1.0])
    w = 2 * math.pi / per * sgn
    A = np.array([rng.uniform(35, 60), rng.uniform(18, 30), rng.uniform(5, 12)])
    b = c[None, :] + r[:, None] * A[None, :] * np.stack(
        [np.cos(w * t), np.sin(w * t), np.sin(w * t + 1.0)], axis=1)
    return np.vstack([a, b])


def seg_throw(rng, cur):
    out = []
    for _ in range(rng.integers(2, 6)):
        wind = rand_pose(rng, (-10, 30), (75, 105), (-85, -60))
        rel = rand_pose(rng, (70, 110), (60, 100), (-10, 20))
        fol = rand_pose(rng, (60, 100), (25, 50), (-20, 10))
        rest = rand_pose(rng, (15, 50), (10, 25), (-30, -5))
        out.append(min_jerk(cur, wind, rng.uniform(0.6, 1.0)))
        out.append(np.repeat(wind[None, :], int(rng.uniform(0.1, 0.3) * FS_MOTION), 0))
        out.append(min_jerk(wind, rel, rng.uniform(0.15, 0.3)))
        out.append(min_jerk(rel, fol, rng.uniform(0.4, 0.7)))
        out.append(min_jerk(fol, rest, rng.uniform(1.0, 1.5)))
        n = int(rng.uniform(0.5, 2.0) * FS_MOTION)
        out.append(rest[None, :] + smooth_noise(rng, n, 0.6, 0.3))
        cur = out[-1][-1]
    return np.vstack(out)


def seg_long_hold(rng, cur):
    p = rand_pose(rng, (-20, 110), (20, 130), (-70, 10))
    a = min_jerk(cur, p, rng.uniform(1.5, 3.0))
    n = int(rng.uniform(8, 25) * FS_MOTION)
    b = p[None, :] + smooth_noise(rng, n, 1.5, 0.3)
    return np.vstack([a, b])


def seg_wander(rng, cur):
    dur = rng.uniform(10, 30)
    tk = [0.0]
    pk = [cur]
    while tk[-1] < dur:
        tk.append(tk[-1] + rng.uniform(1.5, 4.0))
        step = rng.normal(0, [25, 20, 20])
        nxt = np.clip(pk[-1] + step, LIMITS[:, 0] + 8, LIMITS[:, 1] - 8)
        pk.append(nxt)
    tk = np.array(tk)
    pk = np.array(pk)
    pk[-1] = pk[-2] if len(pk) > 2 else pk[-1]
    n = int(tk[-1] * FS_MOTION)
    return PchipInterpolator(tk, pk, axis=0)(np.arange(1, n + 1) / FS_MOTION)


def seg_raise_reps(rng, cur):
    th = rng.uniform(0, 90)
    lo = np.array([th, rng.uniform(15, 30), rng.uniform(-30, -5)])
    out = [min_jerk(cur, lo, rng.uniform(1.0, 1.8))]
    for _ in range(rng.integers(3, 7)):
        hi = np.array([th + rng.normal(0, 5), rng.uniform(80, 140), lo[2] + rng.normal(0, 8)])
        out.append(min_jerk(out[-1][-1], hi, rng.uniform(1.0, 2.5)))
        out.append(np.repeat(hi[None, :], int(rng.uniform(0.0, 0.8) * FS_MOTION) + 1, 0))
        out.append(min_jerk(hi, lo, rng.uniform(1.0, 2.5)))
        out.append(np.repeat(lo[None, :], int(rng.uniform(0.0, 0.8) * FS_MOTION) + 1, 0))
    return np.vstack(out)


SEGMENTS = {
    "rest": (seg_rest, 0.10), "reach_shelf": (seg_reach_shelf, 0.17),
    "comb_hair": (seg_comb_hair, 0.12), "circumduction": (seg_circumduction, 0.12),
    "throw": (seg_throw, 0.10), "long_hold": (seg_long_hold, 0.14),
    "wander": (seg_wander, 0.12), "raise_reps": (seg_raise_reps, 0.13),
}


def gen_motion(rng, T):
    names = list(SEGMENTS)
    p = np.array([SEGMENTS[k][1] for k in names])
    p = p / p.sum()
    cur = np.array([30.0, 12.0, -15.0])
    parts = [np.repeat(cur[None, :], int(3 * FS_MOTION), 0)]
    labels = [("rest", 0.0, 3.0)]
    total = parts[0].shape[0]
    last = None
    while total < (T + 1.0) * FS_MOTION:
        k = names[rng.choice(len(names), p=p)]
        if k == last:
            k = names[rng.choice(len(names), p=p)]
        seg = SEGMENTS[k][0](rng, cur)
        seg = np.clip(seg, LIMITS[:, 0], LIMITS[:, 1])
        parts.append(seg)
        labels.append((k, total / FS_MOTION, (total + seg.shape[0]) / FS_MOTION))
        total += seg.shape[0]
        cur = seg[-1]
        last = k
    q = np.vstack(parts)
    # physiological tremor, small
    q = q + smooth_noise(rng, q.shape[0], 0.1, 0.05)
    return q, labels


def pose_at(qgrid, t):
    """Degrees (n, 3) at times t by linear interpolation of the 1 kHz grid."""
    x = t * FS_MOTION
    i = np.clip(np.floor(x).astype(int), 0, qgrid.shape[0] - 2)
    f = (x - i)[:, None]
    return qgrid[i] * (1 - f) + qgrid[i + 1] * f


# ============================================================================ suit geometry

SC = np.array([0.03, 0.02, -0.17])   # sternoclavicular pivot relative to the GH centre, m
R_ARM = 0.048

ROUTES = ["pec", "ant_delt", "mid_delt", "post_delt", "lat", "spiral_ant", "spiral_post",
          "axill_ant", "cap", "cuff"]


def Ry(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1),
                     np.stack([-s, z, c], -1)], -2)


def Rx(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1),
                     np.stack([z, s, c], -1)], -2)


def arm_point(alpha_deg, d):
    a = alpha_deg * DEG
    return np.array([R_ARM * math.cos(a), -d, R_ARM * math.sin(a)])


def thorax_anchor(rng, region):
    U = rng.uniform
    if region == "chest":
        return np.array([U(0.07, 0.10), U(-0.06, 0.0), U(-0.13, -0.07)])
    if region == "top":
        return np.array([U(-0.02, 0.02), U(0.06, 0.09), U(-0.12, -0.07)])
    if region == "back":
        return np.array([U(-0.11, -0.08), U(-0.06, 0.02), U(-0.13, -0.06)])
    if region == "low_back":
        return np.array([U(-0.10, -0.07), U(-0.14, -0.09), U(-0.10, -0.06)])
    if region == "low_chest":
        return np.array([U(0.06, 0.09), U(-0.14, -0.09), U(-0.11, -0.07)])
    raise ValueError(region)


def make_band(rng, route, K=16):
    U = rng.uniform
    d = U(0.10, 0.19)
    if route == "pec":
        A, B = thorax_anchor(rng, "chest"), arm_point(U(-10, 25), d)
    elif route == "ant_delt":
        A, B = thorax_anchor(rng, rng.choice(["chest", "top"])), arm_point(U(25, 60), d)
    elif route == "mid_delt":
        A, B = thorax_anchor(rng, "top"), arm_point(U(75, 105), d)
    elif route == "post_delt":
        A, B = thorax_anchor(rng, "back"), arm_point(U(120, 160), d)
    elif route == "lat":
        A, B = thorax_anchor(rng, "low_back"), arm_point(U(165, 200), d)
    elif route == "spiral_ant":
        A, B = thorax_anchor(rng, "back"), arm_point(U(-20, 20), d)
    elif route == "spiral_post":
        A, B = thorax_anchor(rng, "chest"), arm_point(U(150, 190), d)
    elif route == "axill_ant":
        A, B = thorax_anchor(rng, "low_chest"), arm_point(U(0, 30), d)
    elif route == "cap":
        A, B = thorax_anchor(rng, "chest"), thorax_anchor(rng, "back")
    elif route == "cuff":
        a1 = U(-10, 60)
        A, B = arm_point(a1, U(0.05, 0.09)), arm_point(a1 + U(90, 170), U(0.10, 0.18))
    else:
        raise ValueError(route)
    mid = 0.5 * (A + B)
    if route == "cap":
        mid = mid + np.array([0.0, 0.0, 0.09])
    nrm = np.linalg.norm(mid)
    rv = max(np.linalg.norm(A), np.linalg.norm(B), 0.07) * U(1.0, 1.15)
    if route == "cuff":
        # via point on the arm surface between the two anchors
        ang = math.atan2(mid[2], mid[0])
        V = np.array([R_ARM * 1.05 * math.cos(ang), mid[1], R_ARM * 1.05 * math.sin(ang)])
    else:
        V = mid / nrm * rv
    C = 2 * V - 0.5 * (A + B)      # Bezier control so that the curve passes V at s=0.5
    s = np.linspace(0, 1, K)[:, None]
    P = (1 - s) ** 2 * A + 2 * s * (1 - s) * C + s**2 * B
    return P


def sig(x):
    return 1.0 / (1.0 + np.exp(-x))


def blend_weights(P):
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    rperp = np.hypot(x, z)
    wh = sig((-y - 0.01) / 0.015) * sig((0.075 - rperp) / 0.012)
    ws_raw = sig((-x + 0.02) / 0.03) * sig((y + 0.04) / 0.02) * sig((z + 0.16) / 0.03)
    ws = (1 - wh) * ws_raw
    wt = 1 - wh - ws
    return np.stack([wt, ws, wh], 1)


class Suit:
    def __init__(self, rng, n_sensors):
        self.k_elev = rng.uniform(0.15, 0.30)      # clavicle elevation per deg of elevation
        self.k_prot = rng.uniform(0.08, 0.20)      # protraction per deg of plane (x sin phi)
        self.bulge = rng.uniform(0.004, 0.010)     # deltoid bulge amplitude, m
        self.bulge_y = rng.uniform(0.05, 0.08)
        perm = list(rng.permutation(ROUTES))
        routes = (perm * 2)[:n_sensors]
        self.routes = routes
        self.bands = [make_band(rng, r) for r in routes]
        self.weights = [blend_weights(P) for P in self.bands]
        self.rest_len = [float(np.linalg.norm(np.diff(P, axis=0), axis=1).sum())
                         for P in self.bands]
        names, cnt = [], {}
        for r in routes:
            cnt[r] = cnt.get(r, 0) + 1
            names.append(r if cnt[r] == 1 else f"{r}{cnt[r]}")
        self.names = names

    def lengths(self, qdeg):
        th, ph, ps = qdeg[:, 0] * DEG, qdeg[:, 1] * DEG, qdeg[:, 2] * DEG
        R = Ry(th) @ Rx(-ph) @ Ry(ps - th)
        phd = qdeg[:, 1]
        e = self.k_elev * (phd - 25) * sig((phd - 25) / 8.0) * DEG
        p = self.k_prot * (qdeg[:, 0] - 40) * np.sin(ph) * DEG
        Rs = Ry(p) @ Rx(-e)
        c = np.einsum("nij,j->ni", Rs, -SC) + SC
        act = np.sin(ph) ** 1.5 * (1 + 0.3 * np.sin(th))
        L = np.empty((qdeg.shape[0], len(self.bands)))
        for b, (P, W) in enumerate(zip(self.bands, self.weights, strict=True)):
            rp = np.hypot(P[:, 0], P[:, 2])
            nrad = np.stack([P[:, 0] / rp, np.zeros_like(rp), P[:, 2] / rp], 1)
            alpha = np.arctan2(P[:, 2], P[:, 0])
            g = (np.exp(-((P[:, 1] + self.bulge_y) / 0.03) ** 2)
                 * (0.6 + 0.4 * np.cos(alpha - math.pi / 2)))
            bul = (self.bulge * g)[None, :, None] * nrad[None] * act[:, None, None]
            ph_ = np.einsum("nij,nkj->nki", R, P[None] + bul) + c[:, None, :]
            ps_ = np.einsum("nij,kj->nki", Rs, P - SC) + SC
            pp = (W[None, :, 0, None] * P[None] + W[None, :, 1, None] * ps_
                  + W[None, :, 2, None] * ph_)
            L[:, b] = np.linalg.norm(np.diff(pp, axis=1), axis=2).sum(1)
        return L


# ============================================================================ transfer

class Transfer:
    def __init__(self, rng, kind, S):
        self.kind = kind
        if kind == "knit_resistive":
            self.units = "kOhm"
            self.R0 = rng.uniform(2, 30, S)
            self.G = rng.uniform(1.5, 4.0, S) * np.where(rng.random(S) < 0.3, -1.0, 1.0)
        elif kind == "elastomer_capacitive":
            self.units = "pF"
            self.C0 = rng.uniform(30, 200, S)
            self.Cp = rng.uniform(5, 40, S)
        else:
            self.units = "pct_strain"
            self.gain = rng.uniform(0.9, 1.1, S)

    def __call__(self, eps, idx=slice(None)):
        if self.kind == "knit_resistive":
            return self.R0[idx] * np.exp(self.G[idx] * eps)
        if self.kind == "elastomer_capacitive":
            return self.Cp[idx] + self.C0[idx] * (1 + eps)
        return 100 * np.log1p(eps) * self.gain[idx]

    def params(self):
        d = {"kind": self.kind, "units": self.units}
        for a in ("R0", "G", "C0", "Cp", "gain"):
            if hasattr(self, a):
                d[a] = np.round(getattr(self, a), 4).tolist()
        return d


# ============================================================================ helpers

def rms(x, axis=0):
    return np.sqrt(np.mean(np.square(x), axis=axis))


def legendre_basis(y, deg=7):
    lo, hi = np.min(y), np.max(y)
    z = 2 * (y - lo) / max(hi - lo, 1e-12) - 1
    return np.polynomial.legendre.legvander(z, deg)


def project_out_static(d, ref, deg=7):
    """Residual of d (N,) after least squares on a degree-deg Legendre basis of ref (N,)."""
    B = legendre_basis(ref, deg)
    coef, *_ = np.linalg.lstsq(B, d, rcond=None)
    return d - B @ coef


def pose_basis(q):
    z = np.stack([(q[:, 0] - 40) / 80, (q[:, 1] - 75) / 75, (q[:, 2] + 35) / 55], 1)
    cols = []
    for i in range(5):
        for j in range(5 - i):
            for k in range(5 - i - j):
                cols.append(z[:, 0] ** i * z[:, 1] ** j * z[:, 2] ** k)
    return np.stack(cols, 1)


def bisect(fn, target, lo, hi, increasing=True, iters=30, log=True):
    """x in [lo, hi] with fn(x) ~= target for monotone fn; returns x (clamped)."""
    def f0(x):
        v = fn(x)
        return v if np.isfinite(v) else np.inf
    f = f0 if increasing else (lambda x: -f0(x))
    tg = target if increasing else -target
    if f(hi) < tg:
        return hi
    if f(lo) > tg:
        return lo
    for _ in range(iters):
        mid = math.sqrt(lo * hi) if log else 0.5 * (lo + hi)
        if f(mid) < tg:
            lo = mid
        else:
            hi = mid
        if (hi / lo - 1 if log else hi - lo) < 1e-4:
            break
    return math.sqrt(lo * hi) if log else 0.5 * (lo + hi)


def uniform_grid(t_end, fs):
    return np.arange(0.0, t_end + 1e-9, 1.0 / fs)


def norm_load(eps):
    lo = np.percentile(eps, 1, axis=0)
    hi = np.percentile(eps, 99, axis=0)
    return (eps - lo) / (hi - lo), lo, hi


# ============================================================================ hysteresis laws
# all take u (M, S) normalised band strain on a uniform grid and return the operator output

def hyst_coleman_hodgdon(rng, u):
    S = u.shape[1]
    alpha = rng.uniform(4, 14, S)
    g0 = rng.uniform(0.15, 0.6, S)
    g1 = rng.uniform(-0.5, 0.5, S)
    c3 = rng.uniform(-0.8, 0.8, S)
    f = lambda x: x + c3 * (x - 0.5) ** 3  # noqa: E731
    g = lambda x: g0 * (1 + g1 * (x - 0.5))  # noqa: E731
    y = f(u[0]).copy()
    out = np.empty_like(u)
    out[0] = y
    for k in range(1, u.shape[0]):
        du = u[k] - u[k - 1]
        n = int(np.ceil(np.max(alpha * np.abs(du)) / 0.1)) or 1
        h = du / n
        x = u[k - 1].copy()
        for _ in range(n):
            y = y + alpha * np.abs(h) * (f(x) - y) + g(x) * h
            x = x + h
        out[k] = y
    return out, {"alpha": alpha, "g0": g0, "g1": g1, "f_cubic": c3}


def hyst_bouc_wen_pinched(rng, u):
    S = u.shape[1]
    n_exp = rng.uniform(1.0, 2.5, S)
    zu = rng.uniform(0.05, 0.2, S)
    bg = zu ** (-n_exp)
    beta = bg * rng.uniform(0.5, 0.8, S)
    gamma = bg - beta
    phi_a = rng.uniform(0.1, 0.3, S) * beta
    z1 = rng.uniform(0.5, 0.9, S)
    z2 = rng.uniform(0.2, 0.5, S) * zu
    qp = rng.uniform(0.0, 0.2, S)
    z = np.zeros(S)
    out = np.empty_like(u)
    out[0] = z
    for k in range(1, u.shape[0]):
        du = u[k] - u[k - 1]
        n = int(np.ceil(np.max(np.abs(du) / (zu / 10)))) or 1
        h = du / n
        sd = np.sign(h)
        for _ in range(n):
            pinch = 1 - z1 * np.exp(-((z * sd - qp * zu) ** 2) / z2**2)
            dz = pinch * (1 - np.abs(z) ** n_exp * (gamma + beta * np.sign(h * z)
                                                   + phi_a * (sd + np.sign(z)))) * h
            z = z + dz
        out[k] = z
    return out, {"n": n_exp, "z_ultimate": zu, "beta": beta, "gamma": gamma,
                 "asym_phi": phi_a, "pinch_zeta1": z1, "pinch_zeta2": z2, "pinch_q": qp}


def hyst_preisach_lorentz(rng, u):
    S = u.shape[1]
    M = 90
    grid = np.linspace(-0.15, 1.15, M)
    A, B = np.meshgrid(grid, grid, indexing="ij")
    keep = A > B
    a, b = A[keep], B[keep]
    mu_w = np.log(rng.uniform(0.05, 0.25, S))
    sg_w = rng.uniform(0.3, 0.9, S)
    gam_b = rng.uniform(0.15, 0.5, S)
    bias_c = rng.uniform(0.35, 0.65, S)
    w = (a - b)[None, :]
    c = (0.5 * (a + b))[None, :]
    dens = (np.exp(-((np.log(w) - mu_w[:, None]) ** 2) / (2 * sg_w[:, None] ** 2)) / w) \
        / (1 + ((c - bias_c[:, None]) / gam_b[:, None]) ** 2)
    dens = dens / dens.sum(1, keepdims=True)
    s = np.where(a[None, :] <= u[0][:, None], 1.0, -1.0)
    out = np.empty_like(u)
    out[0] = (dens * s).sum(1)
    for k in range(1, u.shape[0]):
        x = u[k][:, None]
        s = np.where(x >= a[None, :], 1.0, np.where(x <= b[None, :], -1.0, s))
        out[k] = (dens * s).sum(1)
    return out, {"relays": int(a.size), "lognormal_width_median": np.exp(mu_w),
                 "lognormal_sigma": sg_w, "lorentz_bias_center": bias_c,
                 "lorentz_bias_hwhm": gam_b}


def hyst_armstrong_frederick(rng, u):
    S = u.shape[1]
    sy = rng.uniform(0.03, 0.12, S)
    C = rng.uniform(0.5, 2.0, S)
    gAF = rng.uniform(2.0, 10.0, S)
    E = 1.0
    sigma = np.zeros(S)
    X = np.zeros(S)
    out = np.empty_like(u)
    out[0] = sigma
    for k in range(1, u.shape[0]):
        du = u[k] - u[k - 1]
        n = int(np.ceil(np.max(np.abs(du) / (sy / 5)))) or 1
        h = du / n
        for _ in range(n):
            tr = sigma + E * h
            f = np.abs(tr - X) - sy
            pl = f > 0
            sg = np.sign(tr - X)
            H = C - gAF * X * sg
            dep = np.where(pl, f / (E + np.maximum(H, 0.05)), 0.0)
            sigma = tr - E * dep * sg
            X = X + C * dep * sg - gAF * X * dep
        out[k] = sigma
    return out, {"yield": sy, "C": C, "gamma_AF": gAF}


def hyst_masing(rng, u, phi_grid):
    S = u.shape[1]
    xr = rng.uniform(0.03, 0.2, S)
    kp = rng.uniform(0.5, 1.5, S)
    F = lambda x, r: x / (1 + np.abs(x) / r)  # noqa: E731
    out = np.empty_like(u)
    for s in range(S):
        x = u[:, s]
        rev = [(x[0], 0.0)]
        d_prev = 0.0
        y = 0.0
        ys = np.empty(x.size)
        ys[0] = 0.0
        for k in range(1, x.size):
            dx = x[k] - x[k - 1]
            if dx == 0:
                ys[k] = y
                continue
            d = 1.0 if dx > 0 else -1.0
            if d_prev != 0 and d != d_prev:
                rev.append((x[k - 1], y))
            d_prev = d
            while len(rev) >= 3 and ((d > 0 and x[k] >= rev[-2][0])
                                       or (d < 0 and x[k] <= rev[-2][0])):
                rev.pop()
                rev.pop()
            x0, y0 = rev[-1]
            y = y0 + 2 * F((x[k] - x0) / 2, xr[s])
            ys[k] = y
        out[:, s] = ys
    scale = (0.3 + np.sin(phi_grid * DEG))[:, None] ** kp[None, :]
    return out * scale, {"backbone_ref_strain": xr, "pose_scale_exponent": kp,
                         "pose_scale": "(0.3+sin(shoulder_elv))**k"}


# ============================================================================ creep laws
# take sigma (M, S) normalised load on a uniform grid of step dt; return creep strain c (M, S)

def creep_schapery(rng, sig_, dt, qg):
    S = sig_.shape[1]
    t1 = rng.uniform(1.5, 4.0)
    t3 = rng.uniform(30, 90)
    taus = np.geomspace(t1, t3, 3)
    m = rng.uniform(0.1, 0.5)
    D = taus**m
    D = D / D.sum()
    k2 = rng.uniform(0.3, 1.5, S)
    k1 = rng.uniform(0.0, 0.5, S)
    ka = rng.uniform(0.5, 2.0, S)
    G = sig_ * (1 + k2 * sig_)
    r = np.repeat(G[0][None, :], 3, 0)
    out = np.empty_like(sig_)
    for k in range(sig_.shape[0]):
        dpsi = dt * np.exp(ka * sig_[k])
        r = r + (G[k][None, :] - r) * (1 - np.exp(-dpsi[None, :] / taus[:, None]))
        out[k] = (1 + k1 * sig_[k]) * (D[:, None] * r).sum(0)
    return out, {"prony_tau_s": taus, "prony_D": D, "g2_k": k2, "g1_k": k1, "shift_k": ka}


def creep_kww(rng, sig_, dt, qg):
    S = sig_.shape[1]
    tau = rng.uniform(3, 40, S)
    beta = rng.uniform(0.3, 0.8, S)
    M = sig_.shape[0]
    tt = np.arange(M) * dt
    out = np.empty_like(sig_)
    nfft = 1 << int(math.ceil(math.log2(2 * M)))
    for s in range(S):
        J = 1 - np.exp(-((tt / tau[s]) ** beta[s]))
        ds = np.diff(sig_[:, s], prepend=sig_[0, s])
        conv = np.fft.irfft(np.fft.rfft(ds, nfft) * np.fft.rfft(J, nfft), nfft)[:M]
        out[:, s] = sig_[0, s] + conv
    return out, {"tau_s": tau, "beta": beta}


def creep_thixotropic(rng, sig_, dt, qg):
    S = sig_.shape[1]
    tc = rng.uniform(1.0, 5.0, S)
    tb = rng.uniform(5.0, 30.0, S)
    tr = rng.uniform(20.0, 80.0, S)
    n0 = int(min(10.0 / dt, sig_.shape[0]))
    sbar = sig_[:n0].mean(0)
    lam = 1 / (1 + tr * np.maximum(sbar, 0) / tb)
    c = sig_[0] * (1 - lam)
    out = np.empty_like(sig_)
    for k in range(sig_.shape[0]):
        sk = np.maximum(sig_[k], 0)
        lam = lam + dt * ((1 - lam) / tr - sk * lam / tb)
        c = c + (sk * (1 - lam) - c) * (1 - np.exp(-dt / tc))
        out[k] = c
    return out, {"tau_creep_s": tc, "tau_breakdown_s": tb, "tau_rebuild_s": tr}


def creep_hygro(rng, sig_, dt, qg):
    S = sig_.shape[1]
    tw = rng.uniform(20, 60)
    kw = rng.uniform(1.0, 4.0, S)
    t0 = rng.uniform(3.0, 15.0, S)
    kt = rng.uniform(0.5, 1.5, S)
    vel = np.abs(np.gradient(qg, dt, axis=0)).sum(1)
    effort = np.clip(vel / 150.0, 0, 1) * 0.5 + 0.5 * np.clip(qg[:, 1] / 120.0, 0, 1)
    w = 0.0
    c = sig_[0].copy()
    out = np.empty_like(sig_)
    wl = np.empty(sig_.shape[0])
    for k in range(sig_.shape[0]):
        w = w + (effort[k] - w) * (1 - math.exp(-dt / tw))
        wl[k] = w
        tau = t0 * np.exp(-kt * w)
        c = c + ((1 + kw * w) * sig_[k] - c) * (1 - np.exp(-dt / tau))
        out[k] = c
    return out, {"tau_moisture_s": tw, "compliance_moisture_k": kw, "tau0_s": t0,
                 "tau_moisture_k": kt, "final_moisture": float(wl[-1])}


def creep_eyring(rng, sig_, dt, qg):
    S = sig_.shape[1]
    kk = rng.uniform(1.0, 4.0, S)
    tau = rng.uniform(2.0, 20.0, S)
    c = sig_[0].copy()
    nsub = int(np.ceil(np.max(np.cosh(kk * 1.5) * dt / tau) / 0.3)) or 1
    h = dt / nsub
    out = np.empty_like(sig_)
    for k in range(sig_.shape[0]):
        for _ in range(nsub):
            x = np.clip(kk * (sig_[k] - c), -30, 30)
            c = c + h * np.sinh(x) / (kk * tau)
        out[k] = c
    return out, {"eyring_k": kk, "tau_s": tau}


# ============================================================================ recording


def pick_touched(rng, S, lo=1):
    k = int(rng.integers(lo, S + 1))
    return sorted(rng.choice(S, k, replace=False).tolist())


def noise_process(rng, kind, N, S, sd, fs):
    if kind == "student_t":
        df = rng.uniform(3.0, 5.0)
        x = rng.standard_t(df, (N, S)) / math.sqrt(df / (df - 2))
        extra = {"df": df}
    elif kind == "bursty":
        env = np.ones(N)
        nb = max(1, int(N / fs / 20))
        for _ in range(nb):
            c = rng.integers(0, N)
            L = int(rng.uniform(0.2, 1.5) * fs)
            env[c:c + L] = rng.uniform(3, 5)
        env = env / math.sqrt(np.mean(env**2))
        x = rng.normal(0, 1, (N, S)) * env[:, None]
        extra = {"bursts": nb}
    else:
        x = rng.normal(0, 1, (N, S))
        extra = {}
    return x * sd[None, :], extra


def build(i, cls, fam, target, without, debug=None):
    rng_s = np.random.default_rng([MASTER_SEED, i, 1])   # suit, rates, durations
    rng_m = np.random.default_rng([MASTER_SEED, i, 2])   # motion
    rng_n = np.random.default_rng([MASTER_SEED, i, 3])   # noise, drops
    rng_e = np.random.default_rng([MASTER_SEED, i, 4])   # effect parameters

    fs = float(rng_s.choice([100, 200, 250, 500], p=[0.2, 0.3, 0.3, 0.2]))
    fm = float(rng_s.choice([60, 90, 100, 120, 150, 200, 240]))
    T = float(rng_s.uniform(60, min(200, 50000 / fs)))
    S = int(rng_s.integers(3, 11))
    suit_kind = str(rng_s.choice(["knit_resistive", "elastomer_capacitive", "strain_board"]))
    suit = Suit(rng_s, S)
    tr = Transfer(rng_s, suit_kind, S)
    pre_draw = rng_s.uniform(0.03, 0.12, S)
    max_draw = rng_s.uniform(0.25, 0.6, S)

    qgrid, motion_labels = gen_motion(rng_m, T)
    N = int(round(T * fs))
    t = np.arange(N) / fs
    q = pose_at(qgrid, t)
    L = suit.lengths(q)
    Lr = np.array(suit.rest_len)
    lam = L / Lr
    # the sensing patch is stiffer than its carrier band and takes a share of its elongation
    share = np.minimum(1.0, max_draw / np.maximum(lam.max(0) - 1, 1e-3))
    lam_p = 1 + share * (lam - 1)
    pre = np.maximum(pre_draw, 1.02 / lam_p.min(0) - 1)
    eps = lam_p * (1 + pre) - 1                         # patch engineering strain, > 0.02
    y_clean = tr(eps)
    rng_range = np.percentile(y_clean, 99, 0) - np.percentile(y_clean, 1, 0)

    # noise spec (drawn before the effect, identical in twins)
    noise_kind = str(rng_n.choice(["gauss", "student_t", "bursty", "gauss_quant"],
                                  p=[0.4, 0.2, 0.2, 0.2]))
    frac = rng_n.uniform(0.003, 0.010, S)
    sd = frac * rng_range

    # effect
    y_base = y_clean
    y_eff = y_clean
    info = {}
    touched = []
    eff_t0 = time.time()
    if cls != "clean":
        y_base, y_eff, touched, info = apply_effect(cls, fam, target, rng_e, t, q, eps, tr,
                                                    y_clean, sd, fs, qgrid)
    eff_dt = time.time() - eff_t0

    if debug is not None:
        debug.update(t=t, q=q, eps=eps, y_base=y_base, y_eff=y_eff, touched=touched, sd=sd,
                     names=suit.names, info=info)
    noise, nextra = noise_process(rng_n, "gauss" if noise_kind == "gauss_quant" else noise_kind,
                                  N, S, sd, fs)
    y_out = (y_base if without else y_eff) + noise
    if noise_kind == "gauss_quant":
        lsb = sd * rng_n.uniform(0.2, 0.5, S)
        y_out = np.round(y_out / lsb) * lsb
        nextra["lsb"] = np.round(lsb, 6).tolist()

    # dropped sensor frames
    keep = np.ones(N, bool)
    n_dropped = 0
    if rng_n.random() < 0.4:
        nb = int(rng_n.integers(3, 30))
        for _ in range(nb):
            c = int(rng_n.integers(1, N - 25))
            keep[c:c + int(rng_n.integers(1, 21))] = False
        n_dropped = int((~keep).sum())
    seq0 = int(rng_n.integers(0, 60000))
    seq = np.arange(N, dtype=np.int64) + seq0

    # mocap
    tm = np.arange(int(T * fm) + 1) / fm
    tm = tm[tm <= T]
    qm = pose_at(qgrid, tm)
    msd = rng_n.uniform(0.15, 0.5)
    qn = rng_n.normal(0, msd, qm.shape)
    qn[:, 0] *= 1 + 0.3 / np.maximum(np.sin(qm[:, 1] * DEG), 0.1)
    qm = qm + qn
    mkeep = np.ones(tm.size, bool)
    gaps = []
    if rng_n.random() < 0.4:
        for _ in range(int(rng_n.integers(1, 7))):
            c = rng_n.uniform(2, T - 3)
            d = rng_n.uniform(0.1, 1.5)
            mkeep &= ~((tm >= c) & (tm < c + d))
            gaps.append([round(c, 3), round(d, 3)])

    rec = Recording(
        sensor_names=tuple(suit.names),
        sensors=SensorStream(seq[keep], t[keep], y_out[keep]),
        mocap={"shoulder": AngleStream(tm[mkeep], ("elv_angle", "shoulder_elv", "shoulder_rot"),
                                       qm[mkeep])},
        sensor_units=tr.units, sensor_rate_hz=fs, mocap_rate_hz=fm, segments=[],
        metadata={"generator": GENERATOR, "seed": f"{MASTER_SEED}-{i:02d}"},
    )

    # truth
    d = (y_eff - y_base)[keep]
    per = rms(d) / sd
    tt = touched if touched else []
    mag = float(np.sqrt(np.mean(per[tt] ** 2))) if tt else 0.0
    res_static = np.array([rms(project_out_static(d[:, s], y_base[keep][:, s]))
                           for s in range(S)]) / sd
    sub = slice(None, None, max(1, int(keep.sum() // 20000)))
    Bp = pose_basis(q[keep][sub])
    coef, *_ = np.linalg.lstsq(Bp, d[sub], rcond=None)
    res_pose = rms(d[sub] - Bp @ coef) / sd
    fmt = lambda v: float(round(float(v), 4))  # noqa: E731
    truth = {
        "file": f"rec_{i:02d}.mcap",
        "effect": cls if not without else "clean",
        "family": fam if not without else "none",
        "magnitude_x_noise": fmt(mag) if not without else 0.0,
        "magnitude_target_x_noise": fmt(target) if not without else 0.0,
        "magnitude_definition": ("RMS over time of (noise-free reading with effect - without) per "
                                 "touched sensor / that sensor's noise SD, then RMS over touched "
                                 "sensors. hysteresis and creep: the applied delta already has "
                                 "its static-function-of-the-reading part projected out "
                                 "(Legendre deg 7 of the clean band strain)."),
        "magnitude_per_sensor": {suit.names[s]: fmt(per[s]) for s in tt} if not without else {},
        "magnitude_resid_static_reading_x_noise":
            fmt(np.sqrt(np.mean(res_static[tt] ** 2))) if (tt and not without) else 0.0,
        "magnitude_resid_pose_poly4_x_noise":
            fmt(np.sqrt(np.mean(res_pose[tt] ** 2))) if (tt and not without) else 0.0,
        "sensors_touched": [suit.names[s] for s in tt] if not without else [],
        "noise_sd": {suit.names[s]: float(f"{sd[s]:.6g}") for s in range(S)},
        "noise_kind": noise_kind, "noise_extra": nextra,
        "units": tr.units, "suit": suit_kind, "routes": suit.routes,
        "n_sensors": S, "sensor_rate_hz": fs, "mocap_rate_hz": fm,
        "duration_s": round(T, 3), "n_frames": int(keep.sum()), "dropped_frames": n_dropped,
        "seq0": seq0, "mocap_noise_deg": round(msd, 3), "mocap_dropouts_t0_dur_s": gaps,
        "prestrain": np.round(pre, 4).tolist(),
        "patch_share_of_band_elongation": np.round(share, 4).tolist(),
        "strain_range": [np.round(eps.min(0), 4).tolist(), np.round(eps.max(0), 4).tolist()],
        "reading_range_p1_p99": np.round(rng_range, 5).tolist(),
        "transfer": tr.params(),
        "movements": [[k, round(a, 2), round(b, 2)] for k, a, b in motion_labels if a < T],
        "seed": f"{MASTER_SEED}-{i:02d}",
    }
    if without:
        truth["twin_of"] = f"rec_{i:02d}.mcap"
        truth["twin_hidden_effect"] = cls
        truth["twin_hidden_family"] = fam
    else:
        truth["params"] = jsonable(info)
    return rec, truth, eff_dt


def jsonable(x):
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return np.round(x.astype(float), 5).tolist()
    if isinstance(x, (np.floating, float)):
        return float(round(float(x), 6))
    if isinstance(x, (np.integer,)):
        return int(x)
    return x


# ============================================================================ effects


def apply_effect(cls, fam, target, rng, t, q, eps, tr, y_clean, sd, fs, qgrid):
    N, S = eps.shape
    T = t[-1]
    if cls in ("hysteresis", "creep"):
        touched = pick_touched(rng, S)
        tgt = target * rng.uniform(0.75, 1.25, len(touched))
        tgt = tgt * target / np.sqrt(np.mean(tgt**2))
        gfs = 100.0 if cls == "hysteresis" else 50.0
        tg = uniform_grid(T, gfs)
        eg = np.stack([np.interp(tg, t, eps[:, s]) for s in touched], 1)
        u, lo, hi = norm_load(eg)
        qg = pose_at(qgrid, tg)
        if cls == "hysteresis":
            # pre-history: one full-range cycle ending at the first value, so that the
            # operator state at t = 0 lies on a realistic branch (no virgin curve)
            npre = 100
            one, zero = np.ones_like(u[0]), np.zeros_like(u[0])
            pre = np.vstack([np.linspace(u[0], one, npre), np.linspace(one, zero, npre),
                             np.linspace(zero, u[0], npre)])
            u = np.vstack([pre, u])
            qg = np.vstack([np.repeat(qg[:1], 3 * npre, 0), qg])
            law = {"coleman_hodgdon": hyst_coleman_hodgdon,
                   "bouc_wen_baber_noori_asym_pinched": hyst_bouc_wen_pinched,
                   "preisach_lognormal_lorentzian": hyst_preisach_lorentz,
                   "armstrong_frederick_kinematic_hardening": hyst_armstrong_frederick}.get(fam)
            if law is None:
                h, par = hyst_masing(rng, u, qg[:, 1])
            else:
                h, par = law(rng, u)
            h = h[3 * npre:]
            u = u[3 * npre:]
            qg = qg[3 * npre:]
            sign = 1.0
        else:
            law = {"schapery_nonlinear": creep_schapery, "kww_stretched_exponential": creep_kww,
                   "thixotropic_stretch_history": creep_thixotropic,
                   "hygro_viscoelastic_moisture": creep_hygro,
                   "eyring_sinh_kelvin": creep_eyring}[fam]
            h, par = law(rng, np.clip(u, 0, None), 1.0 / gfs, qg)
            sign = -1.0   # the reading relaxes under sustained stretch
        y_eff = y_clean.copy()
        amps = []
        for j, s in enumerate(touched):
            hs = np.interp(t, tg, h[:, j])
            hs = project_out_static(hs, eps[:, s])
            hs = sign * hs / max(rms(hs), 1e-12) * (hi[j] - lo[j])
            def fn(a, s=s, hs=hs):
                return rms(tr(eps[:, s] + a * hs, s) - y_clean[:, s]) / sd[s]
            a = bisect(fn, tgt[j], 1e-5, 0.5)
            y_eff[:, s] = tr(eps[:, s] + a * hs, s)
            amps.append(a)
        par["amplitude_rms_of_strain_range"] = np.array(amps)
        par["touched_strain_p1_p99"] = [lo, hi]
        return y_clean, y_eff, touched, par

    if cls == "saturation":
        touched = pick_touched(rng, S)
        tgt = target * rng.uniform(0.75, 1.25, len(touched))
        tgt = tgt * target / np.sqrt(np.mean(tgt**2))
        y_eff = y_clean.copy()
        y_base = y_clean.copy()
        par = {"knee_quantile": [], "knee_value": []}
        shape = {}
        if fam == "jamming_gain_collapse":
            shape["residual_gain"] = rng.uniform(0.05, 0.3, len(touched))
            shape["width_frac"] = rng.uniform(0.05, 0.3, len(touched))
        elif fam == "log_compression":
            shape["scale_frac"] = rng.uniform(0.05, 0.3, len(touched))
        elif fam == "piecewise_cubic_plateau":
            shape["width_frac"] = rng.uniform(0.1, 0.5, len(touched))
        elif fam == "two_sided_algebraic":
            shape["p"] = rng.uniform(4.0, 10.0, len(touched))
            shape["center_quantile"] = rng.uniform(0.4, 0.6, len(touched))
        elif fam == "gent_series_compliance":
            shape["anchor_to_band_stiffness"] = rng.uniform(5.0, 30.0, len(touched))
        for j, s in enumerate(touched):
            e = eps[:, s]
            y = y_clean[:, s]
            if fam == "jamming_gain_collapse":
                r, wf = shape["residual_gain"][j], shape["width_frac"][j]
                w = wf * (np.percentile(e, 99) - np.percentile(e, 1))
                def law(qq, e=e, r=r, w=w, s=s):
                    ej = np.quantile(e, qq)
                    x = np.maximum(e - ej, 0)
                    jammed = np.where(e > ej, ej + r * x + (1 - r) * w * (1 - np.exp(-x / w)), e)
                    return tr(jammed, s), ej
                base = y
            elif fam == "log_compression":
                sc = shape["scale_frac"][j] * (np.percentile(y, 99) - np.percentile(y, 1))
                def law(qq, y=y, sc=sc, s=s):
                    yk = np.quantile(y, qq)
                    x = np.maximum(y - yk, 0)
                    return np.where(y > yk, yk + sc * np.log1p(x / sc), y), yk
                base = y
            elif fam == "piecewise_cubic_plateau":
                w = shape["width_frac"][j] * (np.percentile(y, 99) - np.percentile(y, 1))
                def law(qq, y=y, w=w, s=s):
                    yk = np.quantile(y, qq)
                    x = np.clip((y - yk) / w, 0, 1)
                    return np.where(y > yk, yk + w * (x - x**3 / 3), y), yk
                base = y
            elif fam == "two_sided_algebraic":
                p = shape["p"][j]
                c = np.quantile(y, shape["center_quantile"][j])
                half = 0.5 * (np.max(y) - np.min(y))
                def law(qq, y=y, p=p, c=c, half=half, s=s):
                    hh = half * (0.3 + 3.0 * qq) / 0.9
                    v = (y - c) / hh
                    return c + hh * v / (1 + np.abs(v) ** p) ** (1 / p), hh
                base = y
            else:  # gent series compliance
                kap = shape["anchor_to_band_stiffness"][j]
                base = tr(e * kap / (1 + kap), s)
                emax = e.max() * kap / (1 + kap)
                def law(qq, e=e, kap=kap, emax=emax, s=s):
                    # qq in [0.02, 0.999] -> limiting strain from 1.01 to ~50 x the max strain
                    em = emax * (1 + 0.01 * (5000.0 ** ((qq - 0.02) / 0.979)))
                    # mu e/(1-e/em) = k (E - e), k = kap mu  ->  quadratic in e
                    a2 = kap / em
                    b2 = -(kap + 1 + kap * e / em)
                    c2 = kap * e
                    root = (-b2 - np.sqrt(np.maximum(b2**2 - 4 * a2 * c2, 0))) / (2 * a2)
                    return tr(root, s), em
            y_base[:, s] = base
            def fn(qq, law=law, base=base, s=s):
                return rms(law(qq)[0] - base) / sd[s]
            qq = bisect(fn, tgt[j], 0.02, 0.999, increasing=False, log=False, iters=40)
            ye, kv = law(qq)
            y_eff[:, s] = ye
            par["knee_quantile"].append(qq)
            par["knee_value"].append(kv)
        par.update(shape)
        par["saturating_end"] = ("high reading end (strain-domain laws: high strain end; "
                                 "two_sided: both ends)")
        return y_base, y_eff, touched, par

    if cls == "lag":
        touched = list(range(S))
        y_eff = y_clean.copy()
        if fam == "cic_sinc3":
            fh = 1000.0
            th = uniform_grid(T, fh)
            yh = CubicSpline(t, y_clean, axis=0)(th)
            def law(W):
                Lb = max(1, int(round(W * fh)))
                z = yh
                for _ in range(3):
                    cs = np.cumsum(np.vstack([np.repeat(z[:1], Lb, 0), z]), 0)
                    z = (cs[Lb:] - cs[:-Lb]) / Lb
                return np.stack([np.interp(t, th, z[:, s]) for s in range(S)], 1)
            lo_, hi_ = 0.001, 0.5
            pname = "box_width_s"
        elif fam == "usb_jitter_delay":
            P = int(rng.integers(4, 17))
            npk = N // P + 1
            extra = rng.exponential(0.5, npk)
            busy = np.zeros(npk)
            for _ in range(max(1, int(T / 25))):
                c = int(rng.integers(0, npk))
                busy[c:c + int(rng.uniform(0.5, 3.0) * fs / P)] = rng.uniform(1.0, 3.0)
            pattern = np.repeat(1.0 + extra + busy, P)[:N]
            spl = CubicSpline(t, y_clean, axis=0)
            def law(d0):
                return spl(np.maximum(t - d0 * pattern, 0))
            lo_, hi_ = 1e-4, 0.5
            pname = "base_latency_s"
        elif fam == "fractional_lowpass":
            al = rng.uniform(0.5, 0.9)
            npad = int(30 * fs)
            x = np.vstack([np.repeat(y_clean[:1], npad, 0),
                           y_clean, np.repeat(y_clean[-1:], npad, 0)])
            nfft = 1 << int(math.ceil(math.log2(x.shape[0])))
            X = np.fft.rfft(x - y_clean[0][None, :], nfft, axis=0)
            w = 2 * math.pi * np.fft.rfftfreq(nfft, 1 / fs)
            def law(tau):
                H = 1.0 / (1.0 + (1j * w * tau) ** al)
                z = np.fft.irfft(X * H[:, None], nfft, axis=0)[npad:npad + N] + y_clean[0][None, :]
                return z
            lo_, hi_ = 1e-4, 1.0
            pname = "tau_s"
        elif fam == "alpha_beta_tracker":
            def law(alpha):
                beta = alpha**2 / (2 - alpha)
                b = [alpha, beta - alpha]
                a = [1.0, alpha + beta - 2.0, 1.0 - alpha]
                zi = signal.lfilter_zi(b, a)
                return np.stack([signal.lfilter(b, a, y_clean[:, s], zi=zi * y_clean[0, s])[0]
                                 for s in range(S)], 1)
            lo_, hi_ = 0.002, 1.0
            pname = "alpha"
        else:  # causal running median
            def law(W):
                W = int(round(W))
                if W <= 1:
                    return y_clean.copy()
                out = np.empty_like(y_clean)
                for s in range(S):
                    xp = np.concatenate([np.repeat(y_clean[0, s], W - 1), y_clean[:, s]])
                    out[:, s] = np.median(np.lib.stride_tricks.sliding_window_view(xp, W), axis=1)
                return out
            lo_, hi_ = 1.0, float(max(3, int(0.6 * fs)))
            pname = "window_samples"
        def fn(p):
            d = law(p) - y_clean
            return float(np.sqrt(np.mean((rms(d) / sd) ** 2)))
        if fam == "causal_running_median":
            lo_i, hi_i = 1, int(hi_)
            while hi_i - lo_i > 1:
                m = (lo_i + hi_i) // 2
                if fn(m) < target:
                    lo_i = m
                else:
                    hi_i = m
            p = hi_i if abs(fn(hi_i) - target) < abs(fn(lo_i) - target) else lo_i
            par = {pname: p, "delay_s_approx": (p - 1) / 2 / fs}
        elif fam == "alpha_beta_tracker":
            p = bisect(fn, target, lo_, hi_, increasing=False)
            par = {pname: p, "beta": p**2 / (2 - p)}
        else:
            p = bisect(fn, target, lo_, hi_, increasing=True)
            par = {pname: p}
            if fam == "cic_sinc3":
                par["group_delay_s"] = 1.5 * max(1, int(round(p * 1000))) / 1000
            if fam == "fractional_lowpass":
                par["order"] = al
            if fam == "usb_jitter_delay":
                par["packet_frames"] = P
                par["mean_delay_s"] = float(p * pattern.mean())
                par["max_delay_s"] = float(p * pattern.max())
        y_eff = law(p)
        return y_clean, y_eff, touched, par

    if cls == "drift":
        y_eff = y_clean.copy()
        par = {}
        if fam == "gauge_factor_thermal_gain":
            touched = list(range(S))
            tw = rng.uniform(0.4, 1.5) * T
            tg = uniform_grid(T, 10.0)
            qg = pose_at(qgrid, tg)
            vel = np.abs(np.gradient(qg, 0.1, axis=0)).sum(1)
            act = signal.lfilter([1 - math.exp(-0.1 / 20)], [1, -math.exp(-0.1 / 20)],
                                 np.clip(vel / 150, 0, 1))
            knots = np.arange(0, T + 40, 20.0)
            air = CubicSpline(knots, rng.normal(0, 0.3, len(knots)))(tg)
            dT = rng.uniform(1, 3) * (1 - np.exp(-tg / tw)) + rng.uniform(0.5, 1.5) * act + air
            dT = dT - dT[0]
            # the static map is calibrated at the mean gauge factor: only T - mean(T) shows
            dTs = np.interp(t, tg, dT - dT.mean())
            coef = rng.uniform(0.7, 1.3, S) * rng.choice([-1.0, 1.0])
            y0 = tr(np.zeros(S))
            shape = (y_clean - y0[None, :]) * dTs[:, None] * coef[None, :]
            def fn(g):
                return float(np.sqrt(np.mean((rms(g * shape) / sd) ** 2)))
            g = bisect(fn, target, 1e-6, 10.0)
            y_eff = y_clean + g * shape
            par = {"gain_per_K": g * coef, "warmup_tau_s": tw, "dT_final_K": float(dT[-1]),
                   "note": "gain relative to the gain at the mean temperature",
                   "dT_max_abs_K": float(np.max(np.abs(dT)))}
            return y_clean, y_eff, touched, par
        if fam == "flicker_1_over_f":
            touched = pick_touched(rng, S)
            gam = rng.uniform(1.0, 1.8)
            nfft = 1 << int(math.ceil(math.log2(N)))
            f = np.fft.rfftfreq(nfft, 1 / fs)
            amp = np.zeros_like(f)
            band = (f >= 1 / T) & (f <= 2.0)
            amp[band] = f[band] ** (-gam / 2)
            shapes = []
            for _ in touched:
                ph = rng.normal(size=f.size) + 1j * rng.normal(size=f.size)
                x = np.fft.irfft(amp * ph, nfft)[:N]
                shapes.append(x - x.mean())
            par = {"spectral_exponent": gam, "band_hz": [1 / T, 2.0]}
        elif fam == "knock_step_recovery":
            touched = pick_touched(rng, S)[: int(rng.integers(1, 4))]
            tk = rng.uniform(0.3, 0.7) * T
            tau = rng.uniform(8, 40)
            fr = rng.uniform(0.5, 0.9)
            shapes = []
            for _ in touched:
                sign = rng.choice([-1, 1])
                b = np.where(t >= tk, sign * (fr * np.exp(-(t - tk) / tau) + (1 - fr)), 0.0)
                shapes.append(b - b.mean())
            par = {"knock_time_s": tk, "recovery_tau_s": tau, "recovered_fraction": fr}
        elif fam == "wear_cycle_baseline":
            touched = pick_touched(rng, S)
            p = rng.uniform(0.5, 1.0)
            shapes = []
            for s in touched:
                W = np.concatenate([[0], np.cumsum(np.abs(np.diff(eps[:, s])))])
                W = W / W[-1]
                b = rng.choice([-1, 1], p=[0.2, 0.8]) * W**p
                shapes.append(b - b.mean())
            par = {"exponent": p, "driver": "cumulative |d strain| of the same band"}
        else:  # sweat gompertz
            touched = list(range(S))
            t0 = rng.uniform(0.2, 0.7) * T
            k = 1.0 / (rng.uniform(0.05, 0.2) * T)
            g = np.exp(-np.exp(-k * (t - t0)))
            sgn = {"knit_resistive": -1.0, "elastomer_capacitive": 1.0}.get(
                tr.kind, rng.choice([-1.0, 1.0]))
            shapes = []
            for _ in touched:
                b = sgn * rng.uniform(0.5, 1.5) * g
                shapes.append(b - b.mean())
            par = {"t0_s": t0, "rate_per_s": k, "sign": sgn}
        tgt = target * rng.uniform(0.75, 1.25, len(touched))
        tgt = tgt * target / np.sqrt(np.mean(tgt**2))
        amps = []
        shapes = [x / max(rms(x), 1e-15) for x in shapes]
        for j, s in enumerate(touched):
            a = tgt[j] * sd[s] / rms(shapes[j])
            y_eff[:, s] = y_clean[:, s] + a * shapes[j]
            amps.append(a)
        par["rms_reading_units"] = np.array(amps)
        return y_clean, y_eff, touched, par
    raise ValueError(cls)


# ============================================================================ main


def main():
    from benchmarks.report import generator_parser

    args = generator_parser(__doc__).parse_args()
    os.makedirs(args.out, exist_ok=True)
    plan = make_plan()
    truths = []
    t_all = time.time()
    for i, cls, fam, target in plan:
        if args.only is not None and i not in args.only:
            continue
        t0 = time.time()
        rec, truth, edt = build(i, cls, fam, target, args.without_effect)
        t1 = time.time()
        write_recording(os.path.join(args.out, truth["file"]), rec)
        t2 = time.time()
        truths.append(truth)
        print(f"{truth['file']} {cls:10s} {fam:38s} S={truth['n_sensors']:2d} "
              f"fs={truth['sensor_rate_hz']:.0f} "
              f"T={truth['duration_s']:.0f} mag={truth['magnitude_x_noise']:.2f}/"
              f"{target:.2f} rs={truth['magnitude_resid_static_reading_x_noise']:.2f} "
              f"rp={truth['magnitude_resid_pose_poly4_x_noise']:.2f} gen={t1 - t0:.1f}s "
              f"(eff {edt:.1f}) write={t2 - t1:.1f}s", flush=True)
    if args.only is None:
        write_text(os.path.join(args.out, "truth.json"), json.dumps(truths, indent=1))
    print(f"total {time.time() - t_all:.1f}s")


if __name__ == "__main__":
    main()

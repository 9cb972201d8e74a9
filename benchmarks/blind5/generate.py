"""blind5: pulley-routed tendons and flex goniometers, one hidden effect per recording (or
none), for the discrepancy workflow's benchmark (``benchmarks.bench_discrepancy_blind``).
Written on 2026-12-05 by a helper session that read only the recording format, the
conventions, ``formats/``, ``kinematics/`` and the laws the generators before it used, and
never the workflow (docs/discrepancy-results.md, "A fifth blind generator").
``--without-effect`` writes each recording's clean twin (every random draw the same, the
effect computed but not applied).

Run from the repository root:
    python -m benchmarks.blind5.generate --out /tmp/blind5
    python -m benchmarks.blind5.generate --out /tmp/blind5-twins --without-effect
README.md next to this file gives every law and range.
"""

from __future__ import annotations

import json
import math
import os
import time

import numpy as np
from mcap.writer import CompressionType, Writer
from scipy import signal
from scipy.special import erf

from benchmarks.report import generator_parser
from exohil.formats.recording import AngleStream, Recording, Segment, SensorStream
from exohil.formats.recording_messages import sensor_decimals
from exohil.formats.recording_writer import RecordingWriter, write_recording
from exohil.kinematics.shoulder import ms_to_matrix

MASTER = 5505
GEN = "blind5"
DEG = math.pi / 180
FS_TRAJ = 1000.0

PLAN = (["clean"] * 7 + ["hysteresis"] * 7 + ["creep"] * 7 + ["saturation"] * 7
        + ["lag"] * 6 + ["drift"] * 6)
FAMILIES = {
    "hysteresis": ["load_dependent_play", "sleeve_axial_slip", "wrinkle_snap_relay"],
    "creep": ["fung_qlv_box_spectrum", "bingham_kelvin_yield", "duffing_kelvin_hardening"],
    "saturation": ["erf_dithered_rail_top", "unsigned_adc_floor_clip", "pnorm_stroke_limit"],
    "lag": ["underdamped_resonant_2nd", "rc_transmission_line", "delay_plus_erlang3"],
    "drift": ["hvac_sine_plus_step", "log_aging_from_power_on", "telegraph_contact"],
}
UNITS = ["mm"] * 7 + ["N"] * 5 + ["counts"] * 7 + ["dR/R0"] * 6 + ["V"] * 5 + ["deg"] * 6 + \
    ["rad"] * 4


def softplus(x, k):
    return k * np.logaddexp(0.0, x / k)


def rms(a, axis=0):
    return np.sqrt(np.mean(np.square(a), axis=axis))


# ------------------------------------------------------------------------------ motion
def minjerk(p0, p1, n):
    s = np.linspace(0, 1, n)[:, None]
    b = 10 * s**3 - 15 * s**4 + 6 * s**5
    return p0 + (p1 - p0) * b


def make_motion(rng, T, long_hold):
    """(n, 3) θ, φ, ψ in degrees at 1 kHz covering T seconds, and labels."""
    segs = []
    labels = []
    cur = np.array([rng.uniform(-10, 40), rng.uniform(3, 8), rng.uniform(-20, 5)])
    t = 0.0

    def add(arr, name):
        nonlocal cur, t
        segs.append(arr)
        labels.append((name, t, t + len(arr) / FS_TRAJ))
        t += len(arr) / FS_TRAJ
        cur = arr[-1].copy()

    def move_to(p, dur):
        add(minjerk(cur, np.asarray(p, float), max(2, int(dur * FS_TRAJ))), "move")

    n = int(rng.uniform(3, 8) * FS_TRAJ)
    add(np.repeat(cur[None], n, 0), "rest")
    kinds = ["raise", "reach", "axial", "wander", "raise", "reach", "circle"]
    hold_done = not long_hold
    while t < T + 8:
        k = kinds[int(rng.integers(len(kinds)))]
        if not hold_done and t > 0.25 * T:
            k = "long_hold"
            hold_done = True
        if k == "raise":
            plane = rng.choice([0, 30, 60, 90, -15, 105]) + rng.uniform(-8, 8)
            lo, hi = rng.uniform(8, 25), rng.uniform(70, 138)
            f = rng.uniform(0.15, 0.5)
            cyc = int(rng.integers(3, 8))
            psi0, psia = rng.uniform(-35, 0), rng.uniform(5, 30)
            move_to([plane, lo, psi0], rng.uniform(1, 2.5))
            tt = np.arange(int(cyc / f * FS_TRAJ)) / FS_TRAJ
            ph = 2 * np.pi * f * tt + 0.15 * np.sin(2 * np.pi * 0.37 * f * tt)
            phi = lo + (hi - lo) * 0.5 * (1 - np.cos(ph))
            psi = psi0 + psia * np.sin(ph * rng.uniform(0.4, 1.3))
            add(np.column_stack([np.full_like(tt, plane), phi, psi]), "raise")
        elif k == "reach":
            for _ in range(int(rng.integers(2, 5))):
                p = [rng.uniform(-15, 105), rng.uniform(20, 130), rng.uniform(-60, 20)]
                move_to(p, rng.uniform(0.7, 2.5))
                n = int(rng.uniform(2, 8) * FS_TRAJ)
                add(np.repeat(cur[None], n, 0), "hold")
        elif k == "long_hold":
            p = [rng.uniform(0, 90), rng.uniform(40, 110), rng.uniform(-40, 10)]
            move_to(p, rng.uniform(1, 2))
            n = int(rng.uniform(30, 50) * FS_TRAJ)
            add(np.repeat(cur[None], n, 0), "long_hold")
        elif k == "axial":
            base = [rng.uniform(0, 80), rng.uniform(40, 95), -20]
            move_to(base, rng.uniform(1, 2))
            f = rng.uniform(0.2, 0.5)
            tt = np.arange(int(rng.integers(4, 9) / f * FS_TRAJ)) / FS_TRAJ
            psi = -22.5 + 42.5 * np.sin(2 * np.pi * f * tt) * np.minimum(1, tt / 1.5)
            add(np.column_stack([np.full_like(tt, base[0]), np.full_like(tt, base[1]),
                                 psi]), "axial")
        elif k == "circle":
            c = [rng.uniform(20, 70), rng.uniform(50, 90), rng.uniform(-30, 0)]
            a1, a2 = rng.uniform(20, 40), rng.uniform(15, 30)
            per = rng.uniform(4, 10)
            tt = np.arange(int(rng.integers(2, 5) * per * FS_TRAJ)) / FS_TRAJ
            arr = np.column_stack([c[0] + a1 * np.sin(2 * np.pi * tt / per),
                                   c[1] + a2 * (np.cos(2 * np.pi * tt / per) - 1) + a2,
                                   c[2] + 15 * np.sin(4 * np.pi * tt / per)])
            move_to(arr[0], rng.uniform(1, 2))
            add(arr, "circle")
        else:  # wander
            dur = rng.uniform(15, 30)
            nn = int(dur * FS_TRAJ)
            fc = rng.uniform(0.05, 0.2)
            b, a = signal.butter(2, fc / (FS_TRAJ / 2))
            w = signal.filtfilt(b, a, rng.normal(0, 1, (nn + 2000, 3)), axis=0)[1000:-1000]
            w = w / w.std(0) * np.array([25, 25, 20])
            arr = cur + w - w[0]
            arr[:, 0] = np.clip(arr[:, 0], -20, 110)
            arr[:, 1] = np.clip(arr[:, 1], 5, 135)
            arr[:, 2] = np.clip(arr[:, 2], -65, 22)
            add(arr, "wander")
        if rng.random() < 0.3:
            rest = [cur[0], rng.uniform(3, 8), rng.uniform(-20, 5)]
            move_to(rest, rng.uniform(1.5, 3))
            add(np.repeat(cur[None], int(rng.uniform(2, 6) * FS_TRAJ), 0), "rest")
    q = np.concatenate(segs)
    q[:, 0] = np.clip(q[:, 0], -20, 110)
    q[:, 1] = np.clip(q[:, 1], 3, 140)
    q[:, 2] = np.clip(q[:, 2], -70, 25)
    q += rng.normal(0, 0.04, q.shape)  # physiological tremor (smooth below)
    b, a = signal.butter(2, 12 / (FS_TRAJ / 2))
    q = signal.filtfilt(b, a, q, axis=0)
    return q, labels


# ------------------------------------------------------------------------------ suit
ROUTES = {
    # name: (proximal anchor mm, [pulley offsets from GH], arm azimuth deg, arm depth range)
    "ant": ((85, -150, -60), [(55, 50, 5)], 0, (110, 190)),
    "sup": ((-30, 85, -95), [(0, 78, 25)], 90, (100, 170)),
    "post": ((-105, -140, -70), [(-60, 40, 15)], 180, (110, 190)),
    "spiral": ((95, -185, -40), [(62, 30, 40)], 225, (150, 220)),
    "lat": ((10, -265, 85), [], 120, (120, 200)),
    "dual": ((-85, -60, -105), [(-40, 72, -20), (22, 72, 42)], 45, (120, 200)),
    "ax": ((65, -125, 15), [], 300, (100, 160)),
}


class Suit:
    def __init__(self, rng, S, kind):
        self.kind = kind  # "tendon", "gonio" or "mixed"
        self.sensors = []
        names = []
        order = list(rng.permutation(list(ROUTES)))
        for s in range(S):
            if kind == "gonio" or (kind == "mixed" and s >= S - int(rng.integers(1, 3))):
                # flex goniometer across the shoulder: angle between a thorax tangent and an
                # arm tangent (tilted in the humerus frame, so axial rotation matters)
                for _ in range(100):
                    tilt_m = rng.uniform(25, 45) * DEG
                    tilt_a = rng.uniform(-15, 15) * DEG
                    t0 = np.array([math.sin(tilt_a), -math.cos(tilt_m) * math.cos(tilt_a),
                                   -math.sin(tilt_m) * math.cos(tilt_a)])
                    beta, gam = rng.uniform(6, 22) * DEG, rng.uniform(0, 2 * np.pi)
                    t1 = np.array([math.sin(beta) * math.cos(gam), -math.cos(beta),
                                   math.sin(beta) * math.sin(gam)])
                    if self._gonio_ok(t0, t1):
                        break
                self.sensors.append(("gonio", t0, t1))
                names.append(f"gon{s}")
            else:
                r = order[s % len(order)]
                A, pul, az, dr = ROUTES[r]
                A = np.array(A, float) + rng.uniform(-15, 15, 3)
                pul = [np.array(p, float) + rng.uniform(-8, 8, 3) for p in pul]
                az = (az + rng.uniform(-20, 20)) * DEG
                d = rng.uniform(*dr)
                rad = rng.uniform(42, 55)
                B = np.array([rad * math.cos(az), -d, rad * math.sin(az)])
                rp = rng.uniform(5, 12)
                self.sensors.append(("tendon", A, pul, B, rp))
                nm = f"{r}{s}"
                names.append(nm)
        self.names = names
        self.k_up = rng.uniform(0.08, 0.14)
        self.k_med = rng.uniform(0.02, 0.06)

    @staticmethod
    def _gonio_ok(t0, t1):
        th, ph, ps = np.meshgrid(np.linspace(-20, 110, 27), np.linspace(3, 140, 28),
                                 np.linspace(-70, 25, 12), indexing="ij")
        R = ms_to_matrix(th.ravel() * DEG, ph.ravel() * DEG, ps.ravel() * DEG)
        c = np.clip((R @ t1) @ t0, -1, 1)
        ang = np.degrees(np.arccos(c))
        return ang.min() > 12 and ang.max() < 168

    def lengths(self, pose_deg):
        """(N, S) physical quantity: tendon path length (mm) or goniometer angle (deg)."""
        th, ph, ps = (pose_deg[:, k] * DEG for k in range(3))
        R = ms_to_matrix(th, ph, ps)
        sp = softplus(pose_deg[:, 1] - 30, 6.0)
        gh = np.column_stack([np.zeros_like(sp), self.k_up * sp, -self.k_med * sp])
        out = np.empty((pose_deg.shape[0], len(self.sensors)))
        for s, sen in enumerate(self.sensors):
            if sen[0] == "gonio":
                _, t0, t1 = sen
                c = np.clip((R @ t1) @ t0, -1, 1)
                out[:, s] = np.degrees(np.arccos(c))
                continue
            _, A, pul, B, rp = sen
            pts = [np.broadcast_to(A, gh.shape)] + [gh + p for p in pul] + \
                [gh + R @ B]
            L = np.zeros(gh.shape[0])
            dirs = []
            for a, b in zip(pts[:-1], pts[1:], strict=True):
                v = b - a
                n = np.linalg.norm(v, axis=1)
                L += n
                dirs.append(v / n[:, None])
            for u0, u1 in zip(dirs[:-1], dirs[1:], strict=True):
                L += rp * np.arccos(np.clip(np.sum(u0 * u1, 1), -1, 1))
            out[:, s] = L
        return out


# ------------------------------------------------------------------------------ transfer
class Transfer:
    def __init__(self, rng, units, q, kinds):
        self.units = units
        S = q.shape[1]
        lo, hi = np.percentile(q, 0.5, 0), np.percentile(q, 99.5, 0)
        span = np.maximum(hi - lo, 1e-6)
        self.lo, self.span = lo, span
        self.p = []
        for s in range(S):
            sgn = 1 if rng.random() < 0.7 else -1
            if units == "mm":
                g, off = sgn * rng.uniform(0.9, 1.1), rng.uniform(-20, 20)
                self.p.append(("lin", g, off - g * lo[s]))
            elif units == "N":
                k, pre = rng.uniform(0.15, 0.5), rng.uniform(5, 20)
                self.p.append(("lin", k, k * (pre - lo[s])))
            elif units == "counts":
                full = rng.uniform(0.6, 0.85) * 4095
                g = sgn * full / span[s]
                base = rng.uniform(200, 4095 - full - 200)
                off = base - g * lo[s] if sgn > 0 else base + full - g * lo[s]
                self.p.append(("lin", g, off))
            elif units == "dR/R0":
                emax = rng.uniform(0.2, 0.5)
                G, G2 = rng.uniform(1.5, 3.0), rng.uniform(-0.8, 1.2)
                self.p.append(("quad", emax / span[s], lo[s], G, G2))
            elif units == "V":
                g = sgn * rng.uniform(3.2, 3.9) / span[s]
                base = rng.uniform(0.3, 0.6)
                off = base - g * lo[s] if sgn > 0 else base + abs(g) * span[s] - g * lo[s]
                self.p.append(("lin", g, off))
            elif units == "deg":
                g = sgn * rng.uniform(0.95, 1.05)
                self.p.append(("lin", g, rng.uniform(-10, 10)))
            elif units == "rad":
                g = sgn * rng.uniform(0.95, 1.05) * DEG
                self.p.append(("lin", g, rng.uniform(-0.2, 0.2)))
        del kinds

    def __call__(self, q):
        y = np.empty_like(q)
        for s, p in enumerate(self.p):
            if p[0] == "lin":
                y[:, s] = p[2] + p[1] * q[:, s]
            else:
                _, a, lo, G, G2 = p
                e = a * (q[:, s] - lo) + 0.01
                y[:, s] = G * e + G2 * e**2
        return y


# ------------------------------------------------------------------------------ effect laws
def play(x, w):
    z = np.empty_like(x)
    zc = x[0]
    for i in range(x.size):
        xi, wi = x[i], w[i]
        if zc < xi - wi:
            zc = xi - wi
        elif zc > xi + wi:
            zc = xi + wi
        z[i] = zc
    return z


def bisect(fn, target, lo, hi, log=True, it=40):
    """Parameter p in [lo, hi] with fn(p) = target, fn increasing."""
    for _ in range(it):
        mid = math.sqrt(lo * hi) if log else 0.5 * (lo + hi)
        if fn(mid) < target:
            lo = mid
        else:
            hi = mid
    return math.sqrt(lo * hi) if log else 0.5 * (lo + hi)


def onepole(x, tau, dt, x0=None):
    a = math.exp(-dt / tau)
    zi = np.array([a * (x[0] if x0 is None else x0)])
    y, _ = signal.lfilter([1 - a], [1, -a], x, zi=zi)
    return y


def grid_of(tau, dt):
    return np.arange(tau[0], tau[-1] + dt, dt)


# ------------------------------------------------------------------------------ one recording
def build(i, cls, fam, units, without):
    r1 = np.random.default_rng([MASTER, i, 1])
    r2 = np.random.default_rng([MASTER, i, 2])
    r3 = np.random.default_rng([MASTER, i, 3])
    r4 = np.random.default_rng([MASTER, i, 4])

    fs = float(r1.choice([100, 200, 250, 1000 / 3, 500, 1000]))
    T = float(min(r1.uniform(60, 240), 60000 / fs))
    T = max(T, 60.0)
    fm = float(r1.choice([50, 60, 100, 120, 240, 300]))
    S = int(r1.integers(2, 9))
    kind = {"deg": "gonio", "rad": "gonio", "counts": "mixed"}.get(units, "tendon")
    if kind == "mixed" and S < 3:
        S = 3
    suit = Suit(r1, S, kind)
    variant = ["std", "std", "std", "durable", "foreign", "segments_elbow", "reordered",
               "std"][i % 8]
    compression = str(r1.choice(["lz4", "zstd", "none"]))
    start_mode = i % 5
    if start_mode in (0, 3):
        t_start = 0.0
    elif i in (7, 22):
        t_start = 1.764e9 + r1.uniform(0, 1e5)  # epoch seconds
    else:
        t_start = r1.uniform(3, 5000)
    long_hold = r1.random() < 0.5
    seq0 = int(r1.choice([0, int(r1.integers(1, 2**31)), int(r1.integers(2**32, 2**40))]))

    # motion (1 kHz true pose), trajectory time tau; clock = tau + t_start
    traj, labels = make_motion(r2, T + 6, long_hold)
    ttraj = np.arange(traj.shape[0]) / FS_TRAJ
    tau_s0 = 2.0
    N = int(T * fs)
    k = np.arange(N)
    tau_s = tau_s0 + k / fs
    pose = np.column_stack([np.interp(tau_s, ttraj, traj[:, j]) for j in range(3)])
    q = suit.lengths(pose)
    q_rest = suit.lengths(np.array([[0.0, 0.0, 0.0]]))
    q = q - q_rest if kind != "gonio" else q
    if kind == "mixed":  # goniometer columns were not extensions: keep angles
        for s, sen in enumerate(suit.sensors):
            if sen[0] == "gonio":
                q[:, s] += q_rest[0, s]
    tr = Transfer(r1, units, q, None)
    y0 = tr(q)
    rng_lo = np.percentile(y0, 1, 0)
    rng_hi = np.percentile(y0, 99, 0)
    yspan = rng_hi - rng_lo

    # noise
    sd = yspan * r3.uniform(0.002, 0.008, S)
    if units == "counts":
        sd = np.maximum(sd, 1.3)
    noise_kind = str(r3.choice(["gauss", "gauss", "hum", "ar1"]))
    if noise_kind == "hum" and fs < 200:
        noise_kind = "gauss"
    white = r3.normal(0, 1, (N, S))
    if noise_kind == "hum":
        share = r3.uniform(0.2, 0.4)
        hum = math.sqrt(2) * np.sin(2 * np.pi * 50.0 * (tau_s[:, None]) + r3.uniform(0, 6, S))
        nz = math.sqrt(1 - share) * white + math.sqrt(share) * hum
    elif noise_kind == "ar1":
        tc = r3.uniform(0.03, 0.3)
        a = math.exp(-1 / (fs * tc))
        col = signal.lfilter([math.sqrt(1 - a * a)], [1, -a], r3.normal(0, 1, (N, S)), axis=0)
        share = r3.uniform(0.3, 0.6)
        nz = math.sqrt(1 - share) * white + math.sqrt(share) * col
    else:
        nz = white
    nz = nz / nz.std(0) * sd

    # drops
    keep = np.ones(N, bool)
    n_drop_events = 0
    if r3.random() < 0.55:
        n_drop_events = int(r3.integers(2, 16))
        for _ in range(n_drop_events):
            c = int(r3.integers(10, N - 60))
            keep[c:c + int(r3.integers(1, 31))] = False
    stall = None
    if i % 6 == 2:  # device stall: 1.5-3 s of frames missing
        c = int(r3.uniform(0.3, 0.7) * N)
        d = int(r3.uniform(1.5, 3) * fs)
        keep[c:c + d] = False
        stall = [round(c / fs, 3), round(d / fs, 3)]

    # mocap
    tau_m0 = max(0.2, tau_s0 + r3.uniform(-1.5, 2.5))
    tau_m1 = tau_s0 + T + r3.uniform(-2.5, 1.5)
    Mn = int((tau_m1 - tau_m0) * fm)
    tau_m = tau_m0 + np.arange(Mn) / fm + r3.uniform(-3e-4, 3e-4, Mn)
    qm = np.column_stack([np.interp(tau_m, ttraj, traj[:, j]) for j in range(3)])
    msd = r3.uniform(0.03, 0.25)
    qn = r3.normal(0, msd, qm.shape)
    qn[:, 0] *= 1 + 0.3 / np.maximum(np.sin(qm[:, 1] * DEG), 0.1)
    qm = qm + qn
    mkeep = np.ones(Mn, bool)
    mgaps = []
    if r3.random() < 0.5:
        for _ in range(int(r3.integers(1, 6))):
            c = r3.uniform(2, tau_m1 - tau_m0 - 5)
            d = r3.uniform(0.1, 4.0)
            mkeep &= ~((tau_m - tau_m0 >= c) & (tau_m - tau_m0 < c + d))
            mgaps.append([round(c, 3), round(d, 3)])

    # ------------------------------------------------------------------ effect
    dt_s = 1 / fs
    u = (q - tr.lo) / tr.span  # normalised physical quantity (~0..1)
    touched = []
    info = {}
    y_eff = y0.copy()
    clip_floor = None
    target = float(np.exp(r4.uniform(np.log(2), np.log(10)))) if cls != "clean" else 0.0

    def mag_of(ye, cols):
        d = (ye - y0)[keep][:, cols]
        return float(np.sqrt(np.mean((rms(d) / sd[cols]) ** 2)))

    def subset(lo=1, hi=None):
        hi = S if hi is None else min(hi, S)
        n = int(r4.integers(lo, hi + 1))
        return sorted(r4.choice(S, n, replace=False).tolist())

    g100 = grid_of(tau_s, 0.01)
    g50 = grid_of(tau_s, 0.02)

    if fam == "load_dependent_play":
        touched = subset()
        info["width_law"] = "w = w0*(0.3+0.7*clip(u,0,1))"
        w0s = {}
        for s in touched:
            xg = np.interp(g100, tau_s, q[:, s])
            ug = np.clip(np.interp(g100, tau_s, u[:, s]), 0, 1)

            def eff(w0, s=s, xg=xg, ug=ug):
                z = play(xg, w0 * (0.3 + 0.7 * ug))
                qq = q.copy()
                qq[:, s] += np.interp(tau_s, g100, z - xg)
                return tr(qq)[:, s]

            w0 = bisect(lambda w, eff=eff, s=s: float(rms((eff(w) - y0[:, s])[keep]) / sd[s]),
                        target, 1e-4, tr.span[s])
            y_eff[:, s] = eff(w0)
            w0s[suit.names[s]] = round(w0, 5)
        info["w0_physical_units"] = w0s
    elif fam == "sleeve_axial_slip":
        touched = list(range(S))
        psig = np.interp(g100, ttraj, traj[:, 2])

        def eff(w):
            ps = play(psig, np.full_like(psig, w))
            p2 = pose.copy()
            p2[:, 2] = np.interp(tau_s, g100, ps)
            qq = suit.lengths(p2)
            qq = qq - q_rest if kind != "gonio" else qq
            if kind == "mixed":
                for s, sen in enumerate(suit.sensors):
                    if sen[0] == "gonio":
                        qq[:, s] += q_rest[0, s]
            return tr(qq)

        # a sleeve slips at most ~20 deg; where that cannot reach the target the achieved
        # magnitude is lower (truth says so)
        w = bisect(lambda w: mag_of(eff(w), touched), target, 0.01, 20.0)
        y_eff = eff(w)
        info["play_width_deg"] = round(w, 4)
    elif fam == "wrinkle_snap_relay":
        touched = subset(1, 2)
        info["relays"] = {}
        for s in touched:
            ug = np.interp(g100, tau_s, u[:, s])
            for _ in range(50):
                c, hg = r4.uniform(0.35, 0.65), r4.uniform(0.08, 0.18)
                st = np.zeros_like(ug)
                cur = 1.0 if ug[0] > c else 0.0
                for j in range(ug.size):
                    if ug[j] > c + hg:
                        cur = 1.0
                    elif ug[j] < c - hg:
                        cur = 0.0
                    st[j] = cur
                if np.count_nonzero(np.diff(st)) >= 4:
                    break
            stf = onepole(st[np.clip(np.searchsorted(g100, tau_s, "right") - 1, 0, None)],
                          0.025, dt_s)
            sgn = r4.choice([-1, 1])
            y1 = tr(q + 0 * q)[:, s]
            qq = q.copy()
            qq[:, s] += sgn * stf
            unit_d = tr(qq)[:, s] - y1
            a = target * sd[s] / rms(unit_d[keep])
            qq[:, s] = q[:, s] + a * sgn * stf
            y_eff[:, s] = tr(qq)[:, s]
            info["relays"][suit.names[s]] = {"centre_u": round(c, 3), "half_gap_u": round(hg, 3),
                                             "switches": int(np.count_nonzero(np.diff(st))),
                                             "amp_physical": round(float(a * sgn), 5)}
    elif cls == "creep":
        touched = subset()
        info["per_sensor"] = {}
        for s in touched:
            sig = np.clip(np.interp(g50, tau_s, u[:, s]), 0, 1.2)
            if fam == "fung_qlv_box_spectrum":
                b = r4.uniform(1, 3)
                se = (np.exp(b * sig) - 1) / (math.exp(b) - 1)
                t1, t2 = r4.uniform(0.5, 2), r4.uniform(50, 300)
                taus = np.geomspace(t1, t2, 10)
                d = np.zeros_like(se)
                for tc in taus:
                    d += (se - onepole(se, tc, 0.02)) / len(taus)
                par = {"b": round(b, 3), "tau1_s": round(t1, 3), "tau2_s": round(t2, 2)}
            elif fam == "bingham_kelvin_yield":
                sy, tc = r4.uniform(0.03, 0.08), r4.uniform(8, 30)
                c = np.empty_like(sig)
                cc = sig[0]
                for j in range(sig.size):
                    e = sig[j] - cc
                    ex = abs(e) - sy
                    if ex > 0:
                        cc += math.copysign(ex, e) * 0.02 / tc
                    c[j] = cc
                d = c - sig
                par = {"yield_u": round(sy, 4), "tau_s": round(tc, 2)}
            else:  # duffing_kelvin_hardening
                k3, tc = r4.uniform(2, 6), r4.uniform(4, 40)
                sg = sig * (1 + k3)
                ceq = np.cbrt(sg / (2 * k3) + np.sqrt((sg / (2 * k3)) ** 2 + (1 / (3 * k3)) ** 3)) \
                    + np.cbrt(sg / (2 * k3) - np.sqrt((sg / (2 * k3)) ** 2 + (1 / (3 * k3)) ** 3))
                c = np.empty_like(sig)
                cc = ceq[0]
                for j in range(sig.size):
                    cc += 0.02 / tc * (sg[j] - cc - k3 * cc**3)
                    c[j] = cc
                d = c - ceq
                par = {"k3": round(k3, 3), "tau_s": round(tc, 2)}
            dd = np.interp(tau_s, g50, d)
            sgn = r4.choice([-1, 1])
            qq = q.copy()
            qq[:, s] += sgn * dd * tr.span[s]
            unit_d = tr(qq)[:, s] - y0[:, s]
            a = target * sd[s] / rms(unit_d[keep])
            qq[:, s] = q[:, s] + a * sgn * dd * tr.span[s]
            y_eff[:, s] = tr(qq)[:, s]
            par["amp_fraction_of_span"] = round(float(a * sgn), 5)
            info["per_sensor"][suit.names[s]] = par
    elif cls == "saturation":
        touched = subset(1, 3)
        info["per_sensor"] = {}
        for s in touched:
            ys = y0[:, s]
            lo_, hi_, sp_ = rng_lo[s], rng_hi[s], yspan[s]
            if fam == "erf_dithered_rail_top":
                wdt = r4.uniform(0.01, 0.03) * sp_

                def law(kk, ys=ys, hi_=hi_, sp_=sp_, wdt=wdt):
                    R = hi_ + sp_ * 0.1 - kk * sp_
                    z = (ys - R) / wdt
                    return ys - ((ys - R) * 0.5 * (1 + erf(z / math.sqrt(2)))
                                 + wdt * np.exp(-0.5 * z * z) / math.sqrt(2 * math.pi))
                par = {"dither_sd_fraction_of_span": round(wdt / sp_, 4)}
            elif fam == "unsigned_adc_floor_clip":
                def law(kk, ys=ys, lo_=lo_, sp_=sp_):
                    return np.maximum(ys, lo_ - 0.1 * sp_ + kk * sp_)
                par = {}
            else:
                p = r4.uniform(4, 12)
                xq = q[:, s]
                qlo, qsp = tr.lo[s], tr.span[s]
                xt = xq - qlo + 0.05 * qsp
                xmax = xt.max()

                def law(kk, s=s, xt=xt, p=p, qlo=qlo, qsp=qsp, xmax=xmax):
                    L = xmax * (1.6 - kk)
                    x2 = (xt ** -p + L ** -p) ** (-1 / p)
                    qq = q.copy()
                    qq[:, s] = x2 + qlo - 0.05 * qsp
                    return tr(qq)[:, s]
                par = {"p": round(p, 3)}

            def m(kk, law=law, s=s):
                return float(rms((law(kk) - y0[:, s])[keep]) / sd[s])
            kk = bisect(m, target, 0.0, 1.1, log=False)
            y_eff[:, s] = law(kk)
            par["knee_param"] = round(kk, 5)
            if fam == "unsigned_adc_floor_clip":
                par["floor_value"] = round(float(lo_ - 0.1 * sp_ + kk * sp_), 5)
            elif fam == "erf_dithered_rail_top":
                par["rail_value"] = round(float(hi_ + sp_ * 0.1 - kk * sp_), 5)
            else:
                par["limit_fraction_of_max"] = round(1.6 - kk, 5)
            par["fraction_of_frames_within_1sd_of_effect"] = round(
                float(np.mean(np.abs(y_eff[:, s] - ys) > sd[s])), 4)
            info["per_sensor"][suit.names[s]] = par
        if fam == "unsigned_adc_floor_clip":
            clip_floor = {s: info["per_sensor"][suit.names[s]]["floor_value"] for s in touched}
    elif cls == "lag":
        touched = list(range(S))
        if fam == "underdamped_resonant_2nd":
            zeta = r4.uniform(0.15, 0.45)

            def eff(fn):
                w = 2 * np.pi * fn
                b, a, _ = signal.cont2discrete(([w * w], [1, 2 * zeta * w, w * w]), dt_s, "zoh")
                b = np.ravel(b)
                zi = signal.lfilter_zi(b, a)
                out = np.empty_like(q)
                for s in range(S):
                    out[:, s], _ = signal.lfilter(b, a, q[:, s], zi=zi * q[0, s])
                return tr(out)
            fn = bisect(lambda f: -mag_of(eff(f), touched), -target, 0.2, 0.45 * fs)
            y_eff = eff(fn)
            info = {"zeta": round(zeta, 4), "natural_freq_hz": round(fn, 4)}
        elif fam == "rc_transmission_line":
            pad = int(30 * fs)

            def eff(tc):
                xp = np.concatenate([np.repeat(q[:1], pad, 0), q, np.repeat(q[-1:], pad, 0)])
                f = np.fft.rfftfreq(xp.shape[0], dt_s)
                H = 1 / np.cosh(np.sqrt(1j * 2 * np.pi * f * tc))
                out = np.fft.irfft(np.fft.rfft(xp, axis=0) * H[:, None], xp.shape[0], axis=0)
                return tr(out[pad:pad + N])
            tc = bisect(lambda x: mag_of(eff(x), touched), target, 1e-6, 5.0)
            y_eff = eff(tc)
            info = {"tau_RC_s": round(tc, 7),
                    "step_10_90_s_approx": round(tc * 0.5, 7)}
        else:
            kap = r4.uniform(1, 3)

            def eff(tc):
                out = np.empty_like(q)
                d = kap * tc
                for s in range(S):
                    x = np.interp(tau_s - d, tau_s, q[:, s])
                    for _ in range(3):
                        x = onepole(x, tc, dt_s)
                    out[:, s] = x
                return tr(out)
            tc = bisect(lambda x: mag_of(eff(x), touched), target, 1e-5, 2.0)
            y_eff = eff(tc)
            info = {"tau_each_s": round(tc, 7), "delay_s": round(kap * tc, 7),
                    "total_group_delay_s": round((3 + kap) * tc, 7)}
    elif cls == "drift":
        clock = tau_s + t_start
        tt = tau_s - tau_s[0]
        if fam == "hvac_sine_plus_step":
            touched = list(range(S))
            P, ph0 = r4.uniform(60, 180), r4.uniform(0, 2 * np.pi)
            ts, tauS = r4.uniform(0.3, 0.7) * T, r4.uniform(5, 20)
            bstep = r4.choice([-1, 1]) * r4.uniform(0.7, 1.5)
            Tc = np.sin(2 * np.pi * tt / P + ph0) + bstep * np.where(
                tt > ts, 1 - np.exp(-(tt - ts) / tauS), 0.0)
            common = r4.choice([-1, 1])
            load = common * r4.uniform(0.5, 1.5, S) * np.where(r4.random(S) < 0.85, 1, -1)
            shape = (Tc - Tc[keep].mean())[:, None] * load[None] * sd[None]
            a = target / mag_of(y0 + shape, touched)
            y_eff = y0 + a * shape
            info = {"period_s": round(P, 2), "step_at_s": round(ts, 2),
                    "step_tau_s": round(tauS, 2), "step_rel": round(float(bstep), 3),
                    "loadings": np.round(load, 3).tolist()}
        elif fam == "log_aging_from_power_on":
            touched = subset()
            t_on = clock[0] - r4.uniform(0, 10)
            info = {"per_sensor": {}}
            for s in touched:
                t0 = r4.uniform(2, 30)
                sh = np.log1p((clock - t_on) / t0)
                sh = sh - sh[keep].mean()
                sgn = r4.choice([-1, 1])
                a = target * sd[s] / rms(sh[keep])
                y_eff[:, s] = y0[:, s] + sgn * a * sh
                info["per_sensor"][suit.names[s]] = {"t0_s": round(t0, 2), "sign": int(sgn)}
            info["power_on_before_first_frame_s"] = round(float(clock[0] - t_on), 3)
        else:
            touched = subset(1, 2)
            info = {"per_sensor": {}}
            for s in touched:
                lam = 1 / r4.uniform(10, 30)
                for _ in range(100):
                    sw = np.cumsum(r4.exponential(1 / lam, 60))
                    sw = sw[sw < T - 3]
                    if sw.size >= 2 and sw[0] > 3:
                        break
                lev = (np.searchsorted(sw, tt, "right") % 2).astype(float)
                lev = onepole(lev, 0.02, dt_s)
                sh = lev - lev[keep].mean()
                sgn = r4.choice([-1, 1])
                a = target * sd[s] / rms(sh[keep])
                y_eff[:, s] = y0[:, s] + sgn * a * sh
                info["per_sensor"][suit.names[s]] = {"switch_times_s": np.round(sw, 2).tolist(),
                                                     "sign": int(sgn)}

    mag = mag_of(y_eff, touched) if touched else 0.0
    # diagnostic: what a pose polynomial (degree 4, true pose) leaves of the delta
    resid = 0.0
    if touched:
        sub = np.flatnonzero(keep)[:: max(1, int(keep.sum() // 20000))]
        P = pose[sub] / 100.0
        cols = [np.ones(sub.size)]
        for a in range(5):
            for b in range(5 - a):
                for c in range(5 - a - b):
                    if a + b + c:
                        cols.append(P[:, 0] ** a * P[:, 1] ** b * P[:, 2] ** c)
        Bm = np.column_stack(cols)
        d = (y_eff - y0)[sub][:, touched]
        coef, *_ = np.linalg.lstsq(Bm, d, rcond=None)
        resid = float(np.sqrt(np.mean((rms(d - Bm @ coef) / sd[touched]) ** 2)))

    y_final = (y0 if without else y_eff) + nz
    if clip_floor is not None and not without:
        for s, F in clip_floor.items():
            y_final[:, s] = np.maximum(y_final[:, s], F)
    if clip_floor is not None:
        shift = np.zeros(S)
        for s, F in clip_floor.items():
            shift[s] = F
        y_final = y_final - shift[None]
        info["readings_shifted_so_floor_is_zero"] = True
    if units == "counts":
        y_final = np.round(y_final)

    seq = seq0 + k
    t_clock = t_start + tau_s
    tm_clock = t_start + tau_m
    mnames = ("elv_angle", "shoulder_elv", "shoulder_rot")
    mvals = qm
    if variant == "reordered":
        mnames = ("shoulder_rot", "shoulder_elv", "elv_angle")
        mvals = qm[:, ::-1]
    segs = []
    if variant == "segments_elbow":
        segs = [Segment(nm, round(a + t_start, 3), round(b + t_start, 3))
                for nm, a, b in labels if b < tau_s[-1] and nm != "move"]
    rec = {
        "seq": seq[keep], "t": t_clock[keep], "y": y_final[keep],
        "tm": tm_clock[mkeep], "mnames": mnames, "m": mvals[mkeep], "segments": segs,
    }
    if variant == "segments_elbow":
        rec["elbow_t"] = tm_clock[mkeep]
        el = 20 + 60 * (0.5 + 0.5 * np.sin(2 * np.pi * tau_m[mkeep] / 7.0))
        rec["elbow"] = el[:, None]
    fmt = lambda v: float(round(float(v), 4))  # noqa: E731
    truth = {
        "file": f"rec_{i:02d}.mcap",
        "effect": "clean" if without else cls,
        "family": "none" if (without or cls == "clean") else fam,
        "magnitude_x_noise": 0.0 if without else fmt(mag),
        "magnitude_target_x_noise": 0.0 if without else fmt(target),
        "magnitude_resid_pose_poly4_x_noise": 0.0 if without else fmt(resid),
        "sensors_touched": [] if without else [suit.names[s] for s in touched],
        "noise_sd": {suit.names[s]: float(f"{sd[s]:.6g}") for s in range(S)},
        "noise_kind": noise_kind,
        "units": units, "suit_kind": kind, "sensor_names": suit.names, "n_sensors": S,
        "sensor_rate_hz": round(fs, 6), "mocap_rate_hz": fm, "duration_s": round(T, 3),
        "n_frames": int(keep.sum()), "dropped_frames": int((~keep).sum()),
        "drop_events": n_drop_events, "device_stall_t_dur_s": stall,
        "seq0": seq0, "t_start_s": round(t_start, 6), "mocap_noise_deg": round(msd, 3),
        "mocap_span_s": [round(tm_clock[mkeep][0], 3), round(tm_clock[mkeep][-1], 3)],
        "sensor_span_s": [round(t_clock[keep][0], 3), round(t_clock[keep][-1], 3)],
        "mocap_dropouts_t0_dur_s": mgaps, "writer_variant": variant,
        "compression": compression, "long_hold": bool(long_hold),
        "movements": [[nm, round(a, 2), round(b, 2)] for nm, a, b in labels
                      if a < T + tau_s0 and nm != "move"],
        "seed": f"{MASTER}-{i:02d}",
    }
    if without:
        truth.update(twin_of=f"rec_{i:02d}.mcap", twin_hidden_effect=cls,
                     twin_hidden_family=fam if cls != "clean" else "none")
    else:
        truth["params"] = json.loads(json.dumps(info, default=float))
    meta = {"generator": GEN, "seed": f"{MASTER}-{i:02d}"}
    return rec, truth, dict(fs=fs, fm=fm, units=units, names=suit.names, variant=variant,
                            compression=compression, meta=meta, i=i)


# ------------------------------------------------------------------------------ writing
def write(path, rec, w):
    variant = w["variant"]
    names, units = tuple(w["names"]), w["units"]
    if variant in ("std", "reordered", "segments_elbow"):
        mocap = {"shoulder": AngleStream(rec["tm"], rec["mnames"], rec["m"])}
        if "elbow" in rec:
            mocap["elbow"] = AngleStream(rec["elbow_t"], ("elbow_flexion",), rec["elbow"])
        r = Recording(sensor_names=names,
                      sensors=SensorStream(rec["seq"], rec["t"], rec["y"]),
                      mocap=mocap, sensor_units=units, sensor_rate_hz=w["fs"],
                      mocap_rate_hz=w["fm"], segments=rec["segments"], metadata=w["meta"])
        write_recording(path, r, compression=w["compression"])
    elif variant == "durable":
        with RecordingWriter(path, names, mocap_joints={"shoulder": rec["mnames"]},
                             sensor_units=units, sensor_rate_hz=w["fs"], mocap_rate_hz=w["fm"],
                             metadata=w["meta"], compression=w["compression"], durable=True,
                             sensor_decimals=sensor_decimals(rec["y"])) as wr:
            # call order: all mocap first, then the sensor frames in blocks (not interleaved)
            wr.add_mocap_samples("shoulder", rec["tm"], rec["m"])
            for a in range(0, rec["seq"].size, 5000):
                wr.add_sensor_frames(rec["seq"][a:a + 5000], rec["t"][a:a + 5000],
                                     rec["y"][a:a + 5000])
            span = rec["t"][-1] - rec["t"][0]
            rate = (rec["seq"][-1] - rec["seq"][0]) / span
            wr.add_metadata({"measured_sensor_rate_hz": f"{rate:.6f}"})
    else:  # foreign: another lab's writer, minimal metadata, zstd, own schema names
        with open(path, "wb") as fh:
            wr = Writer(fh, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
            wr.start(profile="", library="lab-daq 0.3")
            sid = wr.register_schema(name="lab.Frame", encoding="jsonschema",
                                     data=b'{"type":"object"}')
            cs = wr.register_channel(topic="/suit/sensors", message_encoding="json",
                                     schema_id=sid)
            sid2 = wr.register_schema(name="lab.Shoulder", encoding="jsonschema",
                                      data=b'{"type":"object"}')
            cm = wr.register_channel(topic="/mocap/shoulder", message_encoding="json",
                                     schema_id=sid2)
            sid3 = wr.register_schema(name="lab.Imu", encoding="jsonschema", data=b"{}")
            ci = wr.register_channel(topic="/imu/upperarm", message_encoding="json",
                                     schema_id=sid3)
            msgs = []
            intvals = units == "counts"
            for sq, tt, yy in zip(rec["seq"].tolist(), np.round(rec["t"], 6).tolist(),
                                  rec["y"].tolist(), strict=True):
                vals = [int(v) for v in yy] if intvals else [round(v, 5) for v in yy]
                msgs.append((tt, 0, cs, {"seq": sq, "t": tt, "values": vals}))
            for tt, row in zip(np.round(rec["tm"], 6).tolist(), rec["m"].tolist(), strict=True):
                msgs.append((tt, 1, cm, {"t": tt, **{n: round(v, 3)
                                                     for n, v in zip(rec["mnames"], row,
                                                                     strict=True)}}))
            for tt in np.round(rec["t"][::10], 6).tolist():
                msgs.append((tt, 2, ci, {"t": tt, "ax": 0.0, "ay": -9.81, "az": 0.1}))
            msgs.sort(key=lambda m: (m[0], m[1]))
            cnt = {cs: 0, cm: 0, ci: 0}
            for tt, _, ch, payload in msgs:
                ns = int(round(tt * 1e9))
                wr.add_message(channel_id=ch, log_time=ns, publish_time=ns, sequence=cnt[ch],
                               data=json.dumps(payload, separators=(",", ":")).encode())
                cnt[ch] += 1
            md = {"format": "exohil-recording", "version": "1", "generator": GEN,
                  "seed": w["meta"]["seed"]}
            if not (len(names) == 4 or (units == "mm" and w["i"] % 2)):
                md["sensors"] = ",".join(names)
            if units != "mm":
                md["units"] = f"{units},deg"
            wr.add_metadata("lab.session", {"operator": "anon", "room": "B2"})
            wr.add_metadata("exohil.recording", md)
            wr.finish()
        w["names_written"] = md.get("sensors", "(omitted)")


def main():
    args = generator_parser(__doc__).parse_args()
    os.makedirs(args.out, exist_ok=True)
    prng = np.random.default_rng([MASTER, 999])
    plan = list(prng.permutation(PLAN))
    units = list(prng.permutation(UNITS))
    fam_cycle = {c: list(prng.permutation(f)) for c, f in FAMILIES.items()}
    fams = []
    used = {c: 0 for c in FAMILIES}
    for c in plan:
        if c == "clean":
            fams.append("none")
            continue
        fams.append(fam_cycle[c][used[c] % 3])
        used[c] += 1
    # the ADC floor needs a unit with a zero rail
    for i, f in enumerate(fams):
        if f == "unsigned_adc_floor_clip" and units[i] not in ("counts", "V"):
            j = next(j for j in range(40) if units[j] in ("counts", "V")
                     and fams[j] != "unsigned_adc_floor_clip")
            units[i], units[j] = units[j], units[i]
    truths = []
    for i in range(40):
        if args.only is not None and i not in args.only:
            continue
        t0 = time.time()
        rec, truth, w = build(i, str(plan[i]), fams[i], units[i], args.without_effect)
        write(os.path.join(args.out, truth["file"]), rec, w)
        if "names_written" in w:
            truth["metadata_sensors_written"] = w["names_written"]
        truths.append(truth)
        print(f"{truth['file']} {plan[i]:10s} {fams[i]:26s} {units[i]:6s} "
              f"S={truth['n_sensors']} fs={truth['sensor_rate_hz']:.1f} "
              f"T={truth['duration_s']:.0f} "
              f"{w['variant']:14s} mag={truth['magnitude_x_noise']:.2f} "
              f"(target {truth['magnitude_target_x_noise']:.2f}, pose-resid "
              f"{truth['magnitude_resid_pose_poly4_x_noise']:.2f}) {time.time() - t0:.1f}s",
              flush=True)
    if args.only is None:
        with open(os.path.join(args.out, "truth.json"), "w") as fh:
            json.dump(truths, fh, indent=1)


if __name__ == "__main__":
    main()

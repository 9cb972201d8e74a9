#!/usr/bin/env python
"""blind3: independent generator of shoulder-exosuit recordings with one hidden effect each.

Deterministic from MASTER_SEED. Writes OUT/rec_XX.mcap and OUT/truth.json (the answer key).
Single-threaded (set OMP_NUM_THREADS=1 before numpy is imported).

Written on 2026-11-26 by a separate session that read only the recording format and the angle
conventions, never the discrepancy workflow; kept here, unchanged in its physics, so that the
held-out benchmark can be re-run (``benchmarks/blind3/README.md``). Run from the repository
root: ``python -m benchmarks.blind3.generate --out DIR [--only N ...] [--without-effect]``.
``--without-effect`` writes each recording's clean twin: every draw the same (motion, suit,
noise, clock), the hidden effect computed but not applied, labelled clean in truth.json.
``--duration S --sensors N`` (timing only, with ``--only``) override a recording's drawn
length and tendon count; what is drawn after them differs, so it is no longer one of the 40.
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from scipy import signal

from exohil.formats.atomic import write_text
from exohil.formats.recording import AngleStream, Recording, SensorStream
from exohil.formats.recording_writer import write_recording

MASTER_SEED = 20261126
N_REC = 40
FS = 250.0
FINE = 1000.0  # trajectory grid, Hz
D2R = math.pi / 180.0


# =============================================================================== kinematics
def rot_x(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1),
                     np.stack([z, s, c], -1)], -2)


def rot_y(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1),
                     np.stack([-s, z, c], -1)], -2)


def humerus_rotation(theta_deg, phi_deg, psi_deg):
    """Thorax <- humerus, ISB thorax frame (X anterior, Y up, Z lateral), MoBL coupled form:
    R = Ry(theta) Rx(-phi) Ry(psi - theta)."""
    th, ph, ps = theta_deg * D2R, phi_deg * D2R, psi_deg * D2R
    return rot_y(th) @ rot_x(-ph) @ rot_y(ps - th)


def softplus(x, s):
    return s * np.logaddexp(0.0, x / s)


# =============================================================================== motion
def minjerk(p0, p1, n):
    tau = np.linspace(0.0, 1.0, n)
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    return p0[None, :] + (p1 - p0)[None, :] * s[:, None]


def smooth_noise(rng, n, fc, sd, fs=FINE):
    """Low-pass filtered gaussian noise with given SD (per column if 2-D shape)."""
    w = rng.standard_normal(n + int(4 * fs / max(fc, 1e-3)))
    b, a = signal.butter(2, fc / (fs / 2))
    y = signal.lfilter(b, a, w)[-n:]
    y = y / (np.std(y) + 1e-12) * sd
    return y


class MotionBuilder:
    def __init__(self, rng, psi_varies, psi_fixed):
        self.rng = rng
        self.psi_varies = psi_varies
        self.psi_fixed = psi_fixed
        self.chunks = [np.array([[20.0, 3.0, psi_fixed]])]
        self.labels = []
        self.t = 0.0

    @property
    def cur(self):
        return self.chunks[-1][-1].copy()

    def _psi(self, lo=-40, hi=40):
        return self.rng.uniform(lo, hi) if self.psi_varies else self.psi_fixed

    def add(self, arr, label):
        n0 = sum(len(c) for c in self.chunks)
        self.chunks.append(arr)
        self.labels.append((label, n0 / FINE, (n0 + len(arr)) / FINE))

    def move_to(self, target, dur):
        n = max(int(dur * FINE), 2)
        self.add(minjerk(self.cur, np.asarray(target, float), n)[1:], "move")

    def hold(self, dur, tremor=0.2):
        n = int(dur * FINE)
        base = np.repeat(self.cur[None, :], n, 0)
        r = self.rng
        base[:, 0] += smooth_noise(r, n, 1.5, tremor)
        base[:, 1] += smooth_noise(r, n, 1.5, tremor)
        if self.psi_varies:
            base[:, 2] += smooth_noise(r, n, 1.5, tremor)
        # taper the tremor in at the start to stay continuous
        ramp = np.minimum(np.arange(n) / 200.0, 1.0)[:, None]
        base = self.cur[None, :] + (base - self.cur[None, :]) * ramp
        return base

    def seg_rest(self):
        r = self.rng
        tgt = [r.uniform(-10, 40), r.uniform(1, 6), self._psi(-10, 10)]
        self.move_to(tgt, r.uniform(1.5, 3.0))
        self.add(self.hold(r.uniform(3, 10), 0.3), "rest")

    def seg_sweep(self):
        r = self.rng
        plane = r.choice([0.0, 90.0, r.uniform(25, 60), r.uniform(-30, -10), r.uniform(100, 130)])
        lo, hi = r.uniform(5, 25), r.uniform(70, 140)
        period = 1.0 / r.uniform(0.1, 0.6)
        ncyc = int(r.integers(3, 9))
        psi0 = self._psi(-20, 20)
        self.move_to([plane, lo, psi0], r.uniform(1.0, 2.5))
        n = int(ncyc * period * FINE)
        tt = np.arange(1, n + 1) / FINE
        # slightly irregular cycles: period modulation
        phase = 2 * np.pi * tt / period * (1 + 0.08 * np.sin(2 * np.pi * tt / (3.1 * period)))
        phi = lo + (hi - lo) * 0.5 * (1 - np.cos(phase))
        th = plane + 4.0 * np.sin(phase * 0.5)
        if self.psi_varies:
            amp = r.uniform(5, 40 - abs(psi0))
            ps = psi0 + amp * np.sin(2 * np.pi * tt / period * r.uniform(0.5, 1.5)) * \
                np.minimum(tt / 1.0, 1.0)
        else:
            ps = np.full(n, psi0)
        self.add(np.stack([th, phi, ps], 1), "sweep")

    def seg_reach_hold(self):
        r = self.rng
        for _ in range(int(r.integers(2, 5))):
            tgt = [r.uniform(-30, 130), r.uniform(30, 140), self._psi()]
            self.move_to(tgt, r.uniform(0.8, 3.0))
            self.add(self.hold(r.uniform(2, 10)), "hold")
        if r.random() < 0.5:
            self.move_to([r.uniform(-10, 40), r.uniform(5, 25), self._psi(-15, 15)],
                         r.uniform(1.0, 2.5))

    def seg_fig8(self):
        r = self.rng
        thc, tha = r.uniform(20, 80), r.uniform(25, 45)
        phc, pha = r.uniform(50, 90), r.uniform(15, 35)
        period = r.uniform(4, 12)
        ncyc = int(r.integers(2, 6))
        psi0 = self._psi(-20, 20)
        self.move_to([thc, phc, psi0], r.uniform(1.0, 2.5))
        n = int(ncyc * period * FINE)
        tt = np.arange(1, n + 1) / FINE
        w = 2 * np.pi / period
        th = thc + tha * np.sin(w * tt)
        ph = phc + pha * np.sin(2 * w * tt)
        if self.psi_varies:
            ps = psi0 + r.uniform(5, 20) * (np.sin(w * tt + 1.0) - np.sin(1.0))
        else:
            ps = np.full(n, psi0)
        self.add(np.stack([th, ph, ps], 1), "fig8")

    def seg_wander(self):
        r = self.rng
        c = np.array([r.uniform(0, 100), r.uniform(30, 100), self._psi(-20, 20)])
        self.move_to(c, r.uniform(1.5, 3.0))
        dur = r.uniform(10, 30)
        n = int(dur * FINE)
        fc = r.uniform(0.03, 0.1)
        amp = r.uniform(10, 25)
        d = np.stack([smooth_noise(r, n, fc, amp), smooth_noise(r, n, fc, amp * 0.8),
                      smooth_noise(r, n, fc, 10) if self.psi_varies else np.zeros(n)], 1)
        d = d - d[0]
        self.add(c[None, :] + d, "wander")

    def build(self, duration):
        r = self.rng
        kinds = [self.seg_sweep, self.seg_reach_hold, self.seg_fig8, self.seg_wander,
                 self.seg_rest]
        weights = np.array([0.32, 0.25, 0.15, 0.13, 0.15])
        self.seg_rest()
        while sum(len(c) for c in self.chunks) / FINE < duration - 12:
            k = int(r.choice(len(kinds), p=weights / weights.sum()))
            kinds[k]()
        # finish with a rest to the exact duration
        self.move_to([r.uniform(-10, 40), r.uniform(1, 6), self._psi(-10, 10)], 2.0)
        arr = np.concatenate(self.chunks, 0)
        need = int(duration * FINE) + 200
        if len(arr) < need:
            self.add(self.hold((need - len(arr)) / FINE + 0.01, 0.3), "rest")
            arr = np.concatenate(self.chunks, 0)
        arr = arr[:need]
        arr[:, 0] = np.clip(arr[:, 0], -30, 130)
        arr[:, 1] = np.clip(arr[:, 1], 0.3, 140)
        arr[:, 2] = np.clip(arr[:, 2], -40, 40) if self.psi_varies else self.psi_fixed
        return arr


# =============================================================================== suit
ROUTES = {
    #          proximal anchor box (x, y, z) mm in rest-thorax frame    on scapula
    #          distal azimuth deg
    "ant":    (((70, 100), (-40, 0), (-50, -10)), False, (70, 110)),
    "supant": (((10, 40), (50, 80), (-30, 0)), True, (30, 60)),
    "sup":    (((-20, 20), (60, 90), (-40, -10)), True, (-20, 20)),
    "suppst": (((-50, -20), (50, 80), (-40, -10)), True, (-60, -30)),
    "post":   (((-100, -70), (-40, 10), (-60, -20)), False, (-110, -70)),
    "spiral": (((60, 90), (-60, -30), (-30, 0)), False, (-150, -110)),
    "neck":   (((-10, 10), (100, 130), (-90, -60)), False, (-10, 30)),
    "latpst": (((-70, -40), (20, 45), (-20, 10)), True, (-40, 0)),
}


class Suit:
    def __init__(self, rng, n_sens):
        self.rng = rng
        names = list(rng.choice(list(ROUTES), size=n_sens, replace=False))
        self.names = names
        self.axes = np.array([rng.uniform(45, 60), rng.uniform(40, 55), rng.uniform(50, 65)])
        self.cap_offset = np.array([rng.uniform(-5, 5), rng.uniform(0, 10), rng.uniform(0, 8)])
        self.pivot = np.array([rng.uniform(-40, -20), rng.uniform(-10, 10), rng.uniform(-90, -60)])
        self.rhythm = rng.uniform(0.28, 0.40)  # scapular upward rotation per deg beyond knee
        self.knee = rng.uniform(25, 35)
        self.prox, self.onscap, self.dist = [], [], []
        for nm in names:
            box, onscap, az = ROUTES[nm]
            p = np.array([rng.uniform(*b) for b in box])
            # keep anchors clearly outside the cap
            u = (p - self.cap_offset) / self.axes
            if np.linalg.norm(u) < 1.25:
                p = self.cap_offset + u / np.linalg.norm(u) * 1.25 * self.axes
            self.prox.append(p)
            self.onscap.append(onscap)
            b = rng.uniform(*az) * D2R
            ra, ell = rng.uniform(40, 55), rng.uniform(110, 200)
            self.dist.append(np.array([ra * np.sin(b), -ell, ra * np.cos(b)]))
        self.guide_wrap = rng.uniform(0.4, 1.5, n_sens)  # rad, fixed eyelet wrap (capstan)

    def lengths(self, th, ph, ps, K=20):
        """Tendon path length (mm) and cap wrap angle (rad), shape (N, S)."""
        s = self.rhythm * softplus(ph - self.knee, 5.0) * D2R
        Rs = rot_x(-s)  # scapula upward rotation (about -X through pivot)
        gh = self.pivot[None, :] + np.einsum("nij,j->ni", Rs, -self.pivot)
        cap_c = self.pivot[None, :] + np.einsum("nij,j->ni", Rs, self.cap_offset - self.pivot)
        Rh = humerus_rotation(th, ph, ps)
        N = th.size
        L = np.zeros((N, len(self.names)))
        W = np.zeros((N, len(self.names)))
        for k in range(len(self.names)):
            if self.onscap[k]:
                P = self.pivot[None, :] + np.einsum("nij,j->ni", Rs, self.prox[k] - self.pivot)
            else:
                P = np.repeat(self.prox[k][None, :], N, 0)
            D = gh + np.einsum("nij,j->ni", Rh, self.dist[k])
            # map into the unit-sphere space of the cap (cap frame = scapula frame)
            u = np.einsum("nji,nj->ni", Rs, P - cap_c) / self.axes
            w = np.einsum("nji,nj->ni", Rs, D - cap_c) / self.axes
            pn, dn = np.linalg.norm(u, axis=1), np.linalg.norm(w, axis=1)
            pn_c, dn_c = np.maximum(pn, 1.0001), np.maximum(dn, 1.0001)
            e1 = u / pn[:, None]
            cosg = np.clip(np.sum(u * w, 1) / (pn * dn), -1, 1)
            gam = np.arccos(cosg)
            ap, ad = np.arccos(1 / pn_c), np.arccos(1 / dn_c)
            arc = gam - ap - ad
            straight = np.linalg.norm(P - D, axis=1)
            wrap = arc > 0
            Lk = straight.copy()
            if wrap.any():
                e2 = w - np.sum(w * e1, 1)[:, None] * e1
                e2n = np.linalg.norm(e2, axis=1)
                e2 = e2 / np.maximum(e2n, 1e-9)[:, None]
                ang = ap[:, None] + np.linspace(0, 1, K + 1)[None, :] * np.maximum(arc, 0)[:, None]
                q = (np.cos(ang)[:, :, None] * e1[:, None, :]
                     + np.sin(ang)[:, :, None] * e2[:, None, :])
                qr = np.einsum("nij,nkj->nki", Rs, q * self.axes) + cap_c[:, None, :]
                arcL = np.sum(np.linalg.norm(np.diff(qr, axis=1), axis=2), 1)
                Lw = (np.linalg.norm(P - qr[:, 0], axis=1) + arcL +
                      np.linalg.norm(D - qr[:, -1], axis=1))
                Lk[wrap] = Lw[wrap]
            L[:, k] = Lk
            W[:, k] = np.maximum(arc, 0)
        return L, W


# =============================================================================== transfer
class Transfer:
    """Tendon extension x (mm) -> reading, per sensor."""

    def __init__(self, rng, unit, S, xmin, xmax, noise_mm):
        self.unit = unit
        self.sign = rng.choice([-1.0, 1.0], S)
        span = np.maximum(xmax - xmin, 5.0)
        self.xmid = 0.5 * (xmin + xmax)
        self.k2 = rng.uniform(-0.015, 0.015, S) / span  # mild curvature (<~1.5% of span)
        self.q = None
        if unit == "mm":
            self.gain = self.sign * rng.uniform(0.85, 1.15, S)
            self.off = rng.uniform(-20, 250, S)
        elif unit == "V":
            self.gain = self.sign * rng.uniform(2.8, 4.2, S) / (span + 6.0)
            self.off = 2.5 - self.gain * self.xmid + rng.uniform(-0.2, 0.2, S)
        elif unit.startswith("counts"):
            bits = 12 if unit == "counts" else 16
            full = 2 ** bits
            travel = np.maximum(rng.uniform(100, 160, S), (span + 6.0) * rng.uniform(1.3, 1.6, S))
            self.gain = self.sign * full / travel
            self.off = full / 2 - self.gain * self.xmid + rng.uniform(-0.04, 0.04, S) * full
            self.q = np.ones(S)
            self.full = full
        elif unit == "mrad":
            r_drum = rng.uniform(6, 12, S)
            cpr = rng.choice([4096, 16384], S)
            self.gain = self.sign * 1000.0 / r_drum
            self.off = rng.uniform(0, 3000, S)
            self.q = 2 * np.pi * 1000.0 / cpr
        else:
            raise ValueError(unit)
        qmm = 0.0 if self.q is None else np.abs(self.q / self.gain)
        self.noise_mm_total = np.sqrt(noise_mm**2 + qmm**2 / 12.0)

    def __call__(self, x, quantise=False):
        d = x - self.xmid
        y = self.off + self.gain * (x + self.k2 * d * d)
        if quantise and self.q is not None:
            y = np.round(y / self.q) * self.q
        return y

    def slope(self, x):
        return self.gain * (1 + 2 * self.k2 * (x - self.xmid))


# =============================================================================== effects
def grad_t(x, t):
    return np.gradient(x, t, axis=0)


def load_of(x, xmin, xmax):
    return 0.2 + 0.8 * np.clip((x - xmin) / np.maximum(xmax - xmin, 1e-6), 0, 1)


def remove_static(e, x, deg=5):
    """Project out the part of e explainable as a static polynomial of x (per column)."""
    out = e.copy()
    for k in range(e.shape[1]):
        xs = (x[:, k] - x[:, k].mean()) / (x[:, k].std() + 1e-9)
        V = np.vander(xs, deg + 1)
        c, *_ = np.linalg.lstsq(V, e[:, k], rcond=None)
        out[:, k] = e[:, k] - V @ c
    return out


# ---- hysteresis ------------------------------------------------------------------
def hyst_duhem(rng, x, t, ctx):
    """Semilinear Duhem: dh/dt = |xdot|/delta * (g_sgn(xdot)(x) - h)."""
    S = x.shape[1]
    delta = rng.uniform(3, 10, S)
    u = (x - ctx["xmin"]) / np.maximum(ctx["xmax"] - ctx["xmin"], 1e-6)
    gp = 0.6 + 0.4 * u
    gm = -(0.6 + 0.4 * (1 - u))
    dx = np.diff(x, axis=0, prepend=x[:1])
    h = np.zeros_like(x)
    hk = np.zeros(S)
    for i in range(1, len(x)):
        g = np.where(dx[i] >= 0, gp[i], gm[i])
        a = np.exp(-np.abs(dx[i]) / delta)
        hk = g + (hk - g) * a
        h[i] = hk
    return h, {"delta_mm": delta.round(2).tolist(), "branch": "g+=0.6+0.4u, g-=-(0.6+0.4(1-u))"}


def hyst_lugre(rng, x, t, ctx):
    """LuGre bristle friction in the sheath; length error = friction / tendon stiffness."""
    S = x.shape[1]
    v = grad_t(x, t)
    dt = np.diff(t, prepend=t[0] - 1 / FS)
    Fc, Fs = 1.0, rng.uniform(1.3, 2.0)
    vs = rng.uniform(3, 15)
    zeta = rng.uniform(0.5, 2.5, S)  # bristle deflection scale, mm
    sig0 = 1.0 / zeta
    sig1 = rng.uniform(0.0, 0.02)
    z = np.zeros(S)
    F = np.zeros_like(x)
    for i in range(len(x)):
        vi = v[i]
        g = Fc + (Fs - Fc) * np.exp(-(vi / vs) ** 2)
        zss = g * np.sign(vi) / sig0
        rate = sig0 * np.abs(vi) / g
        znew = zss + (z - zss) * np.exp(-rate * dt[i])
        zdot = (znew - z) / dt[i]
        z = znew
        F[i] = sig0 * z + sig1 * zdot
    return F, {"Fs/Fc": round(Fs, 3), "vs_mm_s": round(vs, 2), "zeta_mm": zeta.round(2).tolist(),
               "sigma1": round(sig1, 4), "sigma2": 0.0}


def hyst_kp(rng, x, t, ctx):
    """Krasnosel'skii-Pokrovskii: weighted sum of ridge-function hysterons."""
    S = x.shape[1]
    M = 48
    u = (x - ctx["xmin"]) / np.maximum(ctx["xmax"] - ctx["xmin"], 1e-6)
    mid = rng.uniform(-0.1, 1.1, (M, S))
    width = np.abs(rng.normal(0, 0.25, (M, S))) + 0.03
    al, be = mid + width / 2, mid - width / 2
    ridge = rng.uniform(0.05, 0.2, (M, S))
    mu = rng.uniform(0.3, 1.0, (M, S))
    s = -np.ones((M, S))
    out = np.zeros_like(x)
    prev = u[0]
    # initialise at the first input by a rising pass
    for i in range(len(u)):
        ui = u[i][None, :]
        up = u[i] >= prev
        r_up = -1 + 2 * np.clip((ui - al + ridge) / ridge, 0, 1)
        r_dn = -1 + 2 * np.clip((ui - be) / ridge, 0, 1)
        s = np.where(up[None, :], np.maximum(s, r_up), np.minimum(s, r_dn))
        out[i] = np.sum(mu * s, 0)
        prev = u[i]
    return out, {"hysterons": M, "ridge_width_u": [0.05, 0.2], "threshold_gap_u_sd": 0.25}


def hyst_capstan(rng, x, t, ctx):
    """Euler-Eytelwein capstan friction over the cap (+ eyelet): T_s = T_spring*e^{mu*beta*sigma},
    sigma a direction state that reverses over a small displacement; error = dT/k_tendon."""
    S = x.shape[1]
    mu = rng.uniform(0.1, 0.3, S)
    beta = ctx["wrap"] + ctx["guide"][None, :]
    Tsp = load_of(x, ctx["xmin"], ctx["xmax"])
    delta = rng.uniform(0.5, 3.0, S)
    dx = np.diff(x, axis=0, prepend=x[:1])
    sig = np.zeros_like(x)
    sk = np.zeros(S)
    for i in range(1, len(x)):
        tgt = np.sign(dx[i])
        a = np.exp(-np.abs(dx[i]) / delta)
        sk = np.where(dx[i] != 0, tgt + (sk - tgt) * a, sk)
        sig[i] = sk
    e = Tsp * (np.exp(mu * beta * sig) - 1)
    return e, {"mu": mu.round(3).tolist(), "eyelet_wrap_rad": ctx["guide"].round(2).tolist(),
               "reversal_mm": delta.round(2).tolist()}


# ---- creep --------------------------------------------------------------------------
def creep_findley(rng, x, t, ctx):
    """Findley power law, time-hardening: dc/dt = n * sigma^m * t^(n-1)  (no recovery)."""
    n = rng.uniform(0.2, 0.45)
    m = rng.uniform(1.2, 2.2)
    sig = load_of(x, ctx["xmin"], ctx["xmax"])
    tt = np.maximum(t - t[0], 1e-3)[:, None]
    rate = n * sig**m * tt ** (n - 1)
    dt = np.diff(t, prepend=t[0])[:, None]
    c = np.cumsum(rate * dt, 0)
    return c, {"n": round(n, 3), "m": round(m, 3), "stress": "0.2+0.8*normalised extension"}


def creep_norton(rng, x, t, ctx):
    """Norton viscoplastic ratcheting: dc/dt = <(sigma - sigma_y)/sigma_ref>^p, accumulates on
    each excursion above the yield load."""
    S = x.shape[1]
    sig = load_of(x, ctx["xmin"], ctx["xmax"])
    sy = rng.uniform(0.45, 0.75, S)
    p = rng.uniform(2.5, 5.0)
    rate = np.maximum(sig - sy[None, :], 0) ** p
    dt = np.diff(t, prepend=t[0])[:, None]
    c = np.cumsum(rate * dt, 0)
    return c, {"sigma_y": sy.round(3).tolist(), "p": round(p, 2)}


def creep_twoexp_asym(rng, x, t, ctx):
    """Two exponential terms relaxing toward k_j*sigma, slower when unloading."""
    S = x.shape[1]
    sig = load_of(x, ctx["xmin"], ctx["xmax"])
    tf, ts = rng.uniform(2, 8), rng.uniform(20, 80)
    ratio = rng.uniform(2, 4)
    wf = rng.uniform(0.3, 0.7)
    dt = np.diff(t, prepend=t[0])
    cf = np.zeros(S)
    cs = np.zeros(S)
    out = np.zeros_like(x)
    sig0 = sig[0].copy()
    for i in range(len(t)):
        # response to load above the initial level (both directions)
        tgt = sig[i] - sig0
        tauf = np.where(tgt > cf, tf, tf * ratio)
        taus = np.where(tgt > cs, ts, ts * ratio)
        cf = tgt + (cf - tgt) * np.exp(-dt[i] / tauf)
        cs = tgt + (cs - tgt) * np.exp(-dt[i] / taus)
        out[i] = wf * cf + (1 - wf) * cs
    return out, {"tau_fast_s": round(tf, 2), "tau_slow_s": round(ts, 2),
                 "unload_tau_ratio": round(ratio, 2), "w_fast": round(wf, 2)}


def creep_hold_andrade(rng, x, t, ctx):
    """Creep only during holds under load: Andrade t^(1/3) flow while still, exponential recovery
    once the tendon moves again."""
    S = x.shape[1]
    sig = load_of(x, ctx["xmin"], ctx["xmax"])
    v = np.abs(grad_t(x, t))
    b, a = signal.butter(1, 2.0 / (FS / 2))
    vs = signal.filtfilt(b, a, v, axis=0)
    vth = rng.uniform(1.0, 3.0)
    tau_r = rng.uniform(3, 10)
    dt = np.diff(t, prepend=t[0])
    c = np.zeros(S)
    th = np.zeros(S)
    out = np.zeros_like(x)
    for i in range(len(t)):
        still = vs[i] < vth
        th = np.where(still, th + dt[i], 0.0)
        grow = sig[i] * (1 / 3) * (th + 0.05) ** (-2 / 3) * dt[i]
        c = np.where(still, c + grow, c * np.exp(-dt[i] / tau_r))
        out[i] = c
    return out, {"still_if_speed_below_mm_s": round(vth, 2), "recovery_tau_s": round(tau_r, 2),
                 "law": "dc = sigma/3 * t_hold^(-2/3) dt while still"}


# ---- saturation (parameter p: larger -> stronger) --------------------------------------
def _ctx_levels(ctx):
    lo, hi = ctx["xmin"], ctx["xmax"]
    return lo, hi, np.maximum(hi - lo, 1e-6)


def sat_slack_floor(rng, x, t, ctx, p):
    """Tendon goes slack: reading stops decreasing below a floor (soft corner)."""
    lo, hi, sp = _ctx_levels(ctx)
    floor = lo + p * sp
    s = 0.02 * sp
    return floor + softplus(x - floor, s) - x


def sat_pwl_knee(rng, x, t, ctx, p, slope=None):
    """Soft piecewise-linear knee at the top: slope 1 -> r beyond the knee (quadratic blend)."""
    lo, hi, sp = _ctx_levels(ctx)
    knee = hi - p * sp
    r = ctx["par"]["after_knee_slope"]
    w = 0.05 * sp
    d = x - knee
    y = np.where(d <= -w, d, d - (1 - r) * (d + w) ** 2 / (4 * w))
    y = np.where(d >= w, r * d, y)
    return knee + y - x


def sat_endstop(rng, x, t, ctx, p):
    """Potentiometer runs out of travel at the top; beyond it only the stop's spring complies:
    y = top + c * g(x - top), g smooth (cubic contact onset)."""
    lo, hi, sp = _ctx_levels(ctx)
    top = hi - p * sp
    c = ctx["par"]["stop_compliance"]
    w = 0.03 * sp
    d = x - top
    y = np.where(d <= 0, d, c * d + (1 - c) * w * (1 - np.exp(-d / w)))
    return top + y - x


def sat_richards(rng, x, t, ctx, p):
    """Generalised (Richards) logistic compression, asymmetric, of the whole range; p sets how
    much of the span lies inside the linear part (small p: mild)."""
    lo, hi, sp = _ctx_levels(ctx)
    nu = ctx["par"]["nu"]
    c = lo + ctx["par"]["centre"] * sp
    W = sp / max(p, 1e-3)  # smaller W -> stronger compression
    # Richards curve with unit slope at its inflection, inflection at c
    kk = (1 + nu) ** (1 + 1 / nu) / 1.0  # slope normaliser
    z = (x - c) * kk / W
    Q = nu
    y = W * ((1 + Q * np.exp(-z)) ** (-1 / nu) - (1 + Q) ** (-1 / nu))
    return c + y - x


# ---- lag (parameter p: larger -> stronger) -----------------------------------------------
def lag_rc(rng, x, t, ctx, p):
    tau = p
    a = np.exp(-(1 / FS) / tau)
    y = signal.lfilter([1 - a], [1, -a], x - x[0], axis=0) + x[0]
    return y - x


def lag_slew(rng, x, t, ctx, p):
    rate = 1.0 / p  # mm/s
    dt = np.diff(t, prepend=t[0])
    y = np.zeros_like(x)
    yk = x[0].copy()
    for i in range(len(t)):
        m = rate * dt[i]
        yk = yk + np.clip(x[i] - yk, -m, m)
        y[i] = yk
    return y - x


def _lfilt(b, a, x):
    zi = signal.lfilter_zi(b, a)
    return signal.lfilter(b, a, x, axis=0, zi=zi[:, None] * x[0][None, :])[0]


def lag_bessel4(rng, x, t, ctx, p):
    fc = 1.0 / p
    b, a = signal.bessel(4, min(fc, 110.0) / (FS / 2), norm="phase")
    return _lfilt(b, a, x) - x


def lag_butter4(rng, x, t, ctx, p):
    fc = 1.0 / p
    b, a = signal.butter(4, min(fc, 110.0) / (FS / 2))
    return _lfilt(b, a, x) - x


def lag_speed_delay(rng, x, t, ctx, p):
    """Transport delay growing with tendon speed: d = p*(c0 + c1*|v|/v_ref)."""
    v = np.abs(grad_t(x, t))
    vref = np.percentile(v, 90, axis=0) + 1e-6
    c0, c1 = ctx["par"]["c0"], ctx["par"]["c1"]
    out = np.zeros_like(x)
    for k in range(x.shape[1]):
        d = p * (c0 + c1 * v[:, k] / vref[k])
        out[:, k] = np.interp(t - d, t, x[:, k]) - x[:, k]
    return out


def lag_sample_hold(rng, x, t, ctx, p):
    """The sensor's front end samples at fs_low = 1/p and the host interpolates linearly between
    the last two samples (one low-rate period late)."""
    T = p
    out = np.zeros_like(x)
    ph = ctx["par"]["phase"]
    ts = np.arange(t[0] - T + ph * T, t[-1] + T, T)
    for k in range(x.shape[1]):
        xs = np.interp(ts, t, x[:, k])
        out[:, k] = np.interp(t - T, ts, xs) - x[:, k]
    return out


# ---- drift ---------------------------------------------------------------------------------
def drift_warmup(rng, x, t, ctx):
    S = x.shape[1]
    tau = rng.uniform(15, 150, S)
    A = rng.choice([-1, 1], S) * rng.uniform(0.5, 1.5, S)
    tt = (t - t[0])[:, None]
    return A * (1 - np.exp(-tt / tau)), {"tau_s": tau.round(1).tolist(),
                                         "rel_amp": A.round(2).tolist()}


def drift_iou(rng, x, t, ctx):
    """Humidity-like wander: integrated Ornstein-Uhlenbeck velocity, independent per sensor."""
    S = x.shape[1]
    tv = rng.uniform(5, 30, S)
    dt = 1 / FS
    n = len(t)
    w = rng.standard_normal((n, S))
    a = np.exp(-dt / tv)
    v = np.stack([signal.lfilter([1], [1, -a[k]], w[:, k]) for k in range(S)], 1)
    d = np.cumsum(v, 0) * dt
    d = d - d[0]
    d = d / (np.std(d, 0) + 1e-12)
    return d, {"tau_v_s": tv.round(1).tolist()}


def drift_sawtooth(rng, x, t, ctx):
    """Linear offset growth, re-zeroed by firmware at irregular instants (jumps back to 0)."""
    S = x.shape[1]
    rates = rng.choice([-1, 1], S) * rng.uniform(0.5, 1.5, S)
    resets = []
    tr = t[0]
    while True:
        tr += rng.uniform(25, 70)
        if tr >= t[-1]:
            break
        resets.append(tr)
    edges = np.array([t[0]] + resets)
    last = edges[np.searchsorted(edges, t, side="right") - 1]
    return (t - last)[:, None] * rates[None, :], {"reset_times_s": [round(r, 2) for r in resets],
                                                   "rel_rates": rates.round(2).tolist()}


def drift_common(rng, x, t, ctx):
    """Baseline shift shared by the sensors (temperature of the electronics): slow sinusoids +
    ramp, per-sensor loadings."""
    S = x.shape[1]
    tt = t - t[0]
    b = rng.uniform(-1, 1) * tt / tt[-1]
    for _ in range(3):
        b = b + rng.uniform(0.3, 1.0) * np.sin(2 * np.pi * tt / rng.uniform(40, 200)
                                               + rng.uniform(0, 6.3))
    b = b - b[0]
    load = rng.choice([-1, 1]) * rng.uniform(0.4, 1.2, S) * np.where(rng.random(S) < 0.8, 1, -1)
    return b[:, None] * load[None, :], {"loadings": load.round(2).tolist()}


def drift_time_x_load(rng, x, t, ctx):
    """Offset proportional to elapsed time x current tendon load."""
    S = x.shape[1]
    sig = load_of(x, ctx["xmin"], ctx["xmax"])
    k = rng.choice([-1, 1], S) * rng.uniform(0.5, 1.5, S)
    return (t - t[0])[:, None] * sig * k[None, :], {"rel_k": k.round(2).tolist()}


LINEAR = {
    "hysteresis": {"duhem_semilinear": hyst_duhem, "lugre_sheath": hyst_lugre,
                   "krasnoselskii_pokrovskii": hyst_kp, "capstan_eytelwein": hyst_capstan},
    "creep": {"findley_power": creep_findley, "norton_ratchet": creep_norton,
              "twoexp_asymmetric": creep_twoexp_asym, "hold_andrade": creep_hold_andrade},
    "drift": {"warmup_exp": drift_warmup, "integrated_ou": drift_iou,
              "sawtooth_rezero": drift_sawtooth, "common_baseline": drift_common,
              "time_x_load": drift_time_x_load},
}
PARAM = {
    "saturation": {"slack_floor": (sat_slack_floor, 0.0005, 0.6),
                   "soft_pwl_knee": (sat_pwl_knee, 0.0005, 0.7),
                   "endstop_spring": (sat_endstop, 0.0005, 0.7),
                   "richards_logistic": (sat_richards, 0.01, 8.0)},
    "lag": {"rc_first_order": (lag_rc, 1e-4, 3.0),
            "slew_limit": (lag_slew, 1e-4, 2.0),
            "bessel4": (lag_bessel4, 1 / 110.0, 20.0),
            "butterworth4": (lag_butter4, 1 / 110.0, 20.0),
            "speed_dependent_delay": (lag_speed_delay, 1e-4, 2.0),
            "sample_hold_interp": (lag_sample_hold, 1e-3, 2.0)},
}


# =============================================================================== plan
def make_plan(rng):
    effects = (["clean"] * 7 + ["hysteresis"] * 7 + ["creep"] * 7 + ["saturation"] * 6 +
               ["lag"] * 7 + ["drift"] * 6)
    assert len(effects) == N_REC
    families = {
        "hysteresis": ["duhem_semilinear", "duhem_semilinear", "lugre_sheath", "lugre_sheath",
                       "krasnoselskii_pokrovskii", "capstan_eytelwein", "capstan_eytelwein"],
        "creep": ["findley_power", "findley_power", "norton_ratchet", "norton_ratchet",
                  "twoexp_asymmetric", "hold_andrade", "hold_andrade"],
        "saturation": ["slack_floor", "slack_floor", "soft_pwl_knee", "endstop_spring",
                       "endstop_spring", "richards_logistic"],
        "lag": ["rc_first_order", "slew_limit", "bessel4", "butterworth4",
                "speed_dependent_delay", "sample_hold_interp", "rc_first_order"],
        "drift": ["warmup_exp", "integrated_ou", "sawtooth_rezero", "common_baseline",
                  "time_x_load", "warmup_exp"],
    }
    plan = []
    for eff, fams in families.items():
        mags = np.geomspace(2.0, 10.0, len(fams)) * rng.uniform(0.93, 1.0, len(fams))
        mags = np.clip(mags, 2.0, 10.0)
        mags = mags[rng.permutation(len(fams))]
        fams = [fams[i] for i in rng.permutation(len(fams))]
        plan += [(eff, f, float(m)) for f, m in zip(fams, mags, strict=True)]
    plan += [("clean", "none", 0.0)] * 7
    order = rng.permutation(len(plan))
    return [plan[i] for i in order]


# =============================================================================== one recording
def magnitude(tr, x_off, x_on, touched):
    d = tr(x_on) - tr(x_off)
    nsd = np.abs(tr.slope(x_off)).mean(0) * tr.noise_mm_total
    z = d[:, touched] / nsd[touched][None, :]
    return float(np.sqrt(np.mean(z**2)))


def generate(idx, eff, fam, target, seed, out, with_effect=True, duration_s=None, n_sensors=None):
    rng = np.random.default_rng(seed)
    duration = float(rng.uniform(60, 200))
    n_sens = int(rng.integers(2, 8))
    # timing only (added by the project): the draws are made, then overridden
    duration = duration if duration_s is None else float(duration_s)
    n_sens = n_sens if n_sensors is None else int(n_sensors)
    psi_varies = idx % 2 == 0
    psi_fixed = float(np.round(rng.uniform(-15, 15), 1)) if rng.random() < 0.7 else 0.0
    unit = str(rng.choice(["mm", "V", "counts", "counts16", "mrad"], p=[0.3, 0.2, 0.2, 0.1, 0.2]))
    unit_str = {"counts16": "counts"}.get(unit, unit)

    # ----- motion
    mb = MotionBuilder(rng, psi_varies, psi_fixed)
    fine = mb.build(duration)
    tf = np.arange(len(fine)) / FINE

    # ----- sensor clock: 250 Hz with jitter and dropped frames
    nfr = int(duration * FS)
    seq_all = np.arange(nfr)
    t_all = seq_all / FS + rng.uniform(-0.0003, 0.0003, nfr)
    t_all[0] = abs(t_all[0])
    keep = np.ones(nfr, bool)
    for _ in range(int(rng.integers(3, 16))):
        s0 = int(rng.integers(10, nfr - 10))
        keep[s0:s0 + int(rng.integers(1, 5))] = False
    seq0 = int(rng.integers(0, 50000))

    th = np.interp(t_all, tf, fine[:, 0])
    ph = np.interp(t_all, tf, fine[:, 1])
    ps = np.interp(t_all, tf, fine[:, 2])

    suit = Suit(rng, n_sens)
    L, W = suit.lengths(th, ph, ps)
    L0, _ = suit.lengths(np.array([0.0]), np.array([0.0]),
                         np.array([psi_fixed if not psi_varies else 0.0]))
    x = L - L0  # extension from the rest pose (mm)
    xmin, xmax = x.min(0), x.max(0)

    noise_mm = float(np.exp(rng.uniform(np.log(0.03), np.log(0.3))))
    coloured = rng.random() < 0.4
    col_frac = float(rng.uniform(0.3, 0.6)) if coloured else 0.0
    col_tau = float(rng.uniform(0.05, 0.5)) if coloured else 0.0
    white_sd = noise_mm / math.sqrt(1 + col_frac**2)
    tr = Transfer(rng, unit, n_sens, xmin, xmax, noise_mm)

    # ----- effect
    touched_mode = rng.choice(["one", "some", "all"], p=[0.3, 0.35, 0.35])
    if touched_mode == "one" or n_sens == 1:
        touched = np.array([int(rng.integers(0, n_sens))])
    elif touched_mode == "all":
        touched = np.arange(n_sens)
    else:
        m = int(rng.integers(1, max(n_sens, 2)))
        touched = np.sort(rng.choice(n_sens, size=max(min(m, n_sens - 1), 1), replace=False))
    # prefer sensors that actually move (span > 8 mm) for effects that need motion
    spans = xmax - xmin
    if eff != "clean" and np.all(spans[touched] < 8.0):
        touched = np.array([int(np.argmax(spans))])

    ctx = {"xmin": xmin, "xmax": xmax, "wrap": W, "suit": suit, "par": {}}
    x_on = x.copy()
    notes = {}
    mag = 0.0
    erng = np.random.default_rng(seed + 777)
    if eff in LINEAR:
        fn = LINEAR[eff][fam]
        e, notes = fn(erng, x[:, touched], t_all, {**ctx, "xmin": xmin[touched],
                                                   "xmax": xmax[touched],
                                                   "wrap": W[:, touched],
                                                   "guide": suit.guide_wrap[touched]})
        if eff == "hysteresis":
            e = remove_static(e, x[:, touched])
            notes["static_part_removed"] = "degree-5 polynomial of extension projected out"
        e = e / (np.sqrt(np.mean(e**2)) + 1e-12)
        if eff == "creep":
            sgn = erng.choice([-1.0, 1.0], len(touched))
            e = e * sgn[None, :]
            notes["sign_per_sensor"] = sgn.tolist()
        amp = 1.0
        for _ in range(4):
            x_on[:, touched] = x[:, touched] + amp * e
            mag = magnitude(tr, x, x_on, touched)
            amp *= target / mag
        x_on[:, touched] = x[:, touched] + amp * e
        mag = magnitude(tr, x, x_on, touched)
        notes["rms_effect_mm"] = float(np.sqrt(np.mean((amp * e) ** 2)))
    elif eff in PARAM:
        fn, plo, phi_ = PARAM[eff][fam]
        par = {}
        if fam == "soft_pwl_knee":
            par["after_knee_slope"] = float(erng.uniform(0.1, 0.4))
        if fam == "endstop_spring":
            par["stop_compliance"] = float(erng.uniform(0.03, 0.15))
        if fam == "richards_logistic":
            par["nu"] = float(erng.uniform(0.3, 3.0))
            par["centre"] = float(erng.uniform(0.3, 0.7))
        if fam == "speed_dependent_delay":
            par["c0"], par["c1"] = float(erng.uniform(0.2, 1.0)), float(erng.uniform(0.5, 2.0))
        if fam == "sample_hold_interp":
            par["phase"] = float(erng.uniform(0, 1))
        c2 = {**ctx, "xmin": xmin[touched], "xmax": xmax[touched], "par": par}
        xt = x[:, touched]

        def mag_of(p):
            xo = x.copy()
            xo[:, touched] = xt + fn(erng, xt, t_all, c2, p)
            return magnitude(tr, x, xo, touched), xo

        lo, hi = math.log(plo), math.log(phi_)
        mhi, _ = mag_of(phi_)
        if mhi < target:
            p = phi_
            notes["warning"] = f"target {target:.2f} unreachable, max {mhi:.2f}"
        else:
            for _ in range(30):
                mid = 0.5 * (lo + hi)
                mm, _ = mag_of(math.exp(mid))
                if mm < target:
                    lo = mid
                else:
                    hi = mid
                if abs(mm - target) / target < 0.01:
                    break
            p = math.exp(0.5 * (lo + hi))
        mag, x_on = mag_of(p)
        notes.update(par)
        pname = {"slack_floor": "floor_frac_of_span_above_min",
                 "soft_pwl_knee": "knee_frac_below_max",
                 "endstop_spring": "stop_frac_below_max", "richards_logistic": "compression_p",
                 "rc_first_order": "tau_s", "slew_limit": "inv_rate_s_per_mm",
                 "bessel4": "1/fc_s", "butterworth4": "1/fc_s",
                 "speed_dependent_delay": "delay_scale_s",
                 "sample_hold_interp": "low_rate_period_s"}[fam]
        notes[pname] = p
        if fam == "slew_limit":
            notes["rate_limit_mm_s"] = 1 / p
        if fam in ("bessel4", "butterworth4"):
            notes["fc_hz"] = min(1 / p, 110.0)
        if fam == "sample_hold_interp":
            notes["low_rate_hz"] = 1 / p
    else:
        touched = np.array([], int)

    # ----- noise and readings
    nrng = np.random.default_rng(seed + 999)
    nz = white_sd * nrng.standard_normal(x.shape)
    if coloured:
        a = math.exp(-1 / (FS * col_tau))
        c = signal.lfilter([1], [1, -a], nrng.standard_normal(x.shape), axis=0)
        c = c / c.std(0) * white_sd * col_frac
        nz = nz + c
    vals = tr((x_on if with_effect else x) + nz, quantise=True)
    n_clipped = 0
    if unit.startswith("counts"):
        n_clipped = int(((vals < 0) | (vals > tr.full - 1)).sum())
        vals = np.clip(vals, 0, tr.full - 1)

    # ----- mocap stream, own clock
    mrate = float(rng.choice([100.0, 120.0, 150.0, 180.0, 200.0]))
    m_off = float(rng.uniform(0.0, 0.03))
    nm = int((duration - m_off) * mrate)
    tm = m_off + np.arange(nm) / mrate + rng.uniform(-0.0004, 0.0004, nm)
    tm = np.maximum.accumulate(np.maximum(tm, 0.0)) + np.arange(nm) * 1e-9
    ang_sd = float(rng.uniform(0.02, 0.1))
    ma = np.stack([np.interp(tm, tf, fine[:, k]) for k in range(3)], 1)
    ma[:, :2] += ang_sd * rng.standard_normal((nm, 2))
    if psi_varies:
        ma[:, 2] += ang_sd * rng.standard_normal(nm)
    else:
        ma[:, 2] = psi_fixed

    names = [f"{nm_}{k}" for k, nm_ in enumerate(suit.names)]
    rec = Recording(
        sensor_names=tuple(names),
        sensors=SensorStream(seq=(seq_all[keep] + seq0).astype(np.int64), t=t_all[keep],
                             values=vals[keep]),
        mocap={"shoulder": AngleStream(tm, ("elv_angle", "shoulder_elv", "shoulder_rot"), ma)},
        sensor_units=unit_str,
        sensor_rate_hz=FS,
        mocap_rate_hz=mrate,
        metadata={"generator": "blind3", "seed": str(seed)},
    )
    fname = f"rec_{idx:02d}.mcap"
    write_recording(out / fname, rec, decimals=5 if unit == "V" else 4)

    nsd = (np.abs(tr.slope(x)).mean(0) * tr.noise_mm_total)
    seg_counts = {}
    for lab, *_ in mb.labels:
        seg_counts[lab] = seg_counts.get(lab, 0) + 1
    truth = {
        "file": fname,
        "effect": eff if with_effect else "clean",
        "family": fam if with_effect else "none",
        **({} if with_effect or eff == "clean" else
           {"twin_of": {"effect": eff, "family": fam, "magnitude_x_noise": round(mag, 3),
                        "sensors_touched": [names[k] for k in touched]}}),
        "magnitude_x_noise": round(mag, 3) if with_effect else 0.0,
        "magnitude_target": round(target, 3),
        "sensors_touched": [names[k] for k in touched] if with_effect else [],
        "noise_sd": [float(f"{v:.4g}") for v in nsd],
        "noise_sd_mm": round(float(tr.noise_mm_total.mean()), 4),
        "duration_s": round(duration, 2),
        "units": unit_str + ("(16-bit)" if unit == "counts16"
                             else "(12-bit)" if unit == "counts" else ""),
        "n_sensors": n_sens,
        "notes": {
            **{k: v for k, v in notes.items()},
            "sensors": names,
            "psi": "varying" if psi_varies else f"fixed {psi_fixed}",
            "coloured_noise": ({"frac": round(col_frac, 3), "tau_s": round(col_tau, 3)}
                               if coloured else None),
            "mocap_rate_hz": mrate,
            "mocap_angle_noise_deg": round(ang_sd, 3),
            "dropped_frames": int((~keep).sum()),
            "adc_clipped_samples": n_clipped,
            "extension_span_mm": spans.round(1).tolist(),
            "phi_max_deg": round(float(ph.max()), 1),
            "segments": seg_counts,
            "transfer_gain_per_mm": tr.gain.round(4).tolist(),
        },
    }
    return truth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for the recordings")
    parser.add_argument("--only", type=int, nargs="*", default=[],
                        help="regenerate only these recordings (truth.json left as it is)")
    parser.add_argument("--without-effect", action="store_true",
                        help="write each recording's clean twin: the same draws, no effect")
    parser.add_argument("--duration", type=float, default=None,
                        help="timing only (with --only): this length, s, instead of the drawn one")
    parser.add_argument("--sensors", type=int, default=None,
                        help="timing only (with --only): tendons (2-8) instead of the drawn count")
    args = parser.parse_args()
    if (args.duration is not None or args.sensors is not None) and not args.only:
        parser.error("--duration and --sensors are for timing single recordings: give --only")
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(MASTER_SEED)
    plan = make_plan(rng)
    seeds = rng.integers(1, 2**31 - 1, N_REC)
    only = args.only
    truths = []
    t0 = time.time()
    for i, (eff, fam, tgt) in enumerate(plan):
        if only and i not in only:
            continue
        ts = time.time()
        tr = generate(i, eff, fam, tgt, int(seeds[i]), out, not args.without_effect,
                      args.duration, args.sensors)
        truths.append(tr)
        print(f"{tr['file']} {tr['effect']:10s} {tr['family']:26s} "
              f"mag={tr['magnitude_x_noise']:6.2f} "
              f"(target {tgt:5.2f}) S={tr['n_sensors']} touched={tr['sensors_touched']} "
              f"{tr['units']} dur={tr['duration_s']}s  [{time.time() - ts:.1f}s]", flush=True)
    if not only:
        write_text(out / "truth.json", json.dumps(truths, indent=1, default=float))
    print(f"total {time.time() - t0:.1f}s")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
# MIT License
#
# Copyright (c) 2026 indepgen authors
#
# Permission is hereby granted, free of charge, to any person obtaining a copy
# of this software and associated documentation files (the "Software"), to deal
# in the Software without restriction, including without limitation the rights
# to use, copy, modify, merge, publish, distribute, sublicense, and/or sell
# copies of the Software, and to permit persons to whom the Software is
# furnished to do so, subject to the following conditions:
#
# The above copyright notice and this permission notice shall be included in
# all copies or substantial portions of the Software.
#
# THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR
# IMPLIED, INCLUDING BUT NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY,
# FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE
# AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER
# LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM,
# OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN THE
# SOFTWARE.
"""Independent generator of voltage-driven actuator recordings with hidden physical effects.

usage: generate.py --out DIR --seed S --cases N [--only LABEL] [--fast] [--first K]
                   [--subset] [--jobs J]
See README.md for the physics and conventions.
"""
import argparse
import csv
import io
import json
import math
import os
import sys
import time

import numpy as np
from scipy.linalg import expm

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kernel import kernel  # noqa: E402

EFFECTS = ["hysteresis", "creep", "dead_zone", "saturation", "delay", "asymmetric_dynamics",
           "slew_limit", "resonance", "drift", "bias_dependent_dynamics"]

PVC_NUM = [1.15, 1.03]
PVC_DEN = [1.0, 17.11, 8.76]
PVC_P2 = [0.1270, 1.3057e-5]
PVC_P3 = [0.0721, 2.1307e-5, -1.7231e-11]


def loguni(rng, a, b):
    return float(math.exp(rng.uniform(math.log(a), math.log(b))))


def nice_q(x):
    """largest 1-2-5 step <= x"""
    e = math.floor(math.log10(x))
    for mnt in (5, 2, 1):
        if mnt * 10 ** e <= x:
            return mnt * 10 ** e
    return 10 ** e


# ----------------------------------------------------------------------------- rigs
def make_rig(kind, rng, closed_loop):
    rig = {"kind": kind}
    if kind == "pvc":
        n3 = rng.random() < 0.25
        rig["poly"] = list(PVC_P3 if n3 else PVC_P2)
        rig["truth_poly"] = "n3" if n3 else "n2"
        rig["num"], rig["den"] = list(PVC_NUM), list(PVC_DEN)
        rig["drive"] = (0.0, 1000.0)
        rig["urange"] = (0.0, 380.0 if n3 else 450.0)
        rig["sigma"] = 0.05
        rig["q"] = 0.01
        rig["rates"] = [100, 1000] if closed_loop else [100, 1000, 1000, 5000]
        rig["desc"] = "PVC gel (paper plant)"
    elif kind == "amp10":
        c1 = rng.uniform(14.0, 18.0) if closed_loop else rng.uniform(4.0, 16.0)
        k3 = rng.uniform(0.0, 0.25)
        rig["poly"] = [c1 * (1 - k3), c1 * k3 / 100.0]   # f(10 V) = 10 c1
        rig["truth_poly"] = "n2"
        p1 = loguni(rng, 0.5, 4.0)
        p2 = loguni(rng, 10.0, 60.0)
        zz = rng.random() < 0.5
        if zz:
            z = loguni(rng, 1.5 * p1, 0.8 * p2)
            num = [p1 * p2 / z, p1 * p2]
        else:
            num = [p1 * p2]
        rig["num"], rig["den"] = num, [1.0, p1 + p2, p1 * p2]
        rig["drive"] = (0.0, 10.0)
        rig["urange"] = (0.0, 10.0)
        stroke = poly_val(rig["poly"], 10.0)
        rig["sigma"] = float("%.3g" % (stroke * rng.uniform(0.0004, 0.001)))
        rig["q"] = nice_q(rig["sigma"] / 4)
        rig["rates"] = [100, 1000]
        rig["desc"] = "actuator behind a 0-10 V amplifier input"
    elif kind in ("piezo", "nano"):
        bip = rng.random() < 0.65
        if kind == "piezo":
            U = float(rng.choice([100.0, 150.0]))
            c1 = rng.uniform(0.05, 0.15)
        else:
            if bip:
                U = 10.0
                c1 = rng.uniform(0.01, 0.1)     # um/V -> 0.2..2 um stroke
            else:
                U = 100.0
                c1 = rng.uniform(0.002, 0.02)
        rig["poly"] = [c1]
        if rng.random() < 0.3:
            rig["poly"] = [c1, c1 * rng.uniform(0.0, 0.08) / U ** 2]
        rig["truth_poly"] = "n1" if len(rig["poly"]) == 1 else "n2"
        if rng.random() < 0.5:
            p = loguni(rng, 100.0, 2000.0)
            rig["num"], rig["den"] = [p], [1.0, p]
        else:
            wn = loguni(rng, 200.0, 2000.0)
            zt = rng.uniform(0.5, 1.3)
            rig["num"], rig["den"] = [wn * wn], [1.0, 2 * zt * wn, wn * wn]
        rig["drive"] = (-U, U) if bip else (0.0, U)
        rig["urange"] = rig["drive"]
        stroke = abs(poly_val(rig["poly"], U) - poly_val(rig["poly"], rig["drive"][0]))
        rig["sigma"] = float("%.3g" % (stroke * rng.uniform(0.0003, 0.001)))
        rig["q"] = nice_q(rig["sigma"] / 4)
        rig["rates"] = [1000, 5000, 10000]
        rig["desc"] = ("piezo stack" if kind == "piezo" else "nanopositioner (nm-scale)") + \
            (", bipolar" if bip else ", unipolar")
    elif kind == "mm":
        bip = rng.random() < 0.5
        U = 10.0
        c1 = rng.uniform(80.0, 250.0)
        k3 = rng.uniform(0.0, 0.2)
        rig["poly"] = [c1 * (1 - k3), c1 * k3 / 100.0]
        rig["truth_poly"] = "n2"
        p1 = loguni(rng, 15.0, 80.0)
        p2 = loguni(rng, 100.0, 400.0)
        rig["num"], rig["den"] = [p1 * p2], [1.0, p1 + p2, p1 * p2]
        rig["drive"] = (-U, U) if bip else (0.0, U)
        rig["urange"] = rig["drive"]
        stroke = abs(poly_val(rig["poly"], U) - poly_val(rig["poly"], rig["drive"][0]))
        rig["sigma"] = float("%.3g" % (stroke * rng.uniform(0.0003, 0.001)))
        rig["q"] = nice_q(rig["sigma"] / 4)
        rig["rates"] = [100, 1000, 5000]
        rig["desc"] = "mm-stroke actuator" + (", bipolar" if bip else ", unipolar")
    rig["bipolar"] = rig["drive"][0] < 0
    rig["dcg"] = rig["num"][-1] / rig["den"][-1]
    return rig


def poly_val(c, u):
    u = np.asarray(u, dtype=float)
    s = 0.0 * u
    for i, ci in enumerate(c):
        s = s + ci * u ** (2 * i + 1)
    return s


# ----------------------------------------------------------------------------- linear block
def g_realisation(num, den):
    """State space (A,B,Cg) of strictly proper G, modal (diagonal) when poles real & distinct.
    Returns also the index of the slowest real-pole state (or -1)."""
    num = np.atleast_1d(np.array(num, float))
    den = np.array(den, float)
    num = num / den[0]
    den = den / den[0]
    poles = np.roots(den)
    n = len(den) - 1
    if np.all(np.abs(poles.imag) < 1e-9) and len(set(np.round(poles.real, 9))) == n:
        p = -poles.real
        A = np.diag(-p)
        B = np.ones(n)
        C = np.zeros(n)
        for i in range(n):
            # residue of num/den at s = -p_i
            nv = np.polyval(num, -p[i])
            dv = np.prod([(-p[i] + p[j]) for j in range(n) if j != i])
            C[i] = nv / dv
        slow = int(np.argmin(p))
        return A, B, C, slow
    # controllable canonical
    A = np.zeros((n, n))
    A[0, :] = -den[1:]
    for i in range(1, n):
        A[i, i - 1] = 1.0
    B = np.zeros(n)
    B[0] = 1.0
    numf = np.concatenate([np.zeros(n - len(num)), num])
    C = numf.copy()
    return A, B, C, -1


def build_linear(rig_num, rig_den, eff):
    """Linear block: G plus creep (parallel or series) plus resonance (series).
    eff: dict of effect specs (by name) with resolved parameters.
    Returns dict with A,B,C (output), Cg, mask (rows scheduled), dcg."""
    A, B, Cg, slow = g_realisation(rig_num, rig_den)
    n = A.shape[0]
    dcg = float(-Cg @ np.linalg.solve(A, B))
    C = Cg.copy()
    mask = np.zeros(n)
    sch = eff.get("asymmetric_dynamics") or eff.get("bias_dependent_dynamics")
    if sch is not None:
        if sch.get("states") == "slow" and slow >= 0:
            mask[slow] = 1.0
        else:
            mask[:] = 1.0
    cr = eff.get("creep")
    if cr is not None and cr["m"] != 0.0:
        taus = np.array(cr["taus"])
        w = np.array(cr["w"])
        gam = cr["m"]
        k = len(taus)
        A2 = np.zeros((n + k, n + k))
        A2[:n, :n] = A
        B2 = np.concatenate([B, np.zeros(k)])
        if cr["kind"] == "add":
            for i in range(k):
                A2[n + i, n + i] = -1.0 / taus[i]
                B2[n + i] = dcg * gam * w[i] / taus[i]
            C2 = np.concatenate([C, np.ones(k)])
        else:  # keep DC: y = (1-g) yG + g sum w_i LP_i(yG)
            for i in range(k):
                A2[n + i, n + i] = -1.0 / taus[i]
                A2[n + i, :n] += C / taus[i]
            C2 = np.concatenate([(1 - gam) * C, gam * w])
        A, B, C = A2, B2, C2
        mask = np.concatenate([mask, np.zeros(k)])
        Cg = np.concatenate([Cg, np.zeros(k)])
        n = n + k
    rs = eff.get("resonance")
    if rs is not None and rs["m"] != 0.0:
        A2 = np.zeros((n + 2, n + 2))
        A2[:n, :n] = A
        B2 = np.concatenate([B, np.zeros(2)])
        if rs["kind"] == "parallel":
            # y = (1-rho) y_G + rho * dcg * w^2/(s^2+2 z w s+w^2) x   (a fast structural mode fed by the force)
            wr, zr, rho = rs["wr"], rs["zr"], rs["m"]
            A2[n, n + 1] = 1.0
            A2[n + 1, n] = -wr * wr
            A2[n + 1, n + 1] = -2 * zr * wr
            B2[n + 1] = wr * wr * dcg
            C2 = np.concatenate([(1 - rho) * C, [rho, 0.0]])
        elif rs["kind"] == "mode":
            wr, zr, rho = rs["wr"], rs["zr"], rs["m"]
            A2[n, n + 1] = 1.0
            A2[n + 1, n] = -wr * wr
            A2[n + 1, n + 1] = -2 * zr * wr
            A2[n + 1, :n] += wr * wr * C
            C2 = np.concatenate([(1 - rho) * C, [rho, 0.0]])
        else:
            wp, zp, zz = rs["wr"], rs["zr"], rs["zz"]
            wz = wp * (1.0 + rs["m"])
            K = wp * wp / (wz * wz)
            A2[n, n + 1] = 1.0
            A2[n + 1, n] = -wp * wp
            A2[n + 1, n + 1] = -2 * zp * wp
            A2[n + 1, :n] += C
            C2 = np.concatenate([K * C, [K * (wz * wz - wp * wp), K * (2 * zz * wz - 2 * zp * wp)]])
        A, B, C = A2, B2, C2
        mask = np.concatenate([mask, np.zeros(2)])
        Cg = np.concatenate([Cg, np.zeros(2)])
        n = n + 2
    return {"A": A, "B": B, "C": C, "Cg": Cg, "mask": mask, "dcg": dcg}


def discretise(A, B, h, lambdas, mask):
    n = A.shape[0]
    L = len(lambdas)
    Phi = np.zeros((L, n, n))
    Gam = np.zeros((L, n))
    for i, lam in enumerate(lambdas):
        s = np.where(mask > 0, lam, 1.0)
        Al = A * s[:, None]
        Bl = B * s
        Mx = np.zeros((n + 1, n + 1))
        Mx[:n, :n] = Al * h
        Mx[:n, n] = Bl * h
        E = expm(Mx)
        Phi[i] = E[:n, :n]
        Gam[i] = E[:n, n]
    return Phi, Gam


# ----------------------------------------------------------------------------- inputs
def smooth_noise(rng, n, fc, fs):
    w = rng.standard_normal(n + int(4 * fs / fc))
    a = math.exp(-2 * math.pi * fc / fs)
    from scipy.signal import lfilter
    y = lfilter([(1 - a) ** 2], [1, -2 * a, a * a], w)
    y = y[-n:]
    return (y - y.mean()) / (y.std() + 1e-12)


def make_input(rng, kind, n, fs, lo, hi, pre_n=0):
    """Input of n+pre_n samples; returns array.  kind in sines, steps, multisine, chirp, random."""
    N = n + pre_n
    t = (np.arange(N) - pre_n) / fs
    span = hi - lo
    dur = n / fs
    fmin = max(0.05, 2.0 / dur)
    if kind == "sines":
        # 1-3 sine segments (bias, amplitude, frequency) joined by smooth 0.3-1 s cross-fades
        nseg = int(rng.integers(1, 4))
        edges = np.linspace(-pre_n / fs, dur, nseg + 1)
        wid = rng.uniform(0.3, 1.0)
        u = np.zeros(N)
        wsum = np.zeros(N)
        for s in range(nseg):
            a = span * rng.uniform(0.1, 0.5)
            b = rng.uniform(lo + a, hi - a)
            f = loguni(rng, fmin, 5.0)
            w = np.ones(N)
            if s > 0:
                w *= 0.5 * (1 + np.tanh((t - edges[s]) / wid * 3))
            if s < nseg - 1:
                w *= 0.5 * (1 - np.tanh((t - edges[s + 1]) / wid * 3))
            u += w * (b + a * np.sin(2 * np.pi * f * (t - edges[s]) + rng.choice([0.0, -np.pi / 2])))
            wsum += w
        u = u / wsum
    elif kind in ("steps", "smallsteps"):
        hold_lo, hold_hi = (1.0, 8.0) if dur > 18 else (0.3, 2.5)
        if kind == "smallsteps":
            hold_lo, hold_hi = 0.2, 1.0
        u = np.zeros(N)
        i = 0
        stair = rng.random() < 0.5
        lev = lo + span * rng.uniform(0.0, 0.3)
        direction = 1
        while i < N:
            L = int(rng.uniform(hold_lo, hold_hi) * fs)
            u[i:i + L] = lev
            i += L
            if stair or kind == "smallsteps":
                stepsz = span * (rng.uniform(0.08, 0.25) if kind == "steps" else rng.uniform(0.04, 0.12))
                nl = lev + direction * stepsz
                if nl > hi or nl < lo:
                    direction = -direction
                    nl = lev + direction * stepsz
                lev = min(max(nl, lo), hi)
            else:
                lev = lo + span * rng.uniform(0.0, 1.0)
    elif kind == "fastsines":
        # one or two superposed fast sines, amplitude faded in smoothly (no jumps)
        a = span * rng.uniform(0.25, 0.5)
        b = rng.uniform(lo + a, hi - a)
        f1 = loguni(rng, 1.0, 5.0)
        tt = t - t[0]
        env = np.clip(tt / rng.uniform(0.5, 2.0), 0, 1)
        s = np.sin(2 * np.pi * f1 * tt)
        if rng.random() < 0.5:
            f2 = loguni(rng, 0.1, 1.0)
            s = 0.6 * s + 0.4 * np.sin(2 * np.pi * f2 * tt)
        u = b + a * env * s
    elif kind == "multisine":
        nf = int(rng.integers(5, 13))
        fr = np.exp(np.linspace(math.log(fmin), math.log(5.0), nf))
        ph = rng.uniform(0, 2 * np.pi, nf)
        s = np.sum(np.sin(2 * np.pi * fr[:, None] * t[None, :] + ph[:, None]) / np.sqrt(fr[:, None]), axis=0)
        s = s / (np.max(np.abs(s)) + 1e-12)
        a = span * rng.uniform(0.25, 0.5)
        b = rng.uniform(lo + a, hi - a)
        u = b + a * s
    elif kind == "chirp":
        f0 = fmin
        f1 = loguni(rng, 1.0, 5.0)
        tt = np.clip(t, 0, None)
        k = math.log(f1 / f0) / dur
        ph = 2 * np.pi * f0 * (np.exp(k * tt) - 1) / k
        a = span * rng.uniform(0.2, 0.5)
        b = rng.uniform(lo + a, hi - a)
        u = b + a * np.sin(ph)
    else:  # random smooth
        fc = loguni(rng, 0.2, 3.0)
        s = smooth_noise(rng, N, fc, fs)
        a = span * rng.uniform(0.15, 0.3)
        b = rng.uniform(lo + 2 * a, hi - 2 * a) if hi - lo > 4 * a else 0.5 * (lo + hi)
        u = b + a * s
    return np.clip(u, lo, hi)


def ref_signal(kind, f, t):
    if kind == "r1":
        return 100.0 + 25.0 * np.sin(2 * np.pi * f * t)
    return (33 + 5 * np.sin(0.2 * np.pi * t)) + (33 + 7 * np.sin(np.pi * t)) + (30 + 12 * np.sin(2 * np.pi * t))


# ----------------------------------------------------------------------------- effects
def draw_effect(name, rng, rig, rate):
    """Fixed (form) parameters of an effect; the magnitude 'm' is solved later."""
    e = {"name": name, "m": 0.0}
    bip = rig["bipolar"]
    lo, hi = rig["urange"]
    if name == "hysteresis":
        forms = ["PI_stops_u", "PI_stops_x", "bouc_wen", "preisach", "duhem"]
        if bip:
            forms.append("jiles_atherton")
        f = str(rng.choice(forms))
        e["form"] = f
        if f.startswith("PI"):
            nr = int(rng.integers(3, 9))
            r = np.sort(np.exp(np.linspace(math.log(0.02), math.log(rng.uniform(0.2, 0.6)), nr)))
            asym = rng.uniform(-0.4, 0.4)
            rl = r * (1 - asym)
            ru = r * (1 + asym)
            w = np.exp(-rng.uniform(0.0, 3.0) * np.arange(nr) / nr) * rng.uniform(0.5, 1.5, nr)
            w = w / np.sum(w * r)
            e.update(mode=1, dom=0 if f == "PI_stops_u" else 1, nr=nr, rl=rl.tolist(), ru=ru.tolist(), w=w.tolist(),
                     asym=asym)
        elif f == "bouc_wen":
            ne = float(rng.choice([1.0, 1.5, 2.0]))
            bg = rng.uniform(0.2, 0.8)  # beta share
            tot = loguni(rng, 2.0, 10.0)
            e.update(mode=3, dom=int(rng.integers(0, 2)), A=1.0, beta=tot * bg, gamma=tot * (1 - bg) * rng.choice([1, -0.3]), ne=ne)
        elif f == "preisach":
            nrel = 150
            mu_c = rng.uniform(0.05, 0.3)
            sd_c = mu_c * rng.uniform(0.3, 0.8)
            sd_i = rng.uniform(0.1, 0.3)
            wid = np.abs(rng.normal(mu_c, sd_c, nrel)) + 0.005
            cen = rng.normal(0.5 if not bip else 0.0, sd_i if not bip else 0.4, nrel)
            if not bip:
                cen = rng.uniform(-0.05, 1.05, nrel)
            a = cen + wid / 2
            b = cen - wid / 2
            w = np.ones(nrel) / nrel
            e.update(mode=4, dom=int(rng.integers(0, 2)), nr=nrel, a=a.tolist(), b=b.tolist(), w=w.tolist())
        elif f == "duhem":
            e.update(mode=5, dom=int(rng.integers(0, 2)), c0=loguni(rng, 3.0, 20.0), c2=rng.uniform(-0.5, 2.0))
        else:
            e.update(mode=6, dom=0, aa=rng.uniform(0.3, 0.8), kk=rng.uniform(0.05, 0.3), cr=rng.uniform(0.0, 0.5))
        e["m0"] = 0.01
    elif name == "creep":
        kind = "add" if rng.random() < 0.5 else "keep"
        spec = "log" if rng.random() < 0.4 else "modes"
        if spec == "log":
            taus = np.logspace(math.log10(0.3), math.log10(300), 7)
            w = np.ones(7) / 7
        else:
            k = int(rng.integers(1, 4))
            taus = np.sort(np.exp(rng.uniform(math.log(1.0), math.log(100.0), k)))
            w = rng.dirichlet(np.ones(k))
        e.update(form=f"{kind}_{spec}", kind=kind, taus=taus.tolist(), w=w.tolist(), m0=0.01)
    elif name == "dead_zone":
        f = "hard" if (bip and rng.random() < 0.6) or (not bip and rng.random() < 0.3) else "smooth"
        e.update(form=f, mode=1 if f == "hard" else 2, centre=0.0, m0=0.005 * (hi - lo))
    elif name == "saturation":
        where = str(rng.choice(["drive", "x", "y"]))
        form = int(rng.integers(1, 3))
        shape = float(rng.uniform(4, 10)) if form == 1 else float(rng.uniform(0.6, 0.9))
        two = bip and rng.random() < 0.5
        e.update(form=f"{where}_{'pnorm' if form == 1 else 'tanhknee'}{'_2sided' if two else ''}",
                 where=where, sform=form, shape=shape, two=two, m0=0.5 if form == 1 else 1.0)
    elif name == "delay":
        e.update(form="transport", m0=0.5)
    elif name == "asymmetric_dynamics":
        states = "slow" if rng.random() < 0.5 else "all"
        share = float(rng.choice([0.0, 0.5, 1.0]))
        sgn = float(rng.choice([1.0, -1.0]))
        e.update(form=f"{states}_share{share}_{'fallfast' if sgn > 0 else 'fallslow'}", states=states,
                 share=share, sgn=sgn, m0=0.05)
    elif name == "slew_limit":
        f = "analog" if rng.random() < 0.6 else "digital"
        e.update(form=f, mode=1 if f == "analog" else 2, m0=1.0 / (5.0 * (hi - lo)))
    elif name == "resonance":
        kind = str(rng.choice(["mode", "polezero", "parallel"]))
        # plant bandwidth: slowest significant pole; series forms only if the mode is within ~30x of it
        poles = -np.roots(rig["den"]).real
        bw = float(np.max(poles)) / (2 * math.pi)
        reldeg = len(rig["den"]) - len(rig["num"])
        fmax = 0.4 * rate
        if bw < 5.0:      # slow actuator: a structural mode far above its bandwidth is never excited
            fmax = min(fmax, 15.0 if reldeg == 1 else 8.0)
        fmax = min(fmax, max(30 * bw, 8.0), 400.0)
        fr = loguni(rng, 5.0, max(fmax, 5.01))
        if kind == "parallel" and rng.random() < 0.5:
            kind = "mode"
        zr = loguni(rng, 0.01, 0.1)
        e.update(form=kind, kind=kind, wr=2 * math.pi * fr, zr=zr, zz=zr * rng.uniform(0.5, 1.5), m0=0.05, f_hz=fr)
    elif name == "drift":
        f = str(rng.choice(["linear", "exponential", "randomwalk", "thermal"]))
        e.update(form=f, m0=1.0, tau=loguni(rng, 5.0, 60.0), fc=loguni(rng, 0.01, 0.1),
                 period=loguni(rng, 30.0, 300.0), phase=rng.uniform(0, 2 * np.pi), sgn=float(rng.choice([-1, 1])))
    elif name == "bias_dependent_dynamics":
        var = str(rng.choice(["y_level", "u_bias", "amplitude"]))
        states = "slow" if rng.random() < 0.5 else "all"
        e.update(form=f"{var}_{states}", var=var, states=states, tau=loguni(rng, 1.0, 5.0),
                 sgn=float(rng.choice([1.0, -1.0])), m0=0.1)
    return e


# ----------------------------------------------------------------------------- simulation
class Case:
    pass


def base_params(case):
    return {
        "slew_mode": 0, "slew_R": 1.0, "M": case.M, "extra_delay": 0.0,
        "dsat_p": np.zeros(5), "dz_p": np.zeros(3), "hy_mode": 0, "hy_p": np.zeros(8), "xs_p": np.zeros(5),
        "ys_p": np.zeros(5), "sch_mode": 0, "sch_p": np.zeros(6), "lin": {}, "drift": None,
    }


def apply_effect(P, e, m, case, rec_stats):
    """Insert effect e with magnitude m into parameter set P (in place)."""
    name = e["name"]
    lo, hi = case.rig["urange"]
    if name == "hysteresis":
        mode = e["mode"]
        P["hy_mode"] = mode
        if e["dom"] == 0:
            scl = max(abs(lo), abs(hi))
        else:
            scl = max(abs(rec_stats["xmin"]), abs(rec_stats["xmax"]))
        if mode == 1:
            hp = [m, e["nr"], e["dom"], scl] + list(e["rl"]) + list(e["ru"]) + list(e["w"])
        elif mode == 3:
            hp = [m, 0, e["dom"], scl, e["A"], e["beta"], e["gamma"], e["ne"]]
        elif mode == 4:
            hp = [m, e["nr"], e["dom"], scl] + list(e["a"]) + list(e["b"]) + list(e["w"])
        elif mode == 5:
            hp = [m, 0, e["dom"], scl, e["c0"], e["c2"]]
        else:
            hp = [m, 0, e["dom"], scl, e["aa"], e["kk"], e["cr"]]
        P["hy_p"] = np.array(hp + [0.0] * 4, float)
    elif name == "creep":
        P["lin"]["creep"] = dict(e, m=m)
    elif name == "resonance":
        P["lin"]["resonance"] = dict(e, m=m)
    elif name == "dead_zone":
        P["dz_p"] = np.array([e["mode"], m, e["centre"]], float)
    elif name == "saturation":
        w = e["where"]
        key = {"drive": "dsat_p", "x": "xs_p", "y": "ys_p"}[w]
        vmax = rec_stats[{"drive": "umax", "x": "xmax", "y": "ymax"}[w]]
        vmin = rec_stats[{"drive": "umin", "x": "xmin", "y": "ymin"}[w]]
        if case.rig["bipolar"]:
            ctr = 0.0
            Lh = max(abs(vmax), 1e-12) / m
            Ll = (max(abs(vmin), 1e-12) / m) if e["two"] else -1.0
        else:
            ctr = 0.0
            Lh = max(vmax, 1e-12) / m
            Ll = -1.0
        P[key] = np.array([e["sform"], Lh, Ll, e["shape"], ctr], float)
    elif name == "delay":
        P["extra_delay"] = m
    elif name == "slew_limit":
        P["slew_mode"] = e["mode"]
        P["slew_R"] = 1.0 / m
    elif name == "asymmetric_dynamics":
        P["lin"]["asymmetric_dynamics"] = e
        lr = math.exp(-e["sgn"] * m * e["share"])
        lf = math.exp(e["sgn"] * m * (1 - e["share"]))
        P["sch_mode"] = 1
        P["lambdas"] = [lr, lf]
    elif name == "bias_dependent_dynamics":
        P["lin"]["bias_dependent_dynamics"] = e
        beta = e["sgn"] * m
        if e["var"] == "y_level":
            P["sch_mode"] = 2
            off, scl = rec_stats["ymin"], max(rec_stats["ymax"] - rec_stats["ymin"], 1e-12)
            phi0 = 0.5
        elif e["var"] == "u_bias":
            P["sch_mode"] = 3
            off, scl = lo, hi - lo
            phi0 = 0.5
        else:
            P["sch_mode"] = 4
            off, scl = lo, (hi - lo) / 2
            phi0 = 0.3
        P["sch_p"] = np.array([beta, phi0, off, scl, e["tau"], phi0], float)
        s1, s2 = beta * (-0.2 - phi0), beta * (1.2 - phi0)
        P["sch_lohi"] = (min(s1, s2), max(s1, s2))
    elif name == "drift":
        P["drift"] = (e, m)


def drift_signal(e, m, n, fs, rng_seed):
    t = np.arange(n) / fs
    T = n / fs
    f = e["form"]
    if f == "linear":
        d = e["sgn"] * t / T
    elif f == "exponential":
        d = e["sgn"] * (1 - np.exp(-t / e["tau"]))
    elif f == "thermal":
        d = np.sin(2 * np.pi * t / e["period"] + e["phase"]) - math.sin(e["phase"])
    else:
        r = np.random.default_rng(rng_seed)
        nn = max(int(T * 20), 50)
        w = np.cumsum(r.standard_normal(nn))
        w = w - w[0]
        from scipy.signal import lfilter
        a = math.exp(-2 * math.pi * e["fc"] / 20.0)
        w = lfilter([1 - a], [1, -a], w - w[0])
        d = np.interp(t, np.arange(nn) / 20.0, w)
    return m * d


def simulate(case, rec, P, closed=None):
    """Simulate one recording with parameter set P.  Returns y_true (n_rec), u (n_rec)."""
    rig = case.rig
    fs = rec["rate"]
    T = 1.0 / fs
    M = P["M"]
    lin = build_linear(case.g_num, case.g_den, P["lin"])
    n = lin["A"].shape[0]
    mask = lin["mask"]
    sch_mode = P["sch_mode"]
    if sch_mode == 0:
        lambdas = [1.0]
        lo_, hi_ = 0.0, 1.0
    elif sch_mode == 1:
        lambdas = P["lambdas"]
        lo_, hi_ = 0.0, 1.0
    else:
        lo_, hi_ = P["sch_lohi"]
        if hi_ - lo_ < 1e-12:
            hi_ = lo_ + 1e-12
        lambdas = np.exp(np.linspace(lo_, hi_, 65))
    key = (fs, M, n, tuple(np.round(np.asarray(lambdas, float), 15)), lin["A"].tobytes(), lin["B"].tobytes(),
           mask.tobytes())
    cache = case.disc_cache
    if key in cache:
        Phi, Gam = cache[key]
    else:
        Phi, Gam = discretise(lin["A"], lin["B"], T / M, lambdas, mask)
        if len(cache) > 40:
            cache.clear()
        cache[key] = (Phi, Gam)
    u_all = rec["u_all"] if closed is None else closed["u_all"]
    npre = rec["npre"]
    N = len(u_all)
    # initial state: equilibrium for the static chain at u_all[0]
    x0 = static_x(case, P, u_all[0])
    A, B = lin["A"], lin["B"]
    z0 = -np.linalg.solve(A, B * x0)
    Df = int(round((rec["d"] + P["extra_delay"]) * M))
    drift = np.zeros(N)
    if P["drift"] is not None:
        e, m = P["drift"]
        drift[npre:] = drift_signal(e, m, N - npre, fs, rec["seed"] + 17)
    if closed is None:
        cl, r, ctrl, cpoly, noise, sens = 0, np.zeros((2, 1)), np.zeros(5), np.zeros(1), np.zeros(1), np.zeros(2)
    else:
        cl, r, ctrl, cpoly, noise, sens = 1, closed["r"], closed["ctrl"], closed["cpoly"], closed["noise"], closed["sens"]
    y, u = kernel(np.ascontiguousarray(u_all, float), npre, M, Df, P["slew_mode"], P["slew_R"], T,
                  P["dsat_p"], P["dz_p"], np.array(case.poly_true, float), P["hy_mode"], P["hy_p"], P["xs_p"],
                  Phi, Gam, lin["C"], lin["Cg"], lin["dcg"], z0,
                  sch_mode, P["sch_p"], lo_, hi_, P["ys_p"], drift,
                  cl, r, ctrl, cpoly, noise, sens)
    return y[npre:], u[npre:]


def static_x(case, P, u):
    from kernel import sat_fn
    ua = u
    if P["dsat_p"][0] > 0:
        d = P["dsat_p"]
        ua = sat_fn(ua - d[4], int(d[0]), d[1], d[2], d[3]) + d[4]
    if P["dz_p"][0] > 0:
        w = ua - P["dz_p"][2]
        dl = P["dz_p"][1]
        if P["dz_p"][0] == 1:
            w = math.copysign(max(abs(w) - dl, 0.0), w)
        elif dl > 0:
            w = w * (1 - math.exp(-(w / dl) ** 2))
        ua = P["dz_p"][2] + w
    x = float(poly_val(case.poly_true, ua))
    if P["xs_p"][0] > 0:
        d = P["xs_p"]
        x = sat_fn(x - d[4], int(d[0]), d[1], d[2], d[3]) + d[4]
    return x


# ----------------------------------------------------------------------------- magnitude solving
def contrib(case, effs_ms, u_override=None):
    """Noise-free effect contribution over all recordings (post-transient mask).
    effs_ms: list of (effect, m).  Returns (rms/sigma, peak/stroke, per-rec rms list)."""
    diffs = []
    y0s = []
    per = []
    for ri, rec in enumerate(case.recs):
        P = base_params(case)
        for e, m in effs_ms:
            apply_effect(P, e, m, case, case.stats)
        if any(e["name"] in ("delay", "slew_limit") for e, _ in effs_ms):
            P["M"] = case.M_fine
        if u_override is not None:
            rr = dict(rec, u_all=np.concatenate([rec["u_all"][:rec["npre"]], u_override[ri]]))
            y0 = nominal_y(case, rr, P["M"], key=("ov", ri, P["M"]))
            y1, _ = simulate(case, rr, P)
        else:
            y0 = nominal_y(case, rec, P["M"], key=("nom", ri, P["M"]))
            y1, _ = simulate(case, rec, P)
        d = (y1 - y0)
        skip = int(0.05 * len(d))
        d = d[skip:]
        diffs.append(d)
        y0s.append(y0[skip:])
        per.append(float(np.sqrt(np.mean(d * d)) / case.sig_eff))
    a = np.concatenate(diffs)
    # part of the contribution that a refit of gain (common) and offset (per recording) cannot absorb
    cols = [np.concatenate(y0s)]
    for ri in range(len(diffs)):
        cols.append(np.concatenate([np.full(len(dd), 1.0 if rj == ri else 0.0) for rj, dd in enumerate(diffs)]))
    X = np.stack(cols, 1)
    coef, *_ = np.linalg.lstsq(X, a, rcond=None)
    res = a - X @ coef
    case.last_resid_ratio = float(np.sqrt(np.mean(res * res)) / case.sig_eff)
    return float(np.sqrt(np.mean(a * a)) / case.sig_eff), float(np.max(np.abs(a)) / case.stroke), per


def nominal_y(case, rec, M, key):
    if key in case.nom_cache and case.nom_cache[key][0] is rec["u_all"]:
        return case.nom_cache[key][1]
    P = base_params(case)
    P["M"] = M
    y, _ = simulate(case, rec, P)
    case.nom_cache[key] = (rec["u_all"], y)
    return y


def solve_m(case, e, target, others=(), max_m=None):
    """Find magnitude m of effect e so that the contribution ratio hits target."""
    m = e["m0"]
    pts = []
    evals = 0
    r = 0.0
    while evals < 40:
        r, pk, per = contrib(case, [(e, m)] + list(others))
        evals += 1
        if not np.isfinite(r):
            m *= 0.3
            r = 0.0
            continue
        pts.append((m, r))
        if r > 1e-9 and abs(r / target - 1) < 0.04:
            return m, r, pk, per, evals
        lo = [p for p in pts if p[1] < target]
        hi = [p for p in pts if p[1] > target]
        if r < 1e-9:
            m *= 4.0
        elif lo and hi:
            a = max(lo, key=lambda p: p[0]) if True else None
            b = min(hi, key=lambda p: p[0])
            a = max([p for p in lo if p[0] < b[0]] or [min(lo, key=lambda p: p[0])], key=lambda p: p[0])
            if a[1] > 1e-9 and a[0] > 0:
                sl = (math.log(b[1]) - math.log(a[1])) / (math.log(b[0]) - math.log(a[0]) + 1e-300)
                if sl > 0.05:
                    mn = math.exp(math.log(a[0]) + (math.log(target) - math.log(a[1])) / sl)
                else:
                    mn = math.sqrt(a[0] * b[0])
            else:
                mn = math.sqrt(a[0] * b[0]) if a[0] > 0 else b[0] / 2
            lo_m, hi_m = min(a[0], b[0]), max(a[0], b[0])
            if not (lo_m < mn < hi_m) or evals % 4 == 0:
                mn = math.sqrt(lo_m * hi_m) if lo_m > 0 else hi_m / 2
            m = mn
        else:
            # extrapolate with slope estimate
            sl = 1.0
            if len(pts) >= 2 and pts[-2][1] > 1e-9 and pts[-1][0] != pts[-2][0]:
                sl = (math.log(pts[-1][1]) - math.log(pts[-2][1])) / (math.log(pts[-1][0]) - math.log(pts[-2][0]))
                sl = min(max(sl, 0.3), 6.0)
            fac = (target / r) ** (1.0 / sl)
            fac = min(max(fac, 1e-3), 1e3)
            m = m * fac
        if max_m is not None and m > max_m:
            if pts and pts[-1][0] == max_m:
                break
            m = max_m
    return m, r, pk, per, evals


# ----------------------------------------------------------------------------- case generation
def plan_cases(N, rng, only=None, mode="tune"):
    if only is not None:
        if "+" in only:
            return [only.split("+")] * N
        return [[only]] * N if only != "none" else [[]] * N
    if mode == "eval":
        n_none = max(44, int(round(0.2 * N)))
        n_mix = max(44, int(round(0.2 * N)))
    elif mode == "subset":
        n_none, n_mix = max(1, N // 6), max(1, N // 6)
    else:
        n_none, n_mix = int(round(0.12 * N)), int(round(0.25 * N))
    n_single = N - n_none - n_mix
    plan = [[]] * n_none
    for i in range(n_single):
        plan.append([EFFECTS[i % 10]])
    pairs = [(a, b) for i, a in enumerate(EFFECTS) for b in EFFECTS[i + 1:]]
    order = rng.permutation(len(pairs))
    for i in range(n_mix):
        a, b = pairs[order[i % len(pairs)]]
        plan.append([a, b])
    idx = rng.permutation(len(plan))
    return [plan[i] for i in idx]


def make_case(ci, effects, seed, fast=False, subset=False, attempt=0, force_closed=False):
    rng = np.random.default_rng([seed, ci, 7919] if attempt == 0 else [seed, ci, 7919, attempt])
    case = Case()
    case.idx = ci
    case.effects = effects
    closed = rng.random() < 0.4 or force_closed
    if "delay" in effects and rng.random() < 0.5 and not force_closed:
        closed = False
    if "dead_zone" in effects:
        closed = False  # closed-loop references keep u far from the zone
    if closed:
        kind = "pvc" if rng.random() < 0.7 else "amp10"
    else:
        kind = str(rng.choice(["pvc", "pvc", "pvc", "piezo", "piezo", "amp10", "nano", "mm"]))
        if any(e in effects for e in ("asymmetric_dynamics", "bias_dependent_dynamics")) and \
                kind in ("piezo", "nano"):
            # sub-millisecond time constants: dynamics not observable with 0.05-5 Hz inputs
            kind = str(rng.choice(["pvc", "amp10", "mm"]))
    rig = make_rig(kind, rng, closed)
    case.rig = rig
    case.closed = closed
    rates = rig["rates"]
    if subset:
        rates = [r for r in rates if r <= 1000]
    rate = int(rng.choice(rates))
    if subset:
        rate = 100 if (100 in rates and rng.random() < 0.6) else int(max(rates))
    case.rate = rate
    case.poly_true = list(rig["poly"])
    case.g_num, case.g_den = list(rig["num"]), list(rig["den"])
    case.disc_cache = {}
    case.nom_cache = {}
    # noise
    case.sigma = rig["sigma"]
    case.q = rig["q"]
    case.sig_eff = math.sqrt(case.sigma ** 2 + case.q ** 2 / 12)
    # constant sensor offset (+-5 % of the rig's nominal stroke) in 30 % of the cases
    ylo = float(poly_val(rig["poly"], rig["urange"][0])) * rig["dcg"]
    yhi = float(poly_val(rig["poly"], rig["urange"][1])) * rig["dcg"]
    case.offset = float(rng.uniform(-0.05, 0.05) * abs(yhi - ylo)) if rng.random() < 0.3 else 0.0
    # io delay
    case.d = int(rng.integers(0, 3))
    case.declared = bool(rng.random() < 0.6) or ("delay" in effects)
    # nominal model
    make_nominal(case, rng)
    # recordings
    nrec = int(rng.integers(1, 5))
    if subset:
        nrec = min(nrec, 2 if rate <= 100 else 1)
    if rate >= 5000:
        nrec = min(nrec, 2)
    case.M = 1
    case.M_fine = 10 if rate <= 1000 else 5
    lo, hi = rig["urange"]
    case.recs = []
    for k in range(nrec):
        if rate >= 5000:
            dur = rng.uniform(5, 10 if rate == 10000 else 15)
        else:
            dur = rng.uniform(20, 60)
        if subset:
            dur = rng.uniform(15, 30) if rate <= 100 else rng.uniform(8, 15)
        if fast:
            dur = dur / 3
        n = int(dur * rate)
        rec = {"rate": rate, "d": case.d, "seed": int(rng.integers(0, 2 ** 31))}
        pre_kind = str(rng.choice(["rest", "rest", "mid", "charged"]))
        if closed:
            pre_kind = "rest" if rng.random() < 0.6 else "charged"
        if closed:
            rk = "r1" if rng.random() < 0.6 else "r2"
            f = float(rng.choice([0.1, 0.5, 1.0]))
            t = np.arange(n) / rate
            rec["r"] = ref_signal(rk, f, t)
            rec["ref"] = f"y_r1 f={f}" if rk == "r1" else "y_r2"
            rec["kind"] = "closed_" + rec["ref"]
            u0 = float(np.clip(poly_inv_py(case.nom_poly, rec["r"][0] / case.nom_dcg, 0, rig["drive"][1]), 0, hi))
            npre = int(rng.uniform(3, 10) * rate)
            upre = np.full(npre, u0)
            if pre_kind == "charged":
                npre2 = int(rng.uniform(10, 30) * rate)
                lev = rng.uniform(lo, hi)
                upre = np.concatenate([np.full(npre2, lev), upre])
                npre += npre2
            rec["u_all"] = np.concatenate([upre, np.full(n, u0)])
            rec["npre"] = npre
        else:
            hint = []
            kinds = ["sines", "steps", "multisine", "chirp", "random"]
            ik = str(rng.choice(kinds))
            if k == 0 and any(e in effects for e in ("creep", "asymmetric_dynamics", "bias_dependent_dynamics")) \
                    and rng.random() < 0.6:
                ik = "steps"   # holds show creep tails / direction-dependent transients
            if k == 0 and "resonance" in effects and rng.random() < 0.7:
                ik = "smallsteps"
            if any(e in effects for e in ("slew_limit", "delay")):
                ik = str(rng.choice(["sines", "multisine", "chirp", "random", "fastsines", "smallsteps"]))
                if k == 0 and "slew_limit" in effects:
                    ik = "fastsines"
                if rig["kind"] == "pvc" and rng.random() < 0.3:
                    ik = "steps"
            if k == 0 and "dead_zone" in effects:
                ik = str(rng.choice(["steps", "sines"]))
                hint = ["low"]
            if pre_kind == "mid":
                npre = int(rng.uniform(0.5, 3.0) * rate)
                u_all = make_input(rng, ik, n, rate, lo, hi, pre_n=npre)
            else:
                npre = int(min(rng.uniform(3, 10), 30) * rate)
                u_rec = make_input(rng, ik, n, rate, lo, hi)
                if "low" in hint:
                    u_rec = lowify(u_rec, lo, hi, ik, rng, case)
                u_all = np.concatenate([np.full(npre, u_rec[0]), u_rec])
                if pre_kind == "charged":
                    npre2 = int(min(rng.uniform(10, 40), 20 if rate >= 5000 else 40) * rate)
                    lev = rng.uniform(lo, hi)
                    u_all = np.concatenate([np.full(npre2, lev), u_all])
                    npre += npre2
            rec["u_all"] = u_all
            rec["npre"] = npre
            rec["kind"] = ik
        rec["pre"] = pre_kind
        case.recs.append(rec)
    case.rng = rng
    return case


def lowify(u, lo, hi, ik, rng, case):
    """Make an input visit the region near zero (for dead-zone cases) while keeping a useful span."""
    umin, umax = float(np.min(u)), float(np.max(u))
    if umax - umin < 1e-12:
        return u
    if case.rig["bipolar"]:
        c = 0.5 * (umin + umax)
        g = rng.uniform(0.5, 1.0) * min(hi, -lo) / max(umax - c, c - umin)
        return np.clip((u - c) * g, lo, hi)
    g = rng.uniform(0.6, 1.0) * (hi - lo) / (umax - umin)
    return np.clip(lo + (u - umin) * g, lo, hi)


def poly_inv_py(c, v, lo, hi):
    a, b = lo, hi
    for _ in range(60):
        m = 0.5 * (a + b)
        if float(poly_val(c, m)) < v:
            a = m
        else:
            b = m
    return 0.5 * (a + b)


def make_nominal(case, rng):
    rig = case.rig
    pert = []
    poly = list(rig["poly"])
    num = list(rig["num"])
    den = list(rig["den"])
    if rig["kind"] == "pvc" and rig["truth_poly"] == "n3":
        if rng.random() < 0.4:
            poly = list(PVC_P2)
            pert.append("poly:n2_paper_with_n3_truth")
        else:
            uu = np.linspace(0, rig["urange"][1], 200)
            X = np.stack([uu, uu ** 3], 1)
            c, *_ = np.linalg.lstsq(X, poly_val(PVC_P3, uu), rcond=None)
            poly = [float(c[0]), float(c[1])]
            pert.append("poly:n2_lsfit_of_n3_truth")
    r = rng.random()
    if r < 0.4:
        pass
    else:
        g_eps = rng.uniform(-0.05, 0.05) if r < 0.7 or r > 0.9 else 0.0
        t_eps = rng.uniform(-0.06, 0.06) if r >= 0.55 else 0.0
        if abs(t_eps) > 0:
            # scale all time constants by (1+t_eps): s -> s*(1+t_eps)
            k = 1 + t_eps
            nd = len(den) - 1
            den = [den[i] * k ** (nd - i) for i in range(len(den))]
            nn = len(num) - 1
            num = [num[i] * k ** (nn - i) for i in range(len(num))]
            pert.append(f"time_constants*{k:.4f}")
        if abs(g_eps) > 0:
            if rng.random() < 0.5:
                num = [v * (1 + g_eps) for v in num]
                pert.append(f"G_gain*{1 + g_eps:.4f}")
            else:
                pe = rng.uniform(-0.04, 0.04, len(poly))
                poly = [v * (1 + p) for v, p in zip(poly, pe)]
                pert.append("poly*(" + ",".join(f"{1 + p:.4f}" for p in pe) + ")")
    # normalise denominator leading coefficient to 1
    d0 = den[0]
    den = [v / d0 for v in den]
    num = [v / d0 for v in num]
    case.nom_poly, case.nom_num, case.nom_den = poly, num, den
    case.nom_dcg = num[-1] / den[-1]
    case.pert = ";".join(pert) if pert else "exact"


def run_case(case, fast=False):
    rng = case.rng
    rig = case.rig
    notes = []
    # closed loop nominal first (gives the u to scale on)
    if case.closed:
        setup_controller(case, rng)
        for rec in case.recs:
            P = base_params(case)
            y, u = simulate(case, rec, P, closed=closed_args(case, rec))
            rec["u_all"] = np.concatenate([rec["u_all"][:rec["npre"]], u])
    # stats of nominal signals
    ys, xs, us = [], [], []
    for ri, rec in enumerate(case.recs):
        y = nominal_y(case, rec, case.M, key=("nom", ri, case.M))
        u = rec["u_all"][rec["npre"]:]
        ys.append(y)
        us.append(u)
        xs.append(poly_val(case.poly_true, u))
    ya = np.concatenate(ys)
    case.stats = {"ymin": float(ya.min()), "ymax": float(ya.max()), "umin": float(min(u.min() for u in us)),
                  "umax": float(max(u.max() for u in us)), "xmin": float(min(x.min() for x in xs)),
                  "xmax": float(max(x.max() for x in xs))}
    case.stroke = max(float(ya.max() - ya.min()), 1e-9)
    # effects
    effs = [draw_effect(n, rng, rig, case.rate) for n in case.effects]
    targets = []
    if len(effs) == 1:
        targets = [rng.uniform(3.4, 7.6)]
    elif len(effs) == 2:
        if rng.random() < 0.7:
            targets = [rng.uniform(5.0, 7.6), rng.uniform(3.3, 4.6)]
        else:
            t0 = rng.uniform(3.6, 7.0)
            targets = [t0, t0 * rng.uniform(0.85, 0.95)]
    ms = []
    indiv = []
    for e, tg in zip(effs, targets):
        max_m = None
        if e["name"] == "slew_limit":
            max_m = 1.0 / 200.0  # 0.2 kV/s minimum slew
            if rig["kind"] != "pvc":
                max_m = 1.0 / 2.0
        if e["name"] == "resonance":
            max_m = 0.6 if e["kind"] != "polezero" else 1.0
        if e["name"] == "saturation":
            max_m = 5.0
        if e["name"] == "delay":
            max_m = 60.0
        if e["name"] == "dead_zone":
            max_m = 0.15 * (rig["urange"][1] - rig["urange"][0])
        if e["name"] in ("asymmetric_dynamics", "bias_dependent_dynamics"):
            max_m = 1.5 if e["name"] == "asymmetric_dynamics" else 3.0
        if e["name"] == "creep":
            max_m = 0.6
        m, r, pk, per, nev = solve_m(case, e, tg, max_m=max_m)
        tries = 0
        while not (r >= 2.95) and tries < 3:
            tries += 1
            e2 = draw_effect(e["name"], rng, rig, case.rate)
            if e["name"] == "resonance":
                e2.update(kind="parallel", form="parallel")
            notes.append(f"{e['name']}: form {e.get('form')} could not reach target (r={r:.2f}); redrawn")
            e = e2
            effs[effs.index(next(x for x in effs if x["name"] == e["name"]))] = e
            m, r, pk, per, nev = solve_m(case, e, tg, max_m=max_m)
        if pk > 0.02 and r > 3.0:
            tg2 = max(3.05, r * 0.02 / pk)
            if tg2 < r * 0.97:
                m, r, pk, per, nev2 = solve_m(dict_case(case), dict(e, m0=m), tg2, max_m=max_m)
                notes.append(f"{e['name']}: target lowered {tg:.2f}->{tg2:.2f} for peak rule")
        if pk > 0.02:
            notes.append(f"{e['name']}: peak {100 * pk:.2f}% of stroke")
        if not (2.95 <= r <= 8.05):
            notes.append(f"{e['name']}: ratio {r:.2f} out of range")
        ms.append(m)
        indiv.append((r, pk, per))
    # closed loop re-run with the effects
    if case.closed and effs:
        for it in range(3):
            uo = []
            for rec in case.recs:
                P = base_params(case)
                for e, m in zip(effs, ms):
                    apply_effect(P, e, m, case, case.stats)
                if any(e["name"] in ("delay", "slew_limit") for e in effs):
                    P["M"] = case.M_fine
                y, u = simulate(case, rec, P, closed=closed_args(case, rec))
                uo.append(u)
            okall = True
            newms = []
            indiv = []
            for e, m, tg in zip(effs, ms, targets):
                r, pk, per = contrib(case, [(e, m)], u_override=uo)
                indiv.append((r, pk, per))
                if not (3.0 <= r <= 8.0):
                    okall = False
                    newms.append(m * (tg / max(r, 1e-6)))
                else:
                    newms.append(m)
            if okall or it == 2:
                break
            ms = newms
        case.u_cl = uo
    else:
        case.u_cl = None
    # ratio left after a gain/offset refit (informative only)
    case.resid = []
    for e, m in zip(effs, ms):
        contrib(case, [(e, m)], u_override=case.u_cl)
        case.resid.append(case.last_resid_ratio)
    # combined ratio
    if effs:
        r_all, pk_all, per_all = contrib(case, list(zip(effs, ms)), u_override=case.u_cl)
    else:
        r_all, pk_all, per_all = 0.0, 0.0, [0.0] * len(case.recs)
    case.effs, case.ms, case.indiv = effs, ms, indiv
    case.r_all, case.pk_all, case.per_all = r_all, pk_all, per_all
    case.notes = notes
    # final data
    final_records(case)


def dict_case(case):
    return case


def setup_controller(case, rng):
    # PI on the error (in x units) + feed-forward r/G_dc + nominal polynomial inverse
    fs = case.rate
    d = case.d
    wc = rng.uniform(8.0, 25.0)
    if fs <= 100:
        wc = min(wc, 12.0 / (1 + d))
    num, den = case.nom_num, case.nom_den
    # high-frequency gain of G: lim s*G(s) ~ num[0]/den[0] if rel. degree 1
    poles = np.sort(-np.roots(den).real)
    if len(den) - len(num) == 1:
        hf = num[0] / den[0]
        Kp = wc / hf
        Ki = Kp * rng.uniform(0.3, 2.0)
    else:
        p1 = poles[0]
        p2 = poles[-1]
        wc = min(p2 * rng.uniform(0.25, 0.5), 0.3 * 2 * math.pi * fs / (2 + d) / 4)
        Kp = wc / (case.nom_dcg * p1)
        Ki = Kp * p1 * rng.uniform(0.7, 1.3)
    hi = min(case.rig["drive"][1], 850.0 if len(case.nom_poly) >= 3 else case.rig["drive"][1])
    case.ctrl = np.array([Kp, Ki, case.nom_dcg, case.rig["drive"][0], hi], float)
    case.ctrl_desc = f"PI Kp={Kp:.4g} Ki={Ki:.4g} + ff G_nom^-1 r (low-passed) + f_nom^-1, clamp [{case.rig['drive'][0]:g},{hi:g}] V"


def feedforward(case, r, fs):
    """v_ff = G_nom(s)^-1 / (tau s + 1)^reldeg applied to r (x units), tau = 1/(2 pi min(10 Hz, fs/10))."""
    from scipy.signal import lsim, TransferFunction
    num, den = np.array(case.nom_num, float), np.array(case.nom_den, float)
    rd = len(den) - len(num)
    tau = 1.0 / (2 * np.pi * min(10.0, fs / 10.0))
    lp = np.array([1.0])
    for _ in range(rd):
        lp = np.polymul(lp, [tau, 1.0])
    sysf = TransferFunction(den, np.polymul(num, lp))
    npre = int(5 * fs)
    rr = np.concatenate([np.full(npre, r[0]), r])
    t = np.arange(len(rr)) / fs
    # start from steady state: simulate deviation from r[0]
    _, v, _ = lsim(sysf, rr - r[0], t)
    return v[npre:] + r[0] / case.nom_dcg


def closed_args(case, rec):
    N = len(rec["u_all"])
    r = np.zeros((2, N))
    r[0, rec["npre"]:] = rec["r"]
    if "vff" not in rec:
        rec["vff"] = feedforward(case, rec["r"], rec["rate"])
    r[1, rec["npre"]:] = rec["vff"]
    if "noise" not in rec:
        nr = np.random.default_rng(rec["seed"])
        rec["noise"] = nr.standard_normal(N) * case.sigma
    return {"u_all": rec["u_all"].copy(), "r": r, "ctrl": case.ctrl, "cpoly": np.array(case.nom_poly, float),
            "noise": rec["noise"], "sens": np.array([case.offset, case.q], float)}


def final_records(case):
    case.outs = []
    for ri, rec in enumerate(case.recs):
        P = base_params(case)
        for e, m in zip(case.effs, case.ms):
            apply_effect(P, e, m, case, case.stats)
        if any(e["name"] in ("delay", "slew_limit") for e in case.effs):
            P["M"] = case.M_fine
        if case.closed:
            ca = closed_args(case, rec)
            ca["sens"] = np.array([case.offset, case.q], float)
            y, u = simulate(case, rec, P, closed=ca)
            noise = rec["noise"][rec["npre"]:]
        else:
            y, u = simulate(case, rec, P)
            nr = np.random.default_rng(rec["seed"])
            noise = nr.standard_normal(len(rec["u_all"]))[rec["npre"]:] * case.sigma
        ym = y + noise + case.offset
        if case.q > 0:
            ym = case.q * np.floor(ym / case.q + 0.5)
        case.outs.append((u, ym, y))


# ----------------------------------------------------------------------------- writing
def fmt_num(v):
    return repr(float(v))


def write_case(case, outdir):
    name = f"case{case.idx:03d}"
    cdir = os.path.join(outdir, name)
    os.makedirs(cdir, exist_ok=True)
    lines = ["[model]",
             "poly = [" + ", ".join(fmt_num(c) for c in case.nom_poly) + "]",
             "G_num = [" + ", ".join(fmt_num(c) for c in case.nom_num) + "]",
             "G_den = [" + ", ".join(fmt_num(c) for c in case.nom_den) + "]"]
    if case.declared:
        lines.append(f"io_delay_samples = {case.d}")
    with open(os.path.join(cdir, "model.toml"), "w") as f:
        f.write("\n".join(lines) + "\n")
    qd = max(0, int(math.ceil(-math.log10(case.q))) + 1) if case.q > 0 else 8
    for ri, (rec, (u, ym, y)) in enumerate(zip(case.recs, case.outs)):
        fs = rec["rate"]
        n = len(u)
        buf = io.StringIO()
        buf.write("# pvcgel-recording: 1\n")
        buf.write(f"# rate_hz: {fs}\n")
        cl = case.closed
        buf.write("t_s,u_V,y_um,r_um\n" if cl else "t_s,u_V,y_um\n")
        t = np.arange(n) / fs
        ts = ["%.10g" % v for v in t]
        us = ["%.10g" % v for v in u]
        yfmt = "%." + str(qd) + "f"
        ys = [yfmt % v for v in ym]
        if cl:
            rs = ["%.10g" % v for v in rec["r"]]
            buf.write("\n".join(f"{a},{b},{c},{d}" for a, b, c, d in zip(ts, us, ys, rs)))
        else:
            buf.write("\n".join(f"{a},{b},{c}" for a, b, c in zip(ts, us, ys)))
        buf.write("\n")
        with open(os.path.join(cdir, f"rec{ri}.csv"), "w") as f:
            f.write(buf.getvalue())
    return name


def label_row(case):
    effs = case.effs
    if not effs:
        eff_s, dom, form, params = "none", "none", "none", "{}"
    else:
        eff_s = "+".join(e["name"] for e in effs)
        rs = [r for r, _, _ in case.indiv]
        dom = effs[int(np.argmax(rs))]["name"]
        form = "+".join(str(e.get("form", "")) for e in effs)
        pp = {}
        for e, m, (r, pk, per), rr in zip(effs, case.ms, case.indiv, case.resid):
            d = {"m": m, "ratio_alone": round(r, 3), "peak_frac_stroke": round(pk, 5),
                 "ratio_after_gain_offset_refit": round(rr, 3)}
            d.update(describe(e, m, case))
            pp[e["name"]] = d
        params = json.dumps(pp, separators=(",", ":"))
    rig = case.rig
    notes = list(case.notes)
    notes.append(f"sigma={case.sigma:g} q={case.q:g} offset={case.offset:.6g} stroke={case.stroke:.6g}")
    notes.append("recs=" + "|".join(f"{r['kind']}/{r['pre']}" for r in case.recs))
    notes.append("ratio_per_rec=" + "|".join(f"{v:.2f}" for v in case.per_all))
    notes.append(f"peak_frac_stroke={case.pk_all:.5f}")
    notes.append(f"truth_poly={rig['truth_poly']}:{[float('%.6g' % c) for c in case.poly_true]}")
    notes.append(f"truth_G={[float('%.6g' % c) for c in case.g_num]}/{[float('%.6g' % c) for c in case.g_den]}")
    if case.closed:
        notes.append(case.ctrl_desc)
    return {"case": f"case{case.idx:03d}", "effects": eff_s, "dominant": dom, "form": form, "params": params,
            "effect_rms_over_noise": f"{case.r_all:.3f}", "io_delay_true": case.d,
            "io_delay_declared": "yes" if case.declared else "no", "closed_loop": "yes" if case.closed else "no",
            "rate_hz": case.rate, "actuator": f"{rig['kind']}: {rig['desc']}",
            "nominal_perturbation": case.pert, "notes": "; ".join(notes)}


def describe(e, m, case):
    n = e["name"]
    d = {}
    if n == "slew_limit":
        d["slew_V_per_s"] = 1.0 / m
    elif n == "delay":
        d["extra_delay_samples"] = round(m * case.M_fine) / case.M_fine
        d["extra_delay_s"] = d["extra_delay_samples"] / case.rate
    elif n == "dead_zone":
        d["half_width_V"] = m
    elif n == "saturation":
        d["limit_over_peak"] = 1.0 / m
    elif n == "creep":
        d["gamma"] = m
        d["taus_s"] = [round(t, 3) for t in e["taus"]]
    elif n == "resonance":
        d["f_hz"] = e["f_hz"]
        d["zeta"] = e["zr"]
    elif n == "asymmetric_dynamics":
        d["lambda_rise"] = math.exp(-e["sgn"] * m * e["share"])
        d["lambda_fall"] = math.exp(e["sgn"] * m * (1 - e["share"]))
    elif n == "bias_dependent_dynamics":
        d["beta"] = e["sgn"] * m
    elif n == "hysteresis":
        d["kappa"] = m
        d["domain"] = "u" if e.get("dom", 0) == 0 else "x"
    elif n == "drift":
        d["amplitude_um"] = m
    for k in ("f_hz",):
        pass
    return d


COLS = ["case", "effects", "dominant", "form", "params", "effect_rms_over_noise", "io_delay_true",
        "io_delay_declared", "closed_loop", "rate_hz", "actuator", "nominal_perturbation", "notes"]


def write_labels(rows, outdir):
    tmp = os.path.join(outdir, ".labels.csv.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLS)
        w.writeheader()
        for r in sorted(rows, key=lambda r: r["case"]):
            w.writerow(r)
    os.replace(tmp, os.path.join(outdir, "labels.csv"))


def gen_one(args_tuple):
    ci, effects, seed, fast, subset, outdir, force_closed = args_tuple
    t0 = time.time()
    for attempt in range(6):
        case = make_case(ci, effects, seed, fast=fast, subset=subset, attempt=attempt,
                         force_closed=force_closed)
        run_case(case, fast=fast)
        ok = np.isfinite(case.r_all) and all(np.isfinite(r) and 2.95 <= r <= 8.05 for r, _, _ in case.indiv)
        ok = ok and all(np.all(np.isfinite(o[1])) for o in case.outs)
        # a mixture whose two contributions cancel would be a hidden 'none': redraw it
        ok = ok and (len(case.effs) < 2 or case.r_all >= 3.0)
        if ok:
            break
    if attempt > 0:
        case.notes.append(f"regenerated (attempt {attempt})")
    write_case(case, outdir)
    row = label_row(case)
    return row, time.time() - t0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--cases", type=int, required=True)
    ap.add_argument("--only", default=None)
    ap.add_argument("--fast", action="store_true")
    ap.add_argument("--first", type=int, default=None, help="write only the first K cases of the plan")
    ap.add_argument("--from", dest="start", type=int, default=0,
                    help="begin at case index N (the same files as a full run: each case draws from its own index)")
    ap.add_argument("--mode", default=None, choices=[None, "tune", "eval", "subset"])
    ap.add_argument("--subset", action="store_true", help="subset constraints (<=1 kHz, <=30 s, <=2 recs)")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--closed", action="store_true",
                    help="closed loop wherever the effect allows it (not dead_zone); draws stay aligned")
    a = ap.parse_args()
    mode = a.mode or ("subset" if a.subset else ("eval" if a.cases >= 200 else "tune"))
    prng = np.random.default_rng([a.seed, 4242])
    plan = plan_cases(a.cases, prng, a.only, mode)
    os.makedirs(a.out, exist_ok=True)
    K = a.first if a.first is not None else a.cases
    tasks = [(i, plan[i], a.seed, a.fast, a.subset, a.out, a.closed) for i in range(a.start, K)]
    rows = []
    if a.jobs > 1:
        import multiprocessing as mp
        with mp.Pool(a.jobs) as pool:
            for row, dt in pool.imap(gen_one, tasks):
                rows.append(row)
                print(f"{row['case']} {row['effects']:<40s} r={row['effect_rms_over_noise']} {dt:.1f}s", flush=True)
    else:
        for t in tasks:
            row, dt = gen_one(t)
            rows.append(row)
            print(f"{row['case']} {row['effects']:<40s} r={row['effect_rms_over_noise']} {dt:.1f}s", flush=True)
    write_labels(rows, a.out)


if __name__ == "__main__":
    main()

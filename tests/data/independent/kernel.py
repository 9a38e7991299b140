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
"""Simulation kernel: one monolithic sample/sub-sample loop of the whole signal chain.

Chain per fine step (h = T/M):
  u_cmd[k] --digital slew (sample level)--> delay Df fine steps --analog slew--> drive saturation
  --> dead zone --> input-domain hysteresis --> truth polynomial f --> output-domain hysteresis
  --> x saturation --> linear block (exact ZOH over the fine step, optionally scheduled)
  y[k] = C z(kT) (strictly proper) --> output stop (saturation on y) + drift --> sensor.
Without numba the same code runs as plain Python (slow but identical).
"""
import math
import numpy as np

try:  # numba is optional: only speed
    from numba import njit
except Exception:  # pragma: no cover
    def njit(*args, **kwargs):
        if len(args) == 1 and callable(args[0]):
            return args[0]

        def deco(f):
            return f
        return deco


@njit(cache=True)
def sat_fn(v, form, L_hi, L_lo, shape):
    """Soft saturation.  form 1: p-norm  v/(1+|v/L|^p)^(1/p), p=shape.
    form 2: tanh knee, knee = shape*L, identity below the knee.
    L_lo <= 0 means one-sided (only top)."""
    if v >= 0.0:
        L = L_hi
    else:
        if L_lo <= 0.0:
            return v
        L = L_lo
    a = abs(v)
    if form == 1:
        r = a / (1.0 + (a / L) ** shape) ** (1.0 / shape)
    else:
        k = shape * L
        if a <= k:
            r = a
        else:
            r = k + (L - k) * math.tanh((a - k) / (L - k))
    return r if v >= 0.0 else -r


@njit(cache=True)
def poly_eval(c, u):
    s = 0.0
    p = u
    u2 = u * u
    for i in range(c.shape[0]):
        s += c[i] * p
        p *= u2
    return s


@njit(cache=True)
def poly_inv(c, v, lo, hi):
    """Solve f(u)=v on [lo,hi] by bisection (f assumed increasing there)."""
    flo = poly_eval(c, lo)
    fhi = poly_eval(c, hi)
    if v <= flo:
        return lo
    if v >= fhi:
        return hi
    a = lo
    b = hi
    for _ in range(60):
        m = 0.5 * (a + b)
        if poly_eval(c, m) < v:
            a = m
        else:
            b = m
    return 0.5 * (a + b)


@njit(cache=True)
def kernel(u_all, n_pre, M, Df,
           slew_mode, slew_R, T,
           dsat_p, dz_p, poly, hy_mode, hy_p, xs_p,
           Phi, Gam, Cy, Cg, dcg, z0,
           sch_mode, sch_p, sch_lo, sch_hi,
           ys_p, drift,
           cl, r, ctrl_p, ctrl_poly, noise, sens_p):
    """Returns (y_true[N], u_cmd[N]).  y_true includes output stop and drift, no noise."""
    N = u_all.shape[0]
    n = z0.shape[0]
    L = Phi.shape[0]
    h = T / M
    y_out = np.zeros(N)
    u_cmd = u_all.copy()
    u_lim = np.zeros(N)           # after the digital limiter
    z = z0.copy()
    zn = np.zeros(n)
    # analog slew state
    v_sl = u_all[0]
    # hysteresis states
    nh = int(hy_p[1]) if hy_mode in (1, 2, 4) else 4
    hs = np.zeros(max(nh, 4))
    hprev = 0.0
    hinit = False
    # scheduling states
    lp1 = 0.0
    lp2 = 0.0
    env = 0.0
    sinit = False
    # controller state
    integ = 0.0
    u_last = u_all[0]
    for k in range(N):
        # ---- measurement at start of sample k
        yl = 0.0
        for i in range(n):
            yl += Cy[i] * z[i]
        if ys_p[0] > 0:
            yl = sat_fn(yl - ys_p[4], int(ys_p[0]), ys_p[1], ys_p[2], ys_p[3]) + ys_p[4]
        yl += drift[k]
        y_out[k] = yl
        # ---- controller
        if cl > 0 and k >= n_pre:
            ym = yl + noise[k] + sens_p[0]
            q = sens_p[1]
            if q > 0:
                ym = q * math.floor(ym / q + 0.5)
            e = r[0, k] - ym
            Kp = ctrl_p[0]
            Ki = ctrl_p[1]
            ff = r[1, k]          # model-inverse feed-forward (precomputed from r)
            integ_new = integ + Ki * T * e
            v = ff + Kp * e + integ_new
            uu = poly_inv(ctrl_poly, v, ctrl_p[3], ctrl_p[4])
            if (uu >= ctrl_p[4] and e > 0) or (uu <= ctrl_p[3] and e < 0):
                pass  # anti-windup: freeze integrator
            else:
                integ = integ_new
            u_cmd[k] = uu
        # ---- digital limiter at sample level
        if slew_mode == 2 and k > 0:
            du = u_cmd[k] - u_lim[k - 1]
            mx = slew_R * T
            if du > mx:
                du = mx
            elif du < -mx:
                du = -mx
            u_lim[k] = u_lim[k - 1] + du
        else:
            u_lim[k] = u_cmd[k]
        # ---- fine steps
        for m in range(M):
            j = k * M + m
            ks = (j - Df) // M
            if ks < 0:
                ks = 0
            ud = u_lim[ks]
            # analog slew: mean of the rate-limited continuous signal over the step
            if slew_mode == 1:
                dv = ud - v_sl
                tr = abs(dv) / slew_R
                if tr >= h:
                    sg = 1.0 if dv > 0 else -1.0
                    ua = v_sl + sg * slew_R * h * 0.5
                    v_sl = v_sl + sg * slew_R * h
                else:
                    ua = ((v_sl + ud) * 0.5 * tr + ud * (h - tr)) / h
                    v_sl = ud
            else:
                ua = ud
            # drive saturation
            if dsat_p[0] > 0:
                ua = sat_fn(ua - dsat_p[4], int(dsat_p[0]), dsat_p[1], dsat_p[2], dsat_p[3]) + dsat_p[4]
            # dead zone (around centre dz_p[2])
            if dz_p[0] > 0:
                c0 = dz_p[2]
                w = ua - c0
                dl = dz_p[1]
                if dz_p[0] == 1:
                    if w > dl:
                        w = w - dl
                    elif w < -dl:
                        w = w + dl
                    else:
                        w = 0.0
                elif dl > 0:
                    w = w * (1.0 - math.exp(-(w / dl) ** 2))
                ua = c0 + w
            # hysteresis.  hy_p[0]=kappa, domain hy_p[2]: 0 input(u) 1 output(x); scales hy_p[3]
            hcontr = 0.0
            if hy_mode > 0:
                dom = hy_p[2]
                scl = hy_p[3]
                if dom == 0:
                    vin = ua / scl
                else:
                    vin = poly_eval(poly, ua) / scl
                if not hinit:
                    hprev = vin
                    hinit = True
                    if hy_mode == 3 or hy_mode == 5 or hy_mode == 6:
                        hs[0] = 0.0 if hy_mode == 3 else vin
                        hs[1] = 0.0
                    if hy_mode == 4:
                        # relays start in the state of zero-width relays
                        for i in range(nh):
                            a_ = hy_p[4 + i]
                            b_ = hy_p[4 + nh + i]
                            hs[i] = 1.0 if vin >= 0.5 * (a_ + b_) else -1.0
                dvin = vin - hprev
                if hy_mode == 1 or hy_mode == 2:
                    # generalized stop operators with asymmetric bounds
                    tot = 0.0
                    for i in range(nh):
                        s = hs[i] + dvin
                        lo_ = -hy_p[4 + i]
                        hi_ = hy_p[4 + nh + i]
                        if s > hi_:
                            s = hi_
                        elif s < lo_:
                            s = lo_
                        hs[i] = s
                        tot += hy_p[4 + 2 * nh + i] * s
                    hval = tot
                elif hy_mode == 3:
                    # Bouc-Wen: dh = A dv - beta |dv| h|h|^(n-1) - gamma dv |h|^n  (sub-stepped)
                    A = hy_p[4]
                    be = hy_p[5]
                    ga = hy_p[6]
                    ne = hy_p[7]
                    nsub = 1 + int(abs(dvin) / 0.002)
                    dd = dvin / nsub
                    hb = hs[0]
                    for _ in range(nsub):
                        ah = abs(hb)
                        hb += A * dd - be * abs(dd) * hb * ah ** (ne - 1.0) - ga * dd * ah ** ne
                    hs[0] = hb
                    hval = hb
                elif hy_mode == 4:
                    # Preisach relays: alpha (up switch) = hy_p[4+i], beta (down) = hy_p[4+nh+i]
                    tot = 0.0
                    for i in range(nh):
                        a_ = hy_p[4 + i]
                        b_ = hy_p[4 + nh + i]
                        if vin >= a_:
                            hs[i] = 1.0
                        elif vin <= b_:
                            hs[i] = -1.0
                        s0 = 1.0 if vin >= 0.5 * (a_ + b_) else -1.0
                        tot += hy_p[4 + 2 * nh + i] * (hs[i] - s0)
                    hval = tot
                elif hy_mode == 5:
                    # Duhem: dH = |dv| (v - H) * c(v),  c = c0 (1 + c2 v^2)  -> hval = v - H
                    c0_ = hy_p[4]
                    c2_ = hy_p[5]
                    nsub = 1 + int(abs(dvin) / 0.002)
                    dd = dvin / nsub
                    Hs = hs[0]
                    vv = hprev
                    for _ in range(nsub):
                        vv += dd
                        cc = c0_ * (1.0 + c2_ * vv * vv)
                        g = abs(dd) * cc
                        if g > 1.0:
                            g = 1.0
                        Hs += g * (vv - Hs)
                    hs[0] = Hs
                    hval = vin - Hs
                else:
                    # Jiles-Atherton-like: M_an = tanh(v/a); dMirr = |dv|/k (M_an - Mirr)
                    # M = c M_an + (1-c) Mirr ; hval = M_an - M
                    aa = hy_p[4]
                    kk = hy_p[5]
                    cr = hy_p[6]
                    nsub = 1 + int(abs(dvin) / 0.002)
                    dd = dvin / nsub
                    Mi = hs[0]
                    vv = hprev
                    for _ in range(nsub):
                        vv += dd
                        man = math.tanh(vv / aa)
                        g = abs(dd) / kk
                        if g > 1.0:
                            g = 1.0
                        Mi += g * (man - Mi)
                    hs[0] = Mi
                    man = math.tanh(vin / aa)
                    hval = (1.0 - cr) * (man - Mi)
                hprev = vin
                hcontr = hy_p[0] * scl * hval
                if dom == 0:
                    ua = ua - hcontr
            x = poly_eval(poly, ua)
            if hy_mode > 0 and hy_p[2] == 1:
                x = x - hcontr
            # x saturation
            if xs_p[0] > 0:
                x = sat_fn(x - xs_p[4], int(xs_p[0]), xs_p[1], xs_p[2], xs_p[3]) + xs_p[4]
            # scheduling
            idx = 0
            if sch_mode == 1:
                yg = 0.0
                for i in range(n):
                    yg += Cg[i] * z[i]
                if dcg * x - yg < 0.0:
                    idx = 1
            elif sch_mode >= 2:
                if sch_mode == 2:
                    yg = 0.0
                    for i in range(n):
                        yg += Cg[i] * z[i]
                    phi = (yg - sch_p[2]) / sch_p[3]
                else:
                    un = (ua - sch_p[2]) / sch_p[3]
                    if not sinit:
                        lp1 = un
                        lp2 = un
                        env = sch_p[5]
                        sinit = True
                    a1 = 1.0 - math.exp(-h / sch_p[4])
                    lp1 += a1 * (un - lp1)
                    if sch_mode == 3:
                        phi = lp1
                    else:
                        env += a1 * (abs(un - lp1) * 1.5707963 - env)
                        phi = env
                s = sch_p[0] * (phi - sch_p[1])
                fi = (s - sch_lo) / (sch_hi - sch_lo) * (L - 1)
                if fi < 0:
                    fi = 0.0
                if fi > L - 1:
                    fi = L - 1.0
                idx = int(fi + 0.5)
            # linear block
            for i in range(n):
                acc = Gam[idx, i] * x
                for jj in range(n):
                    acc += Phi[idx, i, jj] * z[jj]
                zn[i] = acc
            for i in range(n):
                z[i] = zn[i]
    return y_out, u_cmd

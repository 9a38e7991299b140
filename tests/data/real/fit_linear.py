# Best linear model of a recording: y = K * G(s) u + c with G = 1/(tau s + 1), by least squares:
# a log grid over tau (Ts/2 .. 2 s), K and c by linear least squares on the ZOH-discretised response
# (u held over each sample, the daemon's convention with no I/O delay). Pure Python (no numpy).
# With a third argument N > 1, f is the project's odd polynomial c1 u + c2 u^3 + ... (N terms) instead of
# K u: the best Hammerstein model without hysteresis (a static curvature is then not blamed on a loop).
# With a fourth argument 2, G has two real poles, 1/((tau1 s + 1)(tau2 s + 1)) (a cascade of two lags,
# as two tanks in series), each exactly ZOH-discretised as a partial fraction, on a 40 x 40 grid.
# With a fourth argument c, G is a complex pole pair, w^2/(s^2 + 2 zeta w s + w^2) (a mass-spring-damper),
# exactly ZOH-discretised, on a 40 x 20 grid of (w from 0.5 Hz to 0.45 of the sample rate, zeta from 0.005
# to 0.95), then a 21 x 21 grid one coarse step either side of the best.
import sys, math, csv
path, out = sys.argv[1], sys.argv[2]
terms = int(sys.argv[3]) if len(sys.argv) > 3 else 1
poles = sys.argv[4] if len(sys.argv) > 4 else '1'
poles = poles if poles == 'c' else int(poles)
t, u, y = [], [], []
with open(path) as f:
    rows = [l for l in f if not l.startswith('#')]
for r in csv.DictReader(rows):
    t.append(float(r['t_s'])); u.append(float(r['u_V'])); y.append(float(r['y_um']))
Ts = t[1] - t[0]; n = len(u)


def solve(A, b):
    """Gaussian elimination with partial pivoting (A small and square)."""
    m = len(b); M = [row[:] + [b[i]] for i, row in enumerate(A)]
    for c in range(m):
        p = max(range(c, m), key=lambda i: abs(M[i][c])); M[c], M[p] = M[p], M[c]
        for i in range(c + 1, m):
            f = M[i][c] / M[c][c]
            for j in range(c, m + 1): M[i][j] -= f * M[c][j]
    x = [0.0] * m
    for i in reversed(range(m)):
        x[i] = (M[i][m] - sum(M[i][j] * x[j] for j in range(i + 1, m))) / M[i][i]
    return x


def lag(v, tau):
    """A unit-gain first-order lag, exactly ZOH-discretised, at rest at v[0]."""
    a = math.exp(-Ts / tau)
    x = [v[0]] * n
    for k in range(1, n):
        x[k] = a * x[k - 1] + (1 - a) * v[k - 1]
    return x


def pair(v, w, zeta):
    """A unit-gain complex pole pair (x = [y, dy/dt], u held over each sample), exactly ZOH-discretised,
    at rest at v[0]."""
    s, wd = zeta * w, w * math.sqrt(1 - zeta * zeta)
    e, c, si = math.exp(-s * Ts), math.cos(wd * Ts), math.sin(wd * Ts)
    a11, a12, a21, a22 = e * (c + s / wd * si), e * si / wd, -w * w * e * si / wd, e * (c - s / wd * si)
    # Bd = A^-1 (Ad - I) B with B = [0, w^2] and A^-1 = [[-2 zeta / w, -1 / w^2], [1, 0]]
    b1, b2 = -2 * zeta / w * a12 * w * w - (a22 - 1), a12 * w * w
    x1, x2 = v[0], 0.0
    out = [x1] * n
    for k in range(1, n):
        x1, x2 = a11 * x1 + a12 * x2 + b1 * v[k - 1], a21 * x1 + a22 * x2 + b2 * v[k - 1]
        out[k] = x1
    return out


def response(v, taus):
    """G applied to v: one lag, or two as partial fractions t1/(t1-t2) and -t2/(t1-t2) (DC gain 1), or
    a complex pair (w, zeta) when poles is c."""
    if poles == 'c':
        return pair(v, *taus)
    if len(taus) == 1:
        return lag(v, taus[0])
    t1, t2 = taus
    a, b = lag(v, t1), lag(v, t2)
    return [(t1 * p - t2 * q) / (t1 - t2) for p, q in zip(a, b)]


def fit(taus):
    cols = [response([w ** (2 * p + 1) for w in u], taus) for p in range(terms)]  # G applied to u^(2p+1)
    cols.append([1.0] * n)
    A = [[sum(p * q for p, q in zip(ci, cj)) for cj in cols] for ci in cols]
    coef = solve(A, [sum(p * q for p, q in zip(ci, y)) for ci in cols])
    fit = [sum(c * col[k] for c, col in zip(coef, cols)) for k in range(n)]
    return math.sqrt(sum((p - q) ** 2 for p, q in zip(fit, y)) / n), taus, coef[:-1], coef[-1]


def log_grid(lo, hi, steps):
    return [lo * (hi / lo) ** (i / (steps - 1)) for i in range(steps)]


if poles == 'c':
    ws, zs = log_grid(2 * math.pi * 0.5, 2 * math.pi * 0.45 / Ts, 40), log_grid(0.005, 0.95, 20)
    best = min((fit((w, z)) for w in ws for z in zs), key=lambda b: b[0])
    w0, z0 = best[1]
    rw, rz = (ws[1] / ws[0]), (zs[1] / zs[0])
    fine = [(w0 * rw ** (i / 10), min(z0 * rz ** (j / 10), 0.99)) for i in range(-10, 11) for j in range(-10, 11)]
    best = min([best] + [fit(p) for p in fine], key=lambda b: b[0])
else:
    steps = 80 if poles == 1 else 40
    grid = log_grid(Ts / 2, 2.0, steps)
    best = min((fit(p) for p in ([(t,) for t in grid] if poles == 1 else [(t1, t2) for t1 in grid for t2 in grid if t2 < t1])),
               key=lambda b: b[0])
r, taus, K, c = best
order = {1: "first-order G", 2: "G with two real poles", 'c': "G a complex pole pair"}[poles]
what = f"{order} and a linear f" if terms == 1 else f"{order} and an odd polynomial f of {terms} terms"
if poles == 'c':
    w, z = taus
    G_num, G_den = [w * w], [1.0, 2 * z * w, w * w]
elif poles == 1:
    G_num, G_den = [1 / taus[0]], [1.0, 1 / taus[0]]
else:
    p = taus[0] * taus[1]
    G_num, G_den = [1 / p], [1.0, (taus[0] + taus[1]) / p, 1 / p]
fmt = lambda v: ', '.join(f'{x:.8g}' for x in v)
open(out, 'w').write(f"# The best {'linear' if terms == 1 else 'Hammerstein'} model of {path.split('/')[-1]} (scripts: fit_linear.py): {what}\n"
                     f"# by least squares; RMS residual {r:.4g} um with an offset of {c:.4g} um.\n"
                     f"[model]\npoly = [{fmt(K)}]\nG_num = [{fmt(G_num)}]\nG_den = [1.0, {fmt(G_den[1:])}]\n")
print(out, 'rms', r, 'taus', taus, 'K', K, 'c', c)

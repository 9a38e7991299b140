# Best linear model of a recording: y = K * G(s) u + c with G = 1/(tau s + 1), by least squares:
# a log grid over tau (Ts/2 .. 2 s), K and c by linear least squares on the ZOH-discretised response
# (u held over each sample, the daemon's convention with no I/O delay). Pure Python (no numpy).
import sys, math, csv
path, out = sys.argv[1], sys.argv[2]
t, u, y = [], [], []
with open(path) as f:
    rows = [l for l in f if not l.startswith('#')]
for r in csv.DictReader(rows):
    t.append(float(r['t_s'])); u.append(float(r['u_V'])); y.append(float(r['y_um']))
Ts = t[1] - t[0]; n = len(u)
best = None
for i in range(80):
    tau = Ts / 2 * (2.0 / (Ts / 2)) ** (i / 79)
    a = math.exp(-Ts / tau)
    x = [u[0]] * n
    for k in range(1, n):
        x[k] = a * x[k - 1] + (1 - a) * u[k - 1]
    sx = sum(x); sy = sum(y); sxx = sum(v * v for v in x); sxy = sum(p * q for p, q in zip(x, y))
    K = (n * sxy - sx * sy) / (n * sxx - sx * sx); c = (sy - K * sx) / n
    r = math.sqrt(sum((K * p + c - q) ** 2 for p, q in zip(x, y)) / n)
    if best is None or r < best[0]:
        best = (r, tau, K, c)
r, tau, K, c = best
open(out, 'w').write(f"# The best linear model of {path.split('/')[-1]} (scripts: fit_linear.py): first-order G and a linear f\n"
                     f"# by least squares; RMS residual {r:.4g} um with an offset of {c:.4g} um.\n"
                     f"[model]\npoly = [{K:.8g}]\nG_num = [{1/tau:.8g}]\nG_den = [1.0, {1/tau:.8g}]\n")
print(out, 'rms', r, 'tau', tau, 'K', K, 'c', c)

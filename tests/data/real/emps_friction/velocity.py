# The EMPS extract as a recording pvcgel diagnose reads: u_V the motor voltage vir (V; times gtau = 35.15 N/V
# the motor force), y_um the carriage's velocity in mm/s (not um), by central differences of the encoder
# position qm as the benchmark's own Script_IDIM_LS.m differentiates it (diffcent), one-sided at the ends.
# Velocity, not position: position is the integral of velocity, a pole at 0 that diagnose refuses (an
# unstable G); force to velocity is a first-order lag M v' = F - Fv v - friction. Pure Python.
# python3 velocity.py emps_position.csv emps_velocity.csv
import csv, sys
src, out = sys.argv[1], sys.argv[2]
rows = list(csv.DictReader(open(src)))
t = [float(r['t_s']) for r in rows]
u = [float(r['vir_V']) for r in rows]
q = [float(r['qm_m']) for r in rows]
Ts = 1e-3  # the benchmark's sampling ("pas means sampling time (1 ms)"); the time column's steps jitter by 1e-8 s
n = len(q)
v = [(q[min(k + 1, n - 1)] - q[max(k - 1, 0)]) / ((min(k + 1, n - 1) - max(k - 1, 0)) * Ts) * 1e3 for k in range(n)]
with open(out, 'w') as f:
    f.write('# pvcgel-recording: 1\n# rate_hz: 1000\nt_s,u_V,y_um\n')
    for k in range(n):
        f.write(f'{k * Ts:.3f},{u[k]:.8f},{v[k]:.6f}\n')

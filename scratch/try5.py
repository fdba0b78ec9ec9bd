import sys, time
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
import proto
from proto import build
cases = {
 'crank5_rest_off5': lambda: record(crank(5.0), 10.0, offset=5e-9, noise=0.2e-9),
 'crank1_rest_off5': lambda: record(crank(1.0), 10.0, offset=5e-9, noise_frac=0.01),
 'crank20_rest_off5': lambda: record(crank(20.0), 10.0, offset=5e-9, noise_frac=0.01, sample='short'),
 'crank5_pon_off20': lambda: record(crank(5.0, since_power_on=True), 10.0, offset=20e-9, noise_frac=0.01),
 'crank1_pon_off20': lambda: record(crank(1.0, since_power_on=True), 10.0, offset=20e-9, noise_frac=0.01),
 'crank_hold_off5': lambda: record(crank_then_hold(3.0, 8.0), 12.0, offset=5e-9, noise=0.2e-9),
 'step_hold': lambda: record(step_hold(), 12.0, sample='big', offset=0, noise_frac=0.01),
 'step_hold_off': lambda: record(step_hold(), 12.0, sample='big', offset=10e-9, noise_frac=0.01),
}
fcs = [float(a) for a in sys.argv[2:]] or [0.1, 0.3, 1.0]
P0 = sys.argv[1]
for name, mk in cases.items():
    t, w, y, m, noise = mk()
    for fc in fcs:
        ssm = build(m, motion_corner_hz=fc, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-13)
        r = proto.run(t, y, ssm, R=noise**2, store=True, p0=P0)
        e = r['w'] - w; s = t >= 1
        cov = np.mean(np.abs(e[s]) <= 2*r['std'][s]); covs = np.mean(np.abs(r['ws'][s]-w[s]) <= 2*r['stds'][s])
        print(f"{name:18s} fc {fc} causal {100*nrmse(r['w'], w, t):6.2f}% smooth {100*nrmse(r['ws'], w, t):6.2f}% cov {cov:.2f}/{covs:.2f} still {r['still'].mean():.2f} std {np.median(r['std'])*1e6:.0f}um", flush=True)

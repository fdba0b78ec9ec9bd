import sys, time
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import run, build
cases = {
 'crank5_rest_off5': lambda: record(crank(5.0), 10.0, offset=5e-9, noise=0.2e-9),
 'crank1_rest_off5': lambda: record(crank(1.0), 10.0, offset=5e-9, noise_frac=0.01),
 'crank5_pon_off20': lambda: record(crank(5.0, since_power_on=True), 10.0, offset=20e-9, noise_frac=0.01),
 'crank_hold_off5': lambda: record(crank_then_hold(3.0, 8.0), 12.0, offset=5e-9, noise=0.2e-9),
 'step_hold': lambda: record(step_hold(), 12.0, sample='big', offset=0, noise_frac=0.01),
}
cfgs = [dict(motion_corner_hz=fc, offset_walk_a=qb, offset_drift_walk_a_per_s=qd) for fc in (0.1, 1.0) for qb in (1e-12,) for qd in (1e-13, 1e-11)]
for name, mk in cases.items():
    t, w, y, m, noise = mk()
    for cfg in cfgs:
        ssm = build(m, **cfg)
        r = run(t, y, ssm, R=noise**2, store=True)
        e = r['w'] - w
        cov = np.mean(np.abs(e[t>=1]) <= 2*r['std'][t>=1])
        print(f"{name:18s} fc {cfg['motion_corner_hz']} qd {cfg['offset_drift_walk_a_per_s']:.0e} causal {100*nrmse(r['w'], w, t):6.2f}% smooth {100*nrmse(r['ws'], w, t):6.2f}% cov {cov:.2f} still {r['still'].mean():.2f}")

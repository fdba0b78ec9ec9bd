import sys, time
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import run, build
import itertools
cases = {
 'crank5_rest_off5': lambda: record(crank(5.0), 10.0, offset=5e-9, noise=0.2e-9),
 'crank5_pon_off20': lambda: record(crank(5.0, since_power_on=True), 10.0, offset=20e-9, noise_frac=0.01),
 'crank_hold_off5': lambda: record(crank_then_hold(3.0, 8.0), 12.0, offset=5e-9, noise=0.2e-9),
 'step_hold': lambda: record(step_hold(), 12.0, sample='big', offset=0, noise_frac=0.01),
}
cfgs = [dict(motion_corner_hz=fc) for fc in (0.05, 0.2, 0.5)]
for name, mk in cases.items():
    t, w, y, m, noise = mk()
    for cfg in cfgs:
        ssm = build(m, **cfg)
        t0 = time.time()
        r = run(t, y, ssm, R=noise**2, store=True)
        e = r['w'] - w
        cov = np.mean(np.abs(e[t>=1]) <= 2*r['std'][t>=1])
        print(f"{name:18s} {cfg} causal {100*nrmse(r['w'], w, t):6.2f}% smooth {100*nrmse(r['ws'], w, t):6.2f}% cov {cov:.2f} still {r['still'].mean():.2f} ({time.time()-t0:.1f}s)")

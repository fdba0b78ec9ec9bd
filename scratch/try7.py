import sys, time
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
import ss5; ss5.enable()
from gen import *
import proto3
from proto import build
cases = {
 'crank5_rest_off5': lambda: record(crank(5.0), 10.0, offset=5e-9, noise=0.2e-9),
 'crank1_rest_off5': lambda: record(crank(1.0), 10.0, offset=5e-9, noise_frac=0.01),
 'crank20_rest_off5': lambda: record(crank(20.0), 10.0, offset=5e-9, noise_frac=0.01, sample='short'),
 'crank5_pon_off20': lambda: record(crank(5.0, since_power_on=True), 10.0, offset=20e-9, noise_frac=0.01),
 'crank1_pon_off20': lambda: record(crank(1.0, since_power_on=True), 10.0, offset=20e-9, noise_frac=0.01),
 'crank_hold_off5': lambda: record(crank_then_hold(3.0, 8.0), 12.0, offset=5e-9, noise=0.2e-9),
 'step_hold_off': lambda: record(step_hold(), 12.0, sample='big', offset=10e-9, noise_frac=0.01),
}
args = sys.argv[1:]
fcs = [float(a) for a in args[0].split(',')] if args else [1.0]
qss = [float(a) for a in args[1].split(',')] if len(args) > 1 else [1e-10]
only = args[2].split(',') if len(args) > 2 and args[2] else None
WSP = float(args[3]) if len(args) > 3 else 1e-3
WFS = bool(int(args[4])) if len(args) > 4 else False
for name, mk in cases.items():
    if only and name not in only: continue
    t, w, y, m, noise = mk()
    for fc in fcs:
      for qs in qss:
        ss5.QH[0] = qs
        ssm = build(m, motion_corner_hz=fc, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-13)
        r = proto3.run(t, y, ssm, R=noise**2, store=True, h_prior=WSP)
        e = r['w'] - w; s = t >= 1
        cov = np.mean(np.abs(e[s]) <= 2*r['std'][s]); covs = np.mean(np.abs(r['ws'][s]-w[s]) <= 2*r['stds'][s])
        print(f"{name:18s} fc {fc} qs {qs:.0e} causal {100*nrmse(r['w'], w, t):6.2f}% smooth {100*nrmse(r['ws'], w, t):6.2f}% cov {cov:.2f}/{covs:.2f} still {r['still'].mean():.2f} std {np.median(r['std'])*1e6:.0f}um", flush=True)

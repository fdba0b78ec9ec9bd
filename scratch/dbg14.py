import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
import proto
from proto import build
t, w, y, m, noise = record(crank(5.0), 10.0, offset=5e-9, noise=0.2e-9)
ssm = build(m, motion_corner_hz=0.1, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-14)
r = proto.run(t, y, ssm, R=noise**2)
for a in (1.5, 2, 3, 5, 8, 9.5):
    s = (t >= a) & (t < a+0.4)
    X = np.c_[np.sin(2*np.pi*5*t[s]), np.cos(2*np.pi*5*t[s]), np.ones(s.sum())]
    cw = np.linalg.lstsq(X, w[s], rcond=None)[0]; ce = np.linalg.lstsq(X, r['w'][s], rcond=None)[0]
    print(a, 'amp ratio', np.hypot(*ce[:2])/np.hypot(*cw[:2]), 'phase', np.degrees(np.angle(complex(*ce[:2]))-np.angle(complex(*cw[:2]))), 'level est', ce[2]*1e6, 'true', cw[2]*1e6, 'std', r['std'][s].mean()*1e6)

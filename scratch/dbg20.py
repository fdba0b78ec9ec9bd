import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
import proto
from proto import build
t, w, y, m, noise = record(crank(5.0, since_power_on=True), 10.0, offset=20e-9, noise_frac=0.01)
print('noise', noise, 'w0', w[0])
for fc in (1.0,):
    ssm = build(m, motion_corner_hz=fc, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-13)
    r = proto.run(t, y, ssm, R=noise**2)
    for a0 in (0.0, 0.5, 1, 2, 4, 8, 9.5):
        s = (t>=a0)&(t<a0+0.4)
        X = np.c_[np.sin(2*np.pi*5*t[s]), np.cos(2*np.pi*5*t[s]), np.ones(s.sum())]
        cw = np.linalg.lstsq(X, w[s], rcond=None)[0]; ce = np.linalg.lstsq(X, r['w'][s], rcond=None)[0]
        print(a0, 'ratio', round(np.hypot(*ce[:2])/np.hypot(*cw[:2]),4), 'level err um', round((ce[2]-cw[2])*1e6,1), 'std', round(r['std'][s].mean()*1e6))

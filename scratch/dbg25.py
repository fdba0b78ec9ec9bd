import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
import ss5; ss5.enable()
from gen import *
import proto3
from proto import build
t, w, y, m, noise = record(crank(20.0), 6.0, offset=5e-9, noise_frac=0.01, sample='short')
print('noise', noise)
for bw in (50., 150.):
  for fc in (1.0, 3.0):
    ssm = build(m, motion_corner_hz=fc, motion_bandwidth_hz=bw, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-13)
    r = proto3.run(t, y, ssm, R=noise**2, h_prior=10e-6)
    s = (t>=3)&(t<3.5)
    X = np.c_[np.sin(2*np.pi*20*t[s]), np.cos(2*np.pi*20*t[s]), np.ones(s.sum())]
    cw = np.linalg.lstsq(X, w[s], rcond=None)[0]; ce = np.linalg.lstsq(X, r['w'][s], rcond=None)[0]
    res = r['w'][s] - X@ce; rt = w[s] - X@cw
    print(bw, fc, 'nrmse', round(100*nrmse(r['w'], w, t, 1.5),2), 'ratio', round(np.hypot(*ce[:2])/np.hypot(*cw[:2]),4), 'phase', round(np.degrees(np.angle(complex(*ce[:2]))-np.angle(complex(*cw[:2]))),2), 'lvl', round((ce[2]-cw[2])*1e6,1), 'harm resid', round(np.std(res-rt)*1e6,1), 'still', r['still'][1500:].mean())

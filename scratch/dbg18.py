import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
import ss3; ss3.enable(True)
from gen import *
import proto
from proto import build
t, w, y, m, noise = record(crank(5.0), 6.0, offset=0e-9, noise=0.2e-9)
for bw in (20., 50., 100.):
  for fc in (0.1, 1.0):
    ssm = build(m, motion_corner_hz=fc, motion_bandwidth_hz=bw, offset_walk_a=1e-15, offset_drift_walk_a_per_s=1e-18, offset_prior_a=1e-15)
    F, Q = ssm.discrete(1); c = ssm.c; R = noise**2
    idx, Pm = proto.stationary_P(ssm)
    for pw in (1e-4, 1e-3):
        x = np.zeros(ssm.size); P = np.zeros((ssm.size, ssm.size)); P[ssm.iw, ssm.iw] = pw**2; P[ssm.ib, ssm.ib]=1e-30
        W = np.empty(t.size); nus = np.empty(t.size)
        for k in range(t.size):
            if k: x = F@x; P = F@P@F.T + Q
            Pc = P@c; S = c@Pc + R; K = Pc/S
            nus[k] = y[k]-c@x
            x = x + K*nus[k]; P = P - np.outer(K, Pc)
            W[k] = x[ssm.iw]
        s = (t>=4)&(t<4.4)
        X = np.c_[np.sin(2*np.pi*5*t[s]), np.cos(2*np.pi*5*t[s]), np.ones(s.sum())]
        cw = np.linalg.lstsq(X, w[s], rcond=None)[0]; ce = np.linalg.lstsq(X, W[s], rcond=None)[0]
        print('bw', bw, 'fc', fc, 'P0w', pw, 'ratio', round(np.hypot(*ce[:2])/np.hypot(*cw[:2]),4), 'nrmse', round(nrmse(W, w, t, 2),4), 'innov', np.sqrt(np.mean(nus[t>3]**2)))

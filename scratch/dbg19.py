import sys
import numpy as np
import scipy.linalg as la
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
import proto
from proto import build
t, w, y, m, noise = record(crank(5.0), 8.0, offset=0e-9, noise=0.2e-9)
for fc in (0.1, 1.0):
    ssm = build(m, motion_corner_hz=fc, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-14, offset_prior_a=1e-12)
    F, Q = ssm.discrete(1); c = ssm.c; R = noise**2
    Pss = la.solve_discrete_are(F.T, c[:,None], Q, np.array([[R]]))
    idx, Pm = proto.stationary_P(ssm)
    Pst = np.zeros_like(Pss); Pst[np.ix_(idx, idx)] = Pm; Pst[ssm.ib, ssm.ib] = 1e-24
    for label, P0 in (('dare', Pss), ('stationary', Pst)):
        x = np.zeros(ssm.size); P = P0.copy()
        W = np.empty(t.size)
        for k in range(t.size):
            if k: x = F@x; P = F@P@F.T + Q
            Pc = P@c; S = c@Pc + R; K = Pc/S
            x = x + K*(y[k]-c@x); P = P - np.outer(K, Pc)
            W[k] = x[ssm.iw]
        out = []
        for a0 in (1.5, 3, 7):
            s = (t>=a0)&(t<a0+0.4)
            X = np.c_[np.sin(2*np.pi*5*t[s]), np.cos(2*np.pi*5*t[s]), np.ones(s.sum())]
            cw = np.linalg.lstsq(X, w[s], rcond=None)[0]; ce = np.linalg.lstsq(X, W[s], rcond=None)[0]
            out.append(round(np.hypot(*ce[:2])/np.hypot(*cw[:2]),4))
        print('fc', fc, label, 'sqrtP0w', np.sqrt(P0[ssm.iw, ssm.iw]), 'ratios', out, 'sqrtPw end', np.sqrt(P[ssm.iw, ssm.iw]))

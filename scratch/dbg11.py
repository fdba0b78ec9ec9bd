import sys
import numpy as np
from scipy.stats import chi2
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
import proto
from proto import build
t, w, y, m, noise = record(crank(5.0), 3.0, offset=5e-9, noise=0.2e-9)
ssm = build(m, motion_corner_hz=1.0, offset_walk_a=1e-12)
# instrument
F, Q = ssm.discrete(1); c = ssm.c; R = noise**2
x, P = ssm.prior; x=x.copy(); P=P.copy()
idx, Pm = proto.stationary_P(ssm); P[np.ix_(idx, idx)] = Pm
ib = ssm.ib
for k in range(400):
    if k: x = F@x; P = F@P@F.T + Q
    r = y[k] - x[ib]
    Pc = P@c; S = c@Pc + R; K = Pc/S
    nu = y[k] - c@x
    x = x + K*nu; P = P - np.outer(K, Pc)
    if k % 50 == 0 or k < 5:
        print(k, 'r', r, 'b', x[ib], 'sqrtPb', np.sqrt(P[ib,ib]), 'S', np.sqrt(S), 'nu', nu, 'w', x[ssm.iw], 'u', x[ssm.iu])

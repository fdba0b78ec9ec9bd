import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
import proto
from proto import build
t, w, y, m, noise = record(crank(5.0, since_power_on=True), 10.0, offset=20e-9, noise_frac=0.01)
import scipy.linalg as la
for fc in (1.0, 10.0):
    ssm = build(m, motion_corner_hz=fc, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-13)
    F, Q = ssm.discrete(1); c = ssm.c; R = noise**2
    x, P = ssm.prior; x = x.copy(); P = P.copy()
    Pss = la.solve_discrete_are(F.T, c[:, None], Q, np.array([[R]]))
    mi = np.r_[np.arange(ssm.n_sensor), ssm.iw, ssm.iu]
    P[np.ix_(mi, mi)] = Pss[np.ix_(mi, mi)]
    for k in range(t.size):
        if k: x = F@x; P = F@P@F.T + Q
        Pc = P@c; S = c@Pc + R; K = Pc/S
        x = x + K*(y[k]-c@x); P = P - np.outer(K, Pc)
        if k % 1000 == 0:
            print(fc, k, 'b', round(x[ssm.ib]*1e9, 2), 'nA sqrtPb', round(np.sqrt(P[ssm.ib,ssm.ib])*1e9,2), 'w-err um', round((x[ssm.iw]-w[k])*1e6), 'd', x[ssm.ib+1]*1e9)

import sys
import numpy as np
import scipy.linalg as la
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
import proto
from proto import build
t, w, y, m, noise = record(crank(5.0), 6.0, offset=5e-9, noise=0.2e-9)
ssm = build(m, motion_corner_hz=1.0, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-14)
r = proto.run(t, y, ssm, R=noise**2, store=True)
F, Q = ssm.discrete(1); c = ssm.c[None,:]; R = noise**2
Pss = la.solve_discrete_are(F.T, c.T, Q, np.array([[R]]))
print('ss sqrt diag', np.sqrt(np.diag(Pss)))
# rerun to get P at t=5
import math
x, P = ssm.prior; x=x.copy(); P=P.copy()
idx, Pm = proto.stationary_P(ssm); P[np.ix_(idx, idx)] = Pm
c1 = ssm.c; cz = ssm.c_rest
for k in range(5000):
    if k: x = F@x; P = F@P@F.T + Q
    if k == 4999: print('tv  sqrt diag', np.sqrt(np.diag(P)))
    Pc = P@c1; S = c1@Pc + R; K = Pc/S
    x = x + K*(y[k]-c1@x); P = P - np.outer(K, Pc)
    if r['still'][k]:
        Pc = P@cz; S = cz@Pc + ssm.r_rest; K = Pc/S; x = x - K*(cz@x); P = P - np.outer(K, Pc)
s = (t>2)
print('ratio', np.std(r['w'][s])/np.std(w[s]))
x, P = ssm.prior; x=x.copy(); P=P.copy()
P[np.ix_(idx, idx)] = Pm
for k in range(1200):
    if k: x = F@x; P = F@P@F.T + Q
    Pc = P@c1; S = c1@Pc + R; K = Pc/S
    x = x + K*(y[k]-c1@x); P = P - np.outer(K, Pc)
    if r['still'][k]:
        Pc = P@cz; S = cz@Pc + ssm.r_rest; K = Pc/S; x = x - K*(cz@x); P = P - np.outer(K, Pc)
    if k in (150, 199, 250, 500, 999, 1100, 1199):
        print(k, r['still'][k], 'sqrtPb', np.sqrt(P[ssm.ib, ssm.ib]), 'b', x[ssm.ib], 'sqrtPu', np.sqrt(P[ssm.iu, ssm.iu]), 'sqrtPw', np.sqrt(P[ssm.iw,ssm.iw]))

import sys
import numpy as np
import scipy.linalg as la
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import build
m = model('slim')
def gain(ssm, drop_d=False, R=1e-18, fs=(1.0, 5.0)):
    F, Q = ssm.discrete(1); c = ssm.c
    idx = np.arange(F.shape[0])
    if drop_d: idx = idx[idx != ssm.ib+1]
    F = F[np.ix_(idx, idx)]; Q = Q[np.ix_(idx, idx)]; c = c[idx][None,:]
    P = la.solve_discrete_are(F.T, c.T, Q, np.array([[R]]))
    K = P @ c.T / (c @ P @ c.T + R); n=F.shape[0]
    Acl = (np.eye(n) - K @ c) @ F
    iw = list(idx).index(ssm.iw)
    out = []
    for f in fs:
        z = np.exp(2j*np.pi*f/1000.)
        G = np.linalg.solve(z*np.eye(n) - Acl, K * z)[:,0]
        out.append(round(abs(G[iw]*m.frequency_response(np.array([f]))[0]), 4))
    return out, K[iw,0], K[list(idx).index(ssm.ib),0]
for qb in (1e-9, 1e-10, 1e-11, 1e-12):
  for fc in (0.1, 1.0):
    ssm = build(m, offset_walk_a=qb, motion_corner_hz=fc)
    print('qb', qb, 'fc', fc, gain(ssm, drop_d=True))

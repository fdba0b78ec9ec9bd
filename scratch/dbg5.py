import sys
import numpy as np
import scipy.linalg as la
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import build
m = model('slim')
def gains(**cfg):
    ssm = build(m, **cfg)
    F, Q = ssm.discrete(1); c = ssm.c[None,:]; R = 1e-18
    P = la.solve_discrete_are(F.T, c.T, Q, np.array([[R]]))
    K = P @ c.T / (c @ P @ c.T + R); n=F.shape[0]
    Acl = (np.eye(n) - K @ c) @ F
    out=[]
    for f in (0.1, 1., 5.):
        z = np.exp(2j*np.pi*f/1000.)
        G = np.linalg.solve(z*np.eye(n) - Acl, K * z)[:,0]
        out.append(np.round(abs(G[ssm.iw]*m.frequency_response(np.array([f]))[0]),4))
    return out
for cfg in [dict(), dict(offset_drift_walk_a_per_s=1e-15), dict(offset_walk_a=1e-15), dict(offset_walk_a=1e-15, offset_drift_walk_a_per_s=1e-15), dict(motion_corner_hz=0.02), dict(motion_bandwidth_hz=200.)]:
    print(cfg, gains(**cfg))

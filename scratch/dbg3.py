import sys
import numpy as np
import scipy.linalg as la
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import build
m = model('slim')
for fc in (0.2, 2.0):
    ssm = build(m, motion_corner_hz=fc)
    F, Q = ssm.discrete(1)
    c = ssm.c[None, :]
    for R in (4e-20, 1e-18):
        # drop offset/drift (random walk: fine) 
        P = la.solve_discrete_are(F.T, c.T, Q + 1e-30*np.eye(F.shape[0]), np.array([[R]]))
        K = P @ c.T / (c @ P @ c.T + R)
        n = F.shape[0]
        # filtered estimate: x+ = (I-Kc) F x+ + K y
        Acl = (np.eye(n) - K @ c) @ F
        fs = 1000.
        for f in (1., 5., 20.):
            z = np.exp(2j*np.pi*f/fs)
            G = np.linalg.solve(z*np.eye(n) - Acl, (np.eye(n)-K@c) @ F @ K * 0 + K * z)  # x+ = z (zI-Acl)^-1 K y ... 
            Gw = G[ssm.iw, 0]
            H = m.frequency_response(np.array([f]))[0]
            print(fc, R, f, 'Gw*H', np.round(Gw*H, 4), 'std_w', np.sqrt(P[ssm.iw, ssm.iw]))

import sys
import numpy as np
import scipy.linalg as la
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import build
m = model('slim')
ssm = build(m)
F, Q = ssm.discrete(1); c = ssm.c[None,:]; R = 1e-18; n=F.shape[0]
# discrete spectra: x = (zI-F)^-1 e, Se = Q.  w = e_w^T x, y = c x + n
for f in (0.01, 0.1, 1.0, 5.0):
    z = np.exp(2j*np.pi*f/1000.)
    T = np.linalg.inv(z*np.eye(n) - F)
    Sx = T @ Q @ T.conj().T
    Swy = Sx[ssm.iw] @ c[0].conj()
    Syy = c[0] @ Sx @ c[0].conj() + R
    G = Swy / Syy
    print(f, 'noncausal w gain*H', np.round(G*m.frequency_response(np.array([f]))[0], 5), 'Syy parts: b', (c[0]*0+1)[ssm.ib]*Sx[ssm.ib,ssm.ib].real/Syy.real)

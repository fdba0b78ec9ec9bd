import sys
import numpy as np
import scipy.linalg as la
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import build
m = model('slim')
ssm = build(m)
F, Q = ssm.discrete(1); c = ssm.c[None,:]; R = 1e-18
P = la.solve_discrete_are(F.T, c.T, Q, np.array([[R]]))
res = F@P@F.T - F@P@c.T@np.linalg.inv(c@P@c.T+R)@c@P@F.T + Q - P
print('rel residual', np.abs(res).max()/np.abs(P).max(), 'diag rel', np.abs(np.diag(res))/np.diag(P))
# iterate
x0, P0 = ssm.prior
Pi = P.copy()*1.0
for k in range(200000):
    S = c@Pi@c.T + R
    Pi = F@(Pi - Pi@c.T@c@Pi/S)@F.T + Q
print('iter vs dare', np.sqrt(np.diag(Pi))/np.sqrt(np.diag(P)))

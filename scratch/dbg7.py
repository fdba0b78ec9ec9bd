import sys
import numpy as np
import scipy.linalg as la
import scipy.signal as sig
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import build
m = model('slim')
ssm = build(m)
F, Q = ssm.discrete(1); c = ssm.c[None,:]; R = 1e-18
P = la.solve_discrete_are(F.T, c.T, Q, np.array([[R]]))
K = P @ c.T / (c @ P @ c.T + R); n = F.shape[0]
Acl = (np.eye(n) - K @ c) @ F
t = np.arange(0, 200., 1e-3)
w = 1e-3*np.sin(2*np.pi*1.0*t)
from ipmc_sensor_ros.simulation.sensor import lti_response_fft
y = lti_response_fft(m.transfer, t, w)
sys_ = sig.StateSpace(Acl, K, np.eye(n), np.zeros((n,1)), dt=1e-3)
x = np.zeros(n); W = np.empty(t.size)
for k in range(t.size):
    x = Acl @ x + K[:,0]*y[k]
    W[k] = x[ssm.iw]
s = t > 150
print('amp ratio', np.std(W[s])/np.std(w[s]))
# predicted current

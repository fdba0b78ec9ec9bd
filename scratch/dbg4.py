import sys
import numpy as np
import scipy.linalg as la
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import build
m = model('slim')
ssm = build(m, motion_corner_hz=0.2)
F, Q = ssm.discrete(1)
keep = np.r_[np.arange(ssm.n_sensor), ssm.iw, ssm.iu]
for label, idx in [('motion only', keep), ('all', np.arange(F.shape[0]))]:
    Fk = F[np.ix_(idx, idx)]; Qk = Q[np.ix_(idx, idx)]; c = ssm.c[idx][None, :]
    R = 1e-18
    P = la.solve_discrete_are(Fk.T, c.T, Qk, np.array([[R]]))
    K = P @ c.T / (c @ P @ c.T + R)
    n = Fk.shape[0]
    Acl = (np.eye(n) - K @ c) @ Fk
    iw = list(idx).index(ssm.iw)
    for f in (1., 5., 20.):
        z = np.exp(2j*np.pi*f/1000.)
        G = np.linalg.solve(z*np.eye(n) - Acl, K * z)
        print(label, f, np.round(G[iw,0]*m.frequency_response(np.array([f]))[0], 4))
    print('K', K.ravel())
    print('eig Acl', np.sort(np.abs(np.linalg.eigvals(Acl)))[-4:])
print('---')
idx = np.arange(F.shape[0]); c = ssm.c[None, :]; R=1e-18
P = la.solve_discrete_are(F.T, c.T, Q, np.array([[R]]))
K = P @ c.T / (c @ P @ c.T + R)
n = F.shape[0]; Acl = (np.eye(n) - K @ c) @ F
for f in (0.01, 0.1, 1., 5.):
    z = np.exp(2j*np.pi*f/1000.)
    G = np.linalg.solve(z*np.eye(n) - Acl, K * z)[:,0]
    H = m.frequency_response(np.array([f]))[0]
    print(f, 'w', np.round(G[ssm.iw]*H,4), 'u', np.round(G[ssm.iu]*H/(2j*np.pi*f),4), 'b', np.round(G[ssm.ib],4))
print(np.sqrt(np.diag(P)))
print('--- scaled')
s = np.sqrt(np.diag(P)); s[s==0]=1
Fs = F / s[:,None] * s[None,:]; Qs = Q / s[:,None] / s[None,:]; cs = c * s[None,:] / 1e-9; Rs = R/1e-18
Ps = la.solve_discrete_are(Fs.T, cs.T, Qs, np.array([[Rs]]))
Ks = Ps @ cs.T / (cs @ Ps @ cs.T + Rs)
K2 = Ks * s[:,None] / 1e-9
P2 = Ps * np.outer(s, s)
Acl = (np.eye(n) - K2 @ c) @ F
for f in (0.01, 0.1, 1., 5.):
    z = np.exp(2j*np.pi*f/1000.)
    G = np.linalg.solve(z*np.eye(n) - Acl, K2 * z)[:,0]
    H = m.frequency_response(np.array([f]))[0]
    print(f, 'w', np.round(G[ssm.iw]*H,4), 'u', np.round(G[ssm.iu]*H/(2j*np.pi*f),4), 'b', np.round(G[ssm.ib],4))
print(np.sqrt(np.diag(P2)))
print('--- parts at 5 Hz')
f=5.; z = np.exp(2j*np.pi*f/1000.)
G = np.linalg.solve(z*np.eye(n) - Acl, K2 * z)[:,0]
print('c x', c[0] @ G, 'parts', c[0]*G)
A, Qc = ssm.continuous
print('A diag', np.diag(A)[:6], 'Bu', A[:4, ssm.iu], 'c', c[0][:6])
H = m.frequency_response(np.array([f]))[0]
s_ = 2j*np.pi*f
print('true xR per unit w', s_/(s_ - np.diag(A)[:4]) , 'est xR/w', G[:4]*H)

import sys
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
import proto
from proto import build
t, w, y, m, noise = record(crank(5.0), 2.5, offset=0e-9, noise=0.2e-9)
ssm = build(m, motion_corner_hz=0.1, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-14, offset_prior_a=1e-12)
F, Q = ssm.discrete(1); c = ssm.c; R = noise**2
n = ssm.size; N = t.size
# keep motion states only (drop b, d) for brute force
keep = np.r_[np.arange(ssm.n_sensor), ssm.iw, ssm.iu]
F = F[np.ix_(keep, keep)]; Q = Q[np.ix_(keep, keep)]; c = c[keep]; n = keep.size
iw = ssm.n_sensor
P0 = np.zeros((n, n)); P0[iw, iw] = 1e-6
# scale states for conditioning
sc = np.ones(n); sc[:ssm.n_sensor] = 1e-5; sc[iw] = 1e-3; sc[iw+1] = 0.03
Fs = F / sc[:,None] * sc[None,:]; Qs = Q / np.outer(sc, sc); cs = c*sc/1e-9; Rs = R/1e-18
P0s = P0/np.outer(sc, sc); P0s += np.eye(n)*1e-12
# information matrix: x0 ~ N(0,P0); x_{k+1} - F x_k ~ N(0, Q); y_k ~ c x_k + N(0, R)
Qi = np.linalg.inv(Qs + np.eye(n)*1e-14); P0i = np.linalg.inv(P0s)
rows=[]; 
Lam = sp.lil_matrix((n*N, n*N)); eta = np.zeros(n*N)
def add(i, j, M):
    Lam[i*n:(i+1)*n, j*n:(j+1)*n] = Lam[i*n:(i+1)*n, j*n:(j+1)*n].toarray() + M
add(0, 0, P0i)
for k in range(N-1):
    add(k, k, Fs.T@Qi@Fs); add(k+1, k+1, Qi); add(k, k+1, -Fs.T@Qi); add(k+1, k, -Qi@Fs)
for k in range(N):
    add(k, k, np.outer(cs, cs)/Rs); eta[k*n:(k+1)*n] += cs*y[k]/1e-9/Rs
xs = spla.spsolve(Lam.tocsc(), eta)
W = xs.reshape(N, n)[:, iw]*sc[iw]
s = (t>=1.8)&(t<2.2)
X = np.c_[np.sin(2*np.pi*5*t[s]), np.cos(2*np.pi*5*t[s]), np.ones(s.sum())]
cw = np.linalg.lstsq(X, w[s], rcond=None)[0]; ce = np.linalg.lstsq(X, W[s], rcond=None)[0]
print('brute force smoother ratio', np.hypot(*ce[:2])/np.hypot(*cw[:2]))
# KF + RTS on same reduced system (scaled)
x = np.zeros(n); P = P0s.copy()
xp = np.zeros((N,n)); Pp = np.zeros((N,n,n)); xf = np.zeros((N,n)); Pf = np.zeros((N,n,n))
for k in range(N):
    if k: x = Fs@x; P = Fs@P@Fs.T + Qs
    xp[k]=x; Pp[k]=P
    Pc = P@cs; S = cs@Pc + Rs; K = Pc/S
    x = x + K*(y[k]/1e-9 - cs@x); P = P - np.outer(K, Pc)
    xf[k]=x; Pf[k]=P
Wf = xf[:, iw]*sc[iw]
xsm = xf.copy()
for k in range(N-2, -1, -1):
    J = Pf[k]@Fs.T@np.linalg.inv(Pp[k+1])
    xsm[k] = xf[k] + J@(xsm[k+1]-xp[k+1])
Ws = xsm[:, iw]*sc[iw]
for lab, WW in (('kf', Wf), ('rts', Ws)):
    ce = np.linalg.lstsq(X, WW[s], rcond=None)[0]
    print(lab, np.hypot(*ce[:2])/np.hypot(*cw[:2]))
print('cond Pp', np.linalg.cond(Pp[N//2]))

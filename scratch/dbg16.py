import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
import proto
from proto import build
t, w, y, m, noise = record(crank(5.0), 10.0, offset=0e-9, noise=0.2e-9)
ssm = build(m, motion_corner_hz=0.1, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-14, offset_prior_a=1e-12)
F, Q = ssm.discrete(1); c = ssm.c; R = noise**2
x, P = ssm.prior; x = x.copy(); P = P.copy()
idx, Pm = proto.stationary_P(ssm); P[np.ix_(idx, idx)] = Pm
sc = np.sqrt(np.maximum(np.diag(P), 1e-30)); sc[sc < 1e-20] = 1e-12
ys = 1e-9
Fs = F / sc[:,None] * sc[None,:]; Qs = Q / np.outer(sc, sc); cs = c * sc / ys; Rs = R / ys**2
xs = np.zeros_like(x); Ps = P / np.outer(sc, sc)
W = np.empty(t.size)
for k in range(t.size):
    if k: xs = Fs @ xs; Ps = Fs @ Ps @ Fs.T + Qs
    Pc = Ps @ cs; S = cs @ Pc + Rs; K = Pc / S
    xs = xs + K * (y[k]/ys - cs @ xs)
    IKC = np.eye(len(xs)) - np.outer(K, cs)
    Ps = IKC @ Ps @ IKC.T + np.outer(K, K) * Rs
    W[k] = xs[ssm.iw] * sc[ssm.iw]
for a in (1.5, 5, 9.5):
    s = (t >= a) & (t < a+0.4)
    X = np.c_[np.sin(2*np.pi*5*t[s]), np.cos(2*np.pi*5*t[s]), np.ones(s.sum())]
    cw = np.linalg.lstsq(X, w[s], rcond=None)[0]; ce = np.linalg.lstsq(X, W[s], rcond=None)[0]
    print(a, round(np.hypot(*ce[:2])/np.hypot(*cw[:2]),4))

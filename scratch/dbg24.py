import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
import ss5; ss5.enable()
from gen import *
import proto3
from proto import build
t, w, y, m, noise = record(crank_then_hold(3.0, 8.0), 12.0, offset=5e-9, noise=0.2e-9)
ss5.QH[0] = 1e-12
ssm = build(m, motion_corner_hz=1.0, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-13)
import scipy.linalg as la
r = proto3.run(t, y, ssm, R=noise**2, h_prior=10e-6)
for a in (0.1, 0.5, 1, 2, 4, 6, 7.9, 8.1, 8.5, 9, 10, 11.9):
    k = int(a*1000)
    print(a, 'true', round(w[k]*1e6), 'est', round(r['w'][k]*1e6), 'std', round(r['std'][k]*1e6), 'still', r['still'][k])

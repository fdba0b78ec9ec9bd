import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
import ss4; ss4.enable()
from gen import *
import proto2
from proto import build
t, w, y, m, noise = record(step_hold(), 12.0, sample='big', offset=10e-9, noise_frac=0.01)
print('noise', noise)
ss4.QS[0] = 1e-9
ssm = build(m, motion_corner_hz=3.0, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-13)
r = proto2.run(t, y, ssm, R=noise**2, store=False, ws_prior=1e-6, wf_stationary=True)
for a in (0.5, 2, 5, 7.9, 8.2, 8.5, 9, 10, 11.9):
    k = int(a*1000)
    print(a, 'true', round(w[k]*1e6), 'est', round(r['w'][k]*1e6), 'std', round(r['std'][k]*1e6), 'still', r['still'][k])

import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import run, build
for nf in [None, 0.01]:
    if nf is None:
        t, w, y, m, noise = record(crank(5.0), 6.0, offset=0, noise=0.2e-9)
    else:
        t, w, y, m, noise = record(crank(5.0), 6.0, offset=0, noise_frac=nf)
    for fc in (0.2, 2.0):
        ssm = build(m, motion_corner_hz=fc)
        r = run(t, y, ssm, R=noise**2, zupt=False)
        s = t > 2
        print(nf, fc, 'nrmse', nrmse(r['w'], w, t), 'ratio', np.std(r['w'][s])/np.std(w[s]), 'mean err', np.mean(r['w'][s]-w[s]))

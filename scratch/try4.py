import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
import proto
from proto import build
recs = {f: record(crank(f), 8.0, offset=0e-9, noise=0.2e-9) for f in (1.0, 5.0, 20.0)}
for bw in (2.0, 5.0, 20.0, 50.0):
  for fc in (0.1, 1.0):
    out = []
    for f, (t, w, y, m, noise) in recs.items():
        ssm = build(m, motion_corner_hz=fc, motion_bandwidth_hz=bw, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-14)
        r = proto.run(t, y, ssm, R=noise**2)
        out.append(round(100*nrmse(r['w'], w, t, 2.0), 2))
    print('bw', bw, 'fc', fc, 'nrmse % at 1/5/20 Hz', out)

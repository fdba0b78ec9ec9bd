import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import run, build
t, w, y, m, noise = record(crank(5.0), 3.0, offset=5e-9, noise=0.2e-9)
ssm = build(m, motion_corner_hz=1.0, offset_walk_a=1e-12)
r = run(t, y, ssm, R=noise**2)
st = r['still']
print(np.flatnonzero(np.diff(st.astype(int)))[:20])
print('w at 0.9 s', r['w'][900], 'std', r['std'][900])

import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from proto import run, build
t, w, y, m, noise = record(crank(5.0), 6.0, offset=0, noise=0.2e-9)
ssm = build(m, motion_corner_hz=0.2)
r = run(t, y, ssm, R=noise**2, zupt=False)
s = t > 2
print('nrmse', nrmse(r['w'], w, t), 'ratio', np.std(r['w'][s])/np.std(w[s]), 'corr', np.corrcoef(r['w'][s], w[s])[0,1])
print('std', r['std'][::1000])
# check model: reduced H vs true
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
red,_ = reduce_model_parts(m, 4, (0.1, 50.))
f = np.array([1., 5., 20.])
print(np.abs(red.frequency_response(f)), np.abs(m.frequency_response(f)))
# steady-state check: transfer of model c (sI-A)^-1 applied to u -> current; H = s*R
A, Q = ssm.continuous
c = ssm.c
for ff in f:
    s_ = 2j*np.pi*ff
    e = np.zeros(ssm.size); 
    # current per unit w: solve (sI - A) x = B_u * 1 where u = s w
    n = ssm.n_sensor
    xr = np.linalg.solve(s_*np.eye(n) - A[:n,:n], A[:n, ssm.iu]) * s_
    print(ff, abs(c[:n] @ xr + c[ssm.iu]*s_))

import sys, time
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
t, w, y, m, noise = record(crank(5.0), 6.0, offset=5e-9, noise_frac=0.01, hum=0.03)
for est_name in ('kalman', 'leaky'):
    d = DeflectionEstimator(m, 1000.0, estimator=est_name)
    t0 = time.process_time()
    out = [d.process(t[k:k+100], y[k:k+100])[1] for k in range(0, t.size, 100)]
    wb = np.concatenate(out)
    t1 = time.process_time()
    d2 = DeflectionEstimator(m, 1000.0, estimator=est_name)
    w1 = np.array([d2.process_one(t[k], y[k])[1] for k in range(t.size)])
    t2 = time.process_time()
    print(est_name, 'nrmse', nrmse(wb, w, t), 'block==one', np.max(np.abs(wb - w1)), f'{1e6*(t1-t0)/t.size:.1f} us/sample block, {1e6*(t2-t1)/t.size:.1f} one', d.status())
    ts, ws, ss = d.smooth(t, y)
    print(' smooth', nrmse(ws, w, t))

import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from ipmc_sensor_ros.estimation.kalman import KalmanEstimator
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
t, w, y, m, noise = record(crank(5.0), 6.0, offset=5e-9, noise_frac=0.01, hum=0.03)
red, _ = reduce_model_parts(m, 4, (0.1, 50.0))
k = KalmanEstimator(red, 1000.0)
for a in range(0, 6000, 250):
    e = k.estimate(y[a:a+250])
    st = k.status()
    print(a, 'err rms um', round(np.sqrt(np.mean((e.deflection_m - w[a:a+250])**2))*1e6,1), 'mean', round(np.mean(e.deflection_m - w[a:a+250])*1e6,1), 'still', e.still.mean(), 'b nA', round(st['offset_a']*1e9,1), 'line', round(st['mains_line_hz'],3), round(st['mains_line_a']*1e9,1))

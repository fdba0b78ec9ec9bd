import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.statespace import StateSpaceModel
from ipmc_sensor_ros.estimation.filter import KalmanFilter
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
t, w, y, m, noise = record(crank(5.0), 6.0, offset=5e-9, noise_frac=0.01, hum=0.03)
t2, w2, y2, m2, noise2 = record(crank(20.0), 6.0, offset=5e-9, noise_frac=0.01, sample='short')
red, _ = reduce_model_parts(m, 4, (0.1, 50.0))
red2, _ = reduce_model_parts(m2, 4, (0.1, 50.0))
for bw in (20., 30., 50.):
  for lw in (1e-9, 1e-8, 1e-7):
    ssm = StateSpaceModel(red, EstimatorConfig(motion_bandwidth_hz=bw, line_walk_a=lw), 1000.0, 50.0)
    f = KalmanFilter(ssm)
    st, wc, sc, still = f.run(f.initial_state(), y)
    ssm2 = StateSpaceModel(red2, EstimatorConfig(motion_bandwidth_hz=bw, line_walk_a=lw), 1000.0, 0.0)
    f2 = KalmanFilter(ssm2)
    st2, wc2, sc2, still2 = f2.run(f2.initial_state(), y2)
    print('bw', bw, 'lw', lw, 'hum case', round(100*nrmse(wc, w, t, 1.0), 2), 'still', round(still[:1000].mean(), 2), '| crank20', round(100*nrmse(wc2, w2, t2, 1.0), 2))

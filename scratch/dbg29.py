import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.statespace import StateSpaceModel
from ipmc_sensor_ros.estimation.filter import KalmanFilter
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
t, w, y, m, noise = record(crank(5.0), 2.0, offset=5e-9, noise_frac=0.01, hum=0.03)
red, _ = reduce_model_parts(m, 4, (0.1, 50.0))
for lw in (1e-9, 1e-7):
    ssm = StateSpaceModel(red, EstimatorConfig(line_walk_a=lw), 1000.0, 50.0)
    F, Q = ssm.discrete(1)
    print('Q lines diag', np.diag(Q)[ssm.il:], 'F line block', F[ssm.il:ssm.il+2, ssm.il:ssm.il+2])
    f = KalmanFilter(ssm)
    st = f.initial_state()
    st, wc, sc, still = f.run(st, y[:800])
    print('lw', lw, 'sqrt P lines (nA)', np.sqrt(np.diag(st.P)[ssm.il:])*ssm.scale[ssm.il:]*1e9)
    print(' sqrt P all', np.sqrt(np.diag(st.P)))

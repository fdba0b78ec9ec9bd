import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.statespace import StateSpaceModel
from ipmc_sensor_ros.estimation.filter import KalmanFilter
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
kw = dict(a.split('=') for a in sys.argv[1:]); kw = {k: float(v) for k, v in kw.items()}
t, w, y, m, noise = record(crank(5.0), 8.0, offset=5e-9, noise_frac=0.01)
red, _ = reduce_model_parts(m, 4, (0.1, 50.0))
ssm = StateSpaceModel(red, EstimatorConfig(**kw), 1000.0, 0.0)
f = KalmanFilter(ssm)
st = f.initial_state()
s = ssm.scale
for a in range(0, 8000, 500):
    st, wc, sc, still = f.run(st, y[a:a+500])
    print(a, 'b nA', round(st.x[ssm.ib]*s[ssm.ib]*1e9, 2), '+-', round(np.sqrt(st.P[ssm.ib, ssm.ib])*s[ssm.ib]*1e9,3), 'd nA/s', round(st.x[ssm.ib+1]*s[ssm.ib+1]*1e9, 3), 'h um', round(st.x[ssm.ih]*s[ssm.ih]*1e6,1), 'mean err um', round(np.mean(wc - w[a:a+500])*1e6, 1))

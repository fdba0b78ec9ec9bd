import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.statespace import StateSpaceModel
from ipmc_sensor_ros.estimation.filter import KalmanFilter
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
t = np.arange(2000)/1000.
y = 300e-9*np.sin(2*np.pi*50*t + 0.3) + 100e-9*np.random.default_rng(0).standard_normal(t.size) + 5e-9
m = model('slim')
red, _ = reduce_model_parts(m, 4, (0.1, 50.0))
ssm = StateSpaceModel(red, EstimatorConfig(), 1000.0, 50.0)
f = KalmanFilter(ssm)
st = f.initial_state()
s = ssm.scale
for a in range(0, 2000, 100):
    st, wc, sc, still = f.run(st, y[a:a+100])
    amp = [np.hypot(st.x[j]*s[j], st.x[j+1]*s[j+1]) for j in range(ssm.il, ssm.size, 2)]
    print(a, np.round(np.array(amp)*1e9,1), 'w um', round(wc[-1]*1e6,1), 'still', still.mean(), 'sqrtPl nA', round(np.sqrt(st.P[ssm.il, ssm.il])*s[ssm.il]*1e9,1))

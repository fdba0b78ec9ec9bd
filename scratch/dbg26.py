import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.statespace import StateSpaceModel
from ipmc_sensor_ros.estimation.filter import KalmanFilter
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
name = sys.argv[1]
cases = {
 'crank20': lambda: record(crank(20.0), 6.0, offset=5e-9, noise_frac=0.01, sample='short'),
 'crank1': lambda: record(crank(1.0), 10.0, offset=5e-9, noise_frac=0.01),
 'hum': lambda: record(crank(5.0), 10.0, offset=5e-9, noise_frac=0.01, hum=0.03),
}
t, w, y, m, noise = cases[name]()
red, _ = reduce_model_parts(m, 4, (0.1, 50.0))
ssm = StateSpaceModel(red, EstimatorConfig(), 1000.0, 50.0 if name == 'hum' else 0.0)
f = KalmanFilter(ssm)
st, wc, sc, still = f.run(f.initial_state(), y)
e = wc - w
for a in np.arange(0.0, t[-1], 0.5):
    s = (t >= a) & (t < a + 0.5)
    print(f"{a:4.1f} rms err {np.sqrt(np.mean(e[s]**2))*1e6:8.1f}um mean err {np.mean(e[s])*1e6:8.1f} true rms {np.sqrt(np.mean(w[s]**2))*1e6:7.1f} still {still[s].mean():.2f}")

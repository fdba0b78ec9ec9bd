import sys
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.statespace import StateSpaceModel
from ipmc_sensor_ros.estimation.filter import KalmanFilter
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
for hum in (0.0, 0.03):
    t, w, y, m, noise = record(crank(5.0), 4.0, offset=5e-9, noise_frac=0.01, hum=hum)
    red, _ = reduce_model_parts(m, 4, (0.1, 50.0))
    ssm = StateSpaceModel(red, EstimatorConfig(), 1000.0, 50.0)
    f = KalmanFilter(ssm)
    st = f.initial_state()
    for a in range(0, 4000, 500):
        st, wc, sc, still = f.run(st, y[a:a+500])
        s = ssm.scale
        amp = [np.hypot(st.x[j]*s[j], st.x[j+1]*s[j+1]) for j in range(ssm.il, ssm.size, 2)]
        print(hum, a, 'lines nA', np.round(np.array(amp)*1e9, 1), 'rms err um', round(np.sqrt(np.mean((wc-w[a:a+500])**2))*1e6,1), 'still', still.mean(), 'noise', np.sqrt(st.noise_var_a2))
    print('true hum amp nA', hum*np.sqrt(np.mean((y-5e-9)**2))*1e9)

import sys
import numpy as np
from bench.scenarios import build
from ipmc_sensor_ros.estimation.kalman import KalmanEstimator
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry
r = build(sys.argv[1], int(sys.argv[2]))
kw = dict((a.split('=')[0], float(a.split('=')[1])) for a in sys.argv[5:])
model = SensorModel.named(r.model, Geometry(*r.geometry_m, r.sample), extra_effects=r.effects)
red = reduce_model_parts(model, 4, (0.1, 50.0))[0]
k = KalmanEstimator(red, r.sample_rate_hz, EstimatorConfig(**kw))
print('offset', r.offset_a[0], r.offset_a[-1], 'noise', r.noise_std_a, 'mains', r.mains_hz)
step = int(sys.argv[3]); stop = int(sys.argv[4])
t = r.time_s
steps = np.ones(t.size, dtype=np.int64); steps[1:] = np.maximum(1, np.rint(np.diff(t)*r.sample_rate_hz))
for a in range(0, min(stop, t.size), step):
    e = k.estimate(r.current_a[a:a+step], steps[a:a+step]); st = k._state; m = k.model; s = m.scale
    w = r.deflection_m[a:a+step]
    print(f"{r.sample_time_s[a]:7.2f} still {e.still.mean():.2f} b {st.x[m.ib]*s[m.ib]*1e9:7.2f}+-{np.sqrt(st.P[m.ib,m.ib])*s[m.ib]*1e9:6.2f} true {r.offset_a[a]*1e9:6.2f} h {st.x[m.ih]*s[m.ih]*1e6:7.0f}+-{np.sqrt(st.P[m.ih,m.ih])*s[m.ih]*1e6:5.0f} err mean {np.mean(e.deflection_m-w)*1e6:7.1f} rms {np.sqrt(np.mean((e.deflection_m-w)**2))*1e6:7.1f} w {np.mean(w)*1e6:7.0f} std {np.mean(e.std_m)*1e6:6.1f} lines {m.fundamentals_hz}")

import sys
import numpy as np
from bench.scenarios import build
name = sys.argv[1]; seed = int(sys.argv[2]) if len(sys.argv) > 2 else 0
r = build(name, seed)
print({k: v for k, v in vars(r).items() if not isinstance(v, np.ndarray)})
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry
model = SensorModel.named(r.model, Geometry(*r.geometry_m, r.sample), extra_effects=r.effects)
est = DeflectionEstimator(model, r.sample_rate_hz)
t = r.time_s; i = r.current_a; w = r.deflection_m
print('dt stats', np.min(np.diff(t)), np.median(np.diff(t)), np.max(np.diff(t)), 't0', t[0])
steps = np.ones(t.size, dtype=np.int64); steps[1:] = np.maximum(1, np.rint(np.diff(t)*r.sample_rate_hz))
out = est.core.estimate(i, steps)
e = out.deflection_m - w
ts = r.sample_time_s
for a in np.arange(0, ts[-1], max(0.5, ts[-1]/20)):
    s = (ts >= a) & (ts < a + max(0.5, ts[-1]/20))
    print(f"{a:6.1f} rms err {np.sqrt(np.mean(e[s]**2))*1e6:8.1f}um mean {np.mean(e[s])*1e6:8.1f} true rms {np.sqrt(np.mean(w[s]**2))*1e6:7.1f} still {out.still[s].mean():.2f} std {np.mean(out.std_m[s])*1e6:.0f}")
print(est.core.status())

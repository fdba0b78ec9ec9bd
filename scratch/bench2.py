import sys
import numpy as np
from bench.scenarios import build
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.kalman import KalmanEstimator
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry
names = sys.argv[1].split(',')
seeds = [int(s) for s in sys.argv[2].split(',')]
grid = [dict((kv.split('=')[0], float(kv.split('=')[1])) for kv in a.split(',')) if a else {} for a in sys.argv[3:]] or [{}]
cache = {}
for g in grid:
    out = []
    for name in names:
        errs = []
        for seed in seeds:
            r = build(name, seed)
            key = (r.model, r.geometry_m, r.effects)
            if key not in cache:
                model = SensorModel.named(r.model, Geometry(*r.geometry_m, r.sample), extra_effects=r.effects)
                cache[key] = reduce_model_parts(model, 4, (0.1, 50.0))[0]
            t = r.time_s
            steps = np.ones(t.size, dtype=np.int64); steps[1:] = np.maximum(1, np.rint(np.diff(t)*r.sample_rate_hz))
            k = KalmanEstimator(cache[key], r.sample_rate_hz, EstimatorConfig(**g))
            e = k.estimate(r.current_a, steps)
            s = r.sample_time_s >= 1.0
            errs.append(100*np.sqrt(np.mean((e.deflection_m[s]-r.deflection_m[s])**2))/np.sqrt(np.mean(r.deflection_m[s]**2)))
        out.append(f"{name}:{np.mean(errs):.2f}/{np.max(errs):.2f}")
    print(g, ' '.join(out), flush=True)

import sys, json
import numpy as np
from bench.scenarios import build
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.kalman import KalmanEstimator
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry
bounds = {(r['scenario'], r['seed']): r['causal_bound'] for r in json.load(open('/tmp/bench_before_kalman_seeds0-2.json'))['rows']}
names = sys.argv[1].split(',')
seed = int(sys.argv[2])
grid = [dict((kv.split('=')[0], float(kv.split('=')[1])) for kv in a.split(',')) if a else {} for a in sys.argv[3:]] or [{}]
cache = {}
print('scenario | bound | ' + ' | '.join(str(g) for g in grid))
for name in names:
    r = build(name, seed)
    key = (r.model, r.geometry_m, r.effects)
    if key not in cache:
        model = SensorModel.named(r.model, Geometry(*r.geometry_m, r.sample), extra_effects=r.effects)
        cache[key] = reduce_model_parts(model, 4, (0.1, 50.0))[0]
    t = r.time_s
    dt = np.diff(t)
    steps = np.ones(t.size, dtype=np.int64); steps[1:] = np.maximum(1, np.rint(dt*r.sample_rate_hz))
    row = []
    for g in grid:
        k = KalmanEstimator(cache[key], r.sample_rate_hz, EstimatorConfig(**g))
        e = k.estimate(r.current_a, steps)
        s = r.sample_time_s >= 1.0
        row.append(100*np.sqrt(np.mean((e.deflection_m[s]-r.deflection_m[s])**2))/np.sqrt(np.mean(r.deflection_m[s]**2)))
    b = 100*bounds.get((name, seed), float('nan'))
    tgt = max(2*b, 1.0)
    print(f"{name} | {b:.3f} | " + ' | '.join(f"{v:.2f}{'*' if v <= tgt else ''}" for v in row), flush=True)

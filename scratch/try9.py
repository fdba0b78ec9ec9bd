import sys, time
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.kalman import KalmanEstimator
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
cases = {
 'crank5_rest_off5': lambda: record(crank(5.0), 10.0, offset=5e-9, noise=0.2e-9),
 'crank1_rest_off5': lambda: record(crank(1.0), 10.0, offset=5e-9, noise_frac=0.01),
 'crank20_rest_off5': lambda: record(crank(20.0), 10.0, offset=5e-9, noise_frac=0.01, sample='short'),
 'crank5_pon_off20': lambda: record(crank(5.0, since_power_on=True), 10.0, offset=20e-9, noise_frac=0.01),
 'crank1_pon_off20': lambda: record(crank(1.0, since_power_on=True), 10.0, offset=20e-9, noise_frac=0.01),
 'crank_hold_off5': lambda: record(crank_then_hold(3.0, 8.0), 12.0, offset=5e-9, noise=0.2e-9),
 'step_hold_off': lambda: record(step_hold(), 12.0, sample='big', offset=10e-9, noise_frac=0.01),
 'crank5_hum50': lambda: record(crank(5.0), 10.0, offset=5e-9, noise_frac=0.01, hum=0.03),
}
recs = {k: v() for k, v in cases.items()}
args = sys.argv[1:]
grid = [dict(tuple(kv.split('=')) for kv in a.split(',')) for a in args] or [{}]
for g in grid:
    kw = {k: float(v) for k, v in g.items()}
    out = []
    for name, (t, w, y, m, noise) in recs.items():
        red, _ = reduce_model_parts(m, 4, (0.1, 50.0))
        k = KalmanEstimator(red, 1000.0, EstimatorConfig(**kw))
        e = k.estimate(y)
        out.append(f'{name.split("_")[0]}{"P" if "pon" in name else ""}{"H" if "hum" in name else ""}:{100*nrmse(e.deflection_m, w, t):.2f}')
    print(kw, ' '.join(out), flush=True)

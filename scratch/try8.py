import sys, time
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.statespace import StateSpaceModel
from ipmc_sensor_ros.estimation.filter import KalmanFilter
from ipmc_sensor_ros.estimation.smoother import smooth
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
args = sys.argv[1:]
kw = dict(a.split('=') for a in args if '=' in a)
kw = {k: float(v) for k, v in kw.items()}
only = [a for a in args if '=' not in a]
for name, mk in cases.items():
    if only and name not in only: continue
    t, w, y, m, noise = mk()
    red, _ = reduce_model_parts(m, 4, (0.1, 50.0))
    line = kw.pop('line_hz', 0.0) if False else (50.0 if 'hum' in name else 0.0)
    ssm = StateSpaceModel(red, EstimatorConfig(**kw), 1000.0, line)
    f = KalmanFilter(ssm)
    t0 = time.process_time()
    st, wc, sc, still = f.run(f.initial_state(), y)
    t1 = time.process_time()
    ws, ss, _ = smooth(f, f.initial_state(), y)
    t2 = time.process_time()
    s = t >= 1
    cov = np.mean(np.abs(wc[s]-w[s]) <= 2*sc[s]); covs = np.mean(np.abs(ws[s]-w[s]) <= 2*ss[s])
    print(f"{name:18s} causal {100*nrmse(wc, w, t):6.2f}% smooth {100*nrmse(ws, w, t):6.2f}% cov {cov:.2f}/{covs:.2f} still {still.mean():.2f} std {np.median(sc)*1e6:.0f}um  noise {np.sqrt(st.noise_var_a2):.3g}/{noise:.3g}  {1e6*(t1-t0)/y.size:.1f}us/s fwd, {1e6*(t2-t1)/y.size:.1f} smooth", flush=True)

import sys, time
import numpy as np
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
import proto
from proto import build
orig_prior = proto.build
cases = {
 'crank5_rest_off5': lambda: record(crank(5.0), 10.0, offset=5e-9, noise=0.2e-9),
 'crank1_rest_off5': lambda: record(crank(1.0), 10.0, offset=5e-9, noise_frac=0.01),
 'crank5_pon_off20': lambda: record(crank(5.0, since_power_on=True), 10.0, offset=20e-9, noise_frac=0.01),
}
import ipmc_sensor_ros.estimation.statespace as ss
for dprior in (600.0, 1e9):
    def prior(self, dprior=dprior):
        cfg = self.config
        P0 = np.zeros((self.size, self.size))
        P0[self.ib, self.ib] = cfg.offset_prior_a ** 2
        P0[self.ib + 1, self.ib + 1] = (cfg.offset_prior_a / dprior) ** 2
        return np.zeros(self.size), P0
    for name, mk in cases.items():
        t, w, y, m, noise = mk()
        for fc in (0.1, 1.0):
            ssm = build(m, motion_corner_hz=fc, offset_walk_a=1e-12, offset_drift_walk_a_per_s=1e-14)
            ssm.__dict__['prior'] = prior(ssm)
            r = proto.run(t, y, ssm, R=noise**2, store=True)
            s = t >= 2
            ratio = np.std(r['w'][s])/np.std(w[s]); lvl = np.mean(r['w'][s]-w[s])
            print(f"d/{dprior:g} {name:18s} fc {fc} causal {100*nrmse(r['w'], w, t):6.2f}% smooth {100*nrmse(r['ws'], w, t):6.2f}% ratio {ratio:.3f} level {lvl*1e6:.1f}um")

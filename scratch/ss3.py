"""Third-order motion prior variant for experiments: patch StateSpaceModel.continuous."""
import math
import numpy as np
import ipmc_sensor_ros.estimation.statespace as ss

def enable(order3=True):
    if not order3:
        return
    # insert acceleration state after u: indices n: w, n+1: u, n+2: acc, n+3: b, n+4: d, lines...
    ss.StateSpaceModel.ib = property(lambda self: self.n_sensor + 3)
    ss.StateSpaceModel.il = property(lambda self: self.n_sensor + 5)
    ss.StateSpaceModel.size = property(lambda self: self.n_sensor + 5 + 2 * len(self.line_hz_all))
    def continuous(self):
        cfg = self.config
        ar, br, _, _ = self._sensor
        n, nx = self.n_sensor, self.size
        a = 2 * math.pi * cfg.motion_bandwidth_hz
        f = 2 * math.pi * cfg.motion_corner_hz
        iw, iu, ia = n, n + 1, n + 2
        A = np.zeros((nx, nx)); Q = np.zeros((nx, nx))
        A[:n, :n] = ar; A[:n, iu] = br
        A[iw, iu] = 1.0; A[iu, ia] = 1.0
        # (s+f)(s+a)^2 = s^3 + (2a+f) s^2 + (a^2+2af) s + a^2 f
        A[ia, iw] = -a*a*f; A[ia, iu] = -(a*a + 2*a*f); A[ia, ia] = -(2*a + f)
        # variance of w for white q through 1/((s+f)(s+a)^2): q * I, I = 1/(4 f a^3) * (a+... ) -> compute numerically
        Q[ia, ia] = 1.0
        import scipy.linalg as la
        sub = [iw, iu, ia]
        Ps = la.solve_continuous_lyapunov(A[np.ix_(sub, sub)], -Q[np.ix_(sub, sub)])
        Q[ia, ia] = cfg.motion_rms_m**2 / Ps[0, 0]
        A[self.ib, self.ib + 1] = 1.0
        Q[self.ib, self.ib] = cfg.offset_walk_a ** 2
        Q[self.ib + 1, self.ib + 1] = cfg.offset_drift_walk_a_per_s ** 2
        for k, fl in enumerate(self.line_hz_all):
            j = self.il + 2 * k; wk = 2 * math.pi * fl
            A[j, j + 1], A[j + 1, j] = -wk, wk
            Q[j, j] = Q[j + 1, j + 1] = cfg.line_walk_a ** 2
        return A, Q
    ss.StateSpaceModel.continuous = property(continuous)
    ss.StateSpaceModel.motion_state = property(lambda self: np.r_[np.arange(self.n_sensor), self.iu, self.iu + 1])

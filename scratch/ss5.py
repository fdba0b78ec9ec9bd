"""Anchor model: u' = -a f (w - h) - (a+f) u + xi_u; h' = xi_h (working point)."""
import math
import numpy as np
import ipmc_sensor_ros.estimation.statespace as ss

QH = [1e-12]

def enable():
    ss.StateSpaceModel.ih = property(lambda self: self.n_sensor + 2)
    ss.StateSpaceModel.ib = property(lambda self: self.n_sensor + 3)
    ss.StateSpaceModel.il = property(lambda self: self.n_sensor + 5)
    ss.StateSpaceModel.size = property(lambda self: self.n_sensor + 5 + 2 * len(self.line_hz_all))
    def continuous(self):
        cfg = self.config
        ar, br, _, _ = self._sensor
        n, nx = self.n_sensor, self.size
        a = 2 * math.pi * cfg.motion_bandwidth_hz
        f = 2 * math.pi * cfg.motion_corner_hz
        iw, iu, ih = n, n + 1, n + 2
        A = np.zeros((nx, nx)); Q = np.zeros((nx, nx))
        A[:n, :n] = ar; A[:n, iu] = br
        A[iw, iu] = 1.0
        A[iu, iw] = -a * f; A[iu, ih] = a * f; A[iu, iu] = -(a + f)
        Q[iu, iu] = 2 * a * f * (a + f) * cfg.motion_rms_m ** 2
        Q[ih, ih] = QH[0]
        A[self.ib, self.ib + 1] = 1.0
        Q[self.ib, self.ib] = cfg.offset_walk_a ** 2
        Q[self.ib + 1, self.ib + 1] = cfg.offset_drift_walk_a_per_s ** 2
        for k, fl in enumerate(self.line_hz_all):
            j = self.il + 2 * k; wk = 2 * math.pi * fl
            A[j, j + 1], A[j + 1, j] = -wk, wk
            Q[j, j] = Q[j + 1, j + 1] = cfg.line_walk_a ** 2
        return A, Q
    ss.StateSpaceModel.continuous = property(continuous)

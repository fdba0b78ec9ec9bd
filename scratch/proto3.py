import math
QHR = [1e-6]
import numpy as np
import scipy.linalg as la
from scipy.stats import chi2

def run(t, y, ssm, R, zupt=True, store=False, h_prior=10e-6):
    cfg = ssm.config
    F, Q = ssm.discrete(1)
    c = ssm.c.copy(); n_s = ssm.n_sensor
    iw, iu, ih, ib = ssm.iw, ssm.iu, ssm.ih, ssm.ib
    cz = np.zeros(ssm.size); cz[iu] = 1.0; rz = ssm.r_rest
    cm = c.copy(); cm[ib:] = 0.0; cm[ih] = 0.0
    r0 = abs(float(np.real(ssm.reduced.charge_response(np.array([0.0]))[0])))
    rm = (r0 * cfg.rest_velocity_m_s) ** 2
    ch = np.zeros(ssm.size); ch[iw] = 1.0; ch[ih] = -1.0; rh = (1e-7) ** 2
    P = np.zeros((ssm.size, ssm.size))
    mi = np.r_[np.arange(n_s), iw, iu]
    P[np.ix_(mi, mi)] = la.solve_discrete_lyapunov(F[np.ix_(mi, mi)], Q[np.ix_(mi, mi)])
    P[ih, ih] = h_prior ** 2
    P[iw, iw] += h_prior ** 2; P[iw, ih] = P[ih, iw] = h_prior ** 2
    x0, P0 = ssm.prior
    P[ib:, ib:] = P0[ib:, ib:]
    x = np.zeros(ssm.size)
    N = int(cfg.rest_window_s * ssm.sample_rate_hz)
    th_e = chi2.ppf(1 - cfg.rest_false_alarm, N - 1)
    th_m = chi2.ppf(1 - cfg.rest_false_alarm, 1)
    buf = np.zeros(N); nb = 0
    still = False
    lines = np.arange(ssm.il, ssm.size, 2)
    n = y.size
    out_w = np.empty(n); out_s = np.empty(n); out_still = np.zeros(n, bool)
    if store:
        xs_p = np.empty((n, x.size)); Ps_p = np.empty((n, x.size, x.size))
        xs_f = np.empty((n, x.size)); Ps_f = np.empty((n, x.size, x.size))
    for k in range(n):
        if k:
            x = F @ x; P = F @ P @ F.T + Q
        if store:
            xs_p[k] = x; Ps_p[k] = P
        r = y[k] - x[lines].sum()
        buf[k % N] = r; nb = min(nb + 1, N)
        if zupt and nb == N:
            m = buf.mean(); e = ((buf - m)**2).sum() / R
            dc = (m - x[ib])**2 / (R/N + P[ib, ib])
            still = (e < th_e) and (dc < th_m)
        Pc = P @ c; S = c @ Pc + R; K = Pc / S
        x = x + K * (y[k] - c @ x); P = P - np.outer(K, Pc)
        if still:
            for cc, rr in ((cz, rz), (cm, rm)):
                Pc = P @ cc; S = cc @ Pc + rr; K = Pc / S
                x = x - K * (cc @ x); P = P - np.outer(K, Pc)
            x[ih] = x[iw]; P[ih, :] = P[iw, :]; P[:, ih] = P[:, iw]
        P = 0.5 * (P + P.T)
        if store:
            xs_f[k] = x; Ps_f[k] = P
        out_w[k] = x[iw]; out_s[k] = math.sqrt(max(P[iw, iw], 0)); out_still[k] = still
    res = dict(w=out_w, std=out_s, still=out_still)
    if store:
        xsm = xs_f.copy(); Psm = Ps_f[-1].copy(); sw = np.empty(n); sw[-1] = Psm[iw, iw]
        for k in range(n - 2, -1, -1):
            J = np.linalg.lstsq(Ps_p[k+1], F @ Ps_f[k], rcond=1e-14)[0].T
            xsm[k] = xs_f[k] + J @ (xsm[k+1] - xs_p[k+1])
            Psm = Ps_f[k] + J @ (Psm - Ps_p[k+1]) @ J.T
            sw[k] = Psm[iw, iw]
        res['ws'] = xsm[:, iw]; res['stds'] = np.sqrt(np.maximum(sw, 0))
    return res

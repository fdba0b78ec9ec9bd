import math
import numpy as np
import scipy.linalg as la
from scipy.stats import chi2

def run(t, y, ssm, R, zupt=True, store=False, ws_prior=1e-3, wf_stationary=False):
    cfg = ssm.config
    F, Q = ssm.discrete(1)
    c = ssm.c.copy(); cz = ssm.c_rest
    rz = ssm.r_rest
    cm = c.copy(); cm[ssm.ib:] = 0.0
    r0 = abs(float(np.real(ssm.reduced.charge_response(np.array([0.0]))[0])))
    rm = (r0 * cfg.rest_velocity_m_s) ** 2
    iws = ssm.iws; iw = ssm.iw; ib = ssm.ib
    ow = np.zeros(ssm.size); ow[iw] = 1; ow[iws] = 1
    # P0: steady state of the detectable part (drop w_s), w_s prior
    det = np.array([i for i in range(ssm.size) if i != iws])
    Fd = F[np.ix_(det, det)]; Qd = Q[np.ix_(det, det)]; cd = c[det]
    Pss = la.solve_discrete_are(Fd.T, cd[:, None], Qd, np.array([[R]]))
    P = np.zeros((ssm.size, ssm.size)); P[np.ix_(det, det)] = Pss
    P[iws, iws] = ws_prior ** 2
    if wf_stationary:
        mi = np.r_[np.arange(ssm.n_sensor), iw, iw + 1]
        Pm = la.solve_discrete_lyapunov(F[np.ix_(mi, mi)], Q[np.ix_(mi, mi)])
        P[np.ix_(mi, mi)] = Pm
    x0, P0 = ssm.prior
    P[ib:, ib:] = P0[ib:, ib:]
    P[ib:, :ib] = 0; P[:ib, ib:] = 0
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
        if store:
            xs_f[k] = x; Ps_f[k] = P
        out_w[k] = ow @ x; out_s[k] = math.sqrt(max(ow @ P @ ow, 0)); out_still[k] = still
    res = dict(w=out_w, std=out_s, still=out_still)
    if store:
        xsm = xs_f.copy(); Psm = Ps_f[-1].copy(); sw = np.empty(n); sw[-1] = ow@Psm@ow
        for k in range(n - 2, -1, -1):
            J = np.linalg.solve(Ps_p[k+1].T, (Ps_f[k] @ F.T).T).T
            xsm[k] = xs_f[k] + J @ (xsm[k+1] - xs_p[k+1])
            Psm = Ps_f[k] + J @ (Psm - Ps_p[k+1]) @ J.T
            sw[k] = ow@Psm@ow
        res['ws'] = xsm @ ow; res['stds'] = np.sqrt(np.maximum(sw, 0))
    return res

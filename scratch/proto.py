import math, time
import numpy as np
from scipy.stats import chi2
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.statespace import StateSpaceModel
from ipmc_sensor_ros.lti.reduction import reduce_model_parts

def stationary_P(ssm):
    import scipy.linalg as la
    F, Q = ssm.discrete(1)
    mi = ssm.motion_state
    idx = np.r_[mi, ssm.iw]
    idx = np.unique(idx)
    Fm = F[np.ix_(idx, idx)]; Qm = Q[np.ix_(idx, idx)]
    Pm = la.solve_discrete_lyapunov(Fm, Qm)
    return idx, Pm

def run(t, y, ssm, R, zupt=True, store=False, p0='dare'):
    cfg = ssm.config
    F, Q = ssm.discrete(1)
    c = ssm.c; cz = ssm.c_rest; rz = ssm.r_rest
    cm = c.copy(); cm[ssm.ib:] = 0.0
    r0 = abs(float(np.real(ssm.reduced.charge_response(np.array([0.0]))[0])))
    rm = (r0 * cfg.rest_velocity_m_s) ** 2
    x, P = ssm.prior
    x = x.copy(); P = P.copy()
    import scipy.linalg as la
    Pss = la.solve_discrete_are(F.T, ssm.c[:, None], Q, np.array([[R]]))
    m_idx = np.r_[np.arange(ssm.n_sensor), ssm.iw, ssm.iu]
    if p0 == 'dare':
        P[np.ix_(m_idx, m_idx)] = Pss[np.ix_(m_idx, m_idx)]
    else:
        P[np.ix_(m_idx, m_idx)] = la.solve_discrete_lyapunov(F[np.ix_(m_idx, m_idx)], Q[np.ix_(m_idx, m_idx)])
    N = int(cfg.rest_window_s * ssm.sample_rate_hz)
    th_e = chi2.ppf(1 - cfg.rest_false_alarm, N - 1)
    th_m = chi2.ppf(1 - cfg.rest_false_alarm, 1)
    buf = np.zeros(N); nb = 0
    still = False
    out_w = np.empty(y.size); out_s = np.empty(y.size); out_still = np.zeros(y.size, bool)
    ib = ssm.ib; iw = ssm.iw
    lines = np.arange(ssm.il, ssm.size, 2)
    if store:
        xs_p = np.empty((y.size, x.size)); Ps_p = np.empty((y.size, x.size, x.size))
        xs_f = np.empty((y.size, x.size)); Ps_f = np.empty((y.size, x.size, x.size))
    for k in range(y.size):
        if k:
            x = F @ x; P = F @ P @ F.T + Q
        if store:
            xs_p[k] = x; Ps_p[k] = P
        # rest test on residual vs offset+lines (predicted)
        r = y[k] - x[lines].sum()
        buf[k % N] = r; nb = min(nb + 1, N)
        if zupt and nb == N:
            m = buf.mean(); e = ((buf - m)**2).sum() / R
            pb = P[ib, ib]
            dc = (m - x[ib])**2 / (R/N + pb)
            now_still = (e < th_e) and (dc < th_m)
            still = now_still
        # update current
        Pc = P @ c; S = c @ Pc + R; K = Pc / S
        x = x + K * (y[k] - c @ x); P = P - np.outer(K, Pc)
        if still:
            for cc, rr in ((cz, rz), (cm, rm)):
                Pc = P @ cc; S = cc @ Pc + rr; K = Pc / S
                x = x + K * (0 - cc @ x); P = P - np.outer(K, Pc)
        if store:
            xs_f[k] = x; Ps_f[k] = P
        out_w[k] = x[iw]; out_s[k] = math.sqrt(max(P[iw, iw], 0)); out_still[k] = still
    res = dict(w=out_w, std=out_s, still=out_still)
    if store:
        xsm = xs_f.copy(); Psm_w = np.empty(y.size)
        Psm = Ps_f[-1].copy(); Psm_w[-1] = Psm[iw, iw]
        for k in range(y.size - 2, -1, -1):
            J = Ps_f[k] @ F.T @ np.linalg.inv(Ps_p[k+1])
            xsm[k] = xs_f[k] + J @ (xsm[k+1] - xs_p[k+1])
            Psm = Ps_f[k] + J @ (Psm - Ps_p[k+1]) @ J.T
            Psm_w[k] = Psm[iw, iw]
        res['ws'] = xsm[:, iw]; res['stds'] = np.sqrt(np.maximum(Psm_w, 0))
    return res

def build(m, fs=1000.0, line_hz=0.0, **cfg):
    red, _ = reduce_model_parts(m, 4, (0.1, 50.0))
    return StateSpaceModel(red, EstimatorConfig(**cfg), fs, line_hz)

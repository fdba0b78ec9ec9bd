"""Scratch records for development (package simulator; the bench uses an independent one)."""
import numpy as np
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
from ipmc_sensor_ros.simulation.sensor import lti_response_fft
from ipmc_sensor_ros.simulation.stimuli import CrankSlider

FS = 1000.0

def model(sample='slim', effects=()):
    return SensorModel.named('h2', PAPER_SAMPLES[sample], extra_effects=effects)

def record(w_fn, T, sample='slim', pre=5.0, offset=0.0, noise=0.2e-9, noise_frac=None, hum=0.0,
           hum_hz=50.0, seed=0, effects=()):
    rng = np.random.default_rng(seed)
    m = model(sample, effects)
    t_all = np.arange(-int(pre*FS), int(T*FS)) / FS
    w_all = w_fn(t_all)
    i_all = lti_response_fft(m.transfer, t_all, w_all, pad_s=2.0)
    sel = t_all >= 0
    t, w, i = t_all[sel], w_all[sel], i_all[sel]
    if noise_frac is not None:
        noise = noise_frac * np.sqrt(np.mean(i**2))
    y = i + offset + noise * rng.standard_normal(t.size)
    if hum:
        A = hum * np.sqrt(np.mean(i**2))
        ph = rng.uniform(0, 2*np.pi, 3)
        y += A*np.sin(2*np.pi*hum_hz*t+ph[0]) + 0.3*A*np.sin(2*np.pi*3*hum_hz*t+ph[1])
    return t, w, y, m, noise

def crank(f, since_power_on=False, start=1.0, r=2e-3):
    c = CrankSlider(motor_frequency_hz=f, crank_radius_m=r, phase_rad=0.3)
    def fn(t):
        w = c.deflection(t)
        if since_power_on:
            return w
        # from rest: crank starts at `start` (phase such that w continuous: ramp amplitude)
        ramp = np.clip((t - start) / 0.5, 0, 1)
        ramp = ramp*ramp*(3-2*ramp)
        return w * ramp
    return fn

def step_hold(level=-0.95e-3, t_move=8.0, dur=0.4):
    def fn(t):
        u = np.clip((t - t_move)/dur, 0, 1)
        return level * u*u*(3-2*u)
    return fn

def crank_then_hold(f=3.0, move_s=8.0):
    c = CrankSlider(motor_frequency_hz=f, crank_radius_m=1e-3, phase_rad=0.0)
    def fn(t):
        # moves from t=0 (power-on since 0: ramp in over 0.3 s), stops at move_s holding where it is
        tt = np.minimum(t, move_s)
        ramp = np.clip(t/0.3, 0, 1); ramp = ramp*ramp*(3-2*ramp)
        return c.deflection(tt) * ramp
    return fn

def nrmse(what, w, t, after=1.0):
    s = t >= after
    return float(np.sqrt(np.mean((what[s]-w[s])**2))/np.sqrt(np.mean(w[s]**2)))

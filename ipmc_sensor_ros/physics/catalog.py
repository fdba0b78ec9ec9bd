# SPDX-License-Identifier: Apache-2.0
"""The built-in effect catalog (see :mod:`ipmc_sensor_ros.physics.effects`)."""
from __future__ import annotations

import math

import numpy as np

from .effects import Effect, EffectParameter, register_effect
from .parameters import ParameterError
from .sensing import h1, surface_resistance_factor

__all__ = [
    'SurfaceResistance',
    'AmplifierBandwidth',
    'TimeDelay',
    'CurrentOffset',
    'HydrationDrift',
    'EffectiveLength',
    'BeamInertia',
    'Nonlinearity',
    'clamped_pinned_slope_ratio',
    'diffusivity_ratio_function',
]


@register_effect
class SurfaceResistance(Effect):
    name = 'surface_resistance'
    summary = "Distributed resistance of the surface electrodes (the paper's H2)."
    physics = (
        'The platinum electrodes have a resistance r0 per unit length and width; the current '
        'generated along the beam flows through an RC line to the clamp (paper Fig. 2, '
        'eqs. 32-43).'
    )
    equation = (
        'H2 = H1 * 2 G(a), G(a) = (1 - cosh a + a sinh a)/(a^2 cosh a), a = L sqrt(s kappa_e '
        "r0 / h) (eqs. 42, 45, 46).  Uses the material's r0; no parameter of its own."
    )
    signature = (
        'Extra phase lag and flatter magnitude slope at high frequency that grow with L^2 '
        '(slim 14.9 vs short 17.3 dB/decade over 1-20 Hz); H1 predicts equal slopes for '
        'samples that differ only in length.'
    )
    reference = 'Chen et al. 2007, section 3.2; Punning et al. 2007 (ref. [30] there).'

    def factor(self, s, model, values):
        return surface_resistance_factor(s, model.material, model.geometry)


@register_effect
class AmplifierBandwidth(Effect):
    name = 'amplifier_bandwidth'
    summary = 'Finite bandwidth of the current amplifier / anti-alias filter of the DAQ.'
    physics = ("A transimpedance amplifier with feedback R_f C_f, or the DAQ's anti-alias filter, "
               'low-pass filters the measured current.')
    equation = 'H -> H / (1 + s / (2 pi f_a))'
    parameters = (EffectParameter('corner_hz', 'Hz', 200.0, 0.5, 1e5, (20.0, 20000.0),
                                  '-3 dB corner frequency f_a of the first-order low-pass'),)
    signature = (
        'Phase lag growing linearly with frequency (about f/f_a rad) and, near f_a, a '
        'magnitude droop; errors concentrated at the top of the band, equal for all samples.'
    )
    reference = ('Any transimpedance-amplifier text, e.g. Horowitz & Hill, '
                 'The Art of Electronics, 3rd ed., 4.3.')

    def factor(self, s, model, values):
        return 1.0 / (1.0 + s / (2 * math.pi * values['corner_hz']))

    def rational(self, model, values):
        wa = 2 * math.pi * values['corner_hz']
        return np.array([]), np.array([-wa]), wa


@register_effect
class TimeDelay(Effect):
    name = 'time_delay'
    summary = 'Skew between the deflection and current channels (sampling, filters, cabling).'
    physics = ('Non-simultaneous sampling of two channels or a digital filter in one of them '
               'delays the current relative to the deflection.')
    equation = 'H -> H exp(-s tau)'
    scope = 'recording'
    parameters = (EffectParameter('delay_s', 's', 1e-3, 1e-6, 0.1, (1e-5, 5e-3),
                                  'delay tau of the current relative to the deflection'),)
    signature = (
        'Phase error exactly proportional to frequency (-360 f tau degrees), no magnitude '
        'error; the residual cross-correlates with the input velocity at a lag of tau.'
    )
    reference = (
        'Pintelon & Schoukens, System Identification: A Frequency Domain Approach, 2nd ed., ch. 2.'
    )

    def factor(self, s, model, values):
        return np.exp(-s * values['delay_s'])

    def delay_s(self, values):
        return float(values['delay_s'])


@register_effect
class CurrentOffset(Effect):
    name = 'current_offset'
    summary = 'Offset and slow linear drift of the measured current.'
    physics = (
        'Amplifier input offset/bias currents, electrode potentials and thermal drift add a '
        'slowly varying current unrelated to deformation.'
    )
    equation = 'i_meas(t) = i(t) + i_0 + i_1 (t - t_start)'
    lti = False
    scope = 'recording'
    parameters = (
        EffectParameter(
            'offset_a', 'A', 0.0, -1e-3, 1e-3, (-1e-6, 1e-6), 'constant offset i_0', False
        ),
        EffectParameter(
            'drift_a_per_s', 'A/s', 0.0, -1e-5, 1e-5, (-1e-8, 1e-8), 'linear drift i_1', False
        ),
    )
    signature = (
        'Residual with a non-zero mean or a ramp: low-frequency content the deflection does '
        'not explain; invisible at the excitation fundamental; the estimated deflection '
        'drifts (leaky integrator).'
    )
    reference = 'Chen et al. 2007 section 4 (the integrator of the inverse); Bonomo et al. 2006.'

    def output_transform(self, t, i, model, values):
        return i + values['offset_a'] + values['drift_a_per_s'] * t

    def inverse_output_transform(self, t, i, model, values):
        return i - values['offset_a'] - values['drift_a_per_s'] * t


@register_effect
class HydrationDrift(Effect):
    name = 'hydration_drift'
    summary = 'Diffusivity changing over a long record as the polymer dries (paper section 5.4).'
    physics = (
        'Water evaporates from the ionomer; ion mobility, hence d, falls (paper Figs. 9-10), '
        'changing both gain and phase over minutes.'
    )
    equation = (
        'd(t) = d_0 [q + (1 - q) exp(r_d tau / (1 - q))], tau = t - t_start, all other '
        'parameters fixed: an exponential relaxation from d_0 toward the equilibrium q d_0 with '
        'initial relative rate r_d; q = 0 (default) is the plain exponential d_0 exp(r_d tau)'
    )
    lti = False
    needs_long_record = True
    parameters = (EffectParameter('diffusivity_rate_per_s', '1/s', 0.0, -0.02, 0.02, (-2e-3, 2e-4),
                                  'initial relative rate r_d of change of d', False),
                  EffectParameter('equilibrium_ratio', '1', 0.0, 0.0, 0.98, (0.0, 0.95),
                                  'q = d_equilibrium / d_0 (0: no equilibrium, plain exponential)',
                                  False))
    signature = (
        'Error that grows with time within a record (time-window breakdown), with gain and '
        'phase of the fundamental trending; a windowed refit of d shows a trend (levelling '
        'off toward an equilibrium as the sample dries).'
    )
    reference = 'Chen et al. 2007, section 5.4; Bonomo et al. 2006 (ref. [27] there).'

    def material_at(self, model, values):
        d0 = model.material.diffusivity_m2_per_s
        ratio = diffusivity_ratio_function(values)
        return lambda tau: model.material.replace(diffusivity_m2_per_s=d0 * ratio(tau))


def diffusivity_ratio_function(values):
    """
    Return d(t)/d_0 of :class:`HydrationDrift` as a function of elapsed seconds.

    Also used by ``track``.
    """
    rate = float(values['diffusivity_rate_per_s'])
    q = float(values.get('equilibrium_ratio', 0.0))

    def ratio(tau):
        r = q + (1.0 - q) * np.exp(rate * np.asarray(tau, float) / (1.0 - q))
        return float(r) if np.ndim(r) == 0 else r
    return ratio


#: x = kL of the zeros (sinh x sin x = 0) and poles (tan x = tanh x) of the tip-slope
#: ratio of a clamped beam with prescribed tip displacement (first two of each)
_BEAM_ZEROS_X = (math.pi, 2 * math.pi)
_BEAM_POLES_X = (3.926602312, 7.068582745)
_FREE_CANTILEVER_X1 = 1.8751040687


def clamped_pinned_slope_ratio(x4: np.ndarray) -> np.ndarray:
    """
    Tip-slope ratio R = w'(L) 2L / (3 w(L)) of a clamped beam with a prescribed tip.

    The tip displacement is prescribed (pinned, zero moment); R is a function of
    x^4 = (kL)^4, k^4 = rho A w^2 / (E I).

    R = (2x/3) sinh x sin x / (sin x cosh x - sinh x cos x) (Euler-Bernoulli), even in x,
    = 1 - 2 x^4 / 315 + O(x^8) for small x (series used below |x^4| = 1e-3, where the
    closed form cancels and the series' truncation error is below 1e-10).
    """
    x4 = np.asarray(x4, dtype=complex)
    out = np.empty_like(x4)
    small = np.abs(x4) < 1e-3
    out[small] = 1.0 - 2.0 * x4[small] / 315.0
    x = x4[~small] ** 0.25
    th = np.tanh(x)
    out[~small] = (2 * x / 3) * th * np.sin(x) / (np.sin(x) - th * np.cos(x))
    return out


@register_effect
class BeamInertia(Effect):
    name = 'beam_inertia'
    summary = 'Dynamic stress profile of the beam near its resonance (inertia of the IPMC).'
    physics = (
        "The paper's stress (eq. 21) is the static profile of a tip-loaded cantilever.  With "
        "the tip held by the slider and the beam's own inertia, the curvature distribution "
        'changes with frequency; the sensing charge, proportional to the integral of the '
        "surface stress, i.e. to the tip slope w'(L), changes accordingly.  Exact undamped "
        '(Euler-Bernoulli): R = (2x/3) sinh x sin x / (sin x cosh x - sinh x cos x), '
        'x = kL (:func:`clamped_pinned_slope_ratio`), zeros at x = n pi (anti-resonances), '
        'poles at tan x = tanh x (clamped-pinned resonances, x = 3.927, 7.069).'
    )
    equation = ('H -> H prod_{n=1,2} [(s^2 + 2 zeta w_zn s + w_zn^2)/w_zn^2] / '
                '[(s^2 + 2 zeta w_pn s + w_pn^2)/w_pn^2], w_zn = w_1 (n pi / 1.8751)^2, '
                "w_pn = w_1 (x_pn / 1.8751)^2, w_1 = 2 pi f_1 the free cantilever's first natural "
                'frequency: the first two modes of R with viscous modal damping zeta '
                '(= 1 - 0.039 (f/f_1)^2 at low frequency, as the exact R).')
    parameters = (
        EffectParameter(
            'natural_frequency_hz',
            'Hz',
            30.0,
            1.0,
            1e4,
            (10.0, 300.0),
            'first natural frequency f_1 of the free cantilever (paper Fig. 7: ~30 Hz)',
        ),
        EffectParameter(
            'damping_ratio', '1', 0.03, 1e-4, 0.7, (0.003, 0.2), 'modal damping ratio zeta'
        ),
    )
    signature = ('Magnitude error growing as f^2 (R ~ 1 - 0.039 (f/f_1)^2), almost no phase error '
                 'below the anti-resonance at 2.8 f_1; independent of amplitude.')
    reference = 'Euler-Bernoulli beam; e.g. Meirovitch, Fundamentals of Vibrations (2001), ch. 8.'

    def rational(self, model, values):
        w1 = 2 * math.pi * values['natural_frequency_hz']
        zeta = values['damping_ratio']

        def pair(x):
            wn = w1 * (x / _FREE_CANTILEVER_X1) ** 2
            re = -zeta * wn
            im = wn * math.sqrt(max(1 - zeta * zeta, 0.0))
            return [complex(re, im), complex(re, -im)], wn

        zeros, poles, gain = [], [], 1.0
        for xz, xp in zip(_BEAM_ZEROS_X, _BEAM_POLES_X):
            z, wz = pair(xz)
            p, wp = pair(xp)
            zeros += z
            poles += p
            gain *= (wp / wz) ** 2
        return np.array(zeros), np.array(poles), gain

    def factor(self, s, model, values):
        z, p, k = self.rational(model, values)
        s = np.asarray(s, dtype=complex)[..., None]
        return k * np.prod((s - z) / (s - p), axis=-1)


@register_effect
class EffectiveLength(Effect):
    name = 'effective_length'
    summary = 'Contact point of the stimulus not at the nominal tip.'
    physics = (
        "The slider's slit grips the beam a distance delta before its tip (paper section 5.1: "
        "'the contact point ... is close to the beam tip'), the same delta whatever the "
        'sample, so the stressed length is L_c = L - delta; the unstressed electrode beyond '
        'L_c is neglected.'
    )
    equation = 'H(s; L) -> H(s; L - delta) (eqs. 31, 45 with L replaced by L - delta)'
    parameters = (EffectParameter('tip_offset_m', 'm', 1e-3, 1e-6, 0.05, (1e-4, 4e-3),
                                  'delta: distance of the contact point from the nominal tip'),)
    signature = (
        'A gain error ~ L/(L - delta) that is larger for short samples, plus a small change '
        'of the surface-resistance dynamics ((L - delta)^2); on a single geometry it ties '
        "with Young's modulus / alpha0 scaling, across lengths it does not."
    )
    reference = 'Chen et al. 2007, section 5.1.'

    def factor(self, s, model, values):
        L = model.geometry.length_m
        delta = values['tip_offset_m']
        if delta >= 0.9 * L:
            raise ParameterError(
                f"effect 'effective_length': tip_offset_m = {delta} m leaves less than "
                f'10 % of the free length {L} m'
            )
        short = model.geometry.replace(length_m=L - delta)
        num, den = h1(s, model.material, short), h1(s, model.material, model.geometry)
        with np.errstate(invalid='ignore', divide='ignore'):
            ratio = np.where(den == 0, L / (L - delta), num / np.where(den == 0, 1.0, den))
        if model.has_effect('surface_resistance'):
            ratio = ratio * (surface_resistance_factor(s, model.material, short)
                             / surface_resistance_factor(s, model.material, model.geometry))
        return ratio


@register_effect
class Nonlinearity(Effect):
    name = 'nonlinearity'
    summary = 'Amplitude-dependent response and harmonics beyond the linear model.'
    physics = (
        "The paper uses small-deflection beam theory (eq. 21; section 2: 'one can ignore "
        "the nonlinearity of stress profile') and drops a term of eq. 9.  The field solver "
        'shows the eq. 9 term is negligible (1 % only near 1 m of deflection), while the '
        'large-deflection beam (elastica) is not: the surface curvature grows faster than w, '
        '1 % error at w = 0.22 L, odd (third harmonic).  Modelled as a static polynomial of '
        'w/L before the linear dynamics (a Hammerstein structure); a symmetric elastic beam '
        'gives a_2 = 0 and a_3 = 0.2.'
    )
    equation = "w' = w + a_2 w^2 / L + a_3 w^3 / L^2,  i = H(s) w'"
    lti = False
    parameters = (
        EffectParameter('quadratic', '1', 0.0, -20.0, 20.0, (-2.0, 2.0), 'a_2', False),
        EffectParameter('cubic', '1', 0.0, -200.0, 200.0, (-20.0, 20.0), 'a_3', False),
    )
    signature = ("Harmonics in the current that the deflection's harmonics do not explain (even "
                 'harmonics for a_2) and a fundamental gain that depends on amplitude (a_3); the '
                 'error grows with amplitude.')
    reference = (
        'Chen et al. 2007, eqs. 9-10 and section 6; Bonomo et al. 2007 (nonlinear IPMC model).'
    )

    def input_transform(self, t, w, model, values):
        L = model.geometry.length_m
        return w + values['quadratic'] * w ** 2 / L + values['cubic'] * w ** 3 / L ** 2

    def inverse_input_transform(self, w_prime, model, values):
        L = model.geometry.length_m
        a2, a3 = values['quadratic'], values['cubic']
        if a2 == 0 and a3 == 0:
            return w_prime
        w = np.array(w_prime, dtype=float)
        for _ in range(8):  # Newton on w + a2 w^2/L + a3 w^3/L^2 = w'
            f = w + a2 * w ** 2 / L + a3 * w ** 3 / L ** 2 - w_prime
            df = 1 + 2 * a2 * w / L + 3 * a3 * w ** 2 / L ** 2
            w = w - f / np.where(np.abs(df) > 1e-6, df, 1e-6)
        return w

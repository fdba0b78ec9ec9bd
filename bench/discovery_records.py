# SPDX-License-Identifier: Apache-2.0
"""
Discovery test records made independently of the code under test.

Nothing here imports the package's prediction code (``simulation``, ``lti``, ``physics.sensing``,
``workbench.timepredict``): the transfer functions are written from the paper and the
textbooks, the current is the exact linear convolution of the deflection by FFT, and the
record is cut from a longer run.  Only the model *under test* (the
:class:`~ipmc_sensor_ros.physics.model.SensorModel` each record carries) and the paper's
parameter tables are taken from the package.

* **Sensor**: H1 (paper eq. 31) and H2 (eq. 45) as printed,
  ``H2 = 3 s Y W (beta h coth(beta h) - 1) / (alpha0 L^3 beta^2) *
  (1 - cosh(aL) + aL sinh(aL)) / (B cosh(aL))`` with ``beta^2 = (s + K)/d`` and
  ``a^2 = B = s kappa_e r0 / h`` (eq. 42), evaluated at every FFT bin (no interpolation).
* **Chain**: an amplifier pole 1/(1 + s/w_a), a channel delay exp(-s tau), a current offset
  and a slow drift, mains hum and its harmonics at a grid frequency off nominal by up to
  +-0.3 Hz, white noise, a 16-bit ADC; factors from outside the catalog: a first-order
  high-pass s/(s + w_c) (an AC-coupled amplifier), a lag network (1 + s/w_z)/(1 + s/w_p)
  and a second-order resonance w_n^2/(s^2 + 2 zeta w_n s + w_n^2).
* **Stimulus**: the crank-slider x = r cos(theta) + sqrt(l^2 - r^2 sin^2 theta) less its
  cycle mean (computed here by averaging over a period), random crank phase per record.
* **Time**: each record is cut from a run that started ``preroll_s`` earlier (raised-cosine
  fade-in of the motion) and goes on 1 s after it (fade-out), and the FFT is at least twice
  the run, so neither the start-up transient, nor the band-limited ringing of the run's end,
  nor the circular wrap-around reaches the record.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_PARAMETERS, PAPER_SAMPLES
from ipmc_sensor_ros.workbench.timepredict import Record

__all__ = ['Truth', 'h2_paper', 'chain_factor', 'crank_deflection', 'make_records',
           'SWEEP_HZ', 'DRIVE_HARMONIC_SWEEP_HZ']

#: the seed study's sweep (8 log-spaced frequencies 1-20 Hz)
SWEEP_HZ = tuple(float(f) for f in np.geomspace(1.0, 20.0, 8))
#: a lab sweep on which 50 and 60 Hz are drive harmonics (of 1, 2, 5, 10 and 1, 2, 3, 5, 10,
#: 20 Hz)
DRIVE_HARMONIC_SWEEP_HZ = (1.0, 2.0, 3.0, 5.0, 7.0, 10.0, 14.0, 20.0)


@dataclass
class Truth:
    """What makes the data (effects by their catalog names; ``outside``: a factor C_true)."""

    surface_resistance: bool = True
    amplifier_hz: float | None = None
    delay_s: float = 0.0
    offset_a: float = 0.0
    drift_a_per_s: float = 0.0
    #: ('high_pass', f_c) | ('lag', f_z, f_p) | ('resonance', f_n, zeta), Hz
    outside: tuple | None = None
    material_scale: dict = field(default_factory=dict)   # material name -> factor on Table 2
    hum_rel: float = 0.0
    hum_hz: float = 50.0                  # the grid's actual frequency (off nominal)
    noise_rel: float = 0.01


def h2_paper(s, material, geometry, surface_resistance=True):
    """
    H2 (eq. 45), or H1 (eq. 31) without surface resistance, A/m, written from the paper.

    ``coth`` as ``1/tanh`` (beta h is ~270 for the paper's material: coth = 1 to 1e-200);
    the surface factor ``(1 - cosh aL + aL sinh aL)/(B cosh aL) * 2/L^2`` as
    ``2 (sech aL - 1 + aL tanh aL) / (aL)^2``, with its series ``1 - (aL)^2/4 + ...`` for
    small aL (cancellation) -- the r0 -> 0 limit of eq. 46 is 1.
    """
    s = np.asarray(s, complex)
    m = material
    k_rate = (m.faraday_constant_c_per_mol ** 2 * m.diffusivity_m2_per_s
              * m.anion_concentration_mol_per_m3 * m.one_minus_anion_volume_fraction
              / (m.permittivity_f_per_m * m.gas_constant_j_per_mol_k * m.temperature_k))
    h = 0.5 * geometry.thickness_m
    bh = np.sqrt((s + k_rate) / m.diffusivity_m2_per_s) * h
    h1 = (3 * s * m.youngs_modulus_pa * geometry.width_m * (bh / np.tanh(bh) - 1)
          / (2 * m.charge_stress_coupling_j_per_c * geometry.length_m * (bh / h) ** 2))
    if not surface_resistance:
        return h1
    al = geometry.length_m * np.sqrt(s * m.permittivity_f_per_m * m.surface_resistance_ohm / h)
    small = np.abs(al) < 1e-3
    a = np.where(small, 1.0, al)
    with np.errstate(over='ignore'):
        sech = 1.0 / np.cosh(a)
    factor = np.where(small, 1 - al ** 2 / 4, 2 * (sech - 1 + a * np.tanh(a)) / a ** 2)
    return h1 * factor


def chain_factor(s, truth: Truth):
    """Return the signal chain's and the outside factors' product at ``s`` (rad/s)."""
    s = np.asarray(s, complex)
    out = np.exp(-s * truth.delay_s)
    if truth.amplifier_hz:
        out = out / (1 + s / (2 * np.pi * truth.amplifier_hz))
    if truth.outside:
        kind, *pars = truth.outside
        if kind == 'high_pass':
            out = out * s / (s + 2 * np.pi * pars[0])
        elif kind == 'lag':
            out = out * (1 + s / (2 * np.pi * pars[0])) / (1 + s / (2 * np.pi * pars[1]))
        elif kind == 'resonance':
            wn, zeta = 2 * np.pi * pars[0], pars[1]
            out = out * wn ** 2 / (s ** 2 + 2 * zeta * wn * s + wn ** 2)
        else:
            raise ValueError(f'unknown outside factor {kind!r}')
    return out


def crank_deflection(t, frequency_hz, radius_m=2e-3, rod_m=15e-3, phase=0.0):
    """Tip deflection of the crank-slider, m: slider position less its cycle mean."""
    theta = 2 * np.pi * frequency_hz * np.asarray(t, float) + phase
    x = radius_m * np.cos(theta) + np.sqrt(rod_m ** 2 - (radius_m * np.sin(theta)) ** 2)
    one_period = np.linspace(0, 2 * np.pi, 4096, endpoint=False)
    mean = np.mean(np.sqrt(rod_m ** 2 - (radius_m * np.sin(one_period)) ** 2))
    return x - mean


def _hum(t, truth: Truth, scale, rng):
    """Mains hum: fundamental, 2nd and 3rd harmonics (random power shares), random phases."""
    shares = rng.dirichlet([8.0, 1.0, 2.0])
    out = np.zeros_like(t)
    for m, share in zip((1, 2, 3), shares):
        out += truth.hum_rel * scale * np.sqrt(2 * share) * np.cos(
            2 * np.pi * m * truth.hum_hz * t + rng.uniform(0, 2 * np.pi))
    return out


def _current(t_run, w_run, geometry, truth: Truth, rate_hz):
    """Exact linear convolution of the run's deflection with H * chain, by FFT (no wrap)."""
    material = PAPER_PARAMETERS.replace(**{k: getattr(PAPER_PARAMETERS, k) * f
                                           for k, f in truth.material_scale.items()})
    n = 1 << int(np.ceil(np.log2(2 * t_run.size)))
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    s = 2j * np.pi * f
    h = np.zeros(f.size, complex)
    h[1:] = h2_paper(s[1:], material, geometry, truth.surface_resistance) * chain_factor(
        s[1:], truth)
    return np.fft.irfft(np.fft.rfft(w_run, n) * h, n)[:t_run.size]


def make_records(truth: Truth, seed: int, *, model_effects=('surface_resistance',),
                 samples=('slim', 'short'), frequencies_hz=SWEEP_HZ, duration_s=6.0,
                 rate_hz=1000.0, preroll_s=6.0, adc_bits=16) -> list[Record]:
    """
    One record per (sample, frequency), made as the module docstring says.

    The noise is ``truth.noise_rel`` x the clean current's RMS per record; the ADC spans
    +-2x the largest noisy sample (quantisation step ``range / 2**adc_bits``).  Each record
    carries the model under test: ``model_effects`` on the paper's material and the sample's
    geometry.
    """
    rng = np.random.default_rng(seed)
    out = []
    for name in samples:
        geometry = PAPER_SAMPLES[name]
        model = SensorModel(geometry, PAPER_PARAMETERS, tuple(model_effects))
        for f in frequencies_hz:
            n_pre, n_rec = int(round(preroll_s * rate_hz)), int(round(duration_s * rate_hz))
            t_run = (np.arange(n_pre + n_rec + int(rate_hz)) - n_pre) / rate_hz
            fade = np.clip(np.minimum(t_run + preroll_s, duration_s + 1.0 - t_run), 0, 1)
            w_run = crank_deflection(t_run, f, phase=rng.uniform(0, 2 * np.pi))
            w_run = w_run * 0.5 * (1 - np.cos(np.pi * fade))
            i_run = _current(t_run, w_run, geometry, truth, rate_hz)
            cut = slice(n_pre, n_pre + n_rec)
            t, w, i = t_run[cut] - t_run[n_pre], w_run[cut], i_run[cut]
            scale = float(np.std(i))
            i = i + rng.normal(0.0, truth.noise_rel * scale, i.size)
            i = i + truth.offset_a + truth.drift_a_per_s * t
            if truth.hum_rel:
                i = i + _hum(t, truth, scale, rng)
            step = 4 * np.max(np.abs(i)) / 2 ** adc_bits
            i = np.round(i / step) * step
            out.append(Record(f'{name}_{f:g}Hz', name, model, t, w, i))
    return out


#: catalog effects drawn beside hum, a small offset or a factor from outside the catalog, with
#: their ranges (inside each effect's plausible range, large enough to be seen in 1 % noise
#: over a 1-20 Hz sweep); 'surface_resistance' means: data from H2, model H1
ONE_OR_TWO = ('amplifier_bandwidth', 'time_delay', 'current_offset', 'surface_resistance')
OUTSIDE_KINDS = ('high_pass', 'lag', 'resonance')


def _draw_effects(rng, names, truth: Truth) -> None:
    """Put ``names`` into ``truth`` with seeded values (surface resistance is always in it)."""
    for name in names:
        if name == 'amplifier_bandwidth':
            truth.amplifier_hz = float(np.exp(rng.uniform(np.log(30.0), np.log(300.0))))
        elif name == 'time_delay':
            truth.delay_s = float(np.exp(rng.uniform(np.log(5e-4), np.log(5e-3))))
        elif name == 'current_offset':
            truth.offset_a = float(rng.choice([-1, 1]) * rng.uniform(1e-7, 5e-7))


def _material(rng) -> dict:
    """Return a sample off the paper's: alpha0, d, kappa_e each within a factor 1.25 of it."""
    return {n: float(np.exp(rng.uniform(-0.22, 0.22)))
            for n in ('charge_stress_coupling_j_per_c', 'diffusivity_m2_per_s',
                      'permittivity_f_per_m')}


def scenario(kind: str, seed: int):
    """
    Return records of one seeded scenario of the discovery study: ``(records, truth, expected)``.

    ``kind``: ``hum`` (3-5 % hum at 50 or 60 Hz +-0.3 Hz on a sweep where it is a drive
    harmonic, one or two catalog effects), ``null`` (nothing missing, no hum), ``offset``
    (a 5-20 nA offset beside one or two effects, 2 % noise: the offset test is significant, its
    BIC test is not always), or one of :data:`OUTSIDE_KINDS` (a factor outside the catalog on
    top of one catalog effect).  ``expected``: the catalog effects a diagnosis should name.
    Every record's sample differs from the paper's (:func:`_material`).
    """
    rng = np.random.default_rng(20_000 + 1000 * (['hum', 'null', 'offset', *OUTSIDE_KINDS]
                                                 .index(kind)) + seed)
    truth = Truth(material_scale=_material(rng))
    kw = {}
    if kind == 'hum':
        names = rng.choice(ONE_OR_TWO, size=int(rng.integers(1, 3)), replace=False)
        nominal = float(rng.choice([50.0, 60.0]))
        truth.hum_hz = nominal + float(rng.uniform(-0.3, 0.3))
        truth.hum_rel = float(rng.uniform(0.03, 0.05))
        kw['frequencies_hz'] = DRIVE_HARMONIC_SWEEP_HZ
    elif kind == 'null':
        names = []
    elif kind == 'offset':
        names = list(rng.choice(ONE_OR_TWO[:2] + ONE_OR_TWO[3:], size=int(rng.integers(1, 3)),
                                replace=False))
        truth.noise_rel = 0.02
    else:
        names = [str(rng.choice(ONE_OR_TWO))]
        if kind == 'high_pass':
            truth.outside = ('high_pass', float(np.exp(rng.uniform(np.log(0.2), np.log(2.0)))))
        elif kind == 'lag':
            pole = float(np.exp(rng.uniform(np.log(2.0), np.log(8.0))))
            truth.outside = ('lag', pole * float(rng.uniform(2.0, 4.0)), pole)
        else:
            truth.outside = ('resonance', float(np.exp(rng.uniform(np.log(3.0), np.log(8.0)))),
                             float(rng.uniform(0.2, 0.5)))
    names = [str(n) for n in names]
    _draw_effects(rng, names, truth)
    if kind == 'offset':
        truth.offset_a = float(rng.choice([-1, 1]) * np.exp(rng.uniform(np.log(5e-9),
                                                                        np.log(20e-9))))
        names.append('current_offset')
    model = () if 'surface_resistance' in names else ('surface_resistance',)
    return make_records(truth, seed, model_effects=model, **kw), truth, set(names)


def write_records(records, out_dir) -> list:
    """Write records as ipmc-timeseries/1 files (one per record) into ``out_dir``; the paths."""
    from pathlib import Path

    from ipmc_sensor_ros.workbench.formats import write_timeseries
    from ipmc_sensor_ros.workbench.measurements import TimeSeries

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for r in records:
        rate = (r.time_s.size - 1) / (r.time_s[-1] - r.time_s[0])
        paths.append(out / f"{r.path.replace('.', 'p')}.csv")
        write_timeseries(paths[-1], TimeSeries(path='', sample=r.sample,
                                               geometry=r.model.geometry, known={},
                                               sample_rate_hz=float(rate), time_s=r.time_s,
                                               current_a=r.current_a,
                                               deflection_m=r.deflection_m))
    return paths

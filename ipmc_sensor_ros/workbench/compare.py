# SPDX-License-Identifier: Apache-2.0
"""
Compare a fixed model with measurements and locate where it fails.

Prediction
    The predicted current of each record is the exact LTI response of the
    model to the measured deflection (:func:`~ipmc_sensor_ros.simulation.sensor.lti_response_fft`),
    so the comparison has no reduction or discretisation error.  The first
    ``settle_s`` seconds (default 0.5 s, about 35 time constants 1/K) are left
    out: they depend on motion before the record started.

Metrics (per record and over all records)
    * ``fit_percent`` -- MATLAB ``compare``: 100 (1 - ||y - y_hat|| / ||y - mean(y)||);
    * ``error`` -- normalised RMS error of the predicted current,
      ||y - y_hat|| / ||y - mean(y)|| = 1 - fit_percent/100;
    * ``noise_floor`` -- the error a perfect model would have, from the
      measurement noise (residual of a harmonic fit for periodic records,
      else the scaled MAD of second differences);
    * per-frequency magnitude (dB) and phase (deg) error at each record's
      excitation fundamental, or at each tone of a multi-sine record
      (:func:`~.tones.tone_responses`, as ``fit`` reads it), with the measurement's
      standard uncertainty;
    * residual tests (MATLAB ``resid``): autocorrelation of the residual at lags
      1..``max_lag`` and its cross-correlation with the input velocity at lags
      -max_lag..max_lag, against the 99 % bound 2.58/sqrt(N).

Where it fails
    The error is broken down by frequency band, by time window, by deflection
    amplitude and by sample; a cell is flagged when its error exceeds what the
    measurement uncertainty explains (frequency cells: |error| > 3 sd; time
    cells: error > 1.5 x noise floor + 0.01).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..errors import DataError
from ..physics.model import SensorModel
from ..simulation.convolution import lti_response_fft
from .adequacy import magnitude_flags
from .blas import single_threaded_blas
from .freqresp import FrequencyPoint
from .metrics import fit_percent, noise_rms
from .tones import tone_responses

__all__ = ['ToneError', 'RecordComparison', 'Comparison', 'compare_records', 'FREQUENCY_BANDS_HZ',
           'BOUND99', 'normalised_cross_correlation']

FREQUENCY_BANDS_HZ = ((0.0, 2.0), (2.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, np.inf))
#: Two-sided 99 % quantile of N(0, 1): a white residual's correlation stays in +-BOUND99/sqrt(N).
BOUND99 = 2.576


#: Samples per piece when the velocity is differentiated piecewise (:func:`_gradient`).
GRADIENT_CHUNK = 65_536


def _gradient(w: np.ndarray, t: np.ndarray) -> np.ndarray:
    """
    ``np.gradient(w, t)`` (edge order 1) computed in pieces of ``GRADIENT_CHUNK`` samples.

    The same arithmetic, hence the same numbers: second-order central differences on
    the non-uniform grid inside, one-sided differences at the two ends, and numpy's
    uniform-grid form when every step equals the first (decided on the whole record,
    as np.gradient does); without np.gradient's record-length temporaries (~60 B per
    sample).
    """
    n = w.size
    d0 = t[1] - t[0]
    pieces = [(a, min(a + GRADIENT_CHUNK, n)) for a in range(0, n, GRADIENT_CHUNK)]
    uniform = all(bool(np.all(np.diff(t[a:b + 1]) == d0)) for a, b in pieces)
    out = np.empty(n)
    out[0] = (w[1] - w[0]) / d0
    out[-1] = (w[-1] - w[-2]) / (d0 if uniform else t[-1] - t[-2])
    for a, b in pieces:
        lo, hi = max(a, 1) - 1, min(b, n - 1) + 1    # interior points a..b-1 and neighbours
        if hi - lo < 3:
            continue
        f = w[lo:hi]
        if uniform:
            out[lo + 1:hi - 1] = (f[2:] - f[:-2]) / (2. * d0)
        else:
            dx = np.diff(t[lo:hi])
            dx1, dx2 = dx[:-1], dx[1:]
            out[lo + 1:hi - 1] = (-(dx2) / (dx1 * (dx1 + dx2)) * f[:-2]
                                  + (dx2 - dx1) / (dx1 * dx2) * f[1:-1]
                                  + dx1 / (dx2 * (dx1 + dx2)) * f[2:])
    return out


def normalised_cross_correlation(a: np.ndarray, b: np.ndarray, lags: np.ndarray) -> np.ndarray:
    """Normalised cross-correlation at ``lags`` of ``a`` and ``b``, means removed beforehand."""
    den = np.sqrt(np.sum(a * a) * np.sum(b * b))
    out = []
    for lag in lags:
        if lag >= 0:
            out.append(np.sum(a[lag:] * b[:a.size - lag]))
        else:
            out.append(np.sum(a[:lag] * b[-lag:]))
    return np.asarray(out) / den if den > 0 else np.zeros(len(lags))


@dataclass(frozen=True)
class ToneError:
    """The measured response at one tone of a record against the model's (measured / model)."""

    point: FrequencyPoint
    model_response: complex
    mag_error_db: float
    phase_error_deg: float
    mag_sd_db: float
    phase_sd_deg: float

    @property
    def frequency_hz(self) -> float:
        return self.point.frequency_hz

    @classmethod
    def of(cls, point: FrequencyPoint, transfer) -> 'ToneError':
        """Return the error of ``transfer`` (the model's H(s)) at a measured ``point``."""
        hm = complex(transfer(np.array([2j * np.pi * point.frequency_hz]))[0])
        ratio = point.response / hm
        return cls(point, hm, float(20 * np.log10(abs(ratio))),
                   float(np.degrees(np.angle(ratio))), float(20 / np.log(10) * point.sd_log_mag),
                   float(np.degrees(point.sd_phase_rad)))

    def to_json(self) -> dict:
        return {'frequency_hz': self.frequency_hz, 'mag_error_db': self.mag_error_db,
                'mag_sd_db': self.mag_sd_db, 'phase_error_deg': self.phase_error_deg,
                'phase_sd_deg': self.phase_sd_deg}

    def text(self) -> str:
        """Return the table's frequency, dMag and dPhase columns ({} for the others)."""
        dm = f'{self.mag_error_db:+6.2f}+-{self.mag_sd_db:.2f}'
        dp = f'{self.phase_error_deg:+6.2f}+-{self.phase_sd_deg:.2f}'
        return f'{self.frequency_hz:7.3g} {{}} {dm:>14} {dp:>14}'


@dataclass
class RecordComparison:
    source: str
    sample: str
    time_s: np.ndarray
    measured_a: np.ndarray
    predicted_a: np.ndarray
    deflection_m: np.ndarray
    fit_percent: float
    error: float
    noise_floor: float
    #: the record's fundamental, or each tone of a multi-sine record (none: not periodic)
    tones: list[ToneError]
    whiteness: dict
    input_correlation: dict
    windows: list[dict] = field(default_factory=list)


@dataclass
class Comparison:
    records: list[RecordComparison]
    fit_percent: float
    error: float
    noise_floor: float
    where: dict
    magnitude_flags: list = field(default_factory=list)   # implausible magnitudes (adequacy.py)

    def to_json(self) -> dict:
        return {
            'magnitude_flags': self.magnitude_flags,
            'error': self.error, 'fit_percent': self.fit_percent, 'noise_floor': self.noise_floor,
            'records': [{
                'source': r.source, 'sample': r.sample, 'error': r.error,
                'fit_percent': r.fit_percent, 'noise_floor': r.noise_floor,
                'tones': [tone.to_json() for tone in r.tones],
                'whiteness': r.whiteness, 'input_correlation': r.input_correlation,
            } for r in self.records],
            'where': self.where,
        }

    def summary(self) -> str:
        lines = [
            f"{'record':<28} {'sample':<8} {'f0 Hz':>7} {'fit %':>7} {'error':>7} {'noise':>7} "
            f"{'dMag dB':>14} {'dPhase deg':>14}"
        ]
        for r in self.records:
            cells = f'{r.fit_percent:7.2f} {r.error:7.4f} {r.noise_floor:7.4f}'
            first = r.tones[0].text() if r.tones else f"      - {{}} {'-':>14} {'-':>14}"
            lines.append(f'{_short(r.source):<28} {r.sample:<8} ' + first.format(cells))
            lines += [f"{'':<28} {'':<8} " + tone.text().format(' ' * 23)
                      for tone in r.tones[1:]]
        lines.append(f'overall: fit {self.fit_percent:.2f} %, error {self.error:.4f} '
                     f'(noise floor {self.noise_floor:.4f})')
        flagged = [
            f"{k}={c['label']}" for k, cells in self.where.items() for c in cells if c['flagged']
        ]
        lines.append('model fails beyond measurement uncertainty at: ' +
                     (', '.join(flagged) if flagged else 'nowhere'))
        lines += [f'IMPLAUSIBLE MAGNITUDE: {f}' for f in self.magnitude_flags]
        return '\n'.join(lines)


def _short(path: str) -> str:
    return path if len(path) <= 28 else '...' + path[-25:]


def compare_records(records: Sequence, model_for: Callable[[object], SensorModel], *,
                    settle_s: float = 0.5, max_lag: int = 25, n_windows: int = 8,
                    transfer_for: Callable[[object], Callable] | None = None) -> Comparison:
    """
    Compare the model with each time record.

    Objects with ``time_s``, ``deflection_m``, ``current_a``,
    ``sample``, ``path``.

    ``model_for(record)`` gives the model of that record's sample;
    ``transfer_for(record)`` may override the transfer function used for
    prediction (e.g. a model with extra effects).
    """
    with single_threaded_blas():    # the fits' thin products only lose time to BLAS threads
        return _compare_records(records, model_for, settle_s, max_lag, n_windows, transfer_for)


def _compare_records(records, model_for, settle_s, max_lag, n_windows, transfer_for):
    out: list[RecordComparison] = []
    for rec in records:
        if rec.deflection_m is None:
            raise DataError(f'{rec.path}: no deflection column: cannot compare')
        model = model_for(rec)
        transfer = transfer_for(rec) if transfer_for else model.transfer
        t, w, y = np.asarray(rec.time_s), np.asarray(rec.deflection_m), np.asarray(rec.current_a)
        y_hat_full = lti_response_fft(transfer, t, w)
        keep = t >= t[0] + settle_s
        n_keep = int(np.count_nonzero(keep))
        if n_keep < 16:
            raise DataError(
                f'{rec.path}: record shorter than settle time {settle_s} s + 16 samples'
            )
        first = t.size - n_keep
        if keep[first:].all():    # increasing times: views of the record, not copies
            keep = slice(first, None)
        tt, yy, yh, ww = t[keep], y[keep], y_hat_full[keep], w[keep]
        del y_hat_full, keep
        try:
            tones = [ToneError.of(p, transfer)
                     for p in tone_responses(tt, ww, yy, source=rec.path)]
        except ValueError:
            tones = []
        fp = fit_percent(yy, yh)
        den = np.linalg.norm(yy - yy.mean())
        noise = noise_rms(tt, ww, yy) * np.sqrt(yy.size) / den if den > 0 else float('nan')
        resid = yy - yh
        centred = resid - resid.mean()
        lags = np.arange(1, max_lag + 1)
        acf = normalised_cross_correlation(centred, centred, lags)
        vel = _gradient(ww, tt)
        vel -= vel.mean()
        xl = np.arange(-max_lag, max_lag + 1)
        ccf = normalised_cross_correlation(centred, vel, xl)
        del centred, vel
        bound = BOUND99 / np.sqrt(resid.size)
        windows = []
        edges = np.linspace(tt[0], tt[-1], n_windows + 1)
        for a, b in zip(edges[:-1], edges[1:]):
            sel = (tt >= a) & (tt <= b)
            if sel.sum() < 8:
                continue
            d = np.linalg.norm(yy[sel] - yy[sel].mean())
            windows.append(
                {
                    'start_s': float(a),
                    'stop_s': float(b),
                    'error': float(np.linalg.norm(resid[sel]) / d) if d > 0 else float('nan'),
                    'amplitude_m': float(0.5 * np.ptp(ww[sel])),
                }
            )
        out.append(RecordComparison(
            source=str(rec.path), sample=str(getattr(rec, 'sample', '') or model.geometry.name),
            time_s=tt, measured_a=yy, predicted_a=yh, deflection_m=ww, fit_percent=fp,
            error=float(1 - fp / 100), noise_floor=float(noise), tones=tones,
            whiteness={'max_abs': float(np.max(np.abs(acf))), 'bound99': float(bound),
                       'fraction_outside': float(np.mean(np.abs(acf) > bound)),
                       'passed': bool(np.mean(np.abs(acf) > bound) <= 0.05)},
            input_correlation={'max_abs': float(np.max(np.abs(ccf))), 'bound99': float(bound),
                               'fraction_outside': float(np.mean(np.abs(ccf) > bound)),
                               'passed': bool(np.mean(np.abs(ccf) > bound) <= 0.05)},
            windows=windows))
        del resid
    if len(out) == 1:    # the same numbers without a copy of the record
        y_all, yh_all = out[0].measured_a, out[0].predicted_a
    else:
        y_all = np.concatenate([r.measured_a for r in out])
        yh_all = np.concatenate([r.predicted_a for r in out])
    fp_all = fit_percent(y_all, yh_all)
    den_all = np.linalg.norm(y_all - y_all.mean())
    noise_all = (
        float(
            np.sqrt(
                sum(
                    (r.noise_floor * np.linalg.norm(r.measured_a - r.measured_a.mean())) ** 2
                    for r in out
                )
            )
            / den_all
        )
        if den_all > 0
        else float('nan')
    )
    return Comparison(records=out, fit_percent=fp_all, error=float(1 - fp_all / 100),
                      noise_floor=noise_all, where=_where_it_fails(out),
                      magnitude_flags=magnitude_flags(records, model_for))


def _freq_cell(label: str, tones: list[ToneError]) -> dict:
    mags = np.array([r.mag_error_db for r in tones])
    phs = np.array([r.phase_error_deg for r in tones])
    msd = np.array([r.mag_sd_db for r in tones])
    psd = np.array([r.phase_sd_deg for r in tones])
    flagged = bool(np.any(np.abs(mags) > 3 * msd) or np.any(np.abs(phs) > 3 * psd))
    return {'label': label, 'n': len(tones),
            'rms_mag_error_db': float(np.sqrt(np.mean(mags ** 2))),
            'rms_phase_error_deg': float(np.sqrt(np.mean(phs ** 2))),
            'max_mag_z': float(np.max(np.abs(mags) / np.maximum(msd, 1e-12))),
            'max_phase_z': float(np.max(np.abs(phs) / np.maximum(psd, 1e-12))), 'flagged': flagged}


def _error_cell(label: str, errors: list[float], floors: list[float]) -> dict:
    e = float(np.sqrt(np.mean(np.square(errors))))
    nf = float(np.sqrt(np.mean(np.square(floors))))
    return {'label': label, 'n': len(errors), 'error': e, 'noise_floor': nf,
            'flagged': bool(e > 1.5 * nf + 0.01)}


def _where_it_fails(recs: list[RecordComparison]) -> dict:
    tones = [tone for r in recs for tone in r.tones]
    by_band = []
    for lo, hi in FREQUENCY_BANDS_HZ:
        sel = [tone for tone in tones if lo <= tone.frequency_hz < hi]
        if sel:
            by_band.append(_freq_cell(f'{lo:g}-{hi:g} Hz', sel))
    by_sample = []
    for name in sorted({r.sample for r in recs}):
        sel = [r for r in recs if r.sample == name]
        cell = _error_cell(name, [r.error for r in sel], [r.noise_floor for r in sel])
        sp = [tone for r in sel for tone in r.tones]
        if sp:
            fc = _freq_cell(name, sp)
            cell.update({k: fc[k] for k in ('rms_mag_error_db', 'rms_phase_error_deg')})
            cell['flagged'] = cell['flagged'] or fc['flagged']
        by_sample.append(cell)
    by_time = []
    n_w = max((len(r.windows) for r in recs), default=0)
    for k in range(n_w):
        errs = [r.windows[k]['error'] for r in recs if k < len(r.windows)]
        floors = [r.noise_floor for r in recs if k < len(r.windows)]
        by_time.append(_error_cell(f'window {k + 1}/{n_w}', errs, floors))
    amps = [(w['amplitude_m'], w['error'], r.noise_floor) for r in recs for w in r.windows]
    by_amp = [_error_cell(label, [x[1] for x in sel], [x[2] for x in sel])
              for label, sel in amplitude_bins(amps)]
    return {'frequency_band': by_band, 'sample': by_sample, 'time_window': by_time,
            'amplitude': by_amp}


#: Amplitudes within this fraction of each other fall in one bin of the failure breakdown.
AMPLITUDE_RESOLUTION = 0.05


def _mm(value_m: float) -> str:
    return f'{value_m * 1e3:.3g}'


def amplitude_bins(items) -> list[tuple[str, list]]:
    """
    Split ``(amplitude_m, ...)`` items into up to three bins at their terciles.

    Each item lands in exactly one bin (``[lo, hi)``, the last one closed).  Edges closer than
    :data:`AMPLITUDE_RESOLUTION` of the largest amplitude are merged, so records driven at one
    amplitude form one bin labelled by that amplitude (``2 mm``), never ``2-2 mm``.
    """
    if not items:
        return []
    a = np.array([x[0] for x in items], float)
    edges = [float(e) for e in np.quantile(a, [0, 1 / 3, 2 / 3, 1])]
    kept = [edges[0]]
    for e in edges[1:]:
        if e - kept[-1] > AMPLITUDE_RESOLUTION * edges[-1]:
            kept.append(e)
    if len(kept) == 1:
        return [(f'{_mm(kept[0])} mm', list(items))]
    kept[-1] = edges[-1]
    out = []
    for k, (lo, hi) in enumerate(zip(kept[:-1], kept[1:])):
        last = k == len(kept) - 2
        sel = [x for x in items if lo <= x[0] < hi or (last and x[0] == hi)]
        if sel:
            out.append((f'{_mm(lo)}-{_mm(hi)} mm', sel))
    return out

# SPDX-License-Identifier: Apache-2.0
"""
The line-free residual: mains lines out of the records, then the noise floor.

* :func:`detect_lines` predicts each record's current from its deflection with a model fitted
  to the records as measured and finds the mains lines in what the prediction leaves
  (:mod:`.lines`); :func:`clean` subtracts them.  Every later fit, the noise floor and
  ``explained`` see the line-free records.  :mod:`.search` looks for the lines again under
  the final model and searches once more when a strong line comes or goes
  (:func:`lines_changed`).
* :func:`noise_floor`: the held-out error a perfect model would have,
  ``sqrt(sum sigma_r^2 n_r / sum ||y_r - mean y_r||^2)`` over the records' kept samples, with
  ``sigma_r`` the measured noise RMS (:func:`~ipmc_sensor_ros.workbench.metrics.noise_rms`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..timefit import FitSpec
from ..timepredict import predict
from .drive import drive_of
from .fitting import evaluate, make_folds
from .history import history_samples, prepare_with_history
from .lines import MAINS_SEARCH_HZ, find_mains_lines, parse_mains

__all__ = ['noise_floor', 'detect_lines', 'clean', 'line_test', 'lines_changed', 'mains_lines']


def noise_floor(prepared) -> float:
    """Held-out error of a perfect model (module docstring)."""
    num = sum(p.sigma ** 2 * p.keep.sum() for p in prepared)
    den = sum(float(np.sum((p.y[p.keep] - p.y[p.keep].mean()) ** 2)) for p in prepared)
    return float(np.sqrt(num / den))


def detect_lines(records, prepared, models, settings, drives=None):
    """
    Mains lines of the records under ``models`` (one per record): ``(lines, fitted, left)``.

    ``prepared``: the records as measured (:func:`~.history.prepare_with_history`); each
    record's current is predicted from its deflection by its model and the lines are looked
    for in what that leaves (:func:`~.lines.find_mains_lines`).
    """
    predictions, keeps = [], []
    for p, m, rec in zip(prepared, models, records):
        n = history_samples(p, rec)
        predictions.append(predict(p, m)[n:])
        keeps.append(p.keep[n:])
    return find_mains_lines(records, predictions, keeps, parse_mains(settings.mains),
                            false_alarm=settings.line_false_alarm, drives=drives)


def clean(records, prepared, fitted, settle_s, drives=None):
    """Return the prepared line-free records (``prepared`` itself when no line was found)."""
    if not any(np.any(f) for f in fitted):
        return prepared
    cleaned = [replace(r, current_a=np.asarray(r.current_a, float) - f) if np.any(f) else r
               for r, f in zip(records, fitted)]
    return prepare_with_history(cleaned, settle_s, drives)


def line_test(settings, lines, left=()) -> dict:
    """
    Return what the JSON says about the line test: its false-alarm rate and what it found.

    ``left_in_residual``: the lines that passed the test on a drive harmonic and were not
    taken for hum (:mod:`.lines`, step 5), with the harmonic of the drive they sit on.
    """
    if parse_mains(settings.mains) is None:
        return {}
    return {'false_alarm_per_record': settings.line_false_alarm,
            'mains': parse_mains(settings.mains), 'search_hz': MAINS_SEARCH_HZ,
            'lines_found': len(lines),
            'left_in_residual': [{'record': ln.record, 'frequency_hz': ln.frequency_hz,
                                  'nominal_hz': ln.nominal_hz, 'level': ln.level, 'z': ln.z,
                                  'drive_harmonic': harmonic}
                                 for ln, harmonic in left]}


def lines_changed(before, after, factor: float = 2.0) -> bool:
    """
    Return True when a line changed by ``factor`` x its test threshold in standard errors.

    A line found in one list only counts with its whole amplitude.  Lines found under the
    starting model and under the final one differ where the starting model's error stood at a
    drive harmonic (a missing nonlinearity puts current at the odd harmonics of a crank, whose
    deflection has none); a line near its threshold that comes and goes changes the records by
    less than the noise.
    """
    a = {(ln.record, ln.nominal_hz): ln for ln in before}
    b = {(ln.record, ln.nominal_hz): ln for ln in after}
    for key in set(a) | set(b):
        x, y = a.get(key), b.get(key)
        ref = x or y
        se = ref.amplitude_a / ref.z
        dc = (x.cos_a if x else 0.0) - (y.cos_a if y else 0.0)
        ds = (x.sin_a if x else 0.0) - (y.sin_a if y else 0.0)
        if np.hypot(dc, ds) >= factor * ref.z_threshold * se:
            return True
    return False


def mains_lines(records, mains='auto', **settings):
    """
    Return ``(lines, cleaned records, left)``: the mains lines of records under their own model.

    As the diagnosis first finds them (:func:`detect_lines`): the records' model with its free
    material (``settings``: fields of :class:`~.settings.Settings`) fitted to the records, the
    lines looked for in what its prediction leaves.  ``lines``: :class:`~.lines.MainsLine`;
    ``left``: (line, drive harmonic) of the lines left in the residual (:mod:`.lines`, step 5).
    """
    from .ranking import baseline_starts
    from .settings import Settings

    s = Settings.from_kwargs({**settings, 'mains': mains})
    spec = FitSpec(s.free_material)
    drives = [drive_of(r) for r in records]
    prepared = prepare_with_history(records, s.settle_s, drives)
    folds, _ = make_folds(prepared, s.n_folds)
    starts = baseline_starts(spec, {}, records[0].model)
    fit = evaluate(prepared, spec, starts, folds, s.fold_nfev, scored=False)
    lines, fitted, left = detect_lines(records, prepared, fit.fit.models, s, drives)
    return lines, [replace(r, current_a=np.asarray(r.current_a, float) - f)
                   for r, f in zip(records, fitted)], left

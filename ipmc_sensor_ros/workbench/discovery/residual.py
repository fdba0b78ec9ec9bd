# SPDX-License-Identifier: Apache-2.0
"""
The line-free residual: mains lines out of the records, then the noise floor.

* :func:`remove_lines` fits the starting model to the records as measured, predicts each
  record's current from its deflection, finds the mains lines in what the prediction leaves
  (:mod:`.lines`) and subtracts them; every later fit, the noise floor and ``explained`` see
  the line-free records.
* :func:`noise_floor`: the held-out error a perfect model would have,
  ``sqrt(sum sigma_r^2 n_r / sum ||y_r - mean y_r||^2)`` over the records' kept samples, with
  ``sigma_r`` the measured noise RMS (:func:`~ipmc_sensor_ros.workbench.metrics.noise_rms`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..timefit import predict, prepare
from .fitting import evaluate
from .lines import MAINS_SEARCH_HZ, find_mains_lines, parse_mains, summarize_lines

__all__ = ['noise_floor', 'remove_lines']


def noise_floor(prepared) -> float:
    """Held-out error of a perfect model (module docstring)."""
    num = sum(p.sigma ** 2 * p.keep.sum() for p in prepared)
    den = sum(float(np.sum((p.y[p.keep] - p.y[p.keep].mean()) ** 2)) for p in prepared)
    return float(np.sqrt(num / den))


def remove_lines(records, prepared, spec, starts, folds, settings, priors):
    """
    Return ``(prepared, lines, line_test, fit)`` for the line-free records.

    ``prepared``: the records as measured; ``fit``: the starting model (``spec`` from
    ``starts``) fitted to them, whose prediction is subtracted before the lines are looked
    for (None with ``mains`` off).  Without lines the measured records are returned as they
    are.
    """
    mains = parse_mains(settings.mains)
    if mains is None:
        return prepared, [], {}, None
    fit = evaluate(prepared, spec, starts, folds, settings.fold_nfev, priors=priors,
                   scored=False)
    predictions = [predict(p, m) for p, m in zip(prepared, fit.fit.models)]
    lines, fitted = find_mains_lines(records, predictions, [p.keep for p in prepared], mains,
                                     false_alarm=settings.line_false_alarm)
    test = {'false_alarm_per_record': settings.line_false_alarm, 'mains': mains,
            'search_hz': MAINS_SEARCH_HZ, 'lines_found': len(lines)}
    if not lines:
        return prepared, [], test, fit
    cleaned = [replace(r, current_a=np.asarray(r.current_a, float) - f) if np.any(f) else r
               for r, f in zip(records, fitted)]
    return prepare(cleaned, settle_s=settings.settle_s), summarize_lines(lines), test, fit

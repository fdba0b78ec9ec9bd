# SPDX-License-Identifier: Apache-2.0
"""
Fitting and scoring one candidate model: the full-data fit, its BIC, its held-out error.

A candidate is the current model with one effect more (or less), every free parameter refitted
(:func:`~ipmc_sensor_ros.workbench.timefit.fit_model`, time-domain output error).  Its
**held-out error** pools ``||y - y_hat|| / ||y - mean(y)||`` over the test parts of
k-fold cross-validation (over records, or over contiguous time blocks when there are fewer
records than folds), each fold refitted from the full-data fit; its **BIC** is that of the
full-data fit (chi^2 + k ln n, residuals in units of the noise).  Candidates are fitted in
worker processes when there are several (:func:`run_jobs`).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np

from ...physics.effects import effect_parameter, get_effect
from ..timefit import FitSpec, ModelFit, fit_model
from ..timepredict import PreparedRecord, predict
from .priors import PRIOR_FACTOR
from .ranking import start_grid
from .verdict import Candidate

__all__ = ['make_folds', 'with_models', 'fit_vector', 'evaluate', 'held_out', 'Job',
           'run_jobs', 'without', 'refit_set']


def make_folds(prepared: Sequence[PreparedRecord],
               n_folds: int) -> tuple[list[list[np.ndarray]], str]:
    """Boolean test masks per fold and record, and their description."""
    n = len(prepared)
    if n >= n_folds:
        folds = []
        for k in range(n_folds):
            test_recs = set(range(k, n, n_folds))
            folds.append([np.full(p.t.size, r in test_recs) for r, p in enumerate(prepared)])
        return folds, f'{n_folds}-fold over {n} records'
    folds = []
    for k in range(n_folds):
        masks = []
        for p in prepared:
            edges = np.linspace(p.t[0], p.t[-1], n_folds + 1)
            masks.append((p.t >= edges[k]) & (p.t <= edges[k + 1]))
        folds.append(masks)
    return folds, f'{n_folds}-fold over contiguous time blocks of {n} record(s)'


def with_models(prepared, models):
    """Return the prepared records with these models (one per record)."""
    return [replace(p, rec=replace(p.rec, model=m)) for p, m in zip(prepared, models)]


def fit_vector(fit: ModelFit, spec: FitSpec) -> np.ndarray:
    """Return the fit-space vector (logs of log-scale parameters) of a fit."""
    x = [np.log(getattr(fit.material, n)) for n in spec.material]
    for eff_name, par_name in spec.effect_params:
        v = fit.effect_values[eff_name][par_name]
        x.append(np.log(v) if effect_parameter(eff_name, par_name).log_scale else v)
    return np.asarray(x, float)


def evaluate(prepared, spec: FitSpec, starts, folds, fold_nfev, effect=None, shape=(),
             priors=None, max_nfev=60, scored=True) -> Candidate:
    """Full-data fit from ``starts``; then (``scored``) the held-out error over ``folds``."""
    full = fit_model(prepared, spec, starts=starts, max_nfev=max_nfev)
    x = fit_vector(full, spec)
    num = den = 0.0
    for p, m in zip(prepared, full.models):
        y = p.y[p.keep]
        num += float(np.sum((y - predict(p, m)[p.keep]) ** 2))
        den += float(np.sum((y - y.mean()) ** 2))
    params = {n: getattr(full.material, n) for n in spec.material}
    if effect is not None:
        params.update(full.effect_values.get(effect, {}))
    flags = list(full.flags)
    for (e, n), v in (priors or {}).items():
        got = full.effect_values.get(e, {}).get(n)
        if got is not None and v != 0 and not (1 / PRIOR_FACTOR <= got / v <= PRIOR_FACTOR):
            flags.append(f"{e}/{n} = {got:.4g} far from the header's {v:.4g}")
    c = Candidate(effect, float(np.sqrt(num / den)), [], full, params, flags, tuple(shape), x,
                  spec)
    c.held_out = False
    return held_out(prepared, c, folds, fold_nfev) if scored else c


def lowest(prepared, spec: FitSpec, groups, folds, fold_nfev, **kw) -> Candidate | None:
    """
    Fit from each group of starts on its own (:func:`evaluate`, unscored); the lowest chi^2.

    The first on a tie; None when there is no group.  Screened together, a start that is
    cheaper at first can end in a higher minimum than another group's.
    """
    fits = (evaluate(prepared, spec, group, folds, fold_nfev, scored=False, **kw)
            for group in groups)
    return min(fits, key=lambda c: c.fit.chi2, default=None)


def held_out(prepared, c: Candidate, folds, fold_nfev) -> Candidate:
    """
    Replace ``c.error`` (in-sample) by the held-out error.

    Refit on each fold's training part (warm start at the full-data fit), predict its
    test part, pool.
    """
    prepared = with_models(prepared, c.fit.models)
    num = den = 0.0
    per_fold = []
    for test in folds:
        train = [~m for m in test]
        fit = fit_model(prepared, c.spec, train=train, starts=[c.x], max_nfev=fold_nfev)
        fn = fd = 0.0
        for p, m, tm in zip(prepared, fit.models, test):
            sel = tm & p.keep
            if not sel.any():
                continue
            y = p.y[sel]
            fn += float(np.sum((y - predict(p, m)[sel]) ** 2))
            fd += float(np.sum((y - y.mean()) ** 2))
        per_fold.append(float(np.sqrt(fn / fd)) if fd > 0 else float('nan'))
        num += fn
        den += fd
    c.in_sample_error = c.error
    c.error, c.fold_errors, c.held_out = float(np.sqrt(num / den)), per_fold, True
    return c


class Job:
    """
    Fit one (effect, shape) candidate on top of a model (full data), or score a candidate.

    Called with ``(name, shape)``: add the effect to every record's model and fit all free
    parameters from a grid of starts (:func:`~.ranking.start_grid`, or the third item,
    ``(name, shape, starts)``), each with the current material and, for an effect fitted
    jointly with a material (``Effect.fitted_material``), with that one (the cheapest start
    is refined).  ``known``: a fit whose values start a second group, refined on its own
    (the one in which C(s) was found, for the search beside it: every parameter it holds
    from there, the new effect's from it or the grid).  A fourth item holds whole vectors
    (material, effects, the new effect: :mod:`.freqstart`), each refined on its own beside
    the grid's: the lowest chi^2 is kept, so a start that is cheaper at first but ends
    higher changes nothing.  Called with a :class:`Candidate`: its held-out error.
    Picklable across a fork.
    """

    def __init__(self, prepared, spec, x, folds, fold_nfev, priors, known=None):
        self.prepared, self.spec, self.x = prepared, spec, x
        self.folds, self.fold_nfev, self.priors = folds, fold_nfev, priors
        self.known = known

    def __call__(self, item) -> Candidate:
        if isinstance(item, Candidate):
            return held_out(self.prepared, item, self.folds, self.fold_nfev)
        name, shape, *more = item
        models = [p.rec.model.with_effect(name) for p in self.prepared]
        prepared = with_models(self.prepared, models)
        spec = FitSpec(self.spec.material,
                       self.spec.effect_params + tuple((name, n) for n in shape))
        grid = more[0] if more else start_grid(name, shape, self.priors)
        grid = grid + self._known_values(name, shape)
        groups = [[np.concatenate([x, np.asarray(c, float)]) for x in group for c in grid]
                  for group in ([self._materials(name)] + [[v] for v in self._known_vector()])]
        groups += [[np.asarray(v, float)] for v in (more[1] if len(more) > 1 else ())]
        return lowest(prepared, spec, groups, self.folds, self.fold_nfev, effect=name,
                      shape=shape, priors=self.priors)

    def _materials(self, name) -> list[np.ndarray]:
        """Return the current vector and (``Effect.fitted_material``) the one with its material."""
        known = get_effect(name).fitted_material
        if not any(n in known for n in self.spec.material):
            return [self.x]
        other = self.x.copy()
        for k, n in enumerate(self.spec.material):
            if n in known:
                other[k] = np.log(known[n])
        return [self.x, other]

    def _known_vector(self) -> list[np.ndarray]:
        """Return the current vector with every value ``known`` holds (material, effects)."""
        if self.known is None or self.known.spec.material != self.spec.material:
            return []
        other = self.x.copy()
        n_mat, eps = len(self.spec.material), self.known.spec.effect_params
        other[:n_mat] = self.known.x[:n_mat]
        for k, ep in enumerate(self.spec.effect_params):
            if ep in eps:
                other[n_mat + k] = self.known.x[n_mat + eps.index(ep)]
        return [other]

    def _known_values(self, name, shape) -> list[list[float]]:
        """Return the new effect's values in ``known`` (fit space): one more start of its grid."""
        eps = () if self.known is None else self.known.spec.effect_params
        if not shape or not all((name, n) in eps for n in shape):
            return []
        n_mat = len(self.known.spec.material)
        return [[float(self.known.x[n_mat + eps.index((name, n))]) for n in shape]]


_JOB = None


def _run_job(item):
    return _JOB(item)


def run_jobs(job, items, n_jobs, say):
    """``[job(item) for item in items]``, in up to ``n_jobs`` forked workers."""
    global _JOB
    if n_jobs > 1 and len(items) > 1:
        import multiprocessing as mp

        try:
            ctx = mp.get_context('fork')
        except ValueError:
            ctx = None
        if ctx is not None:
            _JOB = job
            try:
                with ctx.Pool(min(n_jobs, len(items))) as pool:
                    return pool.map(_run_job, items)
            finally:
                _JOB = None
    out = []
    for item in items:
        say(f'fitting {item.effect if isinstance(item, Candidate) else item[0]}')
        out.append(job(item))
    return out


def refit_set(prepared, start: Candidate, effects, folds, fold_nfev, priors) -> Candidate:
    """Fit ``effects`` ((name, shape), ...) added one by one to ``start``, each from a grid."""
    c = start
    for item in effects:
        c = Job(with_models(prepared, c.fit.models), c.spec, c.x, folds, fold_nfev,
                priors)(item)
    return c


def without(prepared, current: Candidate, name, folds, fold_nfev, priors) -> Candidate:
    """Return the current model without effect ``name``, refitted (warm start, not scored)."""
    n_mat = len(current.spec.material)
    idx = list(range(n_mat)) + [n_mat + k for k, (e, _) in enumerate(current.spec.effect_params)
                                if e != name]
    spec = FitSpec(current.spec.material,
                   tuple(ep for ep in current.spec.effect_params if ep[0] != name))
    models = [p.rec.model.without_effect(name) for p in prepared]
    return evaluate(with_models(prepared, models), spec, [current.x[idx]], folds, fold_nfev,
                    None, (), priors, scored=False)

# SPDX-License-Identifier: Apache-2.0
"""
Missing-physics discovery: finding which effects the model lacks.

Procedure (:func:`diagnose`)
----------------------------
0. Mains interference (``mains``: 50, 60, ``auto``, None) is detected and
   removed from the currents (:mod:`.interference`).
1. Fit the given model (base + effects) to all records: the free material
   parameters (default alpha0, d, kappa_e) and the parameters of the effects in
   ``fit_effects`` by the time-domain output-error fit of :mod:`.timefit`.
2. **Offset test**: the sensor cannot produce a mean current (H(0) = 0), so a
   mean residual over whole stimulus periods is an offset.  Per record its
   z-score (mean / (sigma/sqrt(n))) is computed; if the chi-square of the
   z-scores has p < 1e-6, ``current_offset`` is named and added (fitted).
3. **Stepwise forward selection** (at most ``max_effects`` effects): for every
   catalog (and plugin) effect not yet in the model, add it and refit *all*
   free parameters (material, every effect chosen so far, the candidate's, from
   several starts across its plausible range).  Every candidate is scored by its
   **held-out** error (k-fold cross-validation over records, or contiguous time
   blocks with fewer records than folds): ``||y - y_hat|| / ||y - mean(y)||``
   pooled over the test parts; and by the BIC of the full-data fit
   (chi^2 + k ln n, residuals in units of the noise).  Candidates within
   ``tie_tol`` (5 %) of the best held-out error are ties: among them a
   plausible candidate (no parameter at a bound or outside its plausible range,
   none far from a header prior) wins over an implausible one, then the lower
   BIC.  The winner is added if it is significant: it lowers the held-out error
   by at least ``min_gain`` (3 %), or by half its excess over the noise floor when
   that is less (near the floor: a 200 Hz amplifier pole beside a 1 ms delay leaves
   2.3 % over it, which the 3 % rule could not remove), **and** the BIC by at least
   ``min_delta_bic`` (20, "very strong" on the Kass-Raftery scale).
   ``hydration_drift`` is tried in two shapes, the plain exponential of d and a
   relaxation toward an equilibrium (``equilibrium_ratio`` free); the shape
   with the lower held-out error is kept (BIC within ``tie_tol``).
4. **Backward check** after each addition: an effect chosen earlier whose
   removal raises the held-out error by less than 1 % and the BIC by less than
   ``min_delta_bic`` is dropped.
5. **Exchange pass** when the search ended above the floor (beyond ``stop_factor``, not
   only when ``explained`` is false): each chosen effect (but the offset) is tried against
   every effect not in the model, all refitted; the best exchange that passes the
   significance rule (on the candidate's own plausibility) is made, until none does (an
   early stand-in, e.g. a delay mimicking an amplifier pole and the diffusion's phase
   together, can fill the effect budget; a 44 Hz amplifier pole taken first for a 3.3 ms
   delay and beam inertia at 23 Hz left a 0.3 ms delay and 1.14x the floor, "explained",
   and the beam unnamed).
6. Stop when the held-out error reaches the noise floor (within ``stop_factor``,
   1 %: on data the model explains it ends 0.3-0.6 % over it; the floor is the error
   a perfect model would have, from the measured noise), when nothing passes the
   significance rule, or after ``max_effects`` additions.  ``explained``: final error
   <= ``explained_factor`` (1.15) x floor + 0.001.  On data the model explains, extra
   parameters only fit noise, so nothing is named.
"""
from __future__ import annotations

import os
from dataclasses import replace
from typing import Callable, Sequence

import numpy as np
from scipy.stats import chi2 as chi2_dist

from ..physics.effects import EFFECTS, get_effect
from .blas import single_threaded_blas
from .discovery import priors_from_headers
from .interference import remove_mains, summarize_lines
from .timefit import FitSpec, ModelFit, PreparedRecord, Record, fit_model, predict, prepare
from .verdict import Candidate, Diagnosis, Step

__all__ = [
    'diagnose',
    'Diagnosis',
    'Candidate',
    'Step',
    'DEFAULT_FREE_MATERIAL',
    'priors_from_headers',
    'SHAPES',
]

DEFAULT_FREE_MATERIAL = (
    'charge_stress_coupling_j_per_c',
    'diffusivity_m2_per_s',
    'permittivity_f_per_m',
)
#: effects tried in several shapes: name -> tuples of free parameters (the rest stay at default)
SHAPES = {
    'hydration_drift': (
        ('diffusivity_rate_per_s',),
        ('diffusivity_rate_per_s', 'equilibrium_ratio'),
    )
}
#: a fitted value more than this factor from its header prior is implausible
PRIOR_FACTOR = 3.0


def _folds(prepared: Sequence[PreparedRecord], n_folds: int) -> tuple[list[list[np.ndarray]], str]:
    """Boolean test masks per fold and record."""
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


def _grid(effect_name: str, shape: Sequence[str], priors: dict) -> list[list[float]]:
    """Return the starting values (fit space) of an effect's free parameters."""
    eff = get_effect(effect_name)
    pars = {p.name: p for p in eff.parameters}
    grids = []
    for name in shape:
        par = pars[name]
        lo, hi = par.typical
        if par.log_scale:
            pts = list(
                np.log(
                    np.exp(np.linspace(np.log(max(lo, par.lower)), np.log(min(hi, par.upper)), 3))
                )
            )
        else:
            pts = [lo, 0.0 if lo < 0 < hi else 0.5 * (lo + hi), hi]
        if (effect_name, name) in priors:
            v = priors[(effect_name, name)]
            pts = [np.log(v) if par.log_scale else v] + pts
        grids.append(pts)
    if not grids:
        return [[]]
    mid = [g[1] if len(g) == 3 else g[0] for g in grids]
    if len(grids) == 1:
        return [[v] for v in grids[0]]
    return [mid] + [[g[j] if i == k else mid[i] for i, g in enumerate(grids)]
                    for k in range(len(grids)) for j in (0, len(grids[k]) - 1)]


def _with_models(prepared, models):
    return [replace(p, rec=replace(p.rec, model=m)) for p, m in zip(prepared, models)]


def _fit_vector(fit: ModelFit, spec: FitSpec) -> np.ndarray:
    from .timefit import _param

    x = [np.log(getattr(fit.material, n)) for n in spec.material]
    for eff_name, par_name in spec.effect_params:
        v = fit.effect_values[eff_name][par_name]
        x.append(np.log(v) if _param(eff_name, par_name).log_scale else v)
    return np.asarray(x, float)


def _evaluate(
    prepared,
    spec: FitSpec,
    starts,
    folds,
    fold_nfev,
    effect=None,
    shape=(),
    priors=None,
    max_nfev=60,
    held_out=True,
) -> Candidate:
    """Full-data fit from ``starts``; then (``held_out``) the held-out error over ``folds``."""
    full = fit_model(prepared, spec, starts=starts, max_nfev=max_nfev)
    x = _fit_vector(full, spec)
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
    c = Candidate(
        effect, float(np.sqrt(num / den)), [], full, params, flags, tuple(shape), x, spec
    )
    c.held_out = False
    return _held_out(prepared, c, folds, fold_nfev) if held_out else c


def _held_out(prepared, c: Candidate, folds, fold_nfev) -> Candidate:
    """
    Replace ``c.error`` (in-sample) by the held-out error.

    Refit on each fold's training part (warm start at the full-data fit), predict its
    test part, pool.
    """
    prepared = _with_models(prepared, c.fit.models)
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


class _Job:
    """
    Fit one (effect, shape) candidate on top of the current model (phase 1, full data).

    Or score a fitted candidate by its held-out error (phase 2); picklable across a
    fork.
    """

    def __init__(self, prepared, spec, x, folds, fold_nfev, priors):
        self.prepared, self.spec, self.x = prepared, spec, x
        self.folds, self.fold_nfev, self.priors = folds, fold_nfev, priors

    def __call__(self, item) -> Candidate:
        if isinstance(item, Candidate):
            return _held_out(self.prepared, item, self.folds, self.fold_nfev)
        name, shape = item
        models = [p.rec.model.with_effect(name) for p in self.prepared]
        prepared = _with_models(self.prepared, models)
        spec = FitSpec(
            self.spec.material, self.spec.effect_params + tuple((name, n) for n in shape)
        )
        starts = [
            np.concatenate([self.x, np.asarray(c, float)]) for c in _grid(name, shape, self.priors)
        ]
        return _evaluate(
            prepared,
            spec,
            starts,
            self.folds,
            self.fold_nfev,
            name,
            shape,
            self.priors,
            held_out=False,
        )


_JOB = None


def _run_job(item):
    return _JOB(item)


def _map(job, items, n_jobs, say):
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


def _rank(cands: list[Candidate], tie_tol: float) -> list[Candidate]:
    """
    Ties (within ``tie_tol`` of the best held-out error) first, plausible before implausible.

    Then by BIC; the rest by held-out error.
    """
    if not cands:
        return []
    best = min(c.error for c in cands)
    tied = [c for c in cands if c.error <= (1 + tie_tol) * best]
    rest = sorted((c for c in cands if c not in tied), key=lambda c: c.error)
    return sorted(tied, key=lambda c: (not c.plausible, c.fit.bic)) + rest


def _values(fit: ModelFit, material_names) -> dict:
    m = fit.models[0]
    out = {e.name: e.as_dict() for e in m.effects if e.as_dict()}
    out['material'] = {n: getattr(fit.material, n) for n in material_names}
    return out


def _offset_test(prepared, models) -> dict:
    """Mean residual over whole stimulus periods per record; chi-square of the z-scores."""
    from .freqresp import fundamental_response

    zs, means, ns = [], [], []
    for p, m in zip(prepared, models):
        t, r = p.t[p.keep], (p.y - predict(p, m))[p.keep]
        try:
            f0 = fundamental_response(t, p.w[p.keep], p.y[p.keep]).frequency_hz
            n_per = int((t[-1] - t[0]) * f0)
            if n_per >= 1:
                sel = t < t[0] + n_per / f0
                t, r = t[sel], r[sel]
        except ValueError:
            pass
        zs.append(float(np.mean(r) / (p.sigma / np.sqrt(r.size))))
        means.append(float(np.mean(r)))
        ns.append(r.size)
    c2 = float(np.sum(np.square(zs)))
    return {'mean_a': float(np.average(means, weights=ns)), 'chi2': c2, 'dof': len(zs),
            'p_value': float(chi2_dist.sf(c2, len(zs))), 'max_abs_z': float(np.max(np.abs(zs)))}


def diagnose(records: Sequence[Record], **kwargs) -> Diagnosis:
    """
    Find the effects missing from the records' models.

    See the module docstring and :func:`_diagnose` for the keyword arguments; runs with
    single-threaded BLAS (:mod:`.blas`: the fits' small products only lose time to BLAS
    threads).
    """
    with single_threaded_blas():
        return _diagnose(records, **kwargs)


def _diagnose(
    records: Sequence[Record],
    *,
    free_material: Sequence[str] = DEFAULT_FREE_MATERIAL,
    candidates: Sequence[str] | None = None,
    fit_effects: Sequence[str] = (),
    max_effects: int = 3,
    n_folds: int = 4,
    explained_factor: float = 1.15,
    min_gain: float = 0.03,
    min_delta_bic: float = 20.0,
    tie_tol: float = 0.05,
    offset_p: float = 1e-6,
    mains='auto',
    stop_factor: float = 1.01,
    priors: dict | None = None,
    progress: Callable[[str], None] | None = None,
    settle_s: float = 0.5,
    fold_nfev: int = 15,
    max_cv: int = 4,
    n_jobs: int | None = None,
) -> Diagnosis:
    """
    Find the effects missing from the records' models (see module docstring).

    ``fit_effects``: effects of the given model whose parameters are fitted too
    (e.g. given by name without values); ``priors``: {(effect, parameter): value}
    from data headers (:func:`priors_from_headers`); ``mains``: 50, 60, 'auto' or None.
    """
    say = progress or (lambda msg: None)
    if max_effects < 0:
        raise ValueError(f'max_effects must be >= 0, got {max_effects}')
    n_jobs = min(2, os.cpu_count() or 1) if n_jobs is None else int(n_jobs)
    priors = dict(priors or {})
    records, lines = remove_mains(records, mains)
    prepared = prepare(records, settle_s=settle_s)
    present = list(records[0].model.effect_names)
    pool_names = [
        n for n in (candidates if candidates is not None else list(EFFECTS)) if n not in present
    ]
    folds, cv = _folds(prepared, n_folds)
    free_mat = tuple(free_material)
    spec = FitSpec(
        free_mat, tuple((e, p.name) for e in fit_effects for p in get_effect(e).parameters)
    )

    say('fitting baseline')
    base_x0 = [np.concatenate([np.log([getattr(records[0].model.material, n) for n in free_mat]),
                               np.asarray(c, float)])
               for c in _grid_for_spec(spec, priors, records[0].model)]
    baseline = _evaluate(prepared, spec, base_x0, folds, fold_nfev, priors=priors, max_nfev=60)
    baseline.params = {**baseline.params, **{f'{e}.{n}': baseline.fit.effect_values[e][n]
                                             for e, n in spec.effect_params}}
    nf_num = sum(p.sigma ** 2 * p.keep.sum() for p in prepared)
    nf_den = sum(float(np.sum((p.y[p.keep] - p.y[p.keep].mean()) ** 2)) for p in prepared)
    noise_floor = float(np.sqrt(nf_num / nf_den))
    threshold = explained_factor * noise_floor + 0.001

    def needed_gain(error):
        # relative drop of the held-out error a step must make (module docstring, step 3)
        return min(min_gain, 0.5 * max(error - noise_floor, 0.0) / error)

    current = baseline
    chosen: list[tuple[str, tuple]] = []
    steps: list[Step] = []
    first_ranking: list[Candidate] = []
    first_ties: list[str] = []
    replaced: set[str] = set()
    late_ties: list[str] = []
    offset_info = {}

    def adopt(c: Candidate):
        nonlocal prepared
        prepared = _with_models(prepared, c.fit.models)

    # -- offset test (H(0) = 0: a mean current is an offset) ----------------------
    if 'current_offset' in pool_names and max_effects > 0:
        offset_info = _offset_test(prepared, current.fit.models)
        if offset_info['p_value'] < offset_p:
            say('mean current found: fitting current_offset')
            shape = _shapes('current_offset')[0]
            c = _Job(prepared, current.spec, current.x, folds, fold_nfev, priors)(
                ('current_offset', shape)
            )
            steps.append(
                Step(
                    'current_offset',
                    'added',
                    c.error,
                    c.fit.bic,
                    _values(c.fit, free_mat),
                    f"mean residual current {offset_info['mean_a'] * 1e9:.3g} nA (offset test "
                    f"p = {offset_info['p_value']:.2g}; the sensor has H(0) = 0)",
                )
            )
            chosen.append(('current_offset', shape))
            current = c
            adopt(c)

    # the search, then the exchange pass; once more if that left the budget unspent above
    # the floor, with the effects a swap had replaced offered again (an amplifier pole
    # that replaced a 3.3 ms delay as its tie, beside surface resistance, blocked the
    # delay's return while beam inertia's fit sat in the pole's basin)
    for completion in (False, True):
        if completion and (len(chosen) >= max_effects
                           or current.error <= stop_factor * noise_floor):
            break
        steps_before = len(steps)
        while len(chosen) < max_effects and current.error > stop_factor * noise_floor:
            # an effect dropped by the backward check is not offered again (no add/drop cycles)
            dropped = {st.effect for st in steps if st.action == 'dropped'} | (
                set() if completion else replaced)
            remaining = [n for n in pool_names if n not in {e for e, _ in chosen} | dropped]
            if not remaining:
                break
            items = [(n, s) for n in remaining
                     for s in _shapes(n)]
            say(
                f'step {len(steps) + 1}: {len(items)} candidate fits on '
                f'{min(n_jobs, len(items))} process(es)'
            )
            job = _Job(prepared, current.spec, current.x, folds, fold_nfev, priors)
            fitted = _map(job, items, n_jobs, say)
            # held-out error only for contenders: a candidate that does not pass the BIC rule on
            # the full data cannot be significant (its error stays the in-sample one, marked)
            contenders = sorted((c for c in fitted
                                 if c.fit.bic <= current.fit.bic - min_delta_bic),
                                key=lambda c: c.fit.bic)[:max_cv]
            say(f'step {len(steps) + 1}: held-out error of {len(contenders)} contender(s)')
            scored = _map(job, contenders, n_jobs, say)
            others = [c for c in fitted if not any(c is k for k in contenders)]
            cands = _merge_shapes(scored, tie_tol)
            ranked = _rank(cands, tie_tol) + sorted(others, key=lambda c: c.error)
            first_iteration = not first_ranking
            if first_iteration:
                first_ranking = ranked
            best = ranked[0]
            gain = needed_gain(current.error)
            significant = (best.held_out and best.error <= (1 - gain) * current.error
                           and best.fit.bic <= current.fit.bic - min_delta_bic)
            if not significant:
                break
            ties = [
                c
                for c in ranked[1:]
                if c.error <= (1 + tie_tol) * best.error
                and c.error <= (1 - gain) * current.error
                and c.fit.bic <= current.fit.bic - min_delta_bic
            ]
            if first_iteration:
                first_ties = [c.effect for c in ties]
            else:   # a later step's tie is as much a verdict as the first's (e.g. beam inertia
                # and an amplifier pole next to a delay, which absorbs the pole's phase)
                late_ties.extend(
                    f'{c.effect} instead of {best.effect} (held-out error {c.error:.4f} vs '
                    f'{best.error:.4f}, dBIC {c.fit.bic - best.fit.bic:+.0f})' for c in ties)
            reason = (
                f'held-out error {current.error:.4f} -> {best.error:.4f} '
                f'({current.error / best.error:.2f}x), BIC -{current.fit.bic - best.fit.bic:.0f}'
            )
            if ties:
                reason += '; tie broken by ' + (
                    'plausibility' if best.plausible and any(not t.plausible for t in ties)
                    else 'BIC'
                )
            steps.append(
                Step(
                    best.effect,
                    'added',
                    best.error,
                    best.fit.bic,
                    _values(best.fit, free_mat),
                    reason,
                    [
                        {
                            'effect': t.effect,
                            'error': t.error,
                            'delta_bic': t.fit.bic - best.fit.bic,
                            'params': t.params,
                            'flags': t.flags,
                        }
                        for t in ties
                    ],
                    [c.effect for c in ranked[1:] if c.held_out and c.plausible],
                )
            )
            chosen.append((best.effect, best.shape))
            current = best
            adopt(best)
            # -- backward check ---------------------------------------------------------
            for name, shape in list(chosen[:-1]):
                without = _without(prepared, current, name, folds, fold_nfev, priors)
                if without.fit.bic >= current.fit.bic + min_delta_bic:
                    continue            # removal costs evidence: keep (no need to score it)
                without = _held_out(prepared, without, folds, fold_nfev)
                if (
                    without.error <= 1.01 * current.error
                    and without.fit.bic < current.fit.bic + min_delta_bic
                ):
                    steps.append(
                        Step(
                            name,
                            'dropped',
                            without.error,
                            without.fit.bic,
                            _values(without.fit, free_mat),
                            f'removing it costs nothing (held-out error {current.error:.4f} -> '
                            f'{without.error:.4f})',
                        )
                    )
                    chosen.remove((name, shape))
                    current = without
                    adopt(without)
            # -- swap check: an earlier pick vs its plausible scored runners-up, now that the model
            # holds more (e.g. an amplifier droop that stood in for delay + beam inertia): a swap
            # needs lower BIC and held-out error; a runner-up within tie_tol is reported as a tie
            for name, shape in list(chosen[:-1]):
                if (name, shape) not in chosen:
                    continue
                added = [st for st in steps
                         if st.effect == name and st.action in ('added', 'swapped')]
                base = None
                for alt in [a for st in added[-1:] for a in st.alternatives]:
                    if alt in {e for e, _ in chosen} or alt in replaced:
                        continue
                    if base is None:        # the model without `name`: the same for every alt
                        base = _without(prepared, current, name, folds, fold_nfev, priors)
                    alt_shape = _shapes(alt)[0]
                    cand = _Job(
                        _with_models(prepared, base.fit.models),
                        base.spec,
                        base.x,
                        folds,
                        fold_nfev,
                        priors,
                    )((alt, alt_shape))
                    # the kept effects' values came from fits with `name` in the model and may sit
                    # in its basin (beam inertia at a bound once an amplifier pole is removed): the
                    # set is also built afresh from the baseline, the lower BIC kept
                    fresh = _refit_set(prepared, baseline, [(alt, alt_shape)] + [
                        c for c in chosen if c != (name, shape)], folds, fold_nfev, priors)
                    if fresh.fit.bic < cand.fit.bic:
                        cand = fresh
                    if not cand.plausible:
                        continue
                    cand = _held_out(prepared, cand, folds, fold_nfev)
                    # a tie whichever BIC is lower (e.g. delay + beam inertia vs amplifier + beam
                    # inertia, 0.6 % apart); a swap only with the lower BIC and held-out error
                    if cand.error <= (1 + tie_tol) * current.error and (
                            cand.error >= current.error or cand.fit.bic >= current.fit.bic):
                        late_ties.append(
                            f'{alt} instead of {name} (held-out error {cand.error:.4f} vs '
                            f'{current.error:.4f}, dBIC {cand.fit.bic - current.fit.bic:+.0f})'
                        )
                    if cand.error < current.error and cand.fit.bic < current.fit.bic:
                        steps.append(
                            Step(
                                alt,
                                'swapped',
                                cand.error,
                                cand.fit.bic,
                                _values(cand.fit, free_mat),
                                f'replaces {name} (its tie): held-out error '
                                f'{current.error:.4f} -> '
                                f'{cand.error:.4f}, BIC -{current.fit.bic - cand.fit.bic:.0f}',
                            )
                        )
                        chosen[chosen.index((name, shape))] = (alt, alt_shape)
                        replaced.add(name)
                        current = cand
                        adopt(cand)
                        break
        if completion and len(steps) == steps_before:
            break                   # nothing added: the exchange pass would repeat itself
        # -- exchange pass: the search ended above the noise floor (budget spent, or nothing left
        # significant; within the 'explained' threshold too) and an early pick may stand in for
        # what is missing (from H1, a 5 ms delay
        # for surface resistance and a 50 Hz amplifier pole together took the slot the pole
        # needed): each chosen effect against every effect not in the model, refitted; the best
        # exchange that passes the significance rule is made, until none does
        for _ in range(len(chosen)):
            if current.error <= stop_factor * noise_floor:
                break
            names = {e for e, _ in chosen}
            best_swap = None
            for name, shape in [c for c in chosen if c[0] != 'current_offset']:
                base = _without(prepared, current, name, folds, fold_nfev, priors)
                job = _Job(_with_models(prepared, base.fit.models), base.spec, base.x, folds,
                           fold_nfev, priors)
                items = [(n, sh) for n in pool_names if n not in names
                         for sh in _shapes(n)]
                say(f'exchange {name}: {len(items)} candidate fits')
                # plausible in its own parameters (the model kept may carry flags of its own, e.g.
                # an offset drift beyond the typical range, shared by every candidate)
                fitted = [c for c in _map(job, items, n_jobs, say)
                          if not any(f.startswith(f'{c.effect}/') for f in c.flags)
                          and c.fit.bic <= current.fit.bic - min_delta_bic]
                fitted = sorted(fitted, key=lambda c: c.fit.bic)[:max_cv]
                gain = needed_gain(current.error)
                for cand in _map(job, fitted, n_jobs, say):
                    if cand.held_out and cand.error <= (1 - gain) * current.error and (
                            best_swap is None or cand.error < best_swap[1].error):
                        best_swap = ((name, shape), cand)
            if best_swap is None:
                break
            (name, shape), cand = best_swap
            steps.append(Step(cand.effect, 'swapped', cand.error, cand.fit.bic,
                              _values(cand.fit, free_mat),
                              f'replaces {name} (exchange pass, the search had ended above the '
                              f'noise floor): held-out error {current.error:.4f} -> '
                              f'{cand.error:.4f}, BIC -{current.fit.bic - cand.fit.bic:.0f}'))
            chosen[chosen.index((name, shape))] = (cand.effect, cand.shape)
            replaced.add(name)
            current = cand
            adopt(cand)

    missing = [e for e, _ in chosen]
    explained = bool(current.error <= threshold)
    if missing:
        reason = (
            f"adding {', '.join(missing)} lowers the held-out error {baseline.error:.4f} -> "
            f'{current.error:.4f} ({baseline.error / current.error:.2f}x)'
            + (
                ''
                if explained
                else f'; the residual stays above the noise floor {noise_floor:.4f}: '
                'something else is missing too'
            )
        )
    elif explained:
        reason = (
            f'baseline error {baseline.error:.4f} is at the noise floor ({noise_floor:.4f}) and '
            'no effect improves it significantly: nothing is missing'
        )
    else:
        reason = (
            f'baseline error {baseline.error:.4f} is above the noise floor {noise_floor:.4f} '
            'and no catalog effect explains it'
        )
    return Diagnosis(
        baseline=baseline,
        candidates=first_ranking,
        noise_floor=noise_floor,
        missing_effect=missing[0] if missing else None,
        explained=explained,
        reason=reason,
        ties=first_ties + late_ties,
        prepared=prepared,
        cv=cv,
        steps=steps,
        missing_effects=missing,
        final=current,
        interference=summarize_lines(lines),
        offset_test=offset_info,
    )


def _grid_for_spec(spec: FitSpec, priors, model) -> list[list[float]]:
    """
    Return the starts for the effect parameters of the baseline.

    Current values, or the prior.
    """
    from .timefit import _param

    x = []
    for e, n in spec.effect_params:
        v = priors.get((e, n), model.effect_values(e)[n])
        x.append(np.log(v) if _param(e, n).log_scale else v)
    return [x]


def _merge_shapes(cands: list[Candidate], tie_tol: float) -> list[Candidate]:
    """Keep one shape per effect: the lower held-out error (BIC decides within ``tie_tol``)."""
    by: dict[str, Candidate] = {}
    for c in cands:
        o = by.get(c.effect)
        if o is None:
            by[c.effect] = c
            continue
        if abs(c.error - o.error) <= tie_tol * min(c.error, o.error):
            by[c.effect] = c if c.fit.bic < o.fit.bic else o
        else:
            by[c.effect] = c if c.error < o.error else o
    return list(by.values())


def _shapes(name: str) -> tuple[tuple[str, ...], ...]:
    """Return the free-parameter sets an effect is tried in (SHAPES, else all its parameters)."""
    return SHAPES.get(name, (tuple(p.name for p in get_effect(name).parameters),))


def _refit_set(prepared, baseline: Candidate, effects, folds, fold_nfev, priors) -> Candidate:
    """Fit ``effects`` ((name, shape), ...) added one by one to the baseline, each from a grid."""
    c = baseline
    for item in effects:
        c = _Job(_with_models(prepared, c.fit.models), c.spec, c.x, folds, fold_nfev,
                 priors)(item)
    return c


def _without(prepared, current: Candidate, name, folds, fold_nfev, priors) -> Candidate:
    """Return the current model without effect ``name``, refitted (warm start)."""
    keep = [k for k, (e, _) in enumerate(current.spec.effect_params)]
    n_mat = len(current.spec.material)
    idx = list(range(n_mat)) + [
        n_mat + k for k in keep if current.spec.effect_params[k][0] != name
    ]
    spec = FitSpec(
        current.spec.material, tuple(ep for ep in current.spec.effect_params if ep[0] != name)
    )
    models = [p.rec.model.without_effect(name) for p in prepared]
    return _evaluate(_with_models(prepared, models), spec, [current.x[idx]], folds, fold_nfev,
                     None, (), priors, held_out=False)

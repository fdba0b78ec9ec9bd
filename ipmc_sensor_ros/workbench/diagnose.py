"""Missing-physics discovery: which effect does the model lack?

Procedure (:func:`diagnose`)
----------------------------
1. Fit the given model (base + effects) to all records: the free material
   parameters (default alpha0, d, kappa_e) by the time-domain output-error fit
   of :mod:`.modelfit`.
2. For every catalog (and plugin) effect not yet in the model, add it and fit
   its parameters together with the free material parameters (several starts
   across the effect's plausible range).
3. Score every model by its **held-out** error: k-fold cross-validation over
   records (grouped, so a record is never both trained and tested on); with
   fewer than ``folds`` records, over contiguous time blocks of each record.
   ``error`` is the held-out normalised RMS error of the predicted current,
   ||y - y_hat|| / ||y - mean(y)|| over the test parts, pooled.  Also the BIC
   of the full-data fit (chi^2 + k ln n, residuals in units of the noise).
4. Verdict.  The best candidate is named if it is significant: it lowers the
   held-out error by at least ``min_gain`` (3 %) **and** the BIC by at least
   ``min_delta_bic`` (20, "very strong" evidence on the Kass-Raftery scale).
   On data the model already explains, extra parameters only fit noise: the
   held-out error does not fall and the BIC rises, so no effect is named (no
   false alarm).  ``explained`` says whether the chosen model's held-out error
   reaches the noise floor (the error a perfect model would have, from the
   measured noise): at most ``explained_factor`` (1.15) x floor + 0.001.
   Candidates within 5 % of the best held-out error are reported as ties
   (indistinguishable on these data); parameters at a bound or outside their
   plausible range are flagged.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import os

import numpy as np

from ..physics.effects import EFFECTS, get_effect
from .modelfit import FitSpec, ModelFit, PreparedRecord, Record, fit_model, predict, prepare

__all__ = ["diagnose", "Diagnosis", "DEFAULT_FREE_MATERIAL"]

DEFAULT_FREE_MATERIAL = ("charge_stress_coupling_j_per_c", "diffusivity_m2_per_s", "permittivity_f_per_m")


@dataclass
class Candidate:
    effect: str | None
    error: float
    fold_errors: list[float]
    fit: ModelFit
    params: dict
    flags: list[str] = field(default_factory=list)

    def to_json(self, baseline: "Candidate | None" = None) -> dict:
        d = {"effect": self.effect, "error": self.error, "fold_errors": self.fold_errors,
             "params": self.params, "bic": self.fit.bic, "aic": self.fit.aic,
             "chi2": self.fit.chi2, "n_params": self.fit.n_params, "flags": self.flags}
        if baseline is not None:
            d["delta_bic"] = self.fit.bic - baseline.fit.bic
            d["improvement"] = baseline.error / self.error if self.error > 0 else float("inf")
        return d


@dataclass
class Diagnosis:
    baseline: Candidate
    candidates: list[Candidate]
    noise_floor: float
    missing_effect: str | None
    explained: bool
    reason: str
    ties: list[str]
    prepared: list[PreparedRecord]
    cv: str

    def to_json(self) -> dict:
        return {
            "baseline": {**self.baseline.to_json(), "model": self.baseline.fit.models[0].describe()},
            "candidates": [c.to_json(self.baseline) for c in self.candidates],
            "noise_floor": self.noise_floor,
            "cross_validation": self.cv,
            "verdict": {"missing_effect": self.missing_effect, "explained": self.explained,
                        "reason": self.reason, "ties": self.ties},
        }

    def summary(self) -> str:
        lines = [f"baseline {self.baseline.fit.models[0].describe()}: held-out error "
                 f"{self.baseline.error:.4f} (noise floor {self.noise_floor:.4f}; {self.cv})",
                 f"{'rank':>4} {'effect':<24} {'error':>8} {'x better':>8} {'dBIC':>10}  params / flags"]
        for k, c in enumerate(self.candidates, 1):
            ratio = self.baseline.error / c.error if c.error > 0 else float("inf")
            params = ", ".join(f"{n}={v:.4g}" for n, v in c.params.items())
            flags = ("  [" + "; ".join(c.flags) + "]") if c.flags else ""
            lines.append(f"{k:>4} {c.effect:<24} {c.error:8.4f} {ratio:8.2f} "
                         f"{c.fit.bic - self.baseline.fit.bic:10.1f}  {params}{flags}")
        lines.append(f"verdict: missing effect = {self.missing_effect}; explained = {self.explained}"
                     f" ({self.reason})")
        if self.ties:
            lines.append("ties (indistinguishable on these data): " + ", ".join(self.ties))
        return "\n".join(lines)


def _folds(prepared: Sequence[PreparedRecord], n_folds: int) -> tuple[list[list[np.ndarray]], str]:
    """Boolean test masks per fold and record."""
    n = len(prepared)
    if n >= n_folds:
        order = np.arange(n)
        folds = []
        for k in range(n_folds):
            test_recs = set(order[k::n_folds])
            folds.append([np.full(p.t.size, r in test_recs) for r, p in enumerate(prepared)])
        return folds, f"{n_folds}-fold over {n} records"
    folds = []
    for k in range(n_folds):
        masks = []
        for p in prepared:
            edges = np.linspace(p.t[0], p.t[-1], n_folds + 1)
            masks.append((p.t >= edges[k]) & (p.t <= edges[k + 1]))
        folds.append(masks)
    return folds, f"{n_folds}-fold over contiguous time blocks of {n} record(s)"


def _starts(effect_name: str, free: FitSpec, base_x: np.ndarray) -> list[np.ndarray]:
    eff = get_effect(effect_name)
    if not eff.parameters:
        return [base_x]
    grids = []
    for par in eff.parameters:
        lo, hi = par.typical
        if par.log_scale:
            pts = np.exp(np.linspace(np.log(max(lo, par.lower)), np.log(min(hi, par.upper)), 3))
            grids.append(np.log(pts))
        else:
            grids.append(np.array([lo, 0.0 if lo < 0 < hi else 0.5 * (lo + hi), hi]))
    if len(grids) == 1:
        combos = [[g] for g in grids[0]]
    else:  # vary one parameter at a time around the middle
        mid = [g[1] for g in grids]
        combos = [mid] + [[g[j] if i == k else mid[i] for i, g in enumerate(grids)]
                          for k in range(len(grids)) for j in (0, 2)]
    return [np.concatenate([base_x, np.asarray(c, float)]) for c in combos]


def _score(prepared, fit_fn, folds) -> tuple[float, list[float], ModelFit]:
    """Held-out error over folds, and the full-data fit."""
    num = den = 0.0
    per_fold = []
    for test in folds:
        train = [~m for m in test]
        fit = fit_fn(train)
        fn = fd = 0.0
        for p, m, tm in zip(prepared, fit.models, test):
            sel = tm & p.keep
            if not sel.any():
                continue
            y = p.y[sel]
            y_hat = predict(p, m)[sel]
            fn += float(np.sum((y - y_hat) ** 2))
            fd += float(np.sum((y - y.mean()) ** 2))
        per_fold.append(float(np.sqrt(fn / fd)) if fd > 0 else float("nan"))
        num += fn
        den += fd
    return float(np.sqrt(num / den)), per_fold, fit_fn(None)


def diagnose(records: Sequence[Record], *, free_material: Sequence[str] = DEFAULT_FREE_MATERIAL,
             candidates: Sequence[str] | None = None, n_folds: int = 4,
             explained_factor: float = 1.15, min_gain: float = 0.03, min_delta_bic: float = 20.0,
             progress: Callable[[str], None] | None = None,
             settle_s: float = 0.5, fold_nfev: int = 15, n_jobs: int | None = None) -> Diagnosis:
    """Rank the effects missing from the records' models (see module docstring)."""
    say = progress or (lambda msg: None)
    n_jobs = min(2, os.cpu_count() or 1) if n_jobs is None else int(n_jobs)
    prepared = prepare(records, settle_s=settle_s)
    present = set(records[0].model.effect_names)
    names = [n for n in (candidates if candidates is not None else list(EFFECTS)) if n not in present]
    folds, cv = _folds(prepared, n_folds)
    free_mat = tuple(free_material)
    base_spec = FitSpec(material=free_mat)

    say("fitting baseline")
    # full-data baseline first: its parameters start every other fit
    base_full = fit_model(prepared, base_spec)
    base_x = np.log([getattr(base_full.material, n) for n in free_mat])

    def base_fit(train):
        if train is None:
            return base_full
        return fit_model(prepared, base_spec, train=train, starts=[base_x], max_nfev=fold_nfev)

    b_err, b_folds, b_fit = _score(prepared, base_fit, folds)
    baseline = Candidate(None, b_err, b_folds, b_fit,
                         {n: getattr(b_fit.material, n) for n in free_mat}, b_fit.flags)
    # noise floor: sqrt(sum sigma^2 N) / ||y - mean|| over kept samples
    nf_num = sum(p.sigma ** 2 * p.keep.sum() for p in prepared)
    nf_den = sum(float(np.sum((p.y[p.keep] - p.y[p.keep].mean()) ** 2)) for p in prepared)
    noise_floor = float(np.sqrt(nf_num / nf_den))

    job = _CandidateJob(prepared, free_mat, base_x, folds, fold_nfev)
    if n_jobs > 1 and len(names) > 1:
        import multiprocessing as mp

        try:
            ctx = mp.get_context("fork")
        except ValueError:
            ctx = None
        if ctx is not None:
            global _JOB
            _JOB = job
            say(f"fitting {len(names)} candidates on {n_jobs} processes")
            with ctx.Pool(n_jobs) as pool:
                cands = pool.map(_run_job, names)
            _JOB = None
        else:
            cands = [job(n) for n in names]
    else:
        cands = []
        for name in names:
            say(f"fitting candidate {name}")
            cands.append(job(name))
    cands.sort(key=lambda c: c.error)

    threshold = explained_factor * noise_floor + 0.001
    ties: list[str] = []

    def significant(c: Candidate) -> bool:
        return c.error <= (1 - min_gain) * baseline.error and c.fit.bic <= baseline.fit.bic - min_delta_bic

    if cands and significant(cands[0]):
        best = cands[0]
        missing = best.effect
        explained = bool(best.error <= threshold)
        ties = [c.effect for c in cands[1:] if c.error <= 1.05 * best.error and significant(c)]
        reason = (f"adding {best.effect} lowers the held-out error {baseline.error:.4f} -> "
                  f"{best.error:.4f} ({baseline.error / best.error:.2f}x) and the BIC by "
                  f"{baseline.fit.bic - best.fit.bic:.0f}" +
                  ("" if explained else f"; the residual stays above the noise floor {noise_floor:.4f}: "
                   "something else is missing too"))
    elif baseline.error <= threshold:
        missing, explained = None, True
        reason = (f"baseline error {baseline.error:.4f} is at the noise floor ({noise_floor:.4f}) and "
                  "no effect improves it significantly: nothing is missing")
    else:
        missing, explained = None, False
        reason = (f"baseline error {baseline.error:.4f} is above the noise floor {noise_floor:.4f} "
                  "and no catalog effect explains it")
    return Diagnosis(baseline=baseline, candidates=cands, noise_floor=noise_floor,
                     missing_effect=missing, explained=explained, reason=reason, ties=ties,
                     prepared=prepared, cv=cv)


class _CandidateJob:
    """Fit and score one candidate effect (picklable across a fork)."""

    def __init__(self, prepared, free_mat, base_x, folds, fold_nfev):
        self.prepared, self.free_mat, self.base_x = prepared, free_mat, base_x
        self.folds, self.fold_nfev = folds, fold_nfev

    def __call__(self, name: str) -> Candidate:
        eff = get_effect(name)
        cand_prepared = [PreparedRecord(**{**p.__dict__, "rec": Record(
            p.rec.path, p.rec.sample, p.rec.model.with_effect(name), p.t, p.w, p.y)})
            for p in self.prepared]
        spec = FitSpec(material=self.free_mat,
                       effect_params=tuple((name, par.name) for par in eff.parameters))
        full = fit_model(cand_prepared, spec, starts=_starts(name, spec, self.base_x))
        full_x = _fit_vector(full, spec)

        def cand_fit(train):
            if train is None:
                return full
            return fit_model(cand_prepared, spec, train=train, starts=[full_x], max_nfev=self.fold_nfev)

        err, per_fold, fit = _score(cand_prepared, cand_fit, self.folds)
        params = {**{n: getattr(fit.material, n) for n in self.free_mat},
                  **fit.effect_values.get(name, {})}
        return Candidate(name, err, per_fold, fit, params, fit.flags)


_JOB: _CandidateJob | None = None


def _run_job(name: str) -> Candidate:
    return _JOB(name)


def _fit_vector(fit: ModelFit, spec: FitSpec) -> np.ndarray:
    from .modelfit import _param

    x = [np.log(getattr(fit.material, n)) for n in spec.material]
    for eff_name, par_name in spec.effect_params:
        v = fit.effect_values[eff_name][par_name]
        x.append(np.log(v) if _param(eff_name, par_name).log_scale else v)
    return np.asarray(x, float)

# SPDX-License-Identifier: Apache-2.0
"""
The one state every stage of the search reads and changes.

A :class:`SearchState` holds the prepared (line-free) records with the current model, the
cross-validation folds, the baseline and the current candidate, the effects chosen so far,
the steps taken, and what the tests found.  Each stage (:mod:`.offset_test`, :mod:`.forward`,
:mod:`.backward`, :mod:`.exchange`, :mod:`.outside`) takes the state and changes it through
:meth:`SearchState.adopt` and :meth:`SearchState.record`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from ..timefit import FitSpec
from .fitting import Job, held_out, refit_set, run_jobs, with_models, without
from .ranking import model_values, shapes
from .settings import Settings
from .verdict import Candidate, Step

__all__ = ['SearchState']


@dataclass
class SearchState:
    """See the module docstring; ``chosen`` holds ``(effect, shape)`` pairs in model order."""

    settings: Settings
    prepared: list
    folds: list
    cv: str
    spec: FitSpec
    priors: dict
    pool: list
    say: Callable[[str], None]
    noise_floor: float = float('nan')
    baseline: Candidate | None = None
    current: Candidate | None = None
    chosen: list = field(default_factory=list)
    steps: list = field(default_factory=list)
    first_ranking: list = field(default_factory=list)
    unranked: str = ''                  # why the search stopped before it ranked any effect
    first_ties: list = field(default_factory=list)
    late_ties: list = field(default_factory=list)
    replaced: set = field(default_factory=set)
    offset: dict = field(default_factory=dict)
    lines: list = field(default_factory=list)
    line_test: dict = field(default_factory=dict)
    line_rows: list = field(default_factory=list)     # the MainsLine of every record
    drives: list = field(default_factory=list)        # the Drive of every record
    kept_by: dict = field(default_factory=dict)
    correction: object | None = None
    given_material: object | None = None              # the records' own (the model file's)
    drive_points: list | None = None    # measured response at each drive (.freqstart)
    known: Candidate | None = None      # a fit whose values start every candidate (Job)

    # -- moves ------------------------------------------------------------------------------
    def adopt(self, c: Candidate) -> None:
        """Make ``c`` the current model (its fitted models go into the prepared records)."""
        self.current = c
        self.prepared = with_models(self.prepared, c.fit.models)

    def record(self, effect: str, action: str, c: Candidate, reason: str, **extra) -> Step:
        """Append a :class:`Step` for candidate ``c``."""
        step = Step(effect, action, c.error, c.fit.bic, self.values(c), reason, **extra)
        self.steps.append(step)
        return step

    # -- fitting helpers bound to this state ------------------------------------------------
    def job(self, base: Candidate | None = None) -> Job:
        """Return a :class:`~.fitting.Job` adding effects to ``base`` (default: current)."""
        base = base or self.current
        s = self.settings
        return Job(with_models(self.prepared, base.fit.models), base.spec, base.x, self.folds,
                   s.fold_nfev, self.priors, self.known)

    def run(self, job: Job, items: list) -> list:
        """Run ``job`` on ``items`` in the worker processes."""
        return run_jobs(job, items, self.settings.workers, self.say)

    def score(self, c: Candidate) -> Candidate:
        """Held-out error of ``c`` (if not scored yet)."""
        return c if c.held_out else held_out(self.prepared, c, self.folds,
                                             self.settings.fold_nfev)

    def without(self, name: str, base: Candidate | None = None) -> Candidate:
        """Return the current model (or ``base``) without effect ``name``, refitted, not scored."""
        base = base or self.current
        return without(with_models(self.prepared, base.fit.models), base, name, self.folds,
                       self.settings.fold_nfev, self.priors)

    def refit_set(self, effects) -> Candidate:
        """Return the baseline with ``effects`` ((name, shape), ...) added, not scored."""
        return refit_set(self.prepared, self.baseline, effects, self.folds,
                         self.settings.fold_nfev, self.priors)

    # -- questions --------------------------------------------------------------------------
    def values(self, c: Candidate) -> dict:
        return model_values(c.fit, self.settings.free_material)

    def names(self) -> set[str]:
        return {e for e, _ in self.chosen}

    def needed_gain(self, error: float) -> float:
        """Relative drop of the held-out error a step must make (:class:`~.settings.Settings`)."""
        excess = max(error - self.noise_floor, 0.0)
        return min(self.settings.min_gain, 0.5 * excess / error)

    def at_floor(self, c: Candidate | None = None) -> bool:
        """Return True when the held-out error is within ``stop_factor`` of the noise floor."""
        return (c or self.current).error <= self.settings.stop_factor * self.noise_floor

    @property
    def explained_threshold(self) -> float:
        return self.settings.explained_factor * self.noise_floor + 0.001

    def first_shape(self, name: str) -> tuple:
        return shapes(name)[0]

# SPDX-License-Identifier: Apache-2.0
"""
``diagnose``: which physical effects the records' model lacks, and what lies outside the catalog.

The search runs in :mod:`ipmc_sensor_ros.workbench.discovery` (one module per stage; the
order in :mod:`~ipmc_sensor_ros.workbench.discovery.search`).  In short: mains lines are
removed by what the deflection explains; the offset test names a mean current; stepwise
forward selection adds the catalog (and plugin) effect that lowers the held-out error and the
BIC most, with backward, swap and exchange checks; each named effect stays by its own test;
when the catalog leaves the error above the noise floor a low-order correction C(s) is fitted
and described.  ``docs/discovery.md`` is the user's guide.
"""
from __future__ import annotations

from typing import Callable, Sequence

from .blas import single_threaded_blas
from .discovery.priors import priors_from_headers
from .discovery.ranking import SHAPES
from .discovery.settings import DEFAULT_FREE_MATERIAL, Settings
from .discovery.verdict import Candidate, Diagnosis, Step
from .timepredict import Record

__all__ = ['diagnose', 'Diagnosis', 'Candidate', 'Step', 'Settings', 'DEFAULT_FREE_MATERIAL',
           'priors_from_headers', 'SHAPES']


def diagnose(records: Sequence[Record], *, priors: dict | None = None,
             progress: Callable[[str], None] | None = None, **settings) -> Diagnosis:
    """
    Find the effects missing from the records' models.

    ``priors``: {(effect, parameter): value} from data headers (:func:`priors_from_headers`);
    ``progress``: called with a line of text per stage; every other keyword is a field of
    :class:`~ipmc_sensor_ros.workbench.discovery.settings.Settings`.  Runs with
    single-threaded BLAS (:mod:`.blas`: the fits' small products only lose time to BLAS
    threads).
    """
    from .discovery.search import run_search

    config = Settings.from_kwargs(settings)
    with single_threaded_blas():
        return run_search(records, config, dict(priors or {}), progress or (lambda msg: None))

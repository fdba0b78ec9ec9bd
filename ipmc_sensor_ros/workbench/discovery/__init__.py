# SPDX-License-Identifier: Apache-2.0
"""
Missing-physics discovery: which effects a model lacks, and what lies outside the catalog.

The entry point is :func:`ipmc_sensor_ros.workbench.diagnose.diagnose`; the search it runs
lives here, one module per stage, all passing one :class:`~.state.SearchState`:

* :mod:`.settings` -- the tuning numbers (named, with units and reasons);
* :mod:`.lines` -- mains lines: the measured current less what the model predicts from the
  measured deflection, tested at a stated false-alarm rate;
* :mod:`.residual` -- the noise floor and the error measures;
* :mod:`.fitting`, :mod:`.ranking` -- fitting and scoring candidate models;
* :mod:`.offset_test` -- the direct test of a mean current (H(0) = 0);
* :mod:`.forward`, :mod:`.backward`, :mod:`.exchange` -- the stepwise search;
* :mod:`.significance` -- each effect's own test (what keeps it in the verdict);
* :mod:`.correction`, :mod:`.outside`, :mod:`.plugin` -- a low-order correction C(s) for
  what the catalog does not explain, and its plugin file;
* :mod:`.search` -- the order of the stages; :mod:`.verdict` -- what is returned.

The command-line glue (:mod:`.commands`, :mod:`.priors`) is imported here; the search modules
are imported only by ``diagnose`` (they pull in the fitting code).
"""
from .commands import (SYMBOL_TO_NAME, acts_on_transfer, diagnosis_next_command,
                       effect_free_names, effects_to_fit, free_names, next_command)
from .priors import PRIOR_FACTOR, PRIOR_KEYS, priors_from_headers

__all__ = ['SYMBOL_TO_NAME', 'acts_on_transfer', 'diagnosis_next_command', 'effect_free_names',
           'effects_to_fit', 'free_names', 'next_command', 'PRIOR_FACTOR', 'PRIOR_KEYS',
           'priors_from_headers']

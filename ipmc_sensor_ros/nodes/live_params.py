# SPDX-License-Identifier: Apache-2.0
"""
Live parameter changes of the estimator node: validate, apply, rebuild off the data path.

:class:`LiveParameters` is the part of :class:`~.estimator_node.EstimatorNode` that takes a
``set_parameters`` call: every value is checked and the estimator built on the running
reduction (a refused change says why in one line); a filter change is swapped in at once; a
model change is reduced on a worker thread, coalesced over :data:`REBUILD_QUIET_S`, and swapped
in at the next message without an output jump (the stream continues the old filter's state).
A build that fails despite validation reverts the parameters, with an error naming it.

The node provides ``_lock``, ``_values``, ``_array``, ``_stream``, ``_source``, ``_reduced``
and ``get_logger`` / ``set_parameters``; :meth:`LiveParameters._init_live_parameters` sets up
the rest once the node has read its parameters.
"""
from __future__ import annotations

import threading
import time

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.parameter import Parameter

from ..errors import IpmcError
from ..estimation.array import check_array_estimators
from ..interface import builders as B
from ..interface import specs as C
from ..physics.parameters import short_repr
from . import params as P

__all__ = ['LiveParameters', 'REBUILD_QUIET_S']

#: A model rebuild starts once no parameter change arrived for this long, s (coalescing).
REBUILD_QUIET_S = 0.1

_ERRORS = (IpmcError,)  # every deliberate error of the package names the parameter


class LiveParameters:
    """Validate, apply and rebuild on parameter changes (module docstring); a node mixin."""

    def _init_live_parameters(self) -> None:
        """Start with the running filter built from the node's values; nothing pending."""
        self._model_key = C.model_key(self._values)
        self._pending: tuple | None = None
        self._built_values = self._values      # the values the running filter was built from
        self._wanted: dict | None = None       # accepted values awaiting a rebuild
        self._rebuilt: tuple | None = None     # (values, estimator) built, not yet swapped in
        self._builder: threading.Thread | None = None
        self._changed: set[str] = set()
        self.rebuilds = 0                      #: filters swapped in after parameter changes

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        """
        Validate a change; nothing is applied here.

        Every value is checked and the estimator is built on the current reduction (cheap);
        a model change must also give a finite, non-zero response over the band.  Any failure,
        whatever the exception, refuses the change with a one-line reason.  The new reduction
        itself is built later, off the data path (:meth:`_rebuild_worker`).
        """
        with self._lock:
            self._pending = None
            values = dict(self._values)
            for p in parameters:
                if p.name not in values:
                    continue
                if p.value is None:
                    return SetParametersResult(successful=False,
                                               reason=f"parameter '{p.name}' cannot be unset")
                values[p.name] = list(p.value) if isinstance(values[p.name], list) else p.value
            try:
                key = C.model_key(values)
                new = self._build(values, validate=True)
                if key != self._model_key:
                    band = np.geomspace(values['band_low_hz'], values['band_high_hz'], 64)
                    h = np.array([e.model.frequency_response(band)
                                  for e in (new if isinstance(new, list) else [new])])
                    if not np.all(np.isfinite(h)) or not np.all(np.abs(h) > 0):
                        raise P.ParameterError('these parameter values give a non-finite or '
                                               'zero sensor response over the band')
            except Exception as exc:  # a remote call must never kill the node
                text = ' '.join(str(exc).split())
                text = text if len(text) <= 300 else text[:300] + '...'
                if not isinstance(exc, _ERRORS):
                    text = f'{type(exc).__name__}: {text}'
                return SetParametersResult(successful=False, reason=text)
            self._pending = (values, key, new)
            return SetParametersResult(successful=True)

    def _on_parameters_set(self, parameters) -> None:
        """Apply a validated change: a filter change at once, a model change once rebuilt."""
        with self._lock:
            if self._pending is None:
                return
            values, key, new = self._pending
            self._pending = None
            old = self._values
            self._values = values
            for ch in (self._array.channels if self._array is not None else (self._stream,)):
                ch.max_gap_s = float(values['max_gap_s'])
                ch.rate_tolerance = float(values['rate_tolerance'])
            self._source.selector.stale_after_s = float(values['stale_after_s'])
            # the values that changed (not the QoS overrides a configure declares again)
            self._changed.update(p.name for p in parameters
                                 if p.name in values and values[p.name] != old[p.name])
            if (key != self._model_key or self._wanted is not None or self._builder is not None
                    or self._rebuilt is not None):
                self._wanted = values        # coalesced: only the latest values are built
                if self._builder is None:
                    self._builder = threading.Thread(target=self._rebuild_worker, daemon=True)
                    self._builder.start()
            elif C.filter_key(values) != C.filter_key(old):
                self._swap(new)
                self._built_values = values
                self._log_rebuilt()

    def _rebuild_worker(self) -> None:
        """
        Build the reduction of the latest accepted values off the executor thread.

        Changes arriving within :data:`REBUILD_QUIET_S` of each other are built once; the data
        path keeps the old filter meanwhile (no input is lost to a long build) and swaps at its
        next message (:meth:`_apply_rebuilt`).  A build that fails despite validation reverts
        the parameters to the last built values, with an error naming the failure.
        """
        while True:
            while True:
                with self._lock:
                    seen = self._wanted
                time.sleep(REBUILD_QUIET_S)
                with self._lock:
                    if self._wanted is seen:
                        self._wanted = None
                        break
            if seen is None:
                with self._lock:
                    self._builder = None
                return
            try:
                new, error = self._build(seen), None
            except Exception as exc:  # noqa: B902 - reverted below, never fatal
                new, error = None, exc
            with self._lock:
                if new is not None:
                    # swapped in even when newer values arrived meanwhile: a peer changing
                    # parameters faster than a build takes must not starve every rebuild
                    self._rebuilt = (seen, new)
                    if self._wanted is not None:
                        continue               # then build the newer values
                    self._builder = None
                    return
                if self._wanted is not None:
                    continue                   # a failed build superseded by newer values
                self._builder = None
                old = self._built_values
                self._rebuilt = None
            self.get_logger().error(
                f'parameter change could not be built, reverted: {short_repr(str(error))}')
            self.set_parameters([Parameter(k, value=old[k]) for k in C.MODEL_KEYS
                                 if old[k] != seen[k]])
            return

    def _build(self, values, validate: bool = False):
        """
        Build the estimator of ``values``: one, or a list for a sensor array.

        ``validate``: reuse the running reductions (a cheap check of the values; the new
        reduction is built later, off the data path).
        """
        if self._array is None:
            return B.build_estimator(values, self._reduced if validate else None)
        reduced = ({C.model_key(B.channel_values(values, c)): ch.estimator.reduced
                    for c, ch in enumerate(self._array.channels)} if validate else None)
        new = B.build_channel_estimators(values, reduced)
        check_array_estimators(new)
        return new

    def _swap(self, new) -> None:
        """Swap in ``new`` (:meth:`_build`), continuing each channel's output."""
        if self._array is None:
            self._stream.replace_estimator(new)
        else:
            self._array.replace_estimators(new)

    def _apply_rebuilt(self) -> None:
        """Swap in a filter the worker has built (caller holds the lock)."""
        values, new = self._rebuilt
        self._rebuilt = None
        self._swap(new)
        self._reduced = (new.reduced if self._array is None else
                         {C.model_key(B.channel_values(values, c)): e.reduced
                          for c, e in enumerate(new)})
        self._model_key = C.model_key(values)
        self._built_values = values
        self._log_rebuilt()

    def _log_rebuilt(self) -> None:
        self.rebuilds += 1
        self.get_logger().info('parameters changed: filter rebuilt ('
                               + ', '.join(sorted(self._changed)) + ')')
        self._changed.clear()

    def settle(self, timeout_s: float = 60.0) -> None:
        """Wait for a pending model rebuild and apply it (in-process use and tests)."""
        builder = self._builder
        if builder is not None:
            builder.join(timeout_s)
        with self._lock:
            if self._rebuilt is not None:
                self._apply_rebuilt()

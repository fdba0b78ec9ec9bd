# SPDX-License-Identifier: Apache-2.0
"""
A sensor array's data path in the estimator node (``channels`` > 1).

:class:`ArrayPath` is the part of :class:`~.estimator_node.EstimatorNode` that takes an
N-column ``current`` block: unpack -> :class:`~ipmc_sensor_ros.estimation.array.ArrayStream`
(one stream core per channel, the same rules) -> one ``deflection/block`` with three columns
per channel and points on ``ch<c>/deflection``; README "Sensor arrays".  The node provides the
lock, the cores, the publishers and :meth:`_publish_point`.
"""
from __future__ import annotations

import numpy as np
from std_msgs.msg import Float64MultiArray

from ..errors import DataError
from ..estimation.array import ArrayStream
from ..interface.blocks import unpack_columns
from ..physics.parameters import short_repr
from .messages import claimed_samples

__all__ = ['ArrayPath']


class ArrayPath:
    """The sensor-array data path and counters (module docstring); a node mixin."""

    def channel_counters(self) -> list[dict[str, int]]:
        """Return copies of the counters of every channel (one for a single sensor)."""
        with self._lock:
            if self._array is not None:
                return self._array.counters()
            return [dict(self._stream.counters)]

    @property
    def array(self) -> ArrayStream | None:
        """Return the sensor-array core when ``channels`` > 1, else None."""
        return self._array

    def _on_current_array(self, msg: Float64MultiArray) -> None:
        """Estimate a sensor array's block: unpack N columns, :class:`ArrayStream`, publish."""
        with self._lock:
            if self._rebuilt is not None:
                self._apply_rebuilt()
            array = self._array
            try:
                times, table = unpack_columns(msg, self._in_columns, values_only_ok=False)
            except DataError as exc:
                array.reject(claimed_samples(msg, self._channels + 1), str(exc))
                return
            out = array.feed(times, table)
            if out is None:
                return
            t, w, std, has = out
            one = table.shape[0] == 1   # observe_one: no numpy per sample (40 -> 6 us)
            for c in np.flatnonzero(has).tolist():
                if one:
                    self._diagnostics.observe_one(float(table[0, c]), self._channel_names[c])
                else:
                    self._diagnostics.observe(table[array.channels[c].accepted, c],
                                              channel=self._channel_names[c])
            flags = np.full(w.shape, np.nan)
            for c in np.flatnonzero(has).tolist():
                flags[:, c] = self._limits[c].flags(array.channels[c].estimator, w[:, c])
            cols = [a for c in range(self._channels) for a in (w[:, c], std[:, c], flags[:, c])]
            try:
                self._pub_block.publish(self._packer.pack(t, *cols))
            except Exception as exc:  # back-pressure: counted per channel, never a reset
                array.unpublished(t.size, short_repr(str(exc)), has)
                return
            mode = self._values['publish_points']
            if mode == 'none':
                return
            rows = range(t.size) if mode == 'per_sample' else (t.size - 1,)
            try:
                for c in np.flatnonzero(has).tolist():
                    for k in rows:
                        self._publish_point(float(t[k]), float(w[k, c]), c)
            except Exception as exc:  # the block went out; points are a convenience view
                self._stream.counters['messages_unpublished'] += 1
                self.get_logger().warning(
                    f'could not publish deflection points: {short_repr(str(exc))}',
                    throttle_duration_sec=1.0)

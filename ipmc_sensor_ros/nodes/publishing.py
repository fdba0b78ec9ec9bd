# SPDX-License-Identifier: Apache-2.0
"""
The estimator node's outputs: a block, its points, the smoothed block.

:class:`EstimatePublishing` is the part of :class:`~.estimator_node.EstimatorNode` that hands
the stream core's estimates to the publishers: ``deflection/block``, ``deflection`` (points;
``publish_points``), ``deflection/smoothed/block`` (``smoothed_lag_s``).  A publish that cannot
complete is counted by the stream core, never fatal.  The node provides the lock, the stream
core, the limits, the packer and the publishers.
"""
from __future__ import annotations

import math

import numpy as np
from std_msgs.msg import Float64MultiArray

from ..physics.parameters import short_repr
from .messages import PointCodec

__all__ = ['EstimatePublishing']


class EstimatePublishing:
    """Publish the estimates (module docstring); a node mixin."""

    def _publish(self, block_msg: Float64MultiArray, times, deflections, n: int) -> None:
        """
        Publish a block and its points.

        a publish that cannot complete (e.g. a stalled reliable subscriber) is counted
        by the stream core, never fatal, never a reset.
        """
        try:
            self._pub_block.publish(block_msg)
        except Exception as exc:  # rclpy raises RCLError and others: back-pressure, not a bug
            self._stream.unpublished(n, short_repr(str(exc)))
            return
        mode = self._values['publish_points']
        if mode == 'none':
            return
        try:
            if n == 1 and not isinstance(times, np.ndarray):
                self._publish_point(times, deflections)
            elif mode == 'last_of_block':
                self._publish_point(float(times[-1]), float(deflections[-1]))
            else:
                for t, w in zip(times.tolist(), deflections.tolist()):
                    self._publish_point(t, w)
        except Exception as exc:  # the block went out; points are a convenience view
            self._stream.counters['messages_unpublished'] += 1
            self.get_logger().warning(
                f'could not publish deflection points: {short_repr(str(exc))}',
                throttle_duration_sec=1.0,
            )

    def _publish_smoothed(self, flush: bool = False) -> None:
        """
        Publish what the stream smoothed with ``smoothed_lag_s`` (a block, when ready).

        ``flush``: also the samples held for their lag (the stream ends: deactivate).
        """
        out = self._stream.pop_smoothed(flush)
        if out is None:
            return
        t, w, std = out
        flags = self._limits[0].flags(self._stream.estimator, w)
        try:
            self._pub_smoothed.publish(self._packer.pack(t, w, std, flags))
        except Exception as exc:  # a second view of samples counted already: as the points
            self._stream.counters['messages_unpublished'] += 1
            self.get_logger().warning(
                f'could not publish smoothed deflection: {short_repr(str(exc))}',
                throttle_duration_sec=1.0)

    def _drain(self) -> None:
        """Publish the samples the smoother still holds for their lag (the stream ends here)."""
        if getattr(self, '_pub_smoothed', None) is not None and self._stream is not None:
            with self._lock:
                self._publish_smoothed(flush=True)

    def _publish_point(self, time_s: float, deflection_m: float, channel: int = 0) -> None:
        key = (float(self._values['length_m']), self._values['frame_id'])
        if self._points is None or self._points.key != key:
            self._points = PointCodec(*key)
        limit = self._limits[channel].limit_m
        if not -limit <= deflection_m <= limit:     # REP 117: out of range is +-inf
            deflection_m = math.copysign(math.inf, deflection_m)
        self._pub_points[channel].publish(self._points.encode(time_s, deflection_m))

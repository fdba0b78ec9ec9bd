# SPDX-License-Identifier: Apache-2.0
"""
ROS 2 node ``ipmc_estimator``: sensing current (A) in, tip deflection (m) out.

Unpack -> :class:`~ipmc_sensor_ros.estimation.stream.StreamEstimator` (every rule of the
stream: values, times, gaps, resets, counters) -> publish: ``deflection/block``
(``time_s,deflection_m,deflection_std_m``, one per accepted input message), ``deflection``
(``PointStamped`` (L, 0, w) in the clamp frame: per sample / last of block / none),
``estimator/counters`` (JSON, 1 Hz) and ``/diagnostics``.  Parameter changes are validated by
building the new estimator and applied without an output jump.  README "ROS 2 interface".
"""
from __future__ import annotations

import json
import sys
import threading
from typing import Any

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from geometry_msgs.msg import PointStamped as PointMsg
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, String

from ..interface import specs as C
from ..estimation.deflection import DeflectionEstimator
from ..estimation.inverse import InverseEstimator
from ..estimation.stream import COUNTER_NAMES, StreamEstimator
from ..errors import DataError, IpmcError
from ..physics.parameters import short_repr
from . import params as P
from .messages import (CURRENT_COLUMNS, ESTIMATE_COLUMNS, BlockPacker, claimed_samples,
                       one_sample, point_message, unpack_block)
from .diagnostics import DiagnosticsPublisher
from .runner import run

__all__ = ['EstimatorNode', 'ESTIMATOR_SPECS', 'COUNTER_NAMES', 'PUBLISH_POINTS', 'main']

PUBLISH_POINTS = C.PUBLISH_POINTS

ESTIMATOR_SPECS = C.ESTIMATOR_SPECS

_ERRORS = (IpmcError,)  # every deliberate error of the package names the parameter


class EstimatorNode(Node):
    """
    The estimator node (module docstring).

    ``kwargs`` go to :class:`rclpy.node.Node`, so several nodes can share a process.
    ParameterError if the parameters make no estimator.
    """

    def __init__(self, node_name: str = 'ipmc_estimator', **kwargs: Any):
        super().__init__(node_name, **kwargs)
        self._lock = threading.RLock()
        P.check_unknown_overrides(self, ESTIMATOR_SPECS, kwargs.get('cli_args'),
                                  default_name='ipmc_estimator')
        P.declare(self, ESTIMATOR_SPECS)
        self._configure()
        self._open_io()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._on_parameters_set)
        self.get_logger().info(self._ready_text())

    # -- construction, in the steps a managed node takes one by one --------------
    def _configure(self) -> None:
        """
        Read the parameters, build the model, the filter and the stream core.

        ParameterError naming the parameter if they make no estimator.  No topic is created.
        """
        self._values = P.read(self, ESTIMATOR_SPECS)
        try:
            estimator = C.build_estimator(self._values)
            self._reduced = estimator.reduced
        except _ERRORS as exc:
            raise P.ParameterError(str(exc)) from None
        for path, (digest, names) in C.load_plugins(self._values['plugins']).items():
            self.get_logger().info(f"plugin {path} (sha256 {digest}): effects {', '.join(names)}; "
                                   'loaded once, not re-read')
        self._model_key = C.model_key(self._values)
        self._pending: tuple | None = None
        self._ticks = 0
        logger = self.get_logger()
        self._stream = StreamEstimator(
            estimator, max_gap_s=float(self._values['max_gap_s']),
            max_block_samples=int(self._values['max_block_samples']),
            source=self.resolve_topic_name('current'),
            now_s=lambda: self.get_clock().now().nanoseconds * 1e-9,
            warn=lambda text: logger.warning(text, throttle_duration_sec=1.0))

    def _open_io(self) -> None:
        """Create the subscription, the publishers, the timer and /diagnostics."""
        qos = P.make_qos(self._values)
        self._sub = P.create_subscription(
            self, Float64MultiArray, 'current', self._on_current, qos
        )
        self._pub_block = P.create_publisher(self, Float64MultiArray, 'deflection/block', qos)
        self._packer = BlockPacker(ESTIMATE_COLUMNS)
        self._pub_point = P.create_publisher(self, PointMsg, 'deflection', qos)
        P.check_qos_overrides(self)
        self._pub_counters = self.create_publisher(String, 'estimator/counters', P.COUNTERS_QOS)
        self._diagnostics = DiagnosticsPublisher(
            self, self._values, channels=(self._sub.topic_name,),
            sample_rate_hz=self._stream.estimator.sample_rate_hz, source=self._status)
        self._timer = self.create_timer(1.0, self._on_timer,  # steady: runs before /clock
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _close_io(self) -> None:
        """Destroy what :meth:`_open_io` created (the stream core and its counters stay)."""
        P.destroy_io(self, ('_timer', '_diagnostics', '_sub', '_pub_block', '_pub_point',
                            '_pub_counters'))

    def _ready_text(self) -> str:
        r, estimator = self._reduced, self._stream.estimator
        return (f'ready: {estimator.model.describe()} model, order {r.order} reduction '
                f'over {r.band_hz[0]}-{r.band_hz[1]} Hz, fs = {estimator.sample_rate_hz} Hz, '
                f'leak corner {estimator.inverse.leak_corner_hz} Hz; '
                f"listening on {self.resolve_topic_name('current')}")

    # -- public helpers -------------------------------------------------------
    def counters(self) -> dict[str, int]:
        """
        Return a copy of the stream counters.

        Invariant: :mod:`ipmc_sensor_ros.estimation.stream`.
        """
        with self._lock:
            return dict(self._stream.counters)

    def _status(self) -> dict:
        """
        Counters and estimator state (offset, rest, std, mains line).

        For the counters topic and /diagnostics.
        """
        with self._lock:
            out = dict(self._stream.counters)
            out.update(self._stream.estimator.status())
        if out['offset_a'] is not None:
            out['estimated_offset_a'] = out['offset_a']   # the filter's own offset (kalman)
        return out

    @property
    def stream(self) -> StreamEstimator:
        """Return the stream core (rules, counters) this node feeds."""
        return self._stream

    @property
    def estimator(self) -> InverseEstimator:
        """Return the discrete inverse filter currently in use (replaced on parameter changes)."""
        return self._stream.estimator.inverse

    @property
    def deflection_estimator(self) -> DeflectionEstimator:
        """Return the core model-aware estimator (filter + effects) currently in use."""
        return self._stream.estimator

    @property
    def input_topic(self) -> str:
        return self._stream.source

    @property
    def last_rejection(self) -> str:
        return self._stream.last_rejection

    @property
    def last_warning(self) -> str:
        return self._stream.last_warning

    # -- data path: unpack -> stream core -> publish ----------------------------
    def _on_current(self, msg: Float64MultiArray) -> None:
        with self._lock:
            one = one_sample(msg)
            if one:
                out = self._stream.feed_one(*one)
                if out is not False:
                    self._diagnostics.observe_one(one[1])
                    if out is not None:
                        std = self._stream.estimator.std_m
                        self._publish(
                            self._packer.pack_one(out[0], out[1], std), out[0], out[1], 1
                        )
                    return
            try:
                block = unpack_block(msg, CURRENT_COLUMNS)
            except DataError as exc:
                self._stream.reject(claimed_samples(msg), str(exc))
                return
            out = self._stream.feed(block.times_s, block.values, claimed=claimed_samples(msg))
            if out is not None:
                self._diagnostics.observe(block.values)
                t, w = out
                std = np.full(t.size, self._stream.estimator.std_m)
                self._publish(self._packer.pack(t, w, std), t, w, t.size)

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

    def _publish_point(self, time_s: float, deflection_m: float) -> None:
        self._pub_point.publish(point_message(time_s, float(self._values['length_m']),
                                              deflection_m, self._values['frame_id']))

    # -- periodic -------------------------------------------------------------
    def _on_timer(self) -> None:
        self._ticks += 1
        counters = self._status()
        if counters['samples_in'] == 0 and self._ticks % 5 == 1:
            self.get_logger().info(f'waiting for data on {self._sub.topic_name}')
        counters['node'] = self.get_fully_qualified_name()
        self._pub_counters.publish(String(data=json.dumps(counters)))

    # -- parameters -------------------------------------------------------------
    def _on_set_parameters(self, parameters) -> SetParametersResult:
        """
        Validate a change by building the new design; nothing is applied here.

        Any failure to build, whatever the exception, refuses the change (one-line
        reason).
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
                new = C.build_estimator(values, self._reduced if key == self._model_key else None)
                reduced = new.reduced
            except Exception as exc:  # a remote call must never kill the node
                text = ' '.join(str(exc).split())
                text = text if len(text) <= 300 else text[:300] + '...'
                if not isinstance(exc, _ERRORS):
                    text = f'{type(exc).__name__}: {text}'
                return SetParametersResult(successful=False, reason=text)
            self._pending = (values, key, reduced, new)
            return SetParametersResult(successful=True)

    def _on_parameters_set(self, parameters) -> None:
        """Apply the validated change: swap the filter, output continues without a jump."""
        with self._lock:
            if self._pending is None:
                return
            values, key, reduced, new = self._pending
            self._pending = None
            old = self._values
            self._values = values
            self._stream.max_gap_s = float(values['max_gap_s'])
            if key != self._model_key or C.filter_key(values) != C.filter_key(old):
                self._stream.replace_estimator(new)
                self._reduced, self._model_key = reduced, key
                self.get_logger().info('parameters changed: filter rebuilt ('
                                       + ', '.join(p.name for p in parameters) + ')')


def main(args=None) -> int:
    """Entry point of ``ros2 run ipmc_sensor_ros ipmc_estimator``."""
    return run(EstimatorNode, 'ipmc_estimator', args)


if __name__ == '__main__':
    sys.exit(main())

# SPDX-License-Identifier: Apache-2.0
"""
ROS 2 node ``ipmc_estimator``: sensing current (A) in, tip deflection (m) out.

Unpack -> :class:`~ipmc_sensor_ros.estimation.stream.StreamEstimator` (every rule of the
stream: values, times, gaps, resets, counters) -> publish: ``deflection/block``
(``time_s,deflection_m,deflection_std_m,deflection_beyond_limit``, one per accepted input
message), ``deflection`` (``PointStamped`` (L, 0, w) in the clamp frame: per sample / last of
block / none; z = +-inf beyond the limit of :mod:`~ipmc_sensor_ros.estimation.limits`),
``deflection/smoothed/block`` (the same columns, smoothed with ``smoothed_lag_s``; only
when it is > 0), ``estimator/counters`` (JSON, 1 Hz) and ``/diagnostics``.  Parameter
changes are validated by building the new estimator and applied without an output jump
(:mod:`.live_params`); the publishing is :mod:`.publishing`.
README "ROS 2 interface".

One source per stream: the node follows one publisher of ``current`` (its GID from the message
info; :class:`~ipmc_sensor_ros.interface.sources.SourceSelector`), counts and names the others it
ignores, counts the followed publisher's messages that never arrived (sequence numbers) and those
the middleware reports lost, and switches to another publisher once the followed one has been
silent for ``stale_after_s``.

``channels`` > 1 (a sensor array): N-column blocks through
:class:`~ipmc_sensor_ros.estimation.array.ArrayStream` (one stream core per channel), points on
``ch<c>/deflection``, one /diagnostics status per channel (:mod:`.array_path`); README
"Sensor arrays".
"""
from __future__ import annotations

import json
import sys
import threading
from typing import Any

from geometry_msgs.msg import PointStamped as PointMsg
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from std_msgs.msg import Float64MultiArray, String

from ..interface import builders as B
from ..interface import specs as C
from ..estimation.deflection import DeflectionEstimator
from ..estimation.core import EstimatorCore
from ..estimation.array import ArrayStream, check_array_estimators
from ..estimation.limits import LimitCheck
from ..estimation.stream import COUNTER_NAMES, StreamEstimator
from ..errors import DataError, IpmcError
from ..physics.parameters import short_repr
from . import params as P
from . import topics as T
from ..interface.blocks import current_columns, estimate_columns
from ..interface.sources import SourceSelector
from .messages import (CURRENT_COLUMNS, BlockPacker, OneSampleCodec, PointCodec,
                       claimed_samples, one_sample, unpack_block)
from .diagnostics import DiagnosticsPublisher
from .array_path import ArrayPath
from .publishing import EstimatePublishing
from .live_params import LiveParameters
from .sources import FollowedSource, subscribe_followed
from .barrier import DefectBarrier
from .runner import run

__all__ = ['EstimatorNode', 'ESTIMATOR_SPECS', 'COUNTER_NAMES', 'PUBLISH_POINTS', 'main']

PUBLISH_POINTS = C.PUBLISH_POINTS

ESTIMATOR_SPECS = C.ESTIMATOR_SPECS

_ERRORS = (IpmcError,)  # every deliberate error of the package names the parameter


class EstimatorNode(DefectBarrier, LiveParameters, ArrayPath, EstimatePublishing, Node):
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
        self._channels = int(self._values['channels'])
        try:
            if self._channels == 1 and self._values['model_files']:
                raise P.ParameterError("parameter 'model_files' is for channels > 1; with one "
                                       "channel use 'model_file'")
            if self._channels > 1 and self._values['smoothed_lag_s']:
                raise P.ParameterError("parameter 'smoothed_lag_s' is for one channel; a sensor "
                                       'array (channels > 1) has no smoothed output')
            estimators = B.build_channel_estimators(self._values)
            estimator = estimators[0]
            self._reduced = ({C.model_key(B.channel_values(self._values, c)): e.reduced
                              for c, e in enumerate(estimators)} if self._channels > 1
                             else estimator.reduced)
            check_array_estimators(estimators)
        except _ERRORS as exc:
            raise P.ParameterError(str(exc)) from None
        for path, (digest, names) in C.load_plugins(self._values['plugins']).items():
            self.get_logger().info(f"plugin {path} (sha256 {digest}): effects {', '.join(names)}; "
                                   'loaded once, not re-read')
        P.log_model_files(self, self._values)
        self._init_live_parameters()
        self._ticks = self._quiet_ticks = self._samples_seen = 0
        logger = self.get_logger()
        topic = self.resolve_topic_name('current')
        rules = dict(max_gap_s=float(self._values['max_gap_s']),
                     max_block_samples=int(self._values['max_block_samples']), source=topic,
                     now_s=lambda: self.get_clock().now().nanoseconds * 1e-9,
                     warn=logger.warning,          # the stream bounds what it says
                     rate_tolerance=float(self._values['rate_tolerance']))
        self._source = FollowedSource(self, SourceSelector(float(self._values['stale_after_s'])),
                                      lambda: self._array or self._stream, self._lock)
        self._array = None
        if self._channels == 1:
            self._stream = StreamEstimator(estimator, **rules)
        else:   # a sensor array: one stream per channel, the same rules
            self._array = ArrayStream(estimators, **rules)
            self._stream = self._array.channels[0]
            self._in_columns = current_columns(self._channels)
        self._limits = [LimitCheck() for _ in range(self._channels)]
        self._channel_names = ((topic,) if self._array is None else
                               tuple(f'{topic} ch{c}' for c in range(self._channels)))

    def _open_io(self) -> None:
        """Create the subscription, the publishers, the timer and /diagnostics."""
        qos = T.make_qos(self._values)
        # raw: bytes in, so that one-sample blocks never become message objects (README
        # "Benchmarks": rclpy's conversion of a Float64MultiArray costs more than the estimate)
        self._sub = subscribe_followed(self, Float64MultiArray, 'current',
                                       self._on_current_message, qos,
                                       self._source.on_message_lost)
        self._source.topic = self._sub.topic_name
        self._source.selector.forget()
        self._pub_block = T.create_publisher(self, Float64MultiArray, 'deflection/block', qos)
        self._packer = BlockPacker(estimate_columns(self._channels))
        self._one_in = OneSampleCodec(CURRENT_COLUMNS)
        self._one_out = OneSampleCodec(estimate_columns(1))
        self._points: PointCodec | None = None
        self._pub_points = [T.create_publisher(self, PointMsg, 'deflection', qos)
                            if self._channels == 1 else
                            T.create_publisher(self, PointMsg, f'ch{c}/deflection', qos)
                            for c in range(self._channels)]
        self._pub_point = self._pub_points[0]
        self._pub_smoothed = (T.create_publisher(self, Float64MultiArray,
                                                 'deflection/smoothed/block', qos)
                              if self._values['smoothed_lag_s'] else None)
        T.check_qos_overrides(self)
        self._pub_counters = self.create_publisher(String, 'estimator/counters', T.COUNTERS_QOS)
        self._diagnostics = DiagnosticsPublisher(
            self, self._values, channels=self._channel_names,
            sample_rate_hz=self._stream.estimator.sample_rate_hz, source=self._status)
        self._timer = self.create_timer(1.0, self._on_timer,  # steady: runs before /clock
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _close_io(self) -> None:
        """Destroy what :meth:`_open_io` created (the stream core and its counters stay)."""
        T.destroy_io(self, ('_timer', '_diagnostics', '_sub', '_pub_block', '_pub_points',
                            '_pub_smoothed', '_pub_counters'))
        self._pub_point = None

    def _ready_text(self) -> str:
        estimator = self._stream.estimator
        r = estimator.reduced
        return (f'ready: {estimator.model.describe()} model, order {r.order} reduction '
                f'over {r.band_hz[0]}-{r.band_hz[1]} Hz, fs = {estimator.sample_rate_hz} Hz, '
                f'{estimator.estimator} estimator, mains {estimator.mains_hz}; '
                f"listening on {self.resolve_topic_name('current')}"
                + (f' ({self._channels} channels)' if self._array is not None else ''))

    # -- public helpers -------------------------------------------------------
    def counters(self) -> dict[str, int]:
        """
        Return a copy of the stream counters.

        Invariant: :mod:`ipmc_sensor_ros.estimation.stream`.  A sensor array: the sums over the
        channels (:meth:`channel_counters` per channel).
        """
        with self._lock:
            if self._array is not None:
                return self._array.totals()
            return dict(self._stream.counters)

    def _status(self, stream: StreamEstimator | None = None) -> dict:
        """
        Counters and estimator state (offset, rest, std, mains line) of a stream.

        For the counters topic and /diagnostics; a sensor array: ``{channel name: status}``.
        """
        if stream is None and self._array is not None:
            return {name: self._status(ch)
                    for name, ch in zip(self._channel_names, self._array.channels)}
        stream = stream or self._stream
        channel = 0 if self._array is None else self._array.channels.index(stream)
        with self._lock:
            out = dict(stream.counters)
            out['samples_beyond_limit'] = self._limits[channel].count
            out.update(stream.estimator.status())
            out['deflection_limit_m'] = self._limits[channel].limit_m
            out.update(stream.status())
            out.update(self._source.status())
        if out['offset_a'] is not None:
            out['estimated_offset_a'] = out['offset_a']   # the filter's own offset (kalman)
        return out

    @property
    def stream(self) -> StreamEstimator:
        """Return the stream core (rules, counters) this node feeds."""
        return self._stream

    @property
    def estimator(self) -> EstimatorCore:
        """Return the estimator core currently in use (replaced on parameter changes)."""
        self.settle()
        return self._stream.estimator.core

    @property
    def deflection_estimator(self) -> DeflectionEstimator:
        """Return the core model-aware estimator (filter + effects) currently in use."""
        self.settle()
        return self._stream.estimator

    @property
    def input_topic(self) -> str:
        return self._stream.source if self._array is None else self._array.source

    @property
    def last_rejection(self) -> str:
        return self._stream.last_rejection

    @property
    def last_warning(self) -> str:
        return self._stream.last_warning

    # -- data path: unpack -> stream core -> publish ----------------------------
    def _on_current_message(self, raw, info=None) -> None:
        """Subscription callback: follow one publisher (module docstring), then the data path."""
        raw, info = FollowedSource.unpack(raw, info)
        if info is None or self._source.admit(info):
            self._on_current_raw(raw)

    def _on_current_raw(self, raw: bytes) -> None:
        """
        Take one serialised message (the data path).

        A one-sample current block is read from its bytes and its estimate written as bytes
        (:class:`OneSampleCodec`); anything else is deserialised and takes :meth:`_on_current`.
        """
        if self._array is None:
            one = self._one_in.decode(raw)
            if one is not None:
                return self._feed_one(*one)
        try:
            msg = deserialize_message(raw, Float64MultiArray)
        except Exception as exc:  # bytes that are no Float64MultiArray: counted, never fatal
            with self._lock:
                (self._array or self._stream).reject(
                    0, f'undecodable message ({len(raw)} bytes): {short_repr(str(exc))}')
            return
        self._on_current(msg)

    def _on_current(self, msg: Float64MultiArray) -> None:
        if self._array is not None:
            return self._on_current_array(msg)
        one = one_sample(msg)
        if one:
            return self._feed_one(*one)
        with self._lock:
            if self._rebuilt is not None:
                self._apply_rebuilt()
            try:
                block = unpack_block(msg, CURRENT_COLUMNS)
            except DataError as exc:
                self._stream.reject(claimed_samples(msg), str(exc))
                return
            out = self._stream.feed(block.times_s, block.values, claimed=claimed_samples(msg))
            if out is not None:
                self._diagnostics.observe(block.values[self._stream.accepted])
                t, w = out
                est = self._stream.estimator
                flags = self._limits[0].flags(est, w)
                self._publish(self._packer.pack(t, w, self._stream.last_std_m, flags),
                              t, w, t.size)
            if self._pub_smoothed is not None:
                self._publish_smoothed()

    def _feed_one(self, time_s: float, current_a: float) -> None:
        """Estimate one timed sample (:meth:`StreamEstimator.feed_one`); publish it as bytes."""
        with self._lock:
            if self._rebuilt is not None:
                self._apply_rebuilt()
            out = self._stream.feed_one(time_s, current_a)
            if out is not None:
                self._diagnostics.observe_one(current_a)
                t, w = out
                est = self._stream.estimator
                flag = self._limits[0].flag_one(est, w)
                self._publish(self._one_out.encode(t, w, est.std_m, flag), t, w, 1)
            if self._pub_smoothed is not None:
                self._publish_smoothed()

    def destroy_node(self) -> None:
        """Publish what the smoother holds, wait ``topics.FLUSH_TIMEOUT_S`` for acks, destroy."""
        self._drain()
        pub = getattr(self, '_pub_smoothed', None)
        if pub is not None:
            pub.wait_for_all_acked(Duration(nanoseconds=int(T.FLUSH_TIMEOUT_S * 1e9)))
        self._say_totals()
        super().destroy_node()

    def _say_totals(self) -> None:
        """Log what became of the samples taken, in the counters' terms (one line)."""
        stream, array = getattr(self, '_stream', None), getattr(self, '_array', None)
        if stream is None and array is None:
            return                  # a managed node never configured, or cleaned up
        c = array.totals() if array is not None else stream.counters
        self.get_logger().info(
            f"stopping: {c['samples_in']} sample(s) in, {c['samples_out']} published, "
            f"{c['samples_rejected']} refused, {c['samples_dropped']} dropped, "
            f"{c['samples_unpublished']} unpublished (estimator/counters has the reasons)")

    # -- periodic -------------------------------------------------------------
    def _on_timer(self) -> None:
        self._ticks += 1
        self._diagnostics.follow_rate(self._stream.sample_rate_hz)
        counters = self._status()
        if self._array is not None:
            counters = dict(self._array.totals(), channels=list(counters.values()))
        if counters['samples_in'] == 0 and self._ticks % 5 == 1:
            self.get_logger().info(f'waiting for data on {self._sub.topic_name}')
        n = counters['samples_in']
        self._quiet_ticks = self._quiet_ticks + 1 if n == self._samples_seen else 0
        self._samples_seen = n
        if self._quiet_ticks > float(self._values['stale_after_s']):      # 1 s ticks
            self._drain()       # the input went silent: what the smoother holds goes out
        counters['node'] = self.get_fully_qualified_name()
        self._pub_counters.publish(String(data=json.dumps(counters)))


def main(args=None) -> int:
    """Entry point of ``ros2 run ipmc_sensor_ros ipmc_estimator``."""
    return run(EstimatorNode, 'ipmc_estimator', args)


if __name__ == '__main__':
    sys.exit(main())

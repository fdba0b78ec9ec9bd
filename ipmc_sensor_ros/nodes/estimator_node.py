"""ROS 2 node ``ipmc_estimator``: sensing current (A) in, tip deflection (m) out.

A thin shell over :class:`ipmc_sensor_ros.estimation.deflection.DeflectionEstimator` (model-aware
inverse filter; the same code path as ``ipmc-model estimate``):

* subscribes ``current`` (``std_msgs/Float64MultiArray``, block layout of
  :mod:`.messages`: 2-D ``time_s,current_A`` pairs, or a 1-D values-only array);
* publishes ``deflection`` (``geometry_msgs/PointStamped``, point = (L, 0, w) in
  the clamp frame, one per sample / last of block / off), ``deflection/block``
  (``Float64MultiArray``, ``time_s,deflection_m``, one per accepted input
  message) and ``estimator/counters`` (``std_msgs/String`` JSON, 1 Hz);
* validates every message before it touches the filter (rejected messages
  never change filter state), resets the filter on backward time jumps and on
  gaps longer than ``max_gap_s``, and rebuilds the filter without an output
  jump on runtime parameter changes.

See docs/ros_interface.md for the full interface.
"""
from __future__ import annotations

import json
import math
import sys
import threading
from typing import Any

import numpy as np
from geometry_msgs.msg import PointStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, String

from ..interface import specs as C
from ..estimation.deflection import DeflectionEstimator
from ..estimation.inverse import MAX_ABS_CURRENT_A, EstimatorError, InverseEstimator, validate_block
from ..physics.parameters import ParameterError
from ..lti.reduction import ReductionError
from . import params as P
from .messages import (CURRENT_COLUMNS, DEFLECTION_COLUMNS, SAMPLE_LABEL, BlockPacker,
                       LayoutError, claimed_samples, unpack_block)
from .runner import run

__all__ = ["EstimatorNode", "ESTIMATOR_SPECS", "COUNTER_NAMES", "PUBLISH_POINTS", "main"]

PUBLISH_POINTS = C.PUBLISH_POINTS

#: Relative tolerance on the median sample period of a block against 1/sample_rate_hz.
PERIOD_TOLERANCE = 0.01

#: Largest representable stamp (builtin_interfaces/Time.sec is int32), s.
MAX_STAMP_S = 2.0 ** 31 - 1.0

COUNTER_NAMES = ("messages_in", "samples_in", "samples_out", "samples_rejected",
                 "messages_rejected", "samples_dropped", "resets", "gaps", "gaps_bridged")

ESTIMATOR_SPECS = C.ESTIMATOR_SPECS

#: Parameters whose change needs a new reduction (the sensor model changes).
_MODEL_KEYS = P.GEOMETRY_NAMES + P.MATERIAL_NAMES + ("model", "effects", "reduction_order",
                                                      "band_low_hz", "band_high_hz")

_ERRORS = (ParameterError, EstimatorError, ReductionError, LayoutError, P.ConfigurationError)


def _model_key(values: dict) -> tuple:
    return tuple((k, tuple(values[k]) if isinstance(values[k], list) else values[k])
                 for k in _MODEL_KEYS)


def _filter_kwargs(values: dict) -> dict:
    offset = float(values["offset_corner_hz"])
    return {"sample_rate_hz": float(values["sample_rate_hz"]),
            "leak_corner_hz": float(values["leak_corner_hz"]),
            "offset_corner_hz": offset if offset > 0.0 else None,
            "prewarp_hz": None}


def check_values(values: dict) -> None:
    """Checks of the non-physical parameters; raise ConfigurationError naming one."""
    try:
        P.check_choice("publish_points", values["publish_points"], PUBLISH_POINTS)
        P.check_choice("qos_reliability", values["qos_reliability"], ("reliable", "best_effort"))
    except ParameterError as exc:
        raise P.ConfigurationError(str(exc)) from None
    gap = float(values["max_gap_s"])
    if not (math.isfinite(gap) and gap > 0.0):
        raise P.ConfigurationError(f"parameter 'max_gap_s' must be > 0 s, got {gap!r}")
    if float(values["offset_corner_hz"]) < 0.0:
        raise P.ConfigurationError("parameter 'offset_corner_hz' must be >= 0 Hz (0 = off), "
                                   f"got {values['offset_corner_hz']!r}")


def design(values: dict, reduced=None):
    """Build (reduced model, fresh core DeflectionEstimator) from parameter values
    (:func:`ipmc_sensor_ros.interface.specs.build_estimator`, as ``ipmc-model estimate`` does).

    ``reduced`` is reused when given (the model part did not change).  Raises
    one of ParameterError / ReductionError / EstimatorError / ConfigurationError
    with a message naming the parameter.
    """
    check_values(values)
    est = C.build_estimator(values, reduced)
    return est.reduced, est


class EstimatorNode(Node):
    """Deflection estimator node; see the module docstring and docs/ros_interface.md.

    ``kwargs`` go to :class:`rclpy.node.Node` (context, namespace,
    parameter_overrides, ...), so several nodes can share one process.
    Raises :class:`~ipmc_sensor_ros.nodes.params.ConfigurationError` if the
    parameters cannot make a valid estimator.
    """

    def __init__(self, node_name: str = "ipmc_estimator", **kwargs: Any):
        super().__init__(node_name, **kwargs)
        self._lock = threading.RLock()
        P.check_unknown_overrides(self, ESTIMATOR_SPECS, kwargs.get("cli_args"))
        P.declare(self, ESTIMATOR_SPECS)
        self._values = P.read(self, ESTIMATOR_SPECS)
        try:
            self._reduced, self._estimator = design(self._values)
        except _ERRORS as exc:
            raise P.ConfigurationError(str(exc)) from None
        for path, (digest, names) in C.load_plugins(self._values["plugins"]).items():
            self.get_logger().info(f"plugin {path} (sha256 {digest}): effects {', '.join(names)}; "
                                   "loaded once, not re-read")
        self._model_key = _model_key(self._values)
        self._refresh_fast_path()
        self._pending: tuple | None = None
        self._counters = dict.fromkeys(COUNTER_NAMES, 0)
        self._last_time_s: float | None = None
        self.last_rejection: str = ""
        self.last_warning: str = ""
        self._ticks = 0

        qos = P.make_qos(self._values)
        self._sub = self.create_subscription(Float64MultiArray, "current", self._on_current, qos)
        self._pub_block = self.create_publisher(Float64MultiArray, "deflection/block", qos)
        self._packer = BlockPacker(DEFLECTION_COLUMNS)
        self._topic = self._sub.topic_name
        self._pub_point = self.create_publisher(PointStamped, "deflection", qos)
        self._pub_counters = self.create_publisher(String, "estimator/counters", P.COUNTERS_QOS)
        # Steady clock: counters and the waiting message must not stall under
        # use_sim_time before /clock arrives.
        self._timer = self.create_timer(1.0, self._on_timer,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._on_parameters_set)
        r = self._reduced
        self.get_logger().info(
            f"ready: {self._estimator.model.describe()} model, order {r.order} reduction "
            f"over {r.band_hz[0]}-{r.band_hz[1]} Hz, fs = {self._estimator.sample_rate_hz} Hz, "
            f"leak corner {self._estimator.inverse.leak_corner_hz} Hz; listening on {self._sub.topic_name}")

    # -- public helpers -------------------------------------------------------
    def counters(self) -> dict[str, int]:
        """Copy of the counters (ints).

        Invariant: samples_in == samples_out + samples_rejected + samples_dropped.
        """
        with self._lock:
            return dict(self._counters)

    @property
    def estimator(self) -> InverseEstimator:
        """The discrete inverse filter currently in use (replaced on parameter changes)."""
        return self._estimator.inverse

    @property
    def deflection_estimator(self) -> DeflectionEstimator:
        """The core model-aware estimator (filter + effects) currently in use."""
        return self._estimator

    @property
    def input_topic(self) -> str:
        return self._sub.topic_name

    # -- logging helpers ------------------------------------------------------
    def _warn(self, text: str) -> None:
        self.last_warning = text
        self.get_logger().warning(text, throttle_duration_sec=1.0)

    def _reject(self, n: int, reason: str) -> None:
        self._counters["messages_rejected"] += 1
        self._counters["samples_rejected"] += n
        self.last_rejection = reason
        self.get_logger().warning(f"rejected message on {self._sub.topic_name} ({n} sample(s)): "
                                  f"{reason}", throttle_duration_sec=5.0)

    def _reset(self, text: str) -> None:
        self._estimator.reset()
        self._counters["resets"] += 1
        self._warn(text)

    # -- data path ------------------------------------------------------------
    def _refresh_fast_path(self) -> None:
        """Cache the values the one-sample path reads (after every parameter change)."""
        self._max_gap_s = float(self._values["max_gap_s"])
        self._fs = float(self._estimator.sample_rate_hz)

    def _times(self, times: np.ndarray | None, n: int) -> np.ndarray:
        """Check the sample times of a block (or infer them); raise EstimatorError."""
        fs = self._estimator.sample_rate_hz
        if times is None:
            if self._last_time_s is None:
                t0 = self.get_clock().now().nanoseconds * 1e-9
                return t0 + np.arange(n) / fs
            return self._last_time_s + np.arange(1, n + 1) / fs
        # strictly increasing with finite ends implies all finite and within the ends
        # (NaN fails 'dt > 0'), so the range is checked on the first and last time only
        dt = np.diff(times)
        if not (dt > 0.0).all():
            if not np.all(np.isfinite(times)):
                raise EstimatorError("sample times contain non-finite values")
            k = int(np.argmax(~(dt > 0.0)))
            raise EstimatorError(f"sample times are not strictly increasing (index {k + 1}: "
                                 f"{times[k + 1]!r} s after {times[k]!r} s)")
        first, last = float(times[0]), float(times[-1])
        if not (math.isfinite(first) and math.isfinite(last)):
            raise EstimatorError("sample times contain non-finite values")
        if first < 0.0 or last > MAX_STAMP_S:
            raise EstimatorError(f"sample times must lie in [0, {MAX_STAMP_S:.0f}] s")
        if n >= 2:
            period = float(np.median(dt))
            if abs(period * fs - 1.0) > PERIOD_TOLERANCE:
                raise EstimatorError(f"median sample period {period:.6g} s does not match "
                                     f"sample_rate_hz = {fs} Hz (1/fs = {1.0 / fs:.6g} s, "
                                     f"tolerance {PERIOD_TOLERANCE:.0%})")
        return times

    def _on_current(self, msg: Float64MultiArray) -> None:
        with self._lock:
            if self._one_sample(msg):
                return
            n_claimed = claimed_samples(msg)
            self._counters["messages_in"] += 1
            self._counters["samples_in"] += n_claimed
            try:
                block = unpack_block(msg, CURRENT_COLUMNS)
                current = validate_block(block.values,
                                         max_samples=int(self._values["max_block_samples"]))
                times = self._times(block.times_s, current.size)
            except (LayoutError, EstimatorError) as exc:
                self._reject(n_claimed, str(exc))
                return
            try:
                self._process(times, current)
            except Exception as exc:  # last resort: never let a callback kill the node
                self._estimator.reset()
                self._counters["samples_dropped"] += current.size
                self.get_logger().error(f"dropped a block of {current.size} sample(s): {exc!r}")

    def _one_sample(self, msg: Float64MultiArray) -> bool:
        """Lean path of a well-formed one-sample timed message that needs no reset, gap
        handling or effects: the general path's checks and results in scalar Python
        (identical output and counters, tested).  Returns False, having touched
        nothing, for any other message, which then takes the general path (and gets
        its precise rejection message)."""
        layout = msg.layout
        dims = layout.dim
        if len(dims) != 2 or layout.data_offset != 0:
            return False
        d0, d1 = dims
        if (d0.size != 1 or d0.stride != 2 or d1.size != 2 or d1.stride != 2
                or d0.label != SAMPLE_LABEL or d1.label != CURRENT_COLUMNS):
            return False
        data = msg.data
        if len(data) != 2:
            return False
        t, i = data[0], data[1]
        # NaN fails every comparison, so non-finite values leave through the general path
        if not (0.0 <= t <= MAX_STAMP_S and -MAX_ABS_CURRENT_A <= i <= MAX_ABS_CURRENT_A):
            return False
        last = self._last_time_s
        if last is not None:
            step = t - last
            if not (0.0 < step <= self._max_gap_s and step * self._fs <= 1.5):
                return False
        est = self._estimator
        if not est.plain:
            return False
        self._counters["messages_in"] += 1
        self._counters["samples_in"] += 1
        t_out, w = est.process_one(t, i)
        if not math.isfinite(w):
            est.reset()
            self._counters["samples_dropped"] += 1
            self._warn(f"non-finite estimate on {self._topic}: block dropped, filter reset")
            return True
        self._last_time_s = t
        self._pub_block.publish(self._packer.pack_one(t_out, w))
        if self._values["publish_points"] != "none":
            self._publish_point(t_out, w)
        self._counters["samples_out"] += 1
        return True

    def _process(self, times: np.ndarray, current: np.ndarray) -> None:
        topic = self._topic
        if self._last_time_s is not None:
            step = float(times[0] - self._last_time_s)
            if step <= 0.0:
                self._reset(f"time jumped back by {-step:.6g} s on {topic}: filter reset")
            elif step > float(self._values["max_gap_s"]):
                self._counters["gaps"] += 1
                self._reset(f"gap of {step:.6g} s (> max_gap_s = {self._values['max_gap_s']} s) "
                            f"on {topic}: filter reset")
            elif step * self._estimator.sample_rate_hz > 1.5:
                self._counters["gaps_bridged"] += 1
        t_out, y = self._estimator.process(times, current)
        if not np.all(np.isfinite(y)):
            self._estimator.reset()
            self._counters["samples_dropped"] += current.size
            self._warn(f"non-finite estimate on {topic}: block dropped, filter reset")
            return
        self._last_time_s = float(times[-1])
        self._pub_block.publish(self._packer.pack(t_out, y))
        self._publish_points(t_out, y)
        self._counters["samples_out"] += current.size

    def _publish_points(self, times: np.ndarray, y: np.ndarray) -> None:
        mode = self._values["publish_points"]
        if mode == "none":
            return
        if mode == "last_of_block":
            times, y = times[-1:], y[-1:]
        for t, w in zip(times.tolist(), y.tolist()):
            self._publish_point(t, w)

    def _publish_point(self, time_s: float, deflection_m: float) -> None:
        sec, nsec = divmod(round(time_s * 1e9), 1_000_000_000)
        p = PointStamped()
        p.header.stamp.sec = sec
        p.header.stamp.nanosec = nsec
        p.header.frame_id = self._values["frame_id"]
        p.point.x = float(self._values["length_m"])
        p.point.z = deflection_m
        self._pub_point.publish(p)

    # -- periodic -------------------------------------------------------------
    def _on_timer(self) -> None:
        self._ticks += 1
        counters = self.counters()
        if counters["samples_in"] == 0 and self._ticks % 5 == 1:
            self.get_logger().info(f"waiting for data on {self._sub.topic_name}")
        counters["node"] = self.get_fully_qualified_name()
        self._pub_counters.publish(String(data=json.dumps(counters)))

    # -- parameters -------------------------------------------------------------
    def _on_set_parameters(self, parameters) -> SetParametersResult:
        """Validate a change by building the new design; nothing is applied here.  Any
        failure to build, whatever the exception, refuses the change (one-line reason)."""
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
                key = _model_key(values)
                reduced, new = design(values, self._reduced if key == self._model_key else None)
            except Exception as exc:  # a remote call must never kill the node
                text = " ".join(str(exc).split())
                text = text if len(text) <= 300 else text[:300] + "..."
                if not isinstance(exc, _ERRORS):
                    text = f"{type(exc).__name__}: {text}"
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
            self._refresh_fast_path()
            if key != self._model_key or _filter_kwargs(values) != _filter_kwargs(old):
                new.continue_from(self._estimator)
                self._estimator = new
                self._refresh_fast_path()
                self._reduced, self._model_key = reduced, key
                self.get_logger().info("parameters changed: filter rebuilt ("
                                       + ", ".join(p.name for p in parameters) + ")")


def main(args=None) -> int:
    """Entry point of ``ros2 run ipmc_sensor_ros ipmc_estimator``."""
    return run(EstimatorNode, "ipmc_estimator", args)


if __name__ == "__main__":
    sys.exit(main())

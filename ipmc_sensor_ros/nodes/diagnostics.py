# SPDX-License-Identifier: Apache-2.0
"""
``/diagnostics`` publisher: a thin ROS shell over :mod:`ipmc_sensor_ros.interface.health`.

One ``diagnostic_msgs/DiagnosticArray`` per period (1 s) on the absolute
topic ``/diagnostics`` (where rqt_robot_monitor and diagnostic_aggregator
listen), holding one ``DiagnosticStatus`` per channel named
``<node>: <channel>`` and, with several channels, one aggregate named
``<node>`` (worst level).  ``hardware_id`` is the parameter of that name (or
the node's fully qualified name).

Use from a node::

    self._diag = DiagnosticsPublisher(self, values, channels=("current",),
                                      sample_rate_hz=fs, source=self.health_status)

where ``source()`` returns ``{channel: status dict}`` (or one status dict for
a single channel): counters (ints), optional ``done`` and
``estimated_offset_a``; or call :meth:`DiagnosticsPublisher.update` from the
node's own timer.  Feed the current to :meth:`observe` (per channel) for the
offset and mains-line estimates.
"""
from __future__ import annotations

from typing import Any, Callable, Mapping, Sequence

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.qos import QoSProfile

from ..interface.health import (DIAGNOSTICS_SPECS, CurrentStatistics, Health, HealthMonitor,
                                limits_from_values, worst)

__all__ = ['DiagnosticsPublisher', 'DIAGNOSTICS_SPECS', 'DIAGNOSTICS_TOPIC', 'to_status']

DIAGNOSTICS_TOPIC = '/diagnostics'
_LEVELS = {0: DiagnosticStatus.OK, 1: DiagnosticStatus.WARN, 2: DiagnosticStatus.ERROR}


def to_status(health: Health, name: str, hardware_id: str) -> DiagnosticStatus:
    """Return the ``DiagnosticStatus`` of one :class:`Health`."""
    return DiagnosticStatus(level=_LEVELS[health.level], name=name, message=health.message,
                            hardware_id=hardware_id,
                            values=[KeyValue(key=k, value=v) for k, v in health.values.items()])


class DiagnosticsPublisher:
    """
    Publishes the health of ``node``'s channels on ``/diagnostics``.

    Parameters
    ----------
    node : the rclpy node (or lifecycle node).
    values : parameter values holding :data:`DIAGNOSTICS_SPECS` (missing = defaults).
    channels : channel names (e.g. the input topic, or one per sensor of an array).
    sample_rate_hz : sample rate of the data of each channel, Hz (None: no offset and
        mains-line estimates).
    samples_key : counter that counts data (``samples_in`` or ``samples_published``).
    source : callable returning the status (see the module docstring); with it a
        steady-clock timer of ``period_s`` publishes by itself.
    expected_rate_hz : samples per second of steady-clock time expected (default:
        ``sample_rate_hz``; a simulator in fast mode passes None: no rate check).

    """

    def __init__(self, node, values: Mapping[str, Any], channels: Sequence[str] = ('data',),
                 sample_rate_hz: float | None = None, samples_key: str = 'samples_in',
                 source: Callable[[], Mapping[str, Any]] | None = None, period_s: float = 1.0,
                 expected_rate_hz: float | None | str = 'sample_rate_hz'):
        merged = {s.name: s.default for s in DIAGNOSTICS_SPECS}
        merged.update({k: v for k, v in values.items() if k in merged})
        self._node = node
        self._limits = limits_from_values(merged)
        self.hardware_id = str(merged['hardware_id']) or node.get_fully_qualified_name()
        self.channels = tuple(channels)
        if expected_rate_hz == 'sample_rate_hz':
            expected_rate_hz = sample_rate_hz
        self._monitors = {c: HealthMonitor(expected_rate_hz, self._limits, samples_key)
                          for c in self.channels}
        self._stats = ({c: CurrentStatistics(sample_rate_hz, self._limits.offset_window_s,
                                             self._limits.line_frequencies_hz)
                        for c in self.channels} if sample_rate_hz else {})
        self._clock = Clock(clock_type=ClockType.STEADY_TIME)
        self._pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC,
                                          QoSProfile(depth=10))
        self._source = source
        self._timer = (node.create_timer(period_s, self._on_timer, clock=self._clock)
                       if source is not None else None)
        self.last: dict[str, Health] = {}

    def observe(self, current_a, channel: str | None = None) -> None:
        """Feed samples of ``channel`` (default: the first) to the offset/line estimates."""
        stats = self._stats.get(channel or self.channels[0])
        if stats is not None:
            stats.observe(current_a)

    def observe_one(self, current_a: float, channel: str | None = None) -> None:
        """:meth:`observe` for one sample (the one-sample message path)."""
        stats = self._stats.get(channel or self.channels[0])
        if stats is not None:
            stats.observe_one(current_a)

    def follow_rate(self, sample_rate_hz: float) -> None:
        """
        Take the current at ``sample_rate_hz`` from now on (a stream that follows its rate).

        The offset and mains-line estimates of a changed rate start afresh; the rate check
        keeps the nominal rate it was built with.
        """
        for channel, stats in self._stats.items():
            if abs(stats.sample_rate_hz / sample_rate_hz - 1.0) > 1e-3:
                self._stats[channel] = CurrentStatistics(
                    sample_rate_hz, self._limits.offset_window_s,
                    self._limits.line_frequencies_hz)

    def update(self, status: Mapping[str, Any]) -> DiagnosticArray:
        """
        Evaluate ``status`` (``{channel: dict}`` or one dict) and publish.

        Returns the message.
        """
        if not status or not all(isinstance(v, Mapping) for v in status.values()):
            status = {self.channels[0]: status}   # one dict: the first channel
        now_s = self._clock.now().nanoseconds * 1e-9
        node_name = self._node.get_fully_qualified_name()
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        results = {}
        for channel in self.channels:
            if channel in status:
                results[channel] = self._monitors[channel].evaluate(
                    status[channel], now_s, self._stats.get(channel))
        if len(self.channels) > 1:
            msg.status.append(to_status(worst(list(results.values())), node_name,
                                        self.hardware_id))
        for channel, health in results.items():
            msg.status.append(to_status(health, f'{node_name}: {channel}', self.hardware_id))
        self.last = results
        self._pub.publish(msg)
        return msg

    def announce(self, message: str, level: int = 0) -> DiagnosticArray:
        """
        Publish ``message`` at ``level`` (0 OK) as the status of every channel.

        For states no health rule describes, e.g. a managed node being deactivated.
        """
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        node_name = self._node.get_fully_qualified_name()
        health = Health(level, message)
        if len(self.channels) > 1:
            msg.status.append(to_status(health, node_name, self.hardware_id))
        for channel in self.channels:
            msg.status.append(to_status(health, f'{node_name}: {channel}', self.hardware_id))
        self._pub.publish(msg)
        return msg

    def _on_timer(self) -> None:
        self.update(self._source())

    def destroy(self) -> None:
        """Release the timer and the publisher (lifecycle cleanup)."""
        if self._timer is not None:
            self._node.destroy_timer(self._timer)
            self._timer = None
        self._node.destroy_publisher(self._pub)

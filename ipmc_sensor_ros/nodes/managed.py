# SPDX-License-Identifier: Apache-2.0
"""
Managed (lifecycle) variants of the nodes: ``ipmc_estimator_managed``, ``ipmc_simulator_managed``.

The transitions, the lock, ``autostart`` and error processing are those of
:mod:`.lifecycle` (:class:`~.lifecycle.ManagedMixin`); here the two nodes and their entry points.
"""
from __future__ import annotations

import sys
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.lifecycle import LifecycleNode

from .estimator_node import ESTIMATOR_SPECS, EstimatorNode
from .lifecycle import AUTOSTART_SPEC, ManagedMixin
from .runner import run
from .simulator_node import SIMULATOR_SPECS, SimulatorNode

__all__ = ['ManagedEstimatorNode', 'ManagedSimulatorNode', 'main_estimator', 'main_simulator',
           'AUTOSTART_SPEC']


class ManagedEstimatorNode(ManagedMixin, EstimatorNode, LifecycleNode):
    """The estimator node (:class:`EstimatorNode`) as a managed node (module docstring)."""

    _SPECS = ESTIMATOR_SPECS + (AUTOSTART_SPEC,)
    _DEFAULT_NAME = 'ipmc_estimator'
    _BUILT = ('_stream', '_array', '_reduced', '_model_key', '_pending')

    def __init__(self, node_name: str = 'ipmc_estimator', **kwargs: Any):
        super().__init__(node_name, **kwargs)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._on_parameters_set)

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        """Unconfigured: accept (configure checks); else the plain node's validation."""
        if not self._configured:
            return SetParametersResult(successful=True)
        return super()._on_set_parameters(parameters)

    def _on_parameters_set(self, parameters) -> None:
        if self._configured:
            super()._on_parameters_set(parameters)

    def _on_current_raw(self, raw) -> None:
        self._guarded(super()._on_current_raw, 'current subscription', raw)

    def _output_publishers(self) -> list:
        return [p for p in [getattr(self, '_pub_block', None),
                            getattr(self, '_pub_smoothed', None),
                            *(getattr(self, '_pub_points', None) or ())] if p is not None]

    def _on_timer(self) -> None:
        self._guarded(super()._on_timer, 'status timer')


class ManagedSimulatorNode(ManagedMixin, SimulatorNode, LifecycleNode):
    """The simulator node (:class:`SimulatorNode`) as a managed node (module docstring)."""

    _SPECS = SIMULATOR_SPECS + (AUTOSTART_SPEC,)
    _DEFAULT_NAME = 'ipmc_simulator'
    _BUILT = ('_sim', '_sims', '_model', '_stimulus')

    def __init__(self, node_name: str = 'ipmc_simulator', **kwargs: Any):
        self._paused_ns: int | None = None
        super().__init__(node_name, **kwargs)

    def counters(self) -> dict[str, Any]:
        """As :meth:`SimulatorNode.counters`; zeros when unconfigured."""
        if not self._configured:
            return {'samples_published': 0, 'blocks_published': 0, 'done': False}
        return super().counters()

    def _on_tick(self) -> None:
        self._guarded(super()._on_tick, 'publish timer')

    def _publish_counters(self) -> None:
        self._guarded(super()._publish_counters, 'counters timer')

    def _on_deactivated(self) -> None:
        self._paused_ns = self.get_clock().now().nanoseconds

    def _on_activated(self) -> None:
        if self._paused_ns is not None and self._t_start_ns is not None:
            self._t_start_ns += self.get_clock().now().nanoseconds - self._paused_ns
        self._paused_ns = None

    def _configure(self) -> None:
        self._paused_ns = None
        super()._configure()


def main_estimator(args=None) -> int:
    """Entry point of ``ros2 run ipmc_sensor_ros ipmc_estimator_managed``."""
    return run(ManagedEstimatorNode, 'ipmc_estimator_managed', args)


def main_simulator(args=None) -> int:
    """Entry point of ``ros2 run ipmc_sensor_ros ipmc_simulator_managed``."""
    return run(ManagedSimulatorNode, 'ipmc_simulator_managed', args)


if __name__ == '__main__':
    sys.exit(main_estimator())

# SPDX-License-Identifier: Apache-2.0
"""
ROS 2 node ``ipmc_simulator``: a simulated IPMC sensor and its DAQ.

Publishes the measured sensing current on ``current`` (``time_s,current_A``
blocks, the estimator's input layout) and the ground-truth tip deflection on
``deflection_truth`` (``time_s,deflection_m`` blocks) with identical sample
times ``t_k = t_start + k / sample_rate_hz``, ``t_start`` = node clock at the
first block (simulation time works).  The stimulus is evaluated at ``k / fs``
(it starts at zero whatever the clock says).  Counters go to
``simulator/counters`` (``std_msgs/String`` JSON, 1 Hz and when done).

Pacing (``realtime_factor``):

* ``> 0``: a node-clock timer publishes the blocks that are due, i.e. simulated
  time follows ``realtime_factor`` x the node clock (sim-time aware).  At most
  ``MAX_BLOCKS_PER_TICK`` blocks per tick and a tick period >= 1 ms cap the
  achievable factor at ``10 * block_size`` (1 kHz data).
* ``0`` (fast mode, for tests and the demo): one block per tick of a 1 ms
  steady-clock timer, i.e. ``block_size * 1 ms^-1`` samples per second at most
  (real-time factor about ``block_size`` at 1 kHz: measured 194 with ``block_size: 200``).
  One block per tick, never a burst, means a subscriber that keeps up with
  one message per millisecond never sees its KEEP_LAST queue overflow, so the
  sample accounting stays exact.

All simulator parameters are read-only (restart to change them).
"""
from __future__ import annotations

import json
import sys
from typing import Any

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, String

from ..physics.beam import check_fidelity
from ..errors import ParameterError
from ..simulation.sensor import FieldSensorSimulator, SensorSimulator
from ..interface.simulator import (CHAIN_PARAMETERS, SIMULATOR_SPECS, STIMULI, build_stimulus,
                                   describe_stimulus, load_stimulus_csv, read_stimulus_csv)
from . import params as P
from . import topics as T
from .diagnostics import DiagnosticsPublisher
from ..interface.blocks import current_columns, deflection_columns
from .messages import BlockPacker
from .barrier import DefectBarrier
from .runner import run

__all__ = ['SimulatorNode', 'SIMULATOR_SPECS', 'STIMULI', 'load_stimulus_csv',
           'read_stimulus_csv', 'build_stimulus', 'main']

MAX_BLOCKS_PER_TICK = 10
MIN_TICK_S = 1e-3


class SimulatorNode(DefectBarrier, Node):
    """
    Simulated sensor + DAQ node; see the module docstring and README "ROS 2 interface".

    ``kwargs`` go to :class:`rclpy.node.Node`.  Raises
    :class:`~ipmc_sensor_ros.nodes.params.ParameterError` on invalid parameters.
    """

    def __init__(self, node_name: str = 'ipmc_simulator', **kwargs: Any):
        super().__init__(node_name, **kwargs)
        P.check_unknown_overrides(self, SIMULATOR_SPECS, kwargs.get('cli_args'),
                                  default_name='ipmc_simulator')
        P.declare(self, SIMULATOR_SPECS)
        self._configure()
        self._open_io()
        self.get_logger().info(self._ready_text())

    # -- construction, in the steps a managed node takes one by one --------------
    def _configure(self) -> None:
        """Read the parameters and build the simulated sensor (ParameterError); no topic."""
        v = self._values = P.read(self, SIMULATOR_SPECS)
        try:
            self._model = P.build_sensor_model(v)
            self._stimulus, self._stim_t0 = build_stimulus(v)
            self._channels = int(v['channels'])
            field = check_fidelity(v['fidelity'], v['beam_model'])
            self._sims = []
            for c in range(self._channels):   # each channel its own sensor and noise
                chain = {name: v[name] for name in CHAIN_PARAMETERS}
                chain['seed'] = v['seed'] + c
                self._sims.append(
                    FieldSensorSimulator(self._model, v['sample_rate_hz'],
                                         beam_model=v['beam_model'], **chain) if field
                    else SensorSimulator(self._model, v['sample_rate_hz'], **chain))
            self._sim = self._sims[0]
        except (ParameterError, ParameterError) as exc:
            raise P.ParameterError(str(exc)) from None
        P.log_model_files(self, v)
        self._fs = float(v['sample_rate_hz'])
        self._block = int(v['block_size'])
        self._rtf = float(v['realtime_factor'])
        self._total = int(round(float(v['duration_s']) * self._fs)) or None
        self._k = 0                       # next sample index
        self._blocks = 0
        self._t_start_ns: int | None = None
        self._done = False

    def _open_io(self) -> None:
        """Create the publishers, the timers and /diagnostics."""
        v = self._values
        qos = T.make_qos(v)
        self._pub_current = T.create_publisher(self, Float64MultiArray, 'current', qos)
        self._pub_truth = T.create_publisher(self, Float64MultiArray, 'deflection_truth', qos)
        T.check_qos_overrides(self)
        self._pack_current = BlockPacker(current_columns(self._channels))
        self._pack_truth = BlockPacker(deflection_columns(self._channels))
        self._offset_s = float(v['channel_time_offset_s'])
        self._pub_counters = self.create_publisher(String, 'simulator/counters', T.COUNTERS_QOS)
        if self._rtf > 0.0:
            period = max(self._block / self._fs / self._rtf, MIN_TICK_S)
            self._timer = self.create_timer(period, self._on_tick)   # node clock: sim-time aware
        else:
            self._timer = self.create_timer(MIN_TICK_S, self._on_tick,
                                            clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._counter_timer = self.create_timer(1.0, self._publish_counters,
                                                clock=Clock(clock_type=ClockType.STEADY_TIME))
        # /diagnostics: expected rate = realtime_factor x sample_rate_hz (no check in fast mode)
        self._diagnostics = DiagnosticsPublisher(
            self, v, channels=self._channel_names(),
            sample_rate_hz=self._fs,
            expected_rate_hz=self._fs * self._rtf if self._rtf > 0.0 else None,
            samples_key='samples_published', source=self._health)

    def _close_io(self) -> None:
        """Destroy what :meth:`_open_io` created (the simulation state stays)."""
        T.destroy_io(self, ('_timer', '_counter_timer', '_diagnostics', '_pub_current',
                            '_pub_truth', '_pub_counters'))

    def _ready_text(self) -> str:
        v = self._values
        return (f'ready: {self._model.describe()} model, stimulus '
                f'{describe_stimulus(self._stimulus, v)}, {self._fs} Hz in blocks of '
                f'{self._block}, realtime_factor {self._rtf}'
                + (f', {self._channels} channels' if self._channels > 1 else '')
                + (f", duration {v['duration_s']} s" if self._total else ', no end')
                + f"; publishing {self.resolve_topic_name('current')}")

    # -- public helpers -----------------------------------------------------------
    def counters(self) -> dict[str, Any]:
        """``samples_published``, ``blocks_published`` (ints) and ``done`` (bool)."""
        return {'samples_published': self._k, 'blocks_published': self._blocks,
                'done': self._done}

    def _channel_names(self) -> tuple[str, ...]:
        topic = self.resolve_topic_name('current')
        if self._channels == 1:
            return (topic,)
        return tuple(f'{topic} ch{c}' for c in range(self._channels))

    def _health(self) -> dict:
        """:meth:`counters` for each channel's /diagnostics status (the channels share them)."""
        return {name: self.counters() for name in self._channel_names()}

    @property
    def done(self) -> bool:
        return self._done

    # -- publishing -------------------------------------------------------------
    def _publish_counters(self) -> None:
        c = self.counters()
        c['node'] = self.get_fully_qualified_name()
        self._pub_counters.publish(String(data=json.dumps(c)))

    def _ready_to_start(self, now_ns: int) -> bool:
        need = int(self._values['wait_for_subscribers'])
        if need and (self._pub_current.get_subscription_count() < need
                     or self._pub_truth.get_subscription_count() < need):
            self.get_logger().info(f'waiting for {need} subscriber(s) on '
                                   f'{self._pub_current.topic_name} and '
                                   f'{self._pub_truth.topic_name}', throttle_duration_sec=5.0)
            return False
        if now_ns <= 0:
            self.get_logger().info('waiting for the clock (use_sim_time without /clock?)',
                                   throttle_duration_sec=5.0)
            return False
        return True

    def _on_tick(self) -> None:
        if self._done:
            return
        now_ns = self.get_clock().now().nanoseconds
        if self._t_start_ns is None:
            if not self._ready_to_start(now_ns):
                return
            self._t_start_ns = now_ns
        if self._rtf > 0.0:
            due = int((now_ns - self._t_start_ns) * 1e-9 * self._rtf * self._fs)
            n_blocks = min(MAX_BLOCKS_PER_TICK, max(due - self._k, 0) // self._block)
        else:
            n_blocks = 1
        for _ in range(n_blocks):
            if not self._publish_block():
                break

    def _publish_block(self) -> bool:
        """Publish the next block; False once the duration is reached."""
        k0 = self._k
        k1 = k0 + self._block if self._total is None else min(k0 + self._block, self._total)
        if k1 <= k0:
            self._finish()
            return False
        k = np.arange(k0, k1)
        times = self._t_start_ns * 1e-9 + k / self._fs
        runs = [sim.run(self._stimulus, self._stim_t0 + c * self._offset_s + k / self._fs)
                for c, sim in enumerate(self._sims)]
        self._pub_current.publish(self._pack_current.pack(times, *(r[1] for r in runs)))
        for name, r in zip(self._channel_names(), runs):
            self._diagnostics.observe(r[1], channel=name)
        self._pub_truth.publish(self._pack_truth.pack(times, *(r[0] for r in runs)))
        self._k = k1
        self._blocks += 1
        if self._total is not None and self._k >= self._total:
            self._finish()
            return False
        return True

    def _finish(self) -> None:
        if not self._done:
            self._done = True
            self._timer.cancel()
            self._publish_counters()
            self.get_logger().info(f'done: published {self._k} samples in {self._blocks} blocks '
                                   f'({self._k / self._fs:g} s of data)')


def main(args=None) -> int:
    """Entry point of ``ros2 run ipmc_sensor_ros ipmc_simulator``."""
    return run(SimulatorNode, 'ipmc_simulator', args)


if __name__ == '__main__':
    sys.exit(main())

# SPDX-License-Identifier: Apache-2.0
"""
Tracking monitor: collect estimate and ground truth, align them by time, score.

Used by the demo (``python -m ipmc_sensor_ros.nodes.demo``) and the integration
tests.  It subscribes, inside ``namespace``, to ``deflection/block``
(estimator output), ``deflection_truth`` (simulator ground truth) and the two
JSON counters topics, with the same QoS as the data topics.
"""
from __future__ import annotations

import json

import numpy as np
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, String

from . import topics as T
from ..workbench.metrics import nrmse
from .messages import DEFLECTION_COLUMNS, ESTIMATE_COLUMNS, unpack_block

__all__ = ['TrackingMonitor', 'nrmse']


class TrackingMonitor:
    """
    Subscriptions of one estimator/simulator pair on ``node``.

    ``namespace``: prefix of the pair's topics (e.g. ``/demo_f5``; ``""`` = the
    node's own namespace, relative names).
    """

    def __init__(self, node: Node, namespace: str = '', qos_depth: int = 1000):
        prefix = namespace.rstrip('/') + '/' if namespace else ''
        qos = T.make_qos({'qos_depth': qos_depth, 'qos_reliability': 'reliable'})
        self._est: list = []
        self._truth: list = []
        self.estimator_counters: dict = {}
        self.simulator_counters: dict = {}
        sub = node.create_subscription
        self.subscriptions = [
            sub(Float64MultiArray, prefix + 'deflection/block',
                lambda m: self._est.append(unpack_block(m, ESTIMATE_COLUMNS)), qos),
            sub(Float64MultiArray, prefix + 'deflection_truth',
                lambda m: self._truth.append(unpack_block(m, DEFLECTION_COLUMNS)), qos),
            sub(String, prefix + 'estimator/counters',
                lambda m: setattr(self, 'estimator_counters', json.loads(m.data)), T.COUNTERS_QOS),
            sub(String, prefix + 'simulator/counters',
                lambda m: setattr(self, 'simulator_counters', json.loads(m.data)), T.COUNTERS_QOS),
        ]

    @property
    def estimate_samples(self) -> int:
        return int(sum(len(b) for b in self._est))

    @property
    def truth_samples(self) -> int:
        return int(sum(len(b) for b in self._truth))

    @property
    def matched(self) -> bool:
        """Return True when the data subscriptions see at least one publisher each."""
        return all(s.get_publisher_count() > 0 for s in self.subscriptions[:2])

    def series(self):
        """(times_s, estimate_m, truth_m) on the common sample times."""
        if not self._est or not self._truth:
            return np.empty(0), np.empty(0), np.empty(0)
        te = np.concatenate([b.times_s for b in self._est])
        ye = np.concatenate([b.values for b in self._est])
        tt = np.concatenate([b.times_s for b in self._truth])
        yt = np.concatenate([b.values for b in self._truth])
        common, ie, it = np.intersect1d(te, tt, return_indices=True)
        return common, ye[ie], yt[it]

    def score(self, last_s: float = 20.0) -> tuple[float, int]:
        """(NRMSE over the last ``last_s`` seconds of common samples, samples compared)."""
        t, est, truth = self.series()
        if t.size == 0:
            return float('nan'), 0
        sel = t >= t[-1] - last_s
        return nrmse(est[sel], truth[sel]), int(sel.sum())

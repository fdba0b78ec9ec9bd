# SPDX-License-Identifier: Apache-2.0
"""
A defect raised in a node's callback is said on one line; the node goes on.

The stream's own barrier keeps an estimator's exception inside the current subscription
(its samples dropped with a reset, counted: :mod:`~ipmc_sensor_ros.estimation.stream`), and
a managed node sends a data callback's exception to error processing
(:mod:`.lifecycle`).  Anything else a callback raises (the status or diagnostics timer, the
smoother's drain when the input goes silent, the simulator's publish tick) is a defect of
the package, not the user's input: :class:`DefectBarrier` wraps the node's timer callbacks
so that it is logged with the package line it passed
(:func:`~ipmc_sensor_ros.errors.defect_text`), at most once per ``DEFECT_LOG_PERIOD_S`` with
the count so far, and the node goes on.  Raised past the callback, rclpy's events executor
logs it with its stack at FATAL on every call before ``spin_once`` re-raises it, and the
process ended with a traceback; the spin loop (:func:`.runner.spin_until_signalled`) says
what still reaches it the same way.
"""
from __future__ import annotations

from ..errors import defect_text

__all__ = ['DefectBarrier', 'DEFECT_LOG_PERIOD_S']

#: Least time between two log lines of callback defects, s (each one is counted).
DEFECT_LOG_PERIOD_S = 10.0


class DefectBarrier:
    """Mixin of a node: its timer callbacks' defects are said, not raised (module docstring)."""

    #: callback defects so far (the spin loop counts those that reach it here too)
    callback_defects = 0

    def create_timer(self, timer_period_sec, callback, *args, **kwargs):
        """As :meth:`rclpy.node.Node.create_timer`, the callback behind the barrier."""
        def guarded():
            try:
                callback()
            except Exception as exc:  # noqa: BLE001 - a defect never ends the node
                self.count_defect(exc)
        return super().create_timer(timer_period_sec, guarded, *args, **kwargs)

    def count_defect(self, exc: BaseException) -> None:
        """Count one callback defect and say it on one line (throttled)."""
        self.callback_defects += 1
        self.get_logger().error(f'{defect_text(exc)}; the node goes on '
                                f'({self.callback_defects} callback defect(s) so far)',
                                throttle_duration_sec=DEFECT_LOG_PERIOD_S)

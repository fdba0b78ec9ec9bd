# SPDX-License-Identifier: Apache-2.0
"""
The lifecycle of the managed nodes (:mod:`.managed`): transitions over a node's construction steps.

``ipmc_estimator_managed`` and ``ipmc_simulator_managed`` have the same names, parameters,
topics and messages as ``ipmc_estimator`` / ``ipmc_simulator``; the construction steps of
those classes (``_configure``, ``_open_io``, ``_close_io``) are run by the standard
lifecycle transitions (``lifecycle_msgs`` services ``<node>/change_state``,
``<node>/get_state``; ``ros2 lifecycle set /ipmc_estimator configure``):

========================  ===================================================================
state / transition        what the node does
========================  ===================================================================
unconfigured              parameters declared (same descriptors); nothing built, no topics;
                          parameter changes are taken as they are and checked by configure
configure                 builds the model and the filter from the parameters; on bad ones
                          it logs one line naming the parameter and the reason and fails
                          (back to unconfigured)
inactive                  built, no topics; parameter changes validated and applied as in
                          the plain node (two phases)
activate                  creates the subscription, the (lifecycle) publishers, the timers
                          and /diagnostics
deactivate                stops taking input, publishes the samples the smoother still
                          holds (``smoothed_lag_s``), waits up to ``topics.FLUSH_TIMEOUT_S`` for
                          reliable subscribers to acknowledge the estimates published,
                          publishes a last /diagnostics status "inactive" and destroys the
                          topics and timers; the stream core (counters, filter state) stays
cleanup / error           destroy the topics and release the model and the filter
processing
shutdown                  as cleanup, then finalized: the executable ends (exit status 0)
========================  ===================================================================

Transitions and data callbacks are serialised by one lock, and a data callback takes its
input only while the node is active: a message the middleware had already queued when
deactivate closed the subscription is not taken (not counted, as any message sent to an
inactive node), so no callback ever meets a half-built or half-torn node, and
``samples_out`` counts only estimates handed to the publishers of an active node.

Parameter ``autostart`` (bool, default false, managed nodes only): at start-up the node
configures and activates itself (as nav2's lifecycle manager does with ``autostart``), for
launch files and users that want the plain behaviour with the lifecycle services available; a
failed configure leaves it unconfigured with the reason logged.

Errors follow the lifecycle design's error processing (rclpy.lifecycle): a transition
callback that raises (e.g. destroying a topic fails during deactivate) is logged on one line
and returns ERROR, so rclpy enters ``errorprocessing`` and calls ``on_error``, which releases
everything and returns SUCCESS (-> ``unconfigured``), or, if that release fails too,
FAILURE (-> ``finalized``).  rclpy does not route an exception raised while *active* by a
data callback (subscription or timer) to error processing (it would end the process with a
traceback): the managed nodes catch it, log one line naming the callback, drop further input
and request ``deactivate`` whose callback returns ERROR, so the node goes through
``errorprocessing`` to ``unconfigured`` and the process keeps running (a supervisor sees the
transition events and may configure it again).

The simulator pauses on deactivate: on activate it continues with the next sample, its
times shifted by the pause (a gap the estimator sees as one).  Signals and exit codes are
those of :func:`~ipmc_sensor_ros.nodes.runner.run`.
"""
from __future__ import annotations

import threading
import time
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from . import params as P
from . import topics as T
from ..interface.specs import Spec, describe_exception

__all__ = ['ManagedMixin', 'AUTOSTART_SPEC']

SUCCESS = TransitionCallbackReturn.SUCCESS
FAILURE = TransitionCallbackReturn.FAILURE
ERROR = TransitionCallbackReturn.ERROR

#: The managed nodes' own parameter (read once, at start-up).
AUTOSTART_SPEC = Spec('autostart', False, bool,
                      'configure and activate at start-up (managed nodes only; as a lifecycle '
                      "manager's autostart); false: wait for the lifecycle services",
                      read_only=True)


class ManagedMixin:
    """
    Lifecycle transitions over a node class's construction steps.

    Put first in the bases, before the node class and :class:`rclpy.lifecycle.LifecycleNode`;
    the class attributes name the specs, the default node name and the attributes that
    hold what configure built (released by cleanup).
    """

    _SPECS: tuple = ()
    _DEFAULT_NAME = ''
    _BUILT: tuple[str, ...] = ()

    def __init__(self, node_name: str | None = None, **kwargs: Any):
        LifecycleNode.__init__(self, node_name or self._DEFAULT_NAME, **kwargs)
        self._lock = threading.RLock()
        self._configured = False
        self._taking = False                 # active: data callbacks take input
        self.finalized = False               # shut down: the executable ends (runner.run)
        for name in self._BUILT:
            setattr(self, name, None)
        P.check_unknown_overrides(self, self._SPECS, kwargs.get('cli_args'),
                                  default_name=self._DEFAULT_NAME)
        P.declare(self, self._SPECS)
        self._autostart_timer = None
        self._fault: str | None = None       # a data callback's error, awaiting error processing
        self._fault_timer = None
        if self.get_parameter('autostart').value:
            # once the executor spins (a transition needs no spinning, but the node's
            # services and the "ready" line come first); steady: runs before /clock
            self._autostart_timer = self.create_timer(
                0.0, self._autostart, clock=Clock(clock_type=ClockType.STEADY_TIME))
            self.get_logger().info('unconfigured (managed node, autostart): configuring')
        else:
            self.get_logger().info(
                'unconfigured (managed node): ros2 lifecycle set '
                f'{self.get_fully_qualified_name()} configure, then activate')

    @property
    def configured(self) -> bool:
        """Return True in the inactive and active states (model and filter built)."""
        return self._configured

    # -- transitions (each holds the lock: no data callback runs meanwhile) ------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Build the model and the filter; FAILURE (one-line reason logged) on bad parameters."""
        with self._lock:
            try:
                self._configure()
            except Exception as exc:  # any failure to build refuses the transition, never a crash
                self._release()
                self.get_logger().error(f'configure failed: {describe_exception(exc)}')
                return FAILURE
            self._configured = True
        self.get_logger().info('configured (inactive): ' + self._ready_text())
        return SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Create the topics, timers and /diagnostics; FAILURE (reason logged) if they fail."""
        with self._lock:
            try:
                self._open_io()
            except Exception as exc:  # e.g. an unknown qos_overrides.* parameter
                self._close_io()
                self.get_logger().error(f'activate failed: {describe_exception(exc)}')
                return FAILURE
            try:
                self._on_activated()
                super().on_activate(state)        # enables the lifecycle publishers
            except Exception as exc:  # error processing follows (module docstring)
                self.get_logger().error(
                    f'activate failed: {describe_exception(exc)}; error processing')
                return ERROR
            self._fault = None
            self._taking = True
        self.get_logger().info('active')
        return SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Stop taking input, flush the outputs, say "inactive" on /diagnostics, close the topics.

        ERROR (-> error processing) after a data callback's error or if this fails.
        """
        with self._lock:
            self._taking = False
            try:
                self._drain()
                self._flush()
                super().on_deactivate(state)
                diagnostics = getattr(self, '_diagnostics', None)
                if diagnostics is not None:
                    diagnostics.announce('error: ' + self._fault if self._fault else
                                         'inactive (lifecycle): no input taken, nothing published')
                self._on_deactivated()
                self._close_io()
            except Exception as exc:  # error processing follows (module docstring)
                self.get_logger().error(
                    f'deactivate failed: {describe_exception(exc)}; error processing')
                return ERROR
            if self._fault:
                return ERROR
        self.get_logger().info('inactive')
        return SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release the model and the filter (back to unconfigured); ERROR if that fails."""
        if not self._release_all('cleanup'):
            return ERROR
        self.get_logger().info('cleaned up (unconfigured)')
        return SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release everything (finalized); the executable then ends (:func:`runner.run`)."""
        if not self._release_all('shutdown'):
            return ERROR
        self.finalized = True
        self.get_logger().info('shut down (finalized): released; the process ends')
        return SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Release everything after an error (state ``errorprocessing``).

        SUCCESS takes the node to unconfigured; FAILURE, if the release fails, to finalized.
        """
        with self._lock:
            self._fault = None
            self._taking = False
            try:
                self._close_io()
                self._release()
            except Exception as exc:  # noqa: BLE001 - finalized, never a crash
                self.get_logger().error(
                    f'error processing failed: {describe_exception(exc)}; finalized')
                self.finalized = True
                return FAILURE
        self.get_logger().error('error processed: released, unconfigured')
        return SUCCESS

    def _release_all(self, what: str) -> bool:
        """Close the topics, release the model (cleanup, shutdown); False (logged) on failure."""
        with self._lock:
            self._taking = False
            try:
                self._close_io()
                self._release()
            except Exception as exc:  # error processing follows (module docstring)
                self.get_logger().error(
                    f'{what} failed: {describe_exception(exc)}; error processing')
                return False
        return True

    def _flush(self) -> None:
        """Wait (at most ``topics.FLUSH_TIMEOUT_S``) until reliable subscribers have the output."""
        end = time.monotonic() + T.FLUSH_TIMEOUT_S
        for publisher in self._output_publishers():
            left = max(end - time.monotonic(), 0.0)
            publisher.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))

    def _output_publishers(self) -> list:
        """Return the data publishers to flush on deactivate (subclass hook)."""
        return []

    def _drain(self) -> None:
        """Publish what the node holds back for later (its own ``_drain``, if it has one)."""
        drain = getattr(super(), '_drain', None)
        if drain is not None:
            drain()

    # -- helpers ----------------------------------------------------------------------
    def _autostart(self) -> None:
        """Configure, then activate, once (parameter ``autostart``)."""
        timer, self._autostart_timer = self._autostart_timer, None
        if timer is None:
            return
        self.destroy_timer(timer)
        if self.trigger_configure() == SUCCESS:
            self.trigger_activate()

    def _guarded(self, callback, name: str, *args) -> None:
        """
        Run a data callback; on an exception, log it and start error processing.

        The transition runs from a one-shot timer, out of the callback (whose topic it
        destroys); until then further calls are dropped.
        """
        with self._lock:
            if self._taking and self._fault is None:
                self._call_guarded(callback, name, *args)

    def _call_guarded(self, callback, name: str, *args) -> None:
        try:
            callback(*args)
        except Exception as exc:  # a bug or a broken device while active: never a crash
            self._fault = f'{name}: {describe_exception(exc)}'
            self.get_logger().error(f'error while active in {self._fault}; error processing '
                                    '(deactivate -> errorprocessing -> unconfigured)')
            self._fault_timer = self.create_timer(
                0.0, self._process_fault, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _process_fault(self) -> None:
        timer, self._fault_timer = self._fault_timer, None
        if timer is None:
            return
        self.destroy_timer(timer)
        if self._fault is not None:
            self.trigger_deactivate()          # returns ERROR: on_error follows

    def _release(self) -> None:
        with self._lock:
            self._configured = False
            for name in self._BUILT:
                setattr(self, name, None)

    def _on_activated(self) -> None:
        """Run after the topics are open (subclass hook)."""

    def _on_deactivated(self) -> None:
        """Run before the topics are closed (subclass hook)."""

    def destroy_publisher(self, publisher) -> bool:
        """Destroy a publisher, lifecycle or not (it leaves the managed entities)."""
        self._managed_entities.discard(publisher)
        return super().destroy_publisher(publisher)

    def destroy_node(self) -> None:
        """
        Publish what is held back, wait for acks, release topics and model, destroy the node.

        rclpy's ``destroy_node`` leaves the lifecycle state machine (its ``transition_event``
        publisher) to the garbage collector; it is destroyed here, or a node that is still
        referenced stays on the graph as a ghost after its context has shut down.
        """
        self._drain()
        self._flush()
        self._close_io()
        self._release()
        super().destroy_node()
        self._state_machine.destroy_when_not_in_use()

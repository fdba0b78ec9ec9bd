# SPDX-License-Identifier: Apache-2.0
"""
One source per stream, ROS side: the subscription of a node that follows one publisher.

:func:`subscribe_followed` creates a raw subscription whose callback receives the message
info (publisher GID, publication sequence number) and registers the middleware's
message-lost event; :class:`FollowedSource` decides each message with a
:class:`~ipmc_sensor_ros.interface.sources.SourceSelector` (the rules, without ROS) and counts
and says what it decided in the stream's accounts
(:class:`~ipmc_sensor_ros.estimation.accounting.StreamAccounts`).
"""
from __future__ import annotations

import copy
import time
from typing import Any, Callable

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.subscription import Subscription

from ..interface.sources import IGNORED, SWITCHED, SourceSelector
from . import topics as T

__all__ = ['FollowedSource', 'subscribe_followed']


def subscribe_followed(node, msg_type, topic: str, callback, qos, on_message_lost):
    """
    Return a raw subscription whose ``callback(raw, info=None)`` gets the message info.

    rclpy calls a callback with the info only if it cannot take one argument, and rclpy
    9.1.2's EventsExecutor then hands it the (message, info) pair as one argument: the callback
    takes one argument or two (:meth:`FollowedSource.unpack`) and the subscription is told to
    pass the info.
    """
    with T.qos_overrides_named(node, topic, 'subscription'):
        sub = node.create_subscription(
            msg_type, topic, callback, copy.copy(qos), raw=True,    # overrides act in place
            qos_overriding_options=T.qos_overriding_options(),
            event_callbacks=SubscriptionEventCallbacks(message_lost=on_message_lost))
    sub._callback_type = Subscription.CallbackType.WithMessageInfo
    return sub


class FollowedSource:
    """
    Decides, counts and says the source of each message of a node's input.

    Parameters
    ----------
    node : rclpy node (its logger-backed accounts and graph are used).
    selector : SourceSelector
        The rules.
    accounts : callable
        Returns the stream accounts to count in (``count(name, n, text)``), or None (a managed
        node not configured: nothing is taken).
    lock : the node's data lock.

    """

    def __init__(self, node, selector: SourceSelector, accounts: Callable[[], Any], lock):
        self._node = node
        self.selector = selector
        self._accounts = accounts
        self._lock = lock
        self.topic = ''

    @staticmethod
    def unpack(raw, info):
        """Return (message, info) of a callback's arguments (see :func:`subscribe_followed`)."""
        if info is None and type(raw) is tuple:
            return raw
        return raw, info

    def admit(self, info) -> bool:
        """Return True when the message with ``info`` is to be estimated (module docstring)."""
        gid = info['publisher_gid']
        gid = None if gid is None else gid['data']
        code = self.selector.admit(gid, info['publication_sequence_number'], time.monotonic())
        return not code or self._event(code, gid)

    def _event(self, code: int, gid: bytes) -> bool:
        """Count and say a source event; return True when the message is taken."""
        accounts = self._accounts()
        if accounts is None:
            return False
        sel = self.selector
        if code == IGNORED:
            first = sel.ignored.get(gid) == 1
            if first:
                self.name_publishers()
            with self._lock:
                accounts.count('messages_ignored', 1, (
                    f'ignoring messages of {sel.name(gid)} on {self.topic}: following '
                    f'{sel.name(sel.followed)} (one source per stream; another is followed once '
                    f'it is silent for stale_after_s = {sel.stale_after_s:g} s)') if first else '')
            return False
        if code == SWITCHED:
            self.name_publishers()
            with self._lock:
                accounts.count('source_switches', 1, (
                    f'{sel.name(sel.previous)} silent on {self.topic} for more than '
                    f'stale_after_s = {sel.stale_after_s:g} s: now following {sel.name(gid)}'))
            return True
        with self._lock:
            accounts.count('messages_lost', code, f'{code} message(s) of {sel.name(gid)} on '
                                                  f'{self.topic} never arrived (sequence numbers)')
        return True

    def name_publishers(self) -> None:
        """Learn the node names of the topic's publishers (for the messages)."""
        try:
            for pub in self._node.get_publishers_info_by_topic(self.topic):
                self.selector.names[bytes(pub.endpoint_gid)] = (
                    f"{pub.node_namespace.rstrip('/')}/{pub.node_name}")
        except Exception:  # noqa: BLE001 - names are a convenience; the GID is said anyway
            pass

    def on_message_lost(self, event) -> None:
        """Count the messages the middleware reports lost on the topic."""
        accounts = self._accounts()
        if accounts is not None and event.total_count_change > 0:
            with self._lock:
                accounts.count('messages_lost_reported', event.total_count_change,
                               f'the middleware reports {event.total_count_change} message(s) '
                               f'lost on {self.topic} ({event.total_count} in all)')

    def status(self) -> dict:
        """Return the followed and ignored publishers, named, for counters and diagnostics."""
        sel = self.selector
        return {'followed_publisher': sel.name(sel.followed) if sel.followed is not None else '',
                'ignored_publishers': sel.describe_ignored()}

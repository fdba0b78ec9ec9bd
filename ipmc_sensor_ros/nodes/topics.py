# SPDX-License-Identifier: Apache-2.0
"""
The nodes' topics: creation with the QoS override parameters, their QoS, their destruction.

Publishers and subscriptions get the standard ``qos_overrides.*`` parameters; their QoS comes
from the node parameters (:func:`make_qos`).  Kept apart from :mod:`.params` (parameter
declaration and reading): a topic's QoS is set once at creation, by ``qos_depth`` /
``qos_reliability`` and by ``qos_overrides.*``, which rclpy declares read-only.
"""
from __future__ import annotations

import contextlib
import copy
from typing import Any, Iterable, Mapping

from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from rclpy.timer import Timer

from ..interface.specs import ParameterError, check_choice
from .params import parameter_overrides

__all__ = ['QOS_OVERRIDE_POLICIES', 'qos_overriding_options', 'create_publisher',
           'create_subscription', 'destroy_io', 'qos_overrides_named', 'check_qos_overrides',
           'FLUSH_TIMEOUT_S', 'COUNTERS_QOS', 'make_qos']


#: QoS parameters of a topic are declared read-only by rclpy as
#: ``qos_overrides.<fully qualified topic>.<publisher|subscription>.<policy>``.
QOS_OVERRIDE_POLICIES = ('history', 'depth', 'reliability', 'durability')


def qos_overriding_options():
    """
    Return the standard ``qos_overrides.*`` parameters.

    History, depth, reliability, durability.
    """
    from rclpy.qos_overriding_options import QoSOverridingOptions

    return QoSOverridingOptions.with_default_policies()


def create_publisher(node, msg_type, topic: str, qos: QoSProfile):
    """
    Create a publisher with the standard QoS override parameters.

    A lifecycle node gets a lifecycle publisher (enabled by its ``on_activate``).
    """
    create = getattr(node, 'create_lifecycle_publisher', node.create_publisher)
    with qos_overrides_named(node, topic, 'publisher'):     # rclpy applies overrides in place
        return create(msg_type, topic, copy.copy(qos),
                      qos_overriding_options=qos_overriding_options())


def destroy_io(node, names: Iterable[str]) -> None:
    """
    Destroy the entities held by the attributes ``names`` of ``node``.

    Timers, publishers and subscriptions are destroyed through the node, anything else
    (a :class:`~ipmc_sensor_ros.nodes.diagnostics.DiagnosticsPublisher`) by its
    ``destroy()``, lists and tuples item by item; each attribute becomes None, and None
    attributes are skipped.
    """
    for name in names:
        held = getattr(node, name, None)
        setattr(node, name, None)
        for entity in held if isinstance(held, (list, tuple)) else (held,):
            _destroy(node, entity)


def _destroy(node, entity) -> None:
    if entity is not None:
        if isinstance(entity, Timer):
            node.destroy_timer(entity)
        elif isinstance(entity, Publisher):
            node.destroy_publisher(entity)
        elif isinstance(entity, Subscription):
            node.destroy_subscription(entity)
        else:
            entity.destroy()


def create_subscription(node, msg_type, topic: str, callback, qos: QoSProfile, raw=False):
    """``node.create_subscription`` with the standard QoS override parameters."""
    with qos_overrides_named(node, topic, 'subscription'):   # a copy: see create_publisher
        return node.create_subscription(msg_type, topic, callback, copy.copy(qos), raw=raw,
                                        qos_overriding_options=qos_overriding_options())


@contextlib.contextmanager
def qos_overrides_named(node, topic: str, kind: str):
    """
    Turn rclpy's refusal of a ``qos_overrides.*`` value into a ParameterError naming it.

    rclpy raises a RuntimeError for a policy value it does not know ('bestefort') and an
    RCLError (a RuntimeError) for a depth the middleware cannot take (-5), as tracebacks.
    """
    try:
        yield
    except (RuntimeError, ValueError, TypeError) as exc:
        prefix = f'qos_overrides.{node.resolve_topic_name(topic)}.{kind}.'
        given = {n: v.value for n, v in parameter_overrides(node).items()
                 if n.startswith(prefix)}
        if not given:
            raise
        text = ' '.join(str(exc).split()).split(', at /')[0]
        raise ParameterError(
            f'{given}: refused by rclpy ({text}); valid: history keep_last, keep_all or '
            'system_default; depth an integer >= 0; reliability reliable, best_effort or '
            'system_default') from None


def check_qos_overrides(node) -> None:
    """
    Refuse ``qos_overrides.*`` overrides naming no topic of the node.

    Call after creating the topics: a misspelt topic would otherwise be ignored silently.
    """
    declared = {n for n in parameter_overrides(node) if node.has_parameter(n)}
    stray = sorted(n for n in parameter_overrides(node)
                   if n.startswith('qos_overrides.') and n not in declared)
    if stray:
        valid = sorted(node.list_parameters(['qos_overrides'], 0).names)
        raise ParameterError(f'unknown QoS override(s) {stray} for node '
                             f"'{node.get_name()}'; valid: {valid}")


#: Longest wait for reliable subscribers to acknowledge what was published when a stream ends
#: (deactivate, node shutdown), s: long enough for loopback DDS, short enough not to hang.
FLUSH_TIMEOUT_S = 1.0

#: QoS of the JSON counters topics: reliable, keep the last one for late joiners.
COUNTERS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)


def make_qos(values: Mapping[str, Any]) -> QoSProfile:
    """KEEP_LAST(qos_depth), reliability per ``qos_reliability``, VOLATILE."""
    rel = check_choice('qos_reliability', values['qos_reliability'], ('reliable', 'best_effort'))
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(values['qos_depth']),
                      reliability=(ReliabilityPolicy.RELIABLE if rel == 'reliable'
                                   else ReliabilityPolicy.BEST_EFFORT),
                      durability=DurabilityPolicy.VOLATILE)

# SPDX-License-Identifier: Apache-2.0
"""
The topics of a rosbag2 bag: message types, topic lookup, decoding and alignment.

Holds what :mod:`.bags` reads and writes below the level of the bag file: the
``rosbags`` type store, the message types and column labels of the current and
deflection topics, finding a topic by name (leading ``/`` optional), reading
every message of one topic into validated, time-ordered ``(time, value)``
arrays (one-sample blocks decoded straight from their CDR bytes), and aligning
the deflection to the current sample times.  The message layouts are described
in :mod:`.bags`.  Every problem raises :class:`DataFormatError` naming the bag
and topic.  Imports without rclpy; ``rosbags`` is imported on first use.
"""
from __future__ import annotations

import array
import functools
from typing import Any, Mapping

import numpy as np

from ..interface.blocks import (
    CURRENT_COLUMNS,
    DEFLECTION_COLUMNS,
    ESTIMATE_COLUMNS,
    ESTIMATE_COLUMNS_UNFLAGGED,
    unpack_columns,
)
from ..interface.cdr import OneSampleCodec
from .formatread import format_exact
from .measurements import DataFormatError

__all__ = ['CURRENT_LABEL', 'DEFLECTION_LABEL', 'MULTIARRAY_TYPE', 'POINT_STAMPED_TYPE',
           'bag_typestore', 'topic_key', 'find_topic', 'describe_topics', 'read_topic',
           'align_deflection']

#: Column label (dim[1].label) of current and deflection blocks in bags.
CURRENT_LABEL = CURRENT_COLUMNS
DEFLECTION_LABEL = DEFLECTION_COLUMNS
MULTIARRAY_TYPE = 'std_msgs/msg/Float64MultiArray'
POINT_STAMPED_TYPE = 'geometry_msgs/msg/PointStamped'


@functools.lru_cache(maxsize=None)
def bag_typestore():
    """Return the ``rosbags`` type store of the bags (ROS 2 Jazzy message definitions)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def topic_key(name: str) -> str:
    """Return a topic name without surrounding blanks and leading ``/`` (how topics match)."""
    return name.strip().lstrip('/')


def find_topic(where: str, topics: Mapping[str, Any], wanted: str):
    """(name, info) of ``wanted`` in the bag (leading '/' optional), or None."""
    matches = [name for name in topics if topic_key(name) == topic_key(wanted)]
    if len(matches) > 1:
        raise DataFormatError(where, None, f'ambiguous: the bag has both {matches}', topic=wanted)
    return (matches[0], topics[matches[0]]) if matches else None


def describe_topics(topics: Mapping[str, Any]) -> str:
    """Return the bag's topics with their types and message counts, for an error message."""
    if not topics:
        return 'the bag has no topics'
    return 'the bag has: ' + ', '.join(f'{name} ({info.msgtype}, {info.msgcount} msgs)'
                                       for name, info in sorted(topics.items()))


def _unpack_block(msg, label: str) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the times and values of a block message; ValueError (DataError) describing a bad layout.

    A deflection topic may also hold the estimator's output (``ESTIMATE_COLUMNS``: the
    estimate and its standard deviation); its first value column is the deflection.
    """
    if label == DEFLECTION_LABEL and msg.layout.dim and len(msg.layout.dim) == 2 \
            and msg.layout.dim[1].label in (ESTIMATE_COLUMNS, ESTIMATE_COLUMNS_UNFLAGGED):
        label = msg.layout.dim[1].label
    times, table = unpack_columns(msg, label, values_only_ok=False)
    return times, table[:, 0]


def _decode_message(where: str, name: str, store, msgtype: str, label: str, count: int, conn,
                    raw: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Return the (times, values) of message ``count`` of a ``msgtype`` topic, in full."""
    try:
        msg = store.deserialize_cdr(raw, conn.msgtype)
    except Exception as exc:  # corrupt payload: any decoder failure
        raise DataFormatError(where, None, f'message {count}: cannot deserialize '
                              f'{conn.msgtype}: {type(exc).__name__}: {exc}',
                              topic=name) from exc
    if msgtype == POINT_STAMPED_TYPE:
        return (np.array([msg.header.stamp.sec + msg.header.stamp.nanosec / 1e9]),
                np.array([float(msg.point.z)]))
    try:
        return _unpack_block(msg, label)
    except ValueError as exc:
        raise DataFormatError(where, None, f'message {count}: {exc}', topic=name) from None


class _TopicSamples:
    """
    The samples of one topic as they are read, each message checked when it is kept.

    Blocks must be finite, strictly increasing in time and start after the previous
    message's last sample; point messages must be finite and have distinct stamps (they
    are sorted by stamp at the end).  One-sample blocks are gathered into a run of flat
    arrays and checked as one block when the run ends (:meth:`flush`).
    """

    def __init__(self, where: str, name: str, quantity: str) -> None:
        self.where, self.name, self.quantity = where, name, quantity
        self.times: list[np.ndarray] = []
        self.values: list[np.ndarray] = []
        self.prev_end: float | None = None
        self.run_t, self.run_v = array.array('d'), array.array('d')
        self.run_first = 0

    def _error(self, text: str) -> DataFormatError:
        return DataFormatError(self.where, None, text, topic=self.name)

    def _check_finite(self, t: np.ndarray, v: np.ndarray, message_of) -> None:
        """Refuse a NaN/Inf; ``message_of(k)`` is the (message, sample) of sample k."""
        bad = ~(np.isfinite(t) & np.isfinite(v))
        if bad.any():
            k = int(np.argmax(bad))
            message, sample = message_of(k)
            raise self._error(f'message {message}, sample {sample}: NaN/Inf (time '
                              f'{format_exact(t[k])}, {self.quantity} {format_exact(v[k])})')

    def _late_error(self, message: int, start: float, prev: float) -> DataFormatError:
        return self._error(f'message {message} starts at {format_exact(start)} s, not after the '
                           f"previous message's last sample at {format_exact(prev)} s (blocks "
                           'overlap or are out of order)')

    def add_one(self, count: int, row) -> None:
        """Add the (time, value) of one-sample block ``count`` to the current run."""
        if not self.run_t:
            self.run_first = count
        self.run_t.append(row[0])
        self.run_v.append(row[1])

    def flush(self) -> None:
        """Check the one-sample run as :meth:`add_block` checks a block; keep it."""
        if not self.run_t:
            return
        t, v = np.array(self.run_t), np.array(self.run_v)
        self.run_t, self.run_v = array.array('d'), array.array('d')
        self._check_finite(t, v, lambda k: (self.run_first + k, 0))
        before = np.concatenate(([-np.inf if self.prev_end is None else self.prev_end], t[:-1]))
        late = t <= before
        if late.any():
            k = int(np.argmax(late))
            raise self._late_error(self.run_first + k, t[k], before[k])
        self._keep(t, v, ordered=True)

    def add_block(self, count: int, t: np.ndarray, v: np.ndarray, ordered: bool) -> None:
        """Check and keep the samples of message ``count`` (``ordered``: a block, not a point)."""
        self._check_finite(t, v, lambda k: (count, k))
        if ordered and t.size:
            steps = np.diff(t)
            if (steps <= 0).any():
                k = int(np.argmax(steps <= 0)) + 1
                raise self._error(f'message {count}, sample {k}: time {format_exact(t[k])} s is '
                                  f'not after {format_exact(t[k - 1])} s (sample times must be '
                                  'strictly increasing)')
            if self.prev_end is not None and t[0] <= self.prev_end:
                raise self._late_error(count, t[0], self.prev_end)
        self._keep(t, v, ordered)

    def _keep(self, t: np.ndarray, v: np.ndarray, ordered: bool) -> None:
        if ordered and t.size:
            self.prev_end = float(t[-1])
        self.times.append(t)
        self.values.append(v)

    def arrays(self, by_stamp: bool) -> tuple[np.ndarray, np.ndarray]:
        """Return all (time, value) samples; ``by_stamp``: sorted, two equal stamps refused."""
        t = np.concatenate(self.times) if self.times else np.empty(0)
        v = np.concatenate(self.values) if self.values else np.empty(0)
        if by_stamp and t.size:
            order = np.argsort(t, kind='stable')
            t, v = t[order], v[order]
            dup = np.diff(t) == 0
            if dup.any():
                k = int(np.argmax(dup))
                raise self._error(f'two samples with the same stamp {format_exact(t[k])} s')
        return t, v


def read_topic(where: str, reader, name: str, info, label: str,
               quantity: str) -> tuple[np.ndarray, np.ndarray]:
    """All (time, value) samples of one topic, in time order, validated."""
    store = bag_typestore()
    msgtype = info.msgtype
    allowed = (
        (MULTIARRAY_TYPE,) if quantity == 'current' else (MULTIARRAY_TYPE, POINT_STAMPED_TYPE)
    )
    if msgtype not in allowed:
        raise DataFormatError(where, None, f'has message type {msgtype!r}; expected '
                              + ' or '.join(repr(a) for a in allowed), topic=name)
    samples = _TopicSamples(where, name, quantity)
    # one-sample blocks (a DAQ driver's message per sample) are read from their bytes into
    # flat arrays: deserialising each cost ~55 us and kept two small arrays per sample
    one = OneSampleCodec(label) if msgtype == MULTIARRAY_TYPE else None
    count = 0
    for conn, _stamp, raw in reader.messages(connections=info.connections):
        count += 1
        row = one.decode(raw) if one is not None else None
        if row is not None:
            samples.add_one(count, row)
            continue
        samples.flush()
        t, v = _decode_message(where, name, store, msgtype, label, count, conn, raw)
        samples.add_block(count, t, v, ordered=msgtype == MULTIARRAY_TYPE)
    samples.flush()
    if count != info.msgcount and info.msgcount:
        raise DataFormatError(where, None, f'the bag lists {info.msgcount} messages but only '
                              f'{count} could be read (truncated bag?)', topic=name)
    return samples.arrays(by_stamp=msgtype == POINT_STAMPED_TYPE)


def align_deflection(where: str, name: str, tc: np.ndarray, td: np.ndarray,
                     vd: np.ndarray) -> tuple[np.ndarray, str]:
    """Deflection at the current times ``tc``: exact match or linear interpolation."""
    if td.size == 0:
        raise DataFormatError(where, None, 'has no deflection samples', topic=name)
    tol = 1e-9 + 4.0 * float(np.spacing(max(abs(tc).max(), abs(td).max())))
    idx = np.clip(np.searchsorted(td, tc), 1, max(td.size - 1, 1))
    lo = np.clip(idx - 1, 0, td.size - 1)
    hi = np.clip(idx, 0, td.size - 1)
    nearest = np.where(np.abs(td[lo] - tc) <= np.abs(td[hi] - tc), lo, hi)
    if np.all(np.abs(td[nearest] - tc) <= tol):
        return vd[nearest].copy(), 'exact'
    if td.size < 2 or td[0] > tc[0] + tol or td[-1] < tc[-1] - tol:
        raise DataFormatError(where, None, f'deflection covers {format_exact(td[0])}..'
                              f'{format_exact(td[-1])} s but the current covers '
                              f'{format_exact(tc[0])}..{format_exact(tc[-1])} s: cannot align '
                              'without extrapolating (trim the recording)', topic=name)
    return np.interp(tc, td, vd), 'linear'

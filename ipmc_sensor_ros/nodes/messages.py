# SPDX-License-Identifier: Apache-2.0
"""
Pack and unpack sample blocks in ``std_msgs/Float64MultiArray`` (pure numpy + std_msgs).

Block layout (defined in :mod:`ipmc_sensor_ros.interface.blocks`; README "ROS 2 interface")
---------------------------------------------------------------------------------
A block of ``n`` timed samples is a 2-D array, row-major::

    layout.dim[0] = MultiArrayDimension(label="sample", size=n, stride=2 n)
    layout.dim[1] = MultiArrayDimension(label=<columns>, size=2, stride=2)
    layout.data_offset = 0 (a non-zero offset is honoured when reading)
    data = [t_0, v_0, t_1, v_1, ..., t_{n-1}, v_{n-1}]   (float64)

``t_k`` is the sample time in seconds (ROS time as float seconds, resolution
about 0.24 us at today's epoch), ``v_k`` the value in the unit named by the
column label: ``"time_s,current_A"`` for the sensing current (amperes),
``"time_s,deflection_m"`` for tip deflections (metres).

A plain 1-D array (no dimension, or one dimension whose size matches the data)
is also accepted on input: values only, no times.

Malformed layouts raise :class:`DataError` with a message saying what is
wrong; nothing here touches ROS middleware, so it is usable (and tested)
without a running context.
"""
from __future__ import annotations

import array
import struct
from dataclasses import dataclass

import numpy as np
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from ..interface.cdr import CdrWalk, OneSampleCodec
from ..interface.blocks import (
    CURRENT_COLUMNS,
    DEFLECTION_COLUMNS,
    ESTIMATE_COLUMNS,
    SAMPLE_LABEL,
    DataError,
    unpack_columns,
)

__all__ = [
    'DataError',
    'Block',
    'SAMPLE_LABEL',
    'CURRENT_COLUMNS',
    'DEFLECTION_COLUMNS',
    'ESTIMATE_COLUMNS',
    'pack_block',
    'BlockPacker',
    'unpack_block',
    'claimed_samples',
    'one_sample',
    'point_message',
    'OneSampleCodec',
    'PointCodec',
]


@dataclass(frozen=True)
class Block:
    """
    An unpacked block: ``times_s`` (None for a 1-D, values-only message).

    ``values`` (the first value column) and ``extra`` (the further columns, shape (n, k
    - 2), or None).
    """

    times_s: np.ndarray | None
    values: np.ndarray
    extra: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.values.size)


def _to_array_d(values: np.ndarray) -> array.array:
    out = array.array('d')
    out.frombytes(np.ascontiguousarray(values, dtype='=f8').tobytes())
    return out


def pack_block(times_s, values, columns: str = CURRENT_COLUMNS, *extra) -> Float64MultiArray:
    """
    Build the 2-D block message from ``times_s`` (s).

    ``values`` and any ``extra`` columns (units per ``columns``).
    """
    return BlockPacker(columns).pack(times_s, values, *extra)


class BlockPacker:
    """
    Packs blocks of one column layout into a single, reused message.

    A publisher's hot path: rclpy serialises a message inside ``publish()``, so
    the same message object can be refilled for the next block; its layout is
    rebuilt only when the block length changes.  Do not keep a packed message
    beyond the next :meth:`pack` call (use :func:`pack_block` for that).
    """

    def __init__(self, columns: str = CURRENT_COLUMNS):
        self.columns = columns
        self.width = len(columns.split(','))
        self._msg = Float64MultiArray()
        self._n = -1

    def pack(self, times_s, *columns) -> Float64MultiArray:
        """
        Return a block of the times and one array per value column.

        As many value columns as ``columns`` names.
        """
        t = np.asarray(times_s, dtype=float).ravel()
        cols = [np.asarray(c, dtype=float).ravel() for c in columns]
        if len(cols) + 1 != self.width:
            raise DataError(f"{len(cols) + 1} columns for the layout '{self.columns}'")
        if any(c.shape != t.shape for c in cols):
            raise DataError(f'times ({t.size}) and values ({[c.size for c in cols]}) differ '
                            'in length')
        n = int(t.size)
        if n == 1:
            return self.pack_one(float(t[0]), *(float(c[0]) for c in cols))
        msg = self._with_layout(n)
        k = self.width
        inter = np.empty(k * n)
        inter[0::k] = t
        for j, c in enumerate(cols, start=1):
            inter[j::k] = c
        msg.data = _to_array_d(inter)
        return msg

    def pack_one(self, time_s: float, *values: float) -> Float64MultiArray:
        """Return a one-sample block from floats (no numpy on the way)."""
        msg = self._with_layout(1)
        msg.data = array.array('d', (time_s, *values))
        return msg

    def _with_layout(self, n: int) -> Float64MultiArray:
        """Return the reused message, its layout set for ``n`` samples (rebuilt only on change)."""
        msg = self._msg
        if n != self._n:
            k = self.width
            msg.layout.dim = [MultiArrayDimension(label=SAMPLE_LABEL, size=n, stride=k * n),
                              MultiArrayDimension(label=self.columns, size=k, stride=k)]
            msg.layout.data_offset = 0
            self._n = n
        return msg


def claimed_samples(msg: Float64MultiArray, width: int = 2) -> int:
    """
    How many samples the message carries, for accounting even when it is malformed.

    Two or more dimensions: ceil(payload / width) (a time and ``width - 1`` values per
    sample); otherwise ceil(payload / (width - 1)) (values only; with one channel, the
    payload length).
    """
    payload = max(len(msg.data) - int(msg.layout.data_offset), 0)
    if len(msg.layout.dim) >= 2:
        return (payload + width - 1) // width
    return (payload + width - 2) // (width - 1)


def unpack_block(msg: Float64MultiArray, columns: str = CURRENT_COLUMNS) -> Block:
    """
    Decode a block message; raise :class:`DataError` if the layout is malformed.

    :func:`ipmc_sensor_ros.interface.blocks.unpack_columns`.

    Returns a :class:`Block`; ``times_s`` is None for a values-only 1-D message.
    Values are *not* checked for finiteness here (that is the estimator's job).
    """
    times, table = unpack_columns(msg, columns)
    return Block(times_s=times, values=table[:, 0],
                 extra=table[:, 1:] if table.shape[1] > 1 else None)


def one_sample(msg: Float64MultiArray):
    """
    Return ``(time, current)`` of a well-formed one-sample timed current message.

    The message has the layout the simulator and DAQ drivers publish; the values come as
    floats without numpy.  ``None`` for any other message, which then takes the general
    path and gets its precise layout check.
    """
    layout = msg.layout
    dims = layout.dim
    if len(dims) != 2 or layout.data_offset != 0:
        return None
    d0, d1 = dims
    if (d0.size != 1 or d0.stride != 2 or d1.size != 2 or d1.stride != 2
            or d0.label != SAMPLE_LABEL or d1.label != CURRENT_COLUMNS):
        return None
    data = msg.data
    if len(data) != 2:
        return None
    return data[0], data[1]


def _stamp(time_s: float) -> tuple[int, int]:
    """Return (sec, nanosec) of a ROS stamp for ``time_s`` (rounded to the nanosecond)."""
    return divmod(round(time_s * 1e9), 1_000_000_000)


def _byte_order(serialised: bytes) -> str:
    """Return the struct byte order of a CDR message from its encapsulation header."""
    return '<' if serialised[1] & 1 else '>'    # CDR_LE = 0x0001, CDR_BE = 0x0000


class PointCodec:
    """
    Write :func:`point_message` as serialised bytes (its stamp and ``z`` set in a template).

    ``length_m`` and ``frame_id`` are fixed per codec; the bytes deserialise to exactly
    :func:`point_message` (tested).
    """

    def __init__(self, length_m: float, frame_id: str):
        self.key = (length_m, frame_id)
        walk = CdrWalk()
        walk.field(4, 2)                                # header.stamp: int32 sec, uint32 nanosec
        walk.string(frame_id)
        self._z_at = walk.field(8, 3) + 16             # point: x, y, z
        self._template = bytearray(serialize_message(point_message(0.0, length_m, 0.0, frame_id)))
        for p in walk.pads:                             # serialisers leave garbage there
            self._template[p] = 0
        order = _byte_order(self._template)
        self._stamp = struct.Struct(order + 'iI')
        self._z = struct.Struct(order + 'd')

    def encode(self, time_s: float, deflection_m: float) -> bytes:
        """Return the serialised point of ``deflection_m`` at ``time_s``."""
        out = bytearray(self._template)
        self._stamp.pack_into(out, 4, *_stamp(time_s))
        self._z.pack_into(out, self._z_at, deflection_m)
        return bytes(out)


def point_message(time_s: float, length_m: float, deflection_m: float, frame_id: str):
    """
    Return the tip as ``geometry_msgs/PointStamped``.

    (L, 0, w) in the clamp frame at ``time_s``.
    """
    from geometry_msgs.msg import PointStamped

    sec, nsec = _stamp(time_s)
    p = PointStamped()
    p.header.stamp.sec = sec
    p.header.stamp.nanosec = nsec
    p.header.frame_id = frame_id
    p.point.x = length_m
    p.point.z = deflection_m
    return p

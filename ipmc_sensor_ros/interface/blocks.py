# SPDX-License-Identifier: Apache-2.0
"""
The sample-block layout of ``std_msgs/Float64MultiArray`` messages, without ROS.

A block of ``n`` timed samples is a 2-D array, row-major::

    layout.dim[0] = (label "sample", size n, stride 2 n)
    layout.dim[1] = (label <columns>, size 2, stride 2)
    layout.data_offset = 0 (a non-zero offset is honoured when reading)
    data = [t_0, v_0, t_1, v_1, ..., t_{n-1}, v_{n-1}]   (float64)

``t_k`` is the sample time in seconds (ROS time as float seconds), ``v_k`` the
value in the unit named by the column label: ``"time_s,current_A"`` for the
sensing current (A), ``"time_s,deflection_m"`` for tip deflections (m).  A plain
1-D array (no dimension, or one whose size matches the data) holds values only.

Used by the nodes (:mod:`ipmc_sensor_ros.nodes.messages`, which also packs) and
by the bag reader of the workbench; works on any object with ``layout.dim``,
``layout.data_offset`` and ``data`` (rclpy or rosbags messages).
"""
from __future__ import annotations

import array

import numpy as np

from ..errors import DataError
from ..physics.parameters import short_repr

__all__ = ['DataError', 'SAMPLE_LABEL', 'CURRENT_COLUMNS', 'DEFLECTION_COLUMNS',
           'ESTIMATE_COLUMNS', 'ESTIMATE_COLUMNS_UNFLAGGED', 'current_columns',
           'deflection_columns', 'estimate_columns', 'unpack_columns', 'unpack_pairs']

#: Label of the row dimension.
SAMPLE_LABEL = 'sample'
#: Column label of current blocks: seconds, amperes.
CURRENT_COLUMNS = 'time_s,current_A'
#: Column label of deflection blocks: seconds, metres.
DEFLECTION_COLUMNS = 'time_s,deflection_m'
#: Column label of the estimator's output blocks: seconds, metres, the standard deviation
#: of each estimate, metres, and its flag ``deflection_beyond_limit`` (1.0 when |w| exceeds
#: what the geometry allows, else 0.0: :mod:`ipmc_sensor_ros.estimation.limits`).
ESTIMATE_COLUMNS = 'time_s,deflection_m,deflection_std_m,deflection_beyond_limit'
#: The estimator's output without the flag column, as recorded bags may hold it (read only).
ESTIMATE_COLUMNS_UNFLAGGED = 'time_s,deflection_m,deflection_std_m'


def current_columns(channels: int = 1) -> str:
    """
    Column label of current blocks of a sensor array of ``channels`` sensors.

    One channel: :data:`CURRENT_COLUMNS`; several: ``time_s,current_ch0_A,current_ch1_A,...``
    (one current column per channel, amperes, sharing the sample times).
    """
    if channels == 1:
        return CURRENT_COLUMNS
    return 'time_s,' + ','.join(f'current_ch{c}_A' for c in range(channels))


def deflection_columns(channels: int = 1) -> str:
    """
    Column label of deflection blocks (e.g. the simulator's truth) of ``channels`` sensors.

    One channel: :data:`DEFLECTION_COLUMNS`; several: ``time_s,deflection_ch0_m,...``.
    """
    if channels == 1:
        return DEFLECTION_COLUMNS
    return 'time_s,' + ','.join(f'deflection_ch{c}_m' for c in range(channels))


def estimate_columns(channels: int = 1) -> str:
    """
    Column label of the estimator's output blocks for ``channels`` sensors.

    One channel: :data:`ESTIMATE_COLUMNS`; several: ``time_s,deflection_ch0_m,
    deflection_std_ch0_m,deflection_beyond_limit_ch0,deflection_ch1_m,...`` (a deflection,
    its standard deviation, metres, and its flag per channel; NaN where that channel has no
    estimate for the block).
    """
    if channels == 1:
        return ESTIMATE_COLUMNS
    return 'time_s,' + ','.join(f'deflection_ch{c}_m,deflection_std_ch{c}_m,'
                                f'deflection_beyond_limit_ch{c}' for c in range(channels))


def _data(msg) -> np.ndarray:
    data = msg.data
    if isinstance(data, array.array) and data.typecode == 'd':
        return np.frombuffer(data, dtype=float)
    return np.asarray(data, dtype=float)


def unpack_columns(msg, columns: str, *, values_only_ok: bool = True):
    """
    Return (times_s or None, table) of a block message whose ``dim[1]`` label is ``columns``.

    ``columns``: ``"time_s,<value>[,<more>...]"``, k names; ``table`` has shape (n, k - 1).
    :class:`DataError` if malformed.  ``values_only_ok``: accept a 1-D values-only message
    (times None, table of shape (n, 1)).  Values are not checked for finiteness here.
    """
    k = len(columns.split(','))
    dims = list(msg.layout.dim)
    offset = int(msg.layout.data_offset)
    data = _data(msg)
    if offset < 0 or offset > data.size:
        raise DataError(f'layout.data_offset {offset} is outside the data (length {data.size})')
    data = data[offset:]
    if len(dims) <= 1 and values_only_ok:
        if dims and dims[0].size != data.size:
            raise DataError(f'1-D layout: dim[0].size = {dims[0].size} but the data holds '
                            f'{data.size} value(s)')
        return None, data[:, None]
    if len(dims) != 2:
        note = ' (values only, no sample times)' if len(dims) < 2 else ''
        raise DataError(f"expected 2 dimensions (dim[0] '{SAMPLE_LABEL}', dim[1] '{columns}'), "
                        f'got {len(dims)}{note}')
    d0, d1 = dims
    if d0.label != SAMPLE_LABEL:
        raise DataError(f"dim[0].label is {short_repr(d0.label)}, expected '{SAMPLE_LABEL}'")
    if d1.label != columns:
        raise DataError(
            f"dim[1].label is {short_repr(d1.label)}, expected '{columns}' (wrong units "
            'or wrong topic?)'
        )
    if d1.size != k or d1.stride != k:
        raise DataError(f'dim[1] must have size {k} and stride {k}, got size {d1.size}, '
                        f'stride {d1.stride}')
    if data.size % k:
        what = 'is odd: samples are (time, value) pairs' if k == 2 else \
            f'is not a multiple of {k}: samples are ({columns}) rows'
        raise DataError(f'data length {data.size} {what}')
    n = data.size // k
    if d0.size != n or d0.stride != k * n:
        raise DataError(f'dim[0] is (size {d0.size}, stride {d0.stride}) but the data holds {n} '
                        f'row(s) of {k}: expected dim[0].size = {n}, dim[0].stride = {k * n}')
    rows = data.reshape(n, k)
    return rows[:, 0].copy(), rows[:, 1:].copy()


def unpack_pairs(msg, columns: str, *, values_only_ok: bool = True):
    """(times_s or None, values) of a two-column block (:func:`unpack_columns`)."""
    times, table = unpack_columns(msg, columns, values_only_ok=values_only_ok)
    return times, table[:, 0]

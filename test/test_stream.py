# SPDX-License-Identifier: Apache-2.0
"""
The stream core owns every rule of a live stream.

The node, the core fed directly and the offline path must give identical outputs and counters
on the same input, bad blocks included.
"""
from __future__ import annotations

import numpy as np
import pytest
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from conftest import DirectNode
from ipmc_sensor_ros.errors import DataError
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.estimation.records import estimate_record
from ipmc_sensor_ros.estimation.stream import COUNTER_NAMES, MAX_STAMP_S, StreamEstimator
from ipmc_sensor_ros.nodes.messages import pack_block

FS = 1000.0


def _values_only(values) -> Float64MultiArray:
    m = Float64MultiArray()
    m.layout.dim = [MultiArrayDimension(label='sample', size=len(values), stride=1)]
    m.data = [float(v) for v in values]
    return m


def _random_stream(rng, n_blocks: int = 120):
    """
    Return (times or None, currents) blocks.

    Good ones, and every kind of bad one a peer can send through a valid layout
    (values and times that break a stream rule).
    """
    blocks, t0 = [], 50.0
    kinds = ('ok',) * 6 + ('nan', 'huge', 'time_nan', 'not_increasing', 'wrong_rate',
                           'backward_inside', 'too_fast', 'gap_bridged', 'gap_reset',
                           'jump_back', 'values_only', 'one_sample', 'negative_time')
    for _ in range(n_blocks):
        kind = str(rng.choice(kinds))
        n = 1 if kind == 'one_sample' else int(rng.integers(2, 60))
        t = t0 + np.arange(n) / FS
        i = 3e-6 * np.sin(2 * np.pi * 2.0 * t) + rng.normal(0, 2e-8, n)
        advance = True
        if kind == 'nan':
            i[n // 2] = np.nan
            advance = False
        elif kind == 'huge':
            i[0] = 5.0
            advance = False
        elif kind == 'time_nan':
            t = t.copy()
            t[-1] = np.nan
            advance = False
        elif kind == 'not_increasing':
            t = t.copy()
            t[n // 2] = t[0]
            advance = False
        elif kind == 'wrong_rate':
            t = t0 + np.arange(n) / (2 * FS)
            advance = False
        elif kind == 'backward_inside':
            t = np.concatenate([t[: n // 2], t[: n - n // 2] - 0.5])
            advance = False
        elif kind == 'too_fast':
            t = t - 0.5 / FS           # starts half a period after the previous sample
            advance = False
        elif kind == 'gap_bridged':
            t = t + 2 / FS
        elif kind == 'gap_reset':
            t = t + 0.3
        elif kind == 'jump_back':
            t = t - 5.0
        elif kind == 'negative_time':
            t = t - 1e6
            advance = False
        blocks.append((None if kind == 'values_only' else t, i))
        if advance:
            t0 = (t[-1] if kind != 'values_only' else t0 + (n - 1) / FS) + 1 / FS
    return blocks


def _message(times, values):
    return _values_only(values) if times is None else pack_block(times, values)


def test_node_and_stream_core_give_identical_outputs_and_counters():
    rng = np.random.default_rng(11)
    blocks = _random_stream(rng)
    node = DirectNode(publish_points='none')
    try:
        # the core fed directly, with the same design the node built
        est = node.node.deflection_estimator
        core = StreamEstimator(DeflectionEstimator(est.model, FS, reduced=est.reduced),
                               max_gap_s=0.1, source='/current', now_s=lambda: 50.0)
        outputs = []
        # the first block of a values-only stream starts at the node's clock: give both the same
        # start by sending a timed block first
        for times, values in blocks:
            node.send(_message(times, values))
            res = core.feed(times, values)
            if res is not None:
                outputs.append(res)
        assert node.node.counters() == core.counters
        c = core.counters
        assert core.check_invariant()
        # every kind of event happened, so the identity covers every rule
        assert c['messages_rejected'] > 0 and c['resets'] >= 2 and c['gaps_bridged'] > 0
        assert len(node.published) == len(outputs)
        # the node takes one-sample messages by the lean path (process_one), the core fed
        # blocks: the default (kalman) estimator's two paths agree to rounding (1e-12 m)
        for pub, (t, w) in zip(node.published, outputs, strict=True):
            assert np.array_equal(pub.times_s, t)
            np.testing.assert_allclose(pub.values, w, rtol=0, atol=1e-12)
    finally:
        node.close()


def test_offline_record_equals_the_stream_fed_sample_by_sample():
    """
    ``estimate_record`` (``ipmc-model estimate``, bag replay) applies the live rules.

    A record of concatenated runs with gaps gives what a live stream of the same samples,
    one message each, gives: the same decisions, counters and estimates.
    """
    rng = np.random.default_rng(3)
    parts, t0 = [], 10.0
    for k in range(4):
        n = int(rng.integers(1500, 2500))
        parts.append(t0 + np.arange(n) / FS)
        t0 = parts[-1][-1] + (0.5 if k == 1 else 1 / FS)      # one long gap
        if k == 2:
            t0 -= 3.0                                          # one run starting earlier
    t = np.concatenate(parts)
    i = 3e-6 * np.sin(2 * np.pi * 1.5 * t) + rng.normal(0, 2e-8, t.size)
    proto = DirectNode(publish_points='none')
    try:
        est = proto.node.deflection_estimator
        make = lambda: DeflectionEstimator(est.model, FS, reduced=est.reduced)  # noqa: E731
    finally:
        proto.close()
    t_off, w_off, stream = estimate_record(make(), t, i, block_samples=500)
    live = StreamEstimator(make(), max_gap_s=0.1)
    out = [live.feed_one(a, b) for a, b in zip(t.tolist(), i.tolist())]
    messages = ('messages_in', 'messages_rejected')
    assert {k: v for k, v in stream.counters.items() if k not in messages} == \
        {k: v for k, v in live.counters.items() if k not in messages}
    assert stream.counters['resets'] == 2 and stream.counters['gaps'] == 1
    assert np.array_equal(t_off, [o[0] for o in out])
    # the default (kalman) core's one-sample and block paths agree to rounding (1e-12 m)
    np.testing.assert_allclose(w_off, [o[1] for o in out], rtol=0, atol=1e-12)
    assert stream.kept.all()


def _fresh_stream():
    proto = DirectNode(publish_points='none')
    try:
        est = proto.node.deflection_estimator
        return StreamEstimator(DeflectionEstimator(est.model, FS, reduced=est.reduced),
                               max_gap_s=0.1)
    finally:
        proto.close()


def test_a_faster_stream_is_decided_alike_in_one_sample_messages_and_blocks():
    """
    Issue #18 defect 4: one rule for one-sample messages and blocks.

    500 one-sample messages stamped at 2 kHz into a 1 kHz estimator were all accepted, 10-sample
    blocks of the same data all rejected.  One rule per sample now: the same decisions either
    way (the grid re-locks to the measured 2 kHz after a few tens of samples).
    """
    t = 100.0 + np.arange(1500) / (2 * FS)
    i = np.full(t.size, 1e-7)
    nodes = [DirectNode(publish_points='none') for _ in range(2)]
    try:
        for node, size in zip(nodes, (1, 10)):
            node.send(pack_block(np.array([t[0] - 1 / FS]), np.array([0.0])))  # 1 kHz before
            for k in range(0, t.size, size):
                node.send(pack_block(t[k:k + size], i[k:k + size]))
        one, block = (n.node.counters() for n in nodes)
        messages = ('messages_in', 'messages_rejected')
        assert {k: v for k, v in one.items() if k not in messages} == \
            {k: v for k, v in block.items() if k not in messages}
        assert 0 < one['rejected_stamp_too_close'] < 64 and one['rate_rebuilds'] == 1
        assert abs(nodes[0].node.stream.measured_rate_hz / (2 * FS) - 1) < 1e-4
    finally:
        for n in nodes:
            n.close()


def test_values_only_messages_obey_the_time_range():
    """Issue #18 defect 10: 1-D messages continued the time past 2^31 s (stamps wrapped)."""
    stream = _fresh_stream()
    assert stream.feed(np.array([MAX_STAMP_S - 0.002]), np.array([0.0])) is not None
    assert stream.feed(None, np.zeros(2)) is not None                  # up to MAX_STAMP_S
    assert stream.feed(None, np.zeros(5)) is None
    assert 'stamps must lie in [0, 2147483647] s' in stream.last_rejection
    assert stream.check_invariant()


def test_unpublished_output_is_counted_once_and_never_resets():
    """
    Issue #18 defect 1 (core part).

    a publish that cannot complete moves the block from samples_out to
    samples_unpublished; the filter runs on, no reset.
    """
    node = DirectNode(publish_points='per_sample')
    try:
        def refuse(_msg):
            raise RuntimeError('cannot publish data')
        node.node._pub_block.publish = refuse
        t = 5.0 + np.arange(300) / FS
        for k in range(0, 300, 1):
            node.send(pack_block(t[k:k + 1], np.full(1, 1e-7)))
        c = node.node.counters()
        assert c['samples_unpublished'] == 300 and c['messages_unpublished'] == 300
        assert c['samples_out'] == 0 and c['resets'] == 0
        assert c['samples_in'] == (c['samples_out'] + c['samples_rejected'] + c['samples_dropped']
                                   + c['samples_unpublished'])
        assert node.node.stream.last_time_s == t[-1]        # the filter ran on
    finally:
        node.close()


def test_counter_names_are_the_documented_ones():
    stream = _fresh_stream()
    assert tuple(stream.counters) == COUNTER_NAMES
    with pytest.raises(DataError, match='max_gap_s'):
        StreamEstimator(stream.estimator, max_gap_s=0.0)


def test_kalman_node_learns_the_offset_at_rest_and_publishes_its_uncertainty():
    """
    Issue #14 through the node: estimator 'kalman' on a DAQ current with a 15 nA offset.

    a 3 % 50 Hz hum and a hold: the block output carries a finite standard deviation, the
    counters topic the learned offset and the rest state, and the held deflection does not
    drift with the offset (the leaky inverse ramps by offset/R0 per leak time).
    """
    from ipmc_sensor_ros.interface.blocks import ESTIMATE_COLUMNS
    from ipmc_sensor_ros.nodes.messages import unpack_block

    node = DirectNode(publish_points='none', estimator='kalman', mains_hz='50')
    try:
        node.node._pub_block.publish = lambda m: node.published.append(
            unpack_block(m, ESTIMATE_COLUMNS))
        rng = np.random.default_rng(2)
        t = 1.0 + np.arange(20_000) / FS                    # 20 s at rest: offset + noise + hum
        i = 15e-9 + rng.normal(0, 5e-9, t.size) + 2e-9 * np.sin(2 * np.pi * 50 * t)
        for k in range(0, t.size, 100):
            node.send(pack_block(t[k:k + 100], i[k:k + 100]))
        node.node._on_timer()
        status = node.node.stream.estimator.status()
        assert status['estimator'] == 'kalman' and status['at_rest']
        # the offset learned from 20 s of rest: within 3 nA of 15 nA (noise 5 nA per sample,
        # hum notched; the running mean's sd is far below that, 3 nA allows for the detector's
        # settling time)
        assert abs(status['offset_a'] - 15e-9) < 3e-9
        w = np.concatenate([b.values for b in node.published])
        std = np.concatenate([b.extra[:, 0] for b in node.published])
        assert np.all(np.isfinite(std)) and np.all(std >= 0)
        # held at rest: the last 10 s of the estimate stay within 0.05 mm (a 15 nA offset
        # through the leaky inverse ramps by ~0.7 mm, issue #14)
        assert np.ptp(w[-10_000:]) < 5e-5
    finally:
        node.close()


@pytest.mark.parametrize('one_sample', [True, False])
def test_a_fault_inside_the_estimator_drops_its_samples_and_the_stream_goes_on(one_sample):
    """
    An exception inside the estimator is a defect, not the input's: it must not end a node.

    Drawn record 228 (2026-12-02) raised a ValueError deep in the filter; in a live node that
    would have ended the callback's executor.  Now the samples of the call that raised are
    dropped and the filter reset, counted (``samples_dropped``, ``resets``) and said with
    the exception's text, and the next samples are estimated: 100 samples fed, the 50th
    raising, 99 estimated.
    """
    stream = _fresh_stream()
    est = stream.estimator
    name = 'process_one' if one_sample else 'process'
    real, calls = getattr(est, name), []

    def faulty(*args):
        calls.append(1)
        if len(calls) == 50 if one_sample else len(calls) == 5:
            raise ValueError('operands could not be broadcast together')
        return real(*args)
    setattr(est, name, faulty)
    t = 3.0 + np.arange(100) / FS
    size = 1 if one_sample else 10
    for k in range(0, t.size, size):
        if one_sample:
            stream.feed_one(float(t[k]), 1e-8)
        else:
            stream.feed(t[k:k + size], np.full(size, 1e-8))
    c = stream.counters
    assert c['samples_dropped'] == size and c['resets'] == 1
    assert c['samples_out'] == 100 - size and stream.check_invariant()
    assert 'estimator fault (ValueError: operands could not' in stream.last_warning
    assert stream.last_fault == 'estimator fault (ValueError: operands could not be broadcast ' \
        'together)'

# SPDX-License-Identifier: Apache-2.0
"""
Sensor arrays: one estimator node, N channels (README "Sensor arrays").

1. Core (:class:`ArrayStream`): each channel's output is bit-identical to a single-sensor
   :class:`StreamEstimator` run on that channel's column with the same block cuts; a bad value
   in one channel is accounted in that channel only; a bad time in every channel.
2. The node in process (:class:`DirectNode` harness): N-column blocks in and out, per-channel
   counters and diagnostics, model_files, parameter changes reaching every channel.
3. Two processes over DDS: simulator (channels=4) -> estimator (channels=4), exact accounting per
   channel and tracking of each channel's own truth.
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from ipmc_sensor_ros.errors import ParameterError
from ipmc_sensor_ros.estimation.array import ArrayStream
from ipmc_sensor_ros.estimation.stream import StreamEstimator
from ipmc_sensor_ros.interface import builders as B
from ipmc_sensor_ros.interface import specs as C
from ipmc_sensor_ros.interface.blocks import (current_columns, deflection_columns,
                                              estimate_columns, unpack_columns)
from ipmc_sensor_ros.physics.modelfile import save_model

FS = 1000.0


def _currents(n: int, channels: int, seed: int = 3) -> np.ndarray:
    """DAQ-like currents: 1 Hz sensing current of 1 uA, 30 nA offset, 2 % noise, 50 Hz hum."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    out = np.empty((n, channels))
    for c in range(channels):
        clean = 1e-6 * np.sin(2 * np.pi * 1.0 * t + 0.4 * c)
        out[:, c] = (clean + 30e-9 + 2e-8 * rng.standard_normal(n)
                     + 5e-9 * np.sin(2 * np.pi * 50.0 * t))
    return out


def _values(**kw):
    v = C.defaults(C.ESTIMATOR_SPECS)
    v.update(kw)
    return v


# -- 1. core -----------------------------------------------------------------------------------
def test_array_equals_single_channel_runs():
    channels, n = 4, 3000
    times = 100.0 + np.arange(n) / FS
    times[1700:] += 0.05              # a bridged gap (50 ms < max_gap_s)
    times[2500:] += 1.0               # a gap beyond max_gap_s: a reset
    table = _currents(n, channels)
    ests = B.build_channel_estimators(_values(channels=channels))
    array = ArrayStream(ests)
    singles = [StreamEstimator(B.build_estimator(_values(), ests[0].reduced))
               for _ in range(channels)]
    cuts = [0, 1, 7, 250, 251, 900, 1700, 2222, 2500, 2999, n]   # one-sample blocks included
    for a, b in zip(cuts[:-1], cuts[1:]):
        if b - a == 1:
            got = array.feed_one(float(times[a]), table[a].tolist())
        else:
            got = array.feed(times[a:b], table[a:b])
        t_out, w, std, has = got
        assert has.all()
        for c, single in enumerate(singles):
            t_ref, w_ref = single.feed(times[a:b], table[a:b, c])
            # the same filter on the same numbers; a one-sample block takes the array's
            # process_one path, which for the default (kalman) estimator agrees with its
            # block path to rounding (1e-12 m, test_kalman)
            np.testing.assert_array_equal(t_out, t_ref)
            np.testing.assert_allclose(w[:, c], w_ref, rtol=0, atol=1e-12)
    for c, single in enumerate(singles):
        assert array.channels[c].counters == single.counters
    assert array.channels[0].counters['resets'] == 1
    assert array.channels[0].counters['gaps_bridged'] == 1
    assert array.check_invariant()


def test_bad_value_in_one_channel_is_accounted_there_only():
    channels = 3
    ests = B.build_channel_estimators(_values(channels=channels))
    array = ArrayStream(ests)
    t = np.arange(150) / FS
    table = _currents(150, channels)
    table[110, 1] = np.nan            # in the second block, channel 1 only
    assert array.feed(t[:100], table[:100])[3].all()
    _, w, std, has = array.feed(t[100:], table[100:])
    assert has.tolist() == [True, True, True]
    # that sample of channel 1 only is refused: NaN in its column, nothing else
    assert np.isnan(w[10, 1]) and np.isfinite(np.delete(w, 10, axis=0)).all()
    assert np.isfinite(w[:, [0, 2]]).all()
    per = array.counters()
    assert per[1]['samples_rejected'] == per[1]['rejected_non_finite'] == 1
    assert per[1]['messages_rejected'] == 0
    assert per[0]['samples_rejected'] == per[2]['samples_rejected'] == 0
    assert per[0]['samples_out'] == per[2]['samples_out'] == 150
    assert per[1]['samples_out'] == 149
    assert array.totals()['samples_in'] == 3 * 150
    assert array.check_invariant()
    # the other channels ran on as if channel 1 did not exist
    single = StreamEstimator(B.build_estimator(_values(), ests[0].reduced))
    single.feed(t[:100], table[:100, 2])
    np.testing.assert_array_equal(w[:, 2], single.feed(t[100:], table[100:, 2])[1])


def test_bad_stamp_refuses_that_sample_in_every_channel():
    array = ArrayStream(B.build_channel_estimators(_values(channels=2)))
    t = np.arange(20) / FS
    t[5] = t[4]                       # a duplicated stamp
    t_out, w, _, has = array.feed(t, _currents(20, 2))
    assert has.all() and t_out.size == 19 and np.isfinite(w).all()
    assert [p['rejected_duplicate_stamp'] for p in array.counters()] == [1, 1]
    assert array.check_invariant()


def test_model_files_per_channel(tmp_path):
    base = B.build_model(_values())
    soft = base.with_material(dataclasses.replace(
        base.material, youngs_modulus_pa=0.5 * base.material.youngs_modulus_pa))
    path = tmp_path / 'soft.yaml'
    save_model(path, soft)
    v = _values(channels=3, model_files=['', str(path), ''])
    ests = B.build_channel_estimators(v)
    ref_soft = B.build_estimator(_values(model_file=str(path)))
    ref_node = B.build_estimator(_values(), ests[0].reduced)
    t = np.arange(500) / FS
    i = _currents(500, 1)[:, 0]
    outs = [e.process(t, i)[1] for e in ests]
    np.testing.assert_array_equal(outs[1], ref_soft.process(t, i)[1])
    np.testing.assert_array_equal(outs[0], ref_node.process(t, i)[1])
    # a softer beam (E halved) bends further for the same charge: the channels must differ
    assert np.max(np.abs(outs[1] - outs[0])) > 0.1 * np.max(np.abs(outs[0]))
    with pytest.raises(ParameterError, match="'model_files' has 2 entries for channels = 3"):
        B.build_channel_estimators(_values(channels=3, model_files=['', '']))
    with pytest.raises(ParameterError, match="'model_files' entry 1"):
        B.build_channel_estimators(_values(channels=2, model_files=['', str(tmp_path / 'no')]))


def test_column_labels():
    assert current_columns(1) == 'time_s,current_A'
    assert current_columns(3) == 'time_s,current_ch0_A,current_ch1_A,current_ch2_A'
    assert deflection_columns(2) == 'time_s,deflection_ch0_m,deflection_ch1_m'
    assert estimate_columns(2) == ('time_s,deflection_ch0_m,deflection_std_ch0_m,'
                                   'deflection_beyond_limit_ch0,deflection_ch1_m,'
                                   'deflection_std_ch1_m,deflection_beyond_limit_ch1')


# -- 2. the node in process ---------------------------------------------------------------------
class _ArrayNode:
    """The :class:`DirectNode` harness with N-column output capture."""

    def __init__(self, channels, **overrides):
        from conftest import DirectNode

        self.d = DirectNode(channels=channels, **overrides)
        self.node = self.d.node
        self.blocks = []
        cols = estimate_columns(channels)
        self.node._pub_block.publish = lambda m: self.blocks.append(unpack_columns(m, cols))
        self.counters_json = []
        self.node._pub_counters.publish = lambda m: self.counters_json.append(json.loads(m.data))
        self.packer_columns = current_columns(channels)

    def send(self, times, table):
        from ipmc_sensor_ros.nodes.messages import pack_block

        cols = [table[:, c] for c in range(table.shape[1])]
        self.d.send(pack_block(times, cols[0], self.packer_columns, *cols[1:]))


@pytest.fixture
def array_node():
    made = []

    def make(channels, **overrides):
        made.append(_ArrayNode(channels, **overrides))
        return made[-1]
    yield make
    for a in made:
        a.d.close()


def test_node_array_blocks_match_the_core(array_node):
    from ipmc_sensor_ros.nodes.messages import pack_block

    channels = 3
    a = array_node(channels)
    n = 1200
    t = 50.0 + np.arange(n) / FS
    table = _currents(n, channels)
    table[650, 2] = np.inf            # that sample of channel 2 is refused, there only
    for k in range(0, n, 200):
        a.send(t[k:k + 200], table[k:k + 200])
    a.send(t[:1], table[:1])          # time jumps back: a reset in every channel (not a rule)
    # one-sample message of an array, then a 1-D (values only) and a wrong-label message
    a.send(t[1:2], table[1:2])
    a.d.send(pack_block(t[2:4], table[2:4, 0]))          # 'time_s,current_A': wrong layout
    assert len(a.blocks) == 8
    ref = ArrayStream([B.build_estimator(_values(), a.node.deflection_estimator.reduced)
                       for _ in range(channels)])
    for k, (times, out) in zip(range(0, n, 200), a.blocks):
        r_t, r_w, r_std, r_has = ref.feed(t[k:k + 200], table[k:k + 200])
        np.testing.assert_array_equal(times, r_t)
        np.testing.assert_array_equal(out[:, 0::3], r_w)     # deflection columns
        np.testing.assert_array_equal(out[:, 1::3], r_std)   # kalman: the filter's std
        # flags: within L/2 where there is an estimate, NaN where the sample was refused
        np.testing.assert_array_equal(out[:, 2::3], np.where(np.isnan(r_w), np.nan, 0.0))
    column = a.blocks[3][1][:, 6]             # channel 2 of the block 600..800
    assert np.isnan(column[50]) and np.isfinite(np.delete(column, 50)).all()
    assert np.isfinite(a.blocks[3][1][:, 0]).all()
    per = a.node.channel_counters()
    # the wrong-layout message is counted as the rows of this array its payload fills:
    # ceil(4 values / 4 columns) = 1
    assert [p['samples_rejected'] for p in per] == [1, 1, 2]
    assert [p['messages_rejected'] for p in per] == [1, 1, 1]
    assert [p['samples_out'] for p in per] == [n + 2, n + 2, n + 1]
    # every channel starts a new run on the jump back (1.2 s > max_gap_s)
    assert [p['resets'] for p in per] == [1, 1, 1], per
    assert a.node.array.check_invariant()
    assert a.node.counters()['samples_in'] == 3 * (n + 3)
    # counters topic: totals plus one entry per channel
    a.node._on_timer()
    msg = a.counters_json[-1]
    assert msg['samples_in'] == 3 * (n + 3) and len(msg['channels']) == channels
    assert msg['channels'][2]['samples_rejected'] == 2
    # /diagnostics: the node's aggregate plus one status per channel
    diag = a.node._diagnostics.update(a.node._status())
    names = [s.name for s in diag.status]
    node_name = a.node.get_fully_qualified_name()
    assert names == [node_name] + [f'{node_name}: {a.node.input_topic} ch{c}'
                                   for c in range(channels)]
    values = {kv.key: kv.value for kv in diag.status[3].values}
    assert values['samples_rejected'] == '2'


def test_node_array_parameter_change_reaches_every_channel(array_node):
    from rclpy.parameter import Parameter

    a = array_node(2)
    t = np.arange(100) / FS
    a.send(t, _currents(100, 2))
    result = a.node.set_parameters([Parameter('motion_corner_hz', value=0.5)])[0]
    assert result.successful, result.reason
    assert [ch.estimator.config.motion_corner_hz
            for ch in a.node.array.channels] == [0.5, 0.5]
    # a model change is rebuilt off the data path, then swapped into every channel
    result = a.node.set_parameters([Parameter('length_m', value=0.03)])[0]
    assert result.successful, result.reason
    a.node.settle()
    assert [ch.estimator.model.geometry.length_m for ch in a.node.array.channels] == [0.03, 0.03]
    a.send(0.1 + t, _currents(100, 2))
    assert a.node.array.check_invariant() and len(a.blocks) == 2
    refused = a.node.set_parameters([Parameter('channels', value=3)])[0]
    assert not refused.successful       # read-only: the array is fixed at start-up


def test_node_array_start_up_errors(tmp_path):
    from conftest import DirectNode
    from ipmc_sensor_ros.nodes.params import ParameterError as NodeParameterError

    with pytest.raises(NodeParameterError, match="'model_files' is for channels > 1"):
        DirectNode(model_files=[str(tmp_path / 'x.yaml')])
    with pytest.raises(NodeParameterError, match="'model_files' has 1 entries for channels = 2"):
        DirectNode(channels=2, model_files=[''])


# -- 3. two processes over DDS -------------------------------------------------------------------
@pytest.mark.ros
def test_simulator_array_to_estimator_array_over_dds(tmp_path, monkeypatch):
    """
    Simulator (channels=4, each channel 0.1 s further along a 1 Hz crank) -> estimator.

    120 s in fast mode, blocks of 200 (600 messages, fewer than the QoS depth of 1000: none can
    be lost, see test_nodes_integration).  Every channel tracks its own truth column within the
    5 % NRMSE of the single-sensor test (same physics, same leak decay by the scored last 20 s).
    """
    from std_msgs.msg import Float64MultiArray, String

    from ipmc_sensor_ros.nodes import topics as T
    from ipmc_sensor_ros.workbench.metrics import nrmse
    from process_graph import ProcessGraph

    channels, duration_s = 4, 120.0
    n_samples = int(duration_s * FS)
    graph = ProcessGraph(tmp_path, monkeypatch)
    qos = T.make_qos({'qos_depth': 1000, 'qos_reliability': 'reliable'})
    est, truth, counters = [], [], {}
    subs = [
        graph.node.create_subscription(
            Float64MultiArray, '/array/deflection/block',
            lambda m: est.append(unpack_columns(m, estimate_columns(channels))), qos),
        graph.node.create_subscription(
            Float64MultiArray, '/array/deflection_truth',
            lambda m: truth.append(unpack_columns(m, deflection_columns(channels))), qos),
        graph.node.create_subscription(
            String, '/array/estimator/counters',
            lambda m: counters.update(json.loads(m.data)), T.COUNTERS_QOS),
    ]

    def rows(blocks):
        return sum(b[0].size for b in blocks)

    try:
        graph.start('estimator', 'estimator_node',
                    {'channels': channels, 'publish_points': 'none'}, '/array')
        graph.spin_until(lambda: subs[0].get_publisher_count() > 0, 'the estimator', 180.0)
        graph.start('simulator', 'simulator_node',
                    {'channels': channels, 'channel_time_offset_s': 0.1,
                     'realtime_factor': 0.0, 'block_size': 200, 'duration_s': duration_s,
                     'noise_rms_a': 1e-9, 'wait_for_subscribers': 1}, '/array')
        graph.spin_until(lambda: rows(est) == n_samples and rows(truth) == n_samples
                         and counters.get('samples_out') == channels * n_samples, 'the run',
                         180.0)
    finally:
        codes = graph.close()
    for c in counters['channels']:
        assert c['samples_in'] == c['samples_out'] == n_samples, c
        assert c['samples_rejected'] == c['samples_dropped'] == c['resets'] == 0, c
    t_e = np.concatenate([b[0] for b in est])
    w_e = np.concatenate([b[1] for b in est])
    t_t = np.concatenate([b[0] for b in truth])
    w_t = np.concatenate([b[1] for b in truth])
    np.testing.assert_array_equal(t_e, t_t)          # the same sample times, in order
    last = t_e >= t_e[-1] - 20.0
    errors = [nrmse(w_e[last, 3 * c], w_t[last, c]) for c in range(channels)]
    print(f'array of {channels} over DDS: NRMSE per channel {np.round(errors, 4).tolist()}')
    assert max(errors) < 0.05, errors
    # the channels are different signals (0.1 s apart on a 1 Hz crank): a swapped column fails
    assert nrmse(w_e[last, 0], w_t[last, 1]) > 0.3
    assert codes == {'estimator': 0, 'simulator': 0}, graph.log_texts()

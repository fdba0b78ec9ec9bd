# SPDX-License-Identifier: Apache-2.0
"""
Reliability: fuzzed input to the estimator node, bad configuration files.

Soak of the estimator core, and finite models across the physical parameter range.
"""
from __future__ import annotations

import os
import random
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from ipmc_sensor_ros.interface import builders
from ipmc_sensor_ros.interface import specs as config
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.estimation.inverse import InverseEstimator, leak_tradeoff
from ipmc_sensor_ros.nodes.messages import pack_block
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_PARAMETERS, PAPER_SAMPLES, Geometry
from ipmc_sensor_ros.lti.reduction import ParameterError, reduce_model
from conftest import DirectNode

ROOT = Path(__file__).resolve().parents[1]
FS = 1000.0
SLIM = PAPER_SAMPLES['slim']


# ---------------------------------------------------------------------------
# Node input fuzzing
# ---------------------------------------------------------------------------
@pytest.fixture(scope='module')
def direct():
    d = DirectNode()
    yield d
    d.close()


def _signal(n, start, rng):
    t = start + np.arange(n) / FS
    return t, 4e-6 * np.sin(2 * np.pi * 3.0 * t) + rng.normal(0, 1e-8, n)


def _corrupt(kind: str, t, i, rng):
    """
    Return a message that must be refused whole, by kind.

    Value and stamp corruptions spoil every sample (one bad sample is refused alone,
    test_stream_time); ``t`` continues a stream whose last sample was at ``t[0] - 1/FS``.
    """
    if kind == 'nan':
        return pack_block(t, np.full(i.size, np.nan))
    if kind == 'inf':
        return pack_block(t, np.full(i.size, -np.inf))
    if kind == 'huge':
        return pack_block(t, np.full(i.size, 1e30))
    if kind == 'time_nan':
        return pack_block(np.full(t.size, np.nan), i)
    if kind == 'not_increasing':       # behind the previous sample (a late block)
        return pack_block(t[0] - 2 / FS - np.arange(t.size)[::-1] * 1e-5, i)
    if kind == 'wrong_rate':           # every stamp on the previous sample's grid slot
        return pack_block(t[0] - 1 / FS + (0.1 + 0.3 * np.arange(t.size) / t.size) / FS, i)
    if kind == 'empty':
        return Float64MultiArray()
    if kind == 'odd':
        m = pack_block(t, i)
        m.data = list(m.data) + [0.0]
        return m
    if kind == 'wrong_label':
        m = pack_block(t, i)
        m.layout.dim[1].label = 'time_s,current_mA'
        return m
    if kind == 'bad_stride':
        m = pack_block(t, i)
        m.layout.dim[0].stride = 3
        return m
    if kind == 'three_dims':
        m = pack_block(t, i)
        m.layout.dim.append(MultiArrayDimension(label='x', size=1, stride=1))
        return m
    if kind == 'bad_offset':
        m = pack_block(t, i)
        m.layout.data_offset = 10 ** 6
        return m
    raise AssertionError(kind)


CORRUPTIONS = ('nan', 'inf', 'huge', 'time_nan', 'not_increasing', 'wrong_rate', 'empty', 'odd',
               'wrong_label', 'bad_stride', 'three_dims', 'bad_offset')


def test_one_sample_lean_path_gives_the_general_paths_results():
    """
    One-sample messages take a lean scalar path (performance issue).

    It must publish exactly what the general block path publishes and count alike,
    through bad messages, a bridged gap, a reset gap and a backward time jump.
    """
    rng = np.random.default_rng(5)
    t, i = _signal(600, 10.0, rng)
    t[300:] += 0.002          # bridged gap (3 periods)
    t[450:] += 0.5            # gap > max_gap_s: reset
    t[520:] -= 2.0            # time jumps back: reset
    msgs = []
    for k in range(t.size):
        msgs.append(pack_block(t[k:k + 1], i[k:k + 1]))
        if k % 37 == 5:
            msgs.append(_corrupt(('nan', 'huge', 'time_nan', 'wrong_label', 'odd')[k % 5],
                                 t[k:k + 1], i[k:k + 1], rng))
    lean, general = DirectNode(publish_points='per_sample'), DirectNode(
        publish_points='per_sample'
    )
    block = general.node.stream.feed

    def as_block(t, i):             # the block path for every one-sample message
        out = block(np.array([t]), np.array([i]))
        return None if out is None else (float(out[0][0]), float(out[1][0]))

    general.node.stream.feed_one = as_block
    try:
        for m in msgs:
            lean.send(m)
            general.send(m)
        assert lean.node.counters() == general.node.counters()
        assert lean.node.counters()['resets'] == 2 and lean.node.counters()['gaps_bridged'] == 1
        # the default (kalman) estimator's one-sample and block paths agree to rounding
        # (1e-12 m, test_kalman); times, counters and frames exactly
        for a, b in zip(lean.published, general.published, strict=True):
            assert np.array_equal(a.times_s, b.times_s)
            np.testing.assert_allclose(a.values, b.values, rtol=0, atol=1e-12)
        assert len(lean.points) == len(general.points) == t.size
        for p, q in zip(lean.points, general.points):
            assert p[:4] == q[:4] and abs(p[4] - q[4]) <= 1e-12
    finally:
        lean.close()
        general.close()


@settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(
    plan=st.lists(
        st.tuples(st.sampled_from(('ok',) * 4 + CORRUPTIONS), st.integers(1, 400)),
        min_size=1,
        max_size=25,
    ),
    seed=st.integers(0, 2**31 - 1),
    denormal=st.booleans(),
)
def test_fuzzed_messages_never_poison_the_filter_and_are_all_accounted(
    direct, plan, seed, denormal
):
    rng = np.random.default_rng(seed)
    node = direct.node
    # each example starts a fresh stream: a backward time jump resets the node
    start = 1000.0 + rng.uniform(0, 1e5)
    node.stream.restart()
    before = node.counters()
    direct.published.clear()
    reference = DeflectionEstimator(node.deflection_estimator.model, FS, reduced=node._reduced)
    expected = []
    plan = [('ok', 5)] + plan          # a stream the bad messages come late to
    for kind, n in plan:
        if kind in ('not_increasing', 'wrong_rate'):
            n = max(n, 3)     # a single sample has no order and no rate to get wrong
        t, i = _signal(n, start, rng)
        if denormal:
            i = i + 5e-320        # subnormal floats must not slow down or break anything
        if kind == 'ok':
            direct.send(pack_block(t, i))
            expected.append(reference.process(t, i)[1])
            start = t[-1] + 1 / FS
        else:
            direct.send(_corrupt(kind, t, i, rng))
    after = node.counters()
    d = {k: after[k] - before[k] for k in after}
    assert d['samples_in'] == d['samples_out'] + d['samples_rejected'] + d['samples_dropped']
    assert d['messages_in'] == len(plan)
    assert d['samples_dropped'] == 0
    assert d['messages_rejected'] == sum(k != 'ok' for k, _ in plan)
    out = np.concatenate([b.values for b in direct.published]) if direct.published else np.empty(0)
    assert np.all(np.isfinite(out))
    ref = np.concatenate(expected) if expected else np.empty(0)
    assert out.shape == ref.shape
    # bad messages left no trace: the output equals a filter that only saw the good ones
    assert np.max(np.abs(out - ref), initial=0.0) <= 1e-12


def test_random_message_generator_and_oversized_message(direct):
    """Plain random bytes-as-floats, random layouts, bursts, and one 10^7-sample message."""
    rng = np.random.default_rng(7)
    before = direct.node.counters()
    for _ in range(300):
        m = Float64MultiArray()
        ndim = int(rng.integers(0, 4))
        for k in range(ndim):
            m.layout.dim.append(MultiArrayDimension(
                label=str(rng.choice(['sample', 'time_s,current_A', 'x', ''])),
                size=int(rng.integers(0, 50)), stride=int(rng.integers(0, 100))))
        m.data = rng.standard_normal(int(rng.integers(0, 200))).view(np.float64).tolist()
        direct.send(m)
    big = np.zeros(20_000_000)   # 10^7 (time, current) pairs
    big[0::2] = 5000.0 + np.arange(10_000_000) / FS
    msg = Float64MultiArray(data=big.tolist()[:0])
    msg.data = big                # array-like payload, as a fast driver would fill it
    msg.layout.dim = [MultiArrayDimension(label='sample', size=10_000_000, stride=20_000_000),
                      MultiArrayDimension(label='time_s,current_A', size=2, stride=2)]
    direct.send(msg)
    after = direct.node.counters()
    d = {k: after[k] - before[k] for k in after}
    assert d['messages_in'] == 301
    assert d['samples_in'] == d['samples_out'] + d['samples_rejected']
    assert 'limit' in direct.node.last_rejection or d['samples_out'] >= 10_000_000


# ---------------------------------------------------------------------------
# Configuration files
# ---------------------------------------------------------------------------
@pytest.mark.parametrize('body,needle', [
    ('lenght_m: 0.022', 'lenght_m'),                       # typo
    ('length_m: 22.0', 'millimetres'),                     # unit mistake
    ('leak_corner_hz: fast', 'leak_corner_hz'),            # wrong type
    ('reduction_order: 12', 'reduction_order'),            # out of range
    ("effects: ['warp_drive']", 'warp_drive'),             # unknown effect
])
def test_bad_params_file_stops_node_startup_naming_key_and_file(tmp_path, body, needle):
    f = tmp_path / 'bad_params.yaml'
    f.write_text(f'/**/ipmc_estimator:\n  ros__parameters:\n    {body}\n')
    env = dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(random.randint(150, 200)))
    res = subprocess.run([sys.executable, '-m', 'ipmc_sensor_ros.nodes.estimator_node',
                          '--ros-args', '--params-file', str(f)], env=env, capture_output=True,
                         text=True, timeout=60)
    assert res.returncode == 2, res.stderr
    assert needle in res.stderr and 'bad_params.yaml' in res.stderr
    assert 'Traceback' not in res.stderr


@pytest.mark.parametrize('body,needle', [
    ('lenght_m: 0.022', 'lenght_m'), ('length_m: 22.0', 'length_m'),
    ('leak_corner_hz: fast', 'leak_corner_hz'), ('model: h3', 'model'),
])
def test_bad_params_file_offline_names_key_and_file(tmp_path, body, needle):
    f = tmp_path / 'bad_params.yaml'
    f.write_text(f'/**/ipmc_estimator:\n  ros__parameters:\n    {body}\n')
    with pytest.raises(config.ParameterError) as err:
        config.load_params_file(f)
    assert needle in str(err.value) and 'bad_params.yaml' in str(err.value)


def test_shipped_config_files_load():
    values = config.load_params_file(ROOT / 'config' / 'estimator.yaml')
    assert values['sample_rate_hz'] == 1000.0 and builders.build_estimator(values) is not None


# ---------------------------------------------------------------------------
# Soak of the estimator core (CI: 10^7 samples; bench: 10^8)
# ---------------------------------------------------------------------------
def soak(n_samples: int, block: int = 1_000_000, offset_a: float = 2e-8, noise_a: float = 1e-8):
    """
    Noisy, offset current through the inverse.

    Returns (max |w|, documented bound, traced memory growth in bytes between
    the first and last block).
    """
    reduced = reduce_model(SensorModel(SLIM), 4)
    est = InverseEstimator(reduced, FS)
    rng = np.random.default_rng(0)
    worst = 0.0
    tracemalloc.start()
    mem_first = None
    for k in range(0, n_samples, block):
        y = est.process(offset_a + rng.normal(0, noise_a, min(block, n_samples - k)))
        assert np.all(np.isfinite(y))
        worst = max(worst, float(np.max(np.abs(y))))
        current, _ = tracemalloc.get_traced_memory()
        mem_first = current if mem_first is None else mem_first
    mem_last, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    # documented bound: the leak's steady offset error plus 6 sigma of the filtered noise
    steady = leak_tradeoff(reduced, est.leak_corner_hz, 1.0, offset_a)['offset_steady_error_m']
    f = np.linspace(0, FS / 2, 200_001)
    gain2 = np.abs(est.frequency_response(f)) ** 2
    noise_sd = noise_a * np.sqrt(np.trapezoid(gain2, f) / (FS / 2))
    return worst, steady + 6 * noise_sd, mem_last - mem_first


def test_soak_core_ten_million_samples():
    worst, bound, growth = soak(10_000_000)
    assert worst <= bound
    assert growth < 1_000_000     # no growth beyond buffers of one block


@pytest.mark.slow
def test_soak_core_hundred_million_samples():
    worst, bound, growth = soak(100_000_000)
    assert worst <= bound and growth < 1_000_000


# ---------------------------------------------------------------------------
# Numerical range
# ---------------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(thickness=st.floats(50e-6, 2e-3), length=st.floats(5e-3, 0.1), width=st.floats(1e-3, 0.05),
       r0=st.floats(0.0, 1000.0), d=st.floats(1e-13, 1e-8), model=st.sampled_from(['h1', 'h2']))
def test_models_finite_across_the_physical_range(thickness, length, width, r0, d, model):
    material = PAPER_PARAMETERS.replace(surface_resistance_ohm=r0, diffusivity_m2_per_s=d)
    m = SensorModel.named(model, Geometry(length, width, thickness), material)
    f = np.logspace(-3, 3, 200)
    h = m.frequency_response(f)
    assert np.all(np.isfinite(h)) and np.all(np.abs(h) > 0)
    try:
        red = reduce_model(m, 4)
    except ParameterError as exc:     # allowed, if it says why
        assert str(exc)
        return
    assert np.all(red.poles_rad_s.real < 0) and np.all(red.zeros_rad_s.real < 0)
    est = InverseEstimator(red, FS)
    assert np.all(np.abs(est.poles()) < 1)

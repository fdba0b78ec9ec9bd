# SPDX-License-Identifier: Apache-2.0
"""
Parameter changes in quick succession are coalesced into one model rebuild (issue 18).

Validation (phase 1) still refuses a bad value at once; the reduction of the accepted values
is built once, off the data path, and equals what one combined change gives.
"""
import numpy as np
import pytest
from rclpy.parameter import Parameter

from conftest import DirectNode
from ipmc_sensor_ros.nodes.messages import pack_block

FS = 1000.0


@pytest.fixture
def nodes():
    made = []

    def make(**overrides):
        made.append(DirectNode(**overrides))
        return made[-1]

    yield make
    for d in made:
        d.close()


def _feed(direct, start_s, n=400):
    t = start_s + np.arange(n) / FS
    i = 4e-6 * np.sin(2 * np.pi * 3.0 * t) + np.random.default_rng(3).normal(0, 4e-8, n)
    for k in range(0, n, 100):
        direct.send(pack_block(t[k:k + 100], i[k:k + 100]))
    return np.concatenate([b.values for b in direct.published])


CHANGES = (('length_m', 0.03), ('thickness_m', 2.5e-4), ('youngs_modulus_pa', 6.0e8))


def test_three_model_changes_in_a_row_rebuild_once_and_equal_one_combined_change(nodes):
    separate, combined = nodes(), nodes()
    before = separate.node._reduced
    for name, value in CHANGES:
        assert separate.node.set_parameters([Parameter(name, value=value)])[0].successful
    # a bad value among them is refused at once (phase 1), whatever is still being built
    refused = separate.node.set_parameters([Parameter('youngs_modulus_pa', value=1e-296)])[0]
    assert not refused.successful and 'youngs_modulus_pa' in refused.reason
    assert combined.node.set_parameters(
        [Parameter(name, value=value) for name, value in CHANGES])[0].successful
    separate.node.settle()
    combined.node.settle()
    assert separate.node.rebuilds == 1 and combined.node.rebuilds == 1
    a, b = separate.node._reduced, combined.node._reduced
    assert a is not before
    assert np.array_equal(a.poles_rad_s, b.poles_rad_s)
    assert np.array_equal(a.zeros_rad_s, b.zeros_rad_s)
    for name, value in CHANGES:
        assert separate.node.get_parameter(name).value == value
    # same filter from here on: bit-identical output
    assert np.array_equal(_feed(separate, 10.0), _feed(combined, 10.0))


def test_data_keeps_the_old_filter_until_the_rebuild_is_swapped_in(nodes):
    changed, unchanged = nodes(), nodes()
    old = changed.node.stream.estimator
    assert changed.node.set_parameters([Parameter('length_m', value=0.03)])[0].successful
    # the parameter call did not wait for the new reduction; the stream still runs the old
    # filter (it is swapped in at the next message once built)
    assert changed.node.rebuilds == 0 and changed.node.stream.estimator is old
    changed.node.settle()
    out_changed = _feed(changed, 10.0)
    out_unchanged = _feed(unchanged, 10.0)
    # a 30 mm instead of 22 mm beam changes the gain: the new model is in use after settle
    assert not np.allclose(out_changed, out_unchanged, rtol=0.01, atol=0)
    assert changed.node.rebuilds == 1


def test_filter_only_change_is_applied_at_once(nodes):
    d = nodes()
    # a filter setting (not the sensor's model): no new reduction, the filter is rebuilt at once
    assert d.node.set_parameters([Parameter('motion_corner_hz', value=4.0)])[0].successful
    assert d.node._builder is None and d.node.rebuilds == 1
    assert d.node.stream.estimator.core.config.motion_corner_hz == 4.0


def test_changes_faster_than_a_build_still_land(nodes, monkeypatch):
    # a peer that changes a model parameter more often than a build takes must not starve
    # every rebuild: each finished build is swapped in, then the newest values are built
    import threading
    import time

    from ipmc_sensor_ros.nodes import live_params as E

    direct = nodes()
    node = direct.node
    real_build = node._build
    slow = threading.Event()

    def slow_build(values, validate=False):
        if not validate:
            slow.set()
            time.sleep(0.5)     # a build 2.5x longer than the 0.2 s between changes below
        return real_build(values, validate)

    monkeypatch.setattr(node, '_build', slow_build)
    lengths = [0.030 + 0.0005 * k for k in range(12)]
    for length in lengths:      # 12 changes over 2.4 s: never 0.5 s without a change
        assert node.set_parameters([Parameter('length_m', value=length)])[0].successful
        time.sleep(0.2)
        with node._lock:
            if node._rebuilt is not None:
                node._apply_rebuilt()
    assert slow.is_set() and node.rebuilds >= 2, node.rebuilds   # builds landed meanwhile
    node.settle()
    assert node._built_values['length_m'] == lengths[-1]
    assert E.REBUILD_QUIET_S < 0.2      # the premise of the timing above

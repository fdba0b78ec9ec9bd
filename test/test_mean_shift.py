# SPDX-License-Identifier: Apache-2.0
"""
estimation/mean_shift.py: a shift of a white sequence's mean, of any size, told once old enough.

The statistic is checked against its own theory on white noise drawn here (no estimator
code): its false alarms, the age at which a shift of a quarter sigma is told, and that the
memories longer than the filter's following time are not used.
"""
from __future__ import annotations

import numpy as np
import pytest

from ipmc_sensor_ros.estimation.mean_shift import ShiftTest
from ipmc_sensor_ros.estimation.rest import RestTest


def _first_alarm(test: ShiftTest, z, follow: float = np.inf):
    sums = None
    for k, value in enumerate(z.tolist()):
        sums, told = test.step(sums, value, follow)
        if told:
            return k
    return None


@pytest.mark.parametrize('false_alarm', [1e-2, 1e-3])
def test_on_white_noise_the_shift_test_alarms_below_its_level(false_alarm):
    """
    Each memory's T_j is chi2_1 at every sample, and one is tested at false_alarm / K.

    The union bound makes the rate at most ``false_alarm`` per sample (restarted after each
    alarm, as the rest test's track is); the sums' correlation keeps it far below (measured
    4-6 %).  Allowed: below the level, and above a hundredth of it (the test is not dead:
    400 or 40 alarms at the level over 40,000 samples, the measured 4 % of them is 16 or 2).
    """
    test = ShiftTest.design(false_alarm)
    rng = np.random.default_rng(5)
    sums, alarms = None, 0
    for value in rng.standard_normal(40_000).tolist():
        sums, told = test.step(sums, value, np.inf)
        if told:
            alarms, sums = alarms + 1, None
    assert alarms < false_alarm * 40_000
    if false_alarm >= 1e-2:
        assert alarms > 0.01 * false_alarm * 40_000


def test_a_quarter_sigma_shift_is_told_at_the_age_its_size_needs():
    """
    A shift of delta = 0.25 is told when delta^2 2^(j+1) passes the limit.

    The limit is 31.5 (chi2_1 at 1e-6 / 52, every memory used).  That needs 2^(j+1) >= 504,
    the memory 256 (or 512) filled: a few hundred samples.  The rest test's CUSUM (drift 0.5)
    has a negative mean step then and would not tell it.
    Allowed per record: after the shift (2,000 white samples before it, at 1e-6 per sample
    none expected) and within 2,000 samples of it (the memory 512's sum reaches its mean by
    then); the median of 20 between 200 and 1,200 (measured 530).
    """
    test = ShiftTest.design(1e-6)
    ages = []
    for seed in range(20):
        z = np.random.default_rng(seed).standard_normal(6000)
        z[2000:] += 0.25
        at = _first_alarm(test, z)
        assert at is not None and 2000 <= at < 4000
        ages.append(at - 2000)
    assert 200 < np.median(ages) < 1200


def test_memories_beyond_the_filters_following_time_are_not_used():
    """
    A filter that follows a step within 16 samples tests memories up to 16 only.

    delta = 0.25 then gives T ~ 0.0625 x 31 = 2 against a limit near 26 (chi2_1 at 1e-6 / 4):
    nothing is told in 20,000 samples, while with every memory it is (the test above).
    """
    test = ShiftTest.design(1e-6)
    z = np.random.default_rng(3).standard_normal(20_000) + 0.25
    assert _first_alarm(test, z, follow=16.0) is None
    assert _first_alarm(test, z) is not None


def test_the_rest_test_ends_a_rest_at_a_shift_its_cusum_cannot_see():
    """
    RestTest.sample_ok with the filter's offset known (P_b = 0): a 0.25 sigma shift ends it.

    With the shift statistic every one of 20 records ends within 1,100 samples (measured
    159-1,011; the CUSUM tells some first).  The same test without it (``shift=None``: the
    per-sample chi-square and the CUSUM only) ends 7 of 20 within 4,000 samples, by
    excursions of a CUSUM whose step has mean -0.25: allowed at most 10.
    """
    with_shift = RestTest.design(0.2, 2000.0, 1e-6)
    without = RestTest(**{**with_shift.__dict__, 'shift': None})
    ended = ([], [])
    for seed in range(20):
        z = np.random.default_rng(100 + seed).standard_normal(4000) + 0.25
        for test, ends in zip((with_shift, without), ended):
            track, at = None, None
            for k, value in enumerate(z.tolist()):
                ok, track = test.sample_ok(value, track, 0.0, 0.0, 1.0, at_rest=True)
                if not ok:
                    at = k
                    break
            ends.append(at)
    assert all(at is not None and at < 1100 for at in ended[0])
    assert sum(at is not None for at in ended[1]) <= 10

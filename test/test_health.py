# SPDX-License-Identifier: Apache-2.0
"""Health evaluator behind /diagnostics (ROS-free)."""
import numpy as np
import pytest

from ipmc_sensor_ros.interface.health import (ERROR, OK, WARN, CurrentStatistics, HealthLimits,
                                              HealthMonitor, worst)

FS = 1000.0


def _counters(samples, **kw):
    c = dict(messages_in=samples // 10, samples_in=samples, messages_rejected=0, resets=0,
             gaps=0, samples_dropped=0)
    c.update(kw)
    return c


def test_ok_at_nominal_rate_then_error_when_stale():
    mon = HealthMonitor(FS, HealthLimits(stale_after_s=2.0))
    assert mon.evaluate(_counters(0), 0.0).level == OK          # just started
    assert mon.evaluate(_counters(1000), 1.0).level == OK       # first data
    h = mon.evaluate(_counters(2000), 2.0)
    assert h.level == OK and h.values['measured_rate_hz'] == '1000'
    assert mon.evaluate(_counters(2000), 3.5).level == OK       # 1.5 s < stale_after_s
    h = mon.evaluate(_counters(2000), 4.5)                       # 2.5 s without data
    assert h.level == ERROR and 'no data for 2.5 s' in h.message


def test_error_when_no_data_ever():
    mon = HealthMonitor(FS, HealthLimits(stale_after_s=2.0))
    mon.evaluate(_counters(0), 10.0)
    h = mon.evaluate(_counters(0), 12.5)
    assert h.level == ERROR and 'since start' in h.message


def test_warn_on_malformed_messages_resets_gaps_only_while_they_happen():
    mon = HealthMonitor(FS)
    mon.evaluate(_counters(1000), 1.0)
    h = mon.evaluate(_counters(2000, rejected_malformed=2, resets=1, gaps=1), 2.0)
    assert h.level == WARN
    for text in ('2 sample(s) in malformed message(s) rejected', '1 filter reset(s)',
                 '1 time gap(s)'):
        assert text in h.message
    # same totals one second later: nothing new, back to OK
    assert mon.evaluate(_counters(3000, rejected_malformed=2, resets=1, gaps=1), 3.0).level == OK


def test_the_first_evaluation_reports_what_was_counted_before_it():
    """
    Counts before the first evaluation are its period's, not lost.

    The first evaluation compared with nothing and skipped the counter warnings: messages of
    a second publisher ignored (or resets, gaps) before the node's first 1 Hz tick were
    never reported (a DDS test failed whenever its messages all arrived within the first
    second).  Its period now runs from the start.
    """
    mon = HealthMonitor(FS)
    h = mon.evaluate(_counters(1000, resets=1, messages_ignored=5), 1.0)
    assert h.level == WARN
    assert '1 filter reset(s)' in h.message and '5 message(s) of other publishers' in h.message
    assert mon.evaluate(_counters(2000, resets=1, messages_ignored=5), 2.0).level == OK


def test_warn_when_the_estimator_takes_a_jump_of_the_offset():
    mon = HealthMonitor(FS)
    assert mon.evaluate(_counters(1000, offset_jumps=0), 1.0).level == OK
    h = mon.evaluate(_counters(2000, offset_jumps=1), 2.0)
    assert h.level == WARN and '1 jump(s) of the current offset taken' in h.message
    assert h.values['offset_jumps'] == '1'
    assert mon.evaluate(_counters(3000, offset_jumps=1), 3.0).level == OK


def test_warn_when_the_lost_or_refused_fraction_exceeds_its_limit():
    mon = HealthMonitor(FS, HealthLimits(loss_warn_fraction=0.01))
    mon.evaluate(_counters(1000), 1.0)
    # 5 lost slots and 5 refused samples in 1000: 0.5 %, within 1 %
    h = mon.evaluate(_counters(2000, samples_lost=5, samples_rejected=5,
                               rejected_duplicate_stamp=5), 2.0)
    assert h.level == OK, h.message
    # 30 slots without a sample (bridged gaps), 20 duplicated and 5 non-finite samples
    h = mon.evaluate(_counters(3000, samples_lost=35, samples_rejected=30,
                               rejected_duplicate_stamp=25, rejected_non_finite=5), 3.0)
    assert h.level == WARN
    assert '2.91 % of the data lost before the node (30 sample slot(s)' in h.message
    assert '2.5 % of the samples refused (duplicate_stamp 20, non_finite 5' in h.message
    # messages that never arrived (sequence numbers) count as lost too
    h = mon.evaluate(_counters(4000, samples_lost=35, samples_rejected=30, messages_lost=50,
                               rejected_duplicate_stamp=25, rejected_non_finite=5), 4.0)
    assert h.level == WARN and '50 message(s) that never arrived' in h.message


def test_warn_naming_the_publishers_ignored():
    mon = HealthMonitor(FS)
    mon.evaluate(_counters(1000), 1.0)
    h = mon.evaluate({**_counters(2000, messages_ignored=1000),
                      'ignored_publishers': '/rogue_daq (gid 01.0f): 1000',
                      'followed_publisher': '/daq (gid 01.0e)'}, 2.0)
    assert h.level == WARN and '/rogue_daq (gid 01.0f): 1000' in h.message
    assert 'following /daq (gid 01.0e)' in h.message


def test_warn_on_rate_off_sample_rate():
    mon = HealthMonitor(FS, HealthLimits(rate_tolerance=0.05))
    mon.evaluate(_counters(1000), 1.0)
    h = mon.evaluate(_counters(1900), 2.0)       # 900 Hz: 10 % low
    assert h.level == WARN and 'sample rate 900 Hz (received per second), expected 1000 Hz' \
        in h.message
    assert mon.evaluate(_counters(2880), 3.0).level == OK      # 980 Hz: within 5 %
    # the rate the stream measured from the stamps wins (a bag replayed at 2x is no mismatch)
    h = mon.evaluate({**_counters(4880), 'measured_rate_hz': 700.0}, 4.0)
    assert h.level == WARN and 'sample rate 700 Hz (measured from the stamps)' in h.message
    assert mon.evaluate({**_counters(6880), 'measured_rate_hz': 1001.0}, 5.0).level == OK


def test_done_source_is_not_stale():
    mon = HealthMonitor(FS, HealthLimits(stale_after_s=1.0), samples_key='samples_published')
    mon.evaluate({'samples_published': 500, 'done': True}, 0.0)
    h = mon.evaluate({'samples_published': 500, 'done': True}, 5.0)
    assert h.level == OK and h.message == 'done'


def test_offset_estimate_recovers_daq_offset_under_motion():
    # 2 Hz charge-rate current (zero mean over whole periods) + 80 nA offset + 2 % noise
    rng = np.random.default_rng(3)
    t = np.arange(int(12 * FS)) / FS
    signal = 1e-6 * np.cos(2 * np.pi * 2.0 * t)
    i = signal + 80e-9 + 0.02e-6 * rng.standard_normal(t.size)
    stats = CurrentStatistics(FS, offset_window_s=10.0)
    for k in range(0, t.size, 37):                 # uneven blocks
        stats.observe(i[k:k + 37])
    # the exponential mean weights a sinusoid by at most 1/sqrt(1+(w tau)^2) ~ 1/126 of
    # its 1 uA amplitude = 8 nA: tolerance 10 nA
    assert abs(stats.offset_a() - 80e-9) < 10e-9
    mon = HealthMonitor(FS, HealthLimits(offset_warn_a=50e-9))
    mon.evaluate(_counters(1000), 1.0, stats)
    h = mon.evaluate(_counters(2000), 2.0, stats)
    assert h.level == WARN and 'estimated current offset' in h.message


def test_mains_line_warns_but_noise_alone_does_not():
    rng = np.random.default_rng(5)
    t = np.arange(int(2 * FS)) / FS
    motion = 1e-6 * np.sin(2 * np.pi * 1.0 * t)
    noise = 0.03e-6 * rng.standard_normal(t.size)
    clean, hum = CurrentStatistics(FS), CurrentStatistics(FS)
    clean.observe(motion + noise)
    hum.observe(motion + noise + 0.1e-6 * np.sin(2 * np.pi * 50.0 * t))
    f, amp, rms, _ = hum.line()
    # Hann window: a 50 Hz tone over a whole number of periods is measured to < 1 %;
    # leakage of the 1 Hz motion at 49 Hz distance is below 1 nA
    assert f == 50.0 and abs(amp - 0.1e-6) < 3e-9
    mon_clean, mon_hum = HealthMonitor(FS), HealthMonitor(FS)
    for mon, stats in ((mon_clean, clean), (mon_hum, hum)):
        mon.evaluate(_counters(1000), 1.0, stats)
    assert mon_clean.evaluate(_counters(2000), 2.0, clean).level == OK
    h = mon_hum.evaluate(_counters(2000), 2.0, hum)
    assert h.level == WARN and 'mains line at 50 Hz' in h.message


def test_worst_aggregates_channels():
    mon_a, mon_b = HealthMonitor(FS), HealthMonitor(FS, HealthLimits(stale_after_s=0.5))
    a = mon_a.evaluate(_counters(10), 0.0)
    b = mon_b.evaluate(_counters(0), 0.0)
    b = mon_b.evaluate(_counters(0), 1.0)
    agg = worst([a, b])
    assert agg.level == ERROR and agg.message == b.message


def test_one_sample_path_equals_block_path():
    # observe_one is the one-sample message path's shortcut of observe fed one-sample
    # blocks: same mean (float rounding of the two forms: 1e-9 relative) and the same ring
    rng = np.random.default_rng(11)
    i = 1e-6 * rng.standard_normal(int(13.5 * FS)) + 40e-9   # past the 10 s window
    blocks, single = CurrentStatistics(FS), CurrentStatistics(FS)
    for x in i:
        blocks.observe(np.array([x]))
        single.observe_one(x)
    assert single.samples == blocks.samples == i.size
    assert single.offset_a() == pytest.approx(blocks.offset_a(), rel=1e-9, abs=1e-18)
    assert single.line() == pytest.approx(blocks.line(), rel=1e-9)


@pytest.mark.parametrize('fs', [4000.0, 100_000.0, 500_000.0])
def test_line_detection_at_high_sample_rates_equals_the_full_rate_lock_in(fs):
    """
    The status' mains detector averages blocks down to >= DETECT_RATE_HZ before its lock-ins.

    (its cost was O(history): 0.5 s of CPU per status at 500 kHz).  It finds the same lines
    as at 1 kHz, and the same level: the block mean's gain (4 % at 300 Hz) is corrected.
    Tolerances: 3 % between the rates (the neighbour bins' noise, 1 % of the signal per
    sample); 10 % against the true level, because the 3 Hz motion (1.5 periods in the
    0.5 s stretch) leaks through the rectangular window into the 60 Hz bin at ~1e-8 A.
    """
    from ipmc_sensor_ros.estimation.mains import DETECT_RATE_HZ, detect_lines

    assert fs // DETECT_RATE_HZ >= 2          # blocks are averaged at these rates
    rng = np.random.default_rng(3)
    level = {}
    for rate in (1000.0, fs):
        t = np.arange(int(0.5 * rate)) / rate
        lines = 3e-8 * np.sin(2 * np.pi * 60 * t + 0.3) + 1.5e-8 * np.sin(2 * np.pi * 300 * t)
        rest = 1e-6 * np.sin(2 * np.pi * 3 * t) + 1e-8 * rng.standard_normal(t.size)
        found = detect_lines(rest + lines, rate)
        assert found['mains_hz'] == 60 and found['harmonics'] == [1, 5], (rate, found)
        level[rate] = found['level']
        truth = np.sqrt(np.mean(lines ** 2)) / np.std(rest + lines)
        assert level[rate] == pytest.approx(truth, rel=0.1), rate
        assert detect_lines(rest, rate)['harmonics'] == []
    assert level[fs] == pytest.approx(level[1000.0], rel=0.03)

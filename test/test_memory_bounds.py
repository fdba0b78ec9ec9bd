# SPDX-License-Identifier: Apache-2.0
"""
Memory of ``estimate`` and ``compare`` grows by a bounded number of bytes per sample (issue 18).

A 5e6-row file must stay within 500 MB of resident memory.  The record itself holds 24 B per
sample (time, deflection, current as float64); every cost on top of it is bounded here per
sample with :mod:`tracemalloc` (numpy's arrays are traced), on 2e5 samples, with the
reasoning for each bound next to it.  Before the fix the regression matrix of the harmonic
fits alone took ~400 B per sample and scipy's detrend ~70 B per sample.

The pieces that work in chunks are checked against the whole-record formulas they replace:
the same numbers (bit-identical where the arithmetic is the same, else within rounding).
"""
import tracemalloc

import numpy as np
import pytest
from scipy.signal import detrend

from ipmc_sensor_ros.cli.data_verbs import estimate_accuracy
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.estimation.records import estimate_record
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
from ipmc_sensor_ros.simulation import convolution
from ipmc_sensor_ros.workbench import compare as compare_module
from ipmc_sensor_ros.workbench import freqresp, metrics
from ipmc_sensor_ros.workbench.blas import single_threaded_blas
from ipmc_sensor_ros.workbench.compare import compare_records

FS = 1000.0


class _Record:
    """A periodic crank-slider-like record: 3 Hz deflection, its model current, 2 % noise."""

    def __init__(self, n: int, seed: int = 0):
        self.model = SensorModel(PAPER_SAMPLES['slim'])
        self.path, self.sample = f'synthetic_{n}', 'slim'
        self.time_s = np.arange(n) / FS
        self.deflection_m = 1e-3 * np.sin(2 * np.pi * 3.0 * self.time_s)
        i = convolution.lti_response_fft(self.model.transfer, self.time_s, self.deflection_m)
        noise = np.random.default_rng(seed).standard_normal(n)
        self.current_a = i + 0.02 * np.std(i) * noise


def _traced_peak(fn) -> int:
    """Bytes allocated at the peak of ``fn()`` above what was allocated before it."""
    tracemalloc.start()
    try:
        base, _ = tracemalloc.get_traced_memory()
        fn()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak - base


def _small_chunks(monkeypatch):
    """Chunks of 4096 samples: their fixed working set is then negligible against 5e4 rows."""
    monkeypatch.setattr(freqresp, 'FIT_CHUNK_ROWS', 4096)
    monkeypatch.setattr(convolution, 'TRANSFER_CHUNK', 4096)
    monkeypatch.setattr(compare_module, 'GRADIENT_CHUNK', 4096)
    monkeypatch.setattr(metrics, 'CHUNK_ROWS', 4096)


def _bytes_per_sample(run, sizes=(50_000, 100_000)) -> float:
    """
    Growth of the traced peak of ``run(record)`` per added sample.

    The slope between two record lengths, so that the fixed working set of the chunked
    pieces is not counted per sample.  The two lengths put the padded FFT length at about
    the same ratio to the record (65536 / 52000 and 131072 / 102000 samples), so the slope
    is that of a long record.
    """
    peaks = []
    for n in sizes:
        rec = _Record(n)          # made before tracing: the record's own 24 B are not counted
        peaks.append(_traced_peak(lambda: run(rec)))
    return (peaks[1] - peaks[0]) / (sizes[1] - sizes[0])


def test_compare_memory_per_sample_is_bounded(monkeypatch):
    _small_chunks(monkeypatch)
    slope = _bytes_per_sample(lambda rec: compare_records([rec], lambda r: r.model))
    # what the design holds per sample on top of the record, FFT length 1.3x the record here:
    # while predicting, the padded deflection (8 B), its spectrum (n/2+1 complex: 10 B), the
    # frequency grid (5 B), the inverse (10 B) and the prediction cut to the record (8 B);
    # afterwards the prediction kept in the result (8 B) with the residual, its centred copy
    # and the velocity (3 x 8 B) and one product temporary (8 B): 40 B either way (measured
    # ~31 B).  Copies of the record's settled part (4 x 8 B) or the harmonic-fit matrix
    # (~400 B) break it.
    print(f'compare: {slope:.1f} B per sample')
    assert slope <= 40, f'{slope:.0f} B per sample'


def test_estimate_memory_per_sample_is_bounded(monkeypatch):
    _small_chunks(monkeypatch)

    def run(rec):
        # leak corner 0.1 Hz: the NRMSE skips an 8 s transient, not 80 s of the 50 s record
        est = DeflectionEstimator(rec.model, FS, estimator='leaky', leak_corner_hz=0.1)
        t, w, _ = estimate_record(est, rec.time_s, rec.current_a)
        estimate_accuracy(t, w, rec.deflection_m, settle=est.settling())

    slope = _bytes_per_sample(run)
    # output times, estimates and their std (3 x 8 B), the 'kept' mask (1 B) and the sample
    # periods the smoother reuses (8 B: the slots and the stamp's fraction) are the result:
    # 33 B; the accuracy works on views and chunks; the filter's own state does not grow.
    # 36 B leaves room for the diff/mask temporaries of the time rules, not for another
    # record-length float array (the whole-record detrend copies took ~70 B per sample
    # before, the joined block lists 16 B more, the fraction kept apart 8 B).
    assert slope <= 36, f'{slope:.0f} B per sample'


def _harmonic_fit_whole(t, x, f0, k):
    """Fit harmonics with the previous one-matrix least squares (reference)."""
    w0 = 2 * np.pi * f0
    powers = np.cumprod(np.broadcast_to(np.exp(1j * w0 * t), (k, t.size)), axis=0)
    a = np.empty((t.size, 2 * k + 1))
    a[:, 0] = 1.0
    a[:, 1::2] = powers.real.T
    a[:, 2::2] = powers.imag.T
    gram_inv = np.linalg.pinv(a.T @ a)
    coef = gram_inv @ (a.T @ x)
    resid = x - a @ coef
    band = freqresp._band_variance(resid, (t.size - 1) / (t[-1] - t[0]), f0, k)  # the noise
    cov = (float(resid @ resid) / max(t.size - a.shape[1], 1) if band is None else band) * gram_inv
    return coef[1::2] - 1j * coef[2::2], resid, cov


def test_chunked_harmonic_fit_equals_the_whole_matrix_fit(monkeypatch):
    rec = _Record(5_000, seed=1)
    t, y = rec.time_s, rec.current_a
    ref = _harmonic_fit_whole(t, y, 3.0, 12)
    one = freqresp.harmonic_fit(t, y, 3.0, 12)       # one chunk: the same arithmetic
    for a, b in zip(ref, one):
        assert np.array_equal(a, b)
    monkeypatch.setattr(freqresp, 'FIT_CHUNK_ROWS', 333)
    many = freqresp.harmonic_fit(t, y, 3.0, 12)
    # normal equations summed in another order: rounding of the 25x25 Gram matrix only
    # (~1e-16 relative, well conditioned on whole periods), so 1e-12 of each quantity's scale
    for a, b in zip(ref, many):
        assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(a))


def test_chunked_transfer_equals_the_one_shot_fft(monkeypatch):
    rec = _Record(3_001)
    t, w, transfer = rec.time_s, rec.deflection_m, rec.model.transfer
    x, n, fs, _ = convolution.padded_record(t, w, 2.0)
    h = np.asarray(transfer(2j * np.pi * np.fft.rfftfreq(n, 1.0 / fs)), dtype=complex)
    h[0] = 0.0
    h[-1] = h[-1].real
    ref = np.fft.irfft(np.fft.rfft(x, n) * h, n)[:t.size]
    monkeypatch.setattr(convolution, 'TRANSFER_CHUNK', 100)     # many chunks, a ragged last one
    assert np.array_equal(convolution.lti_response_fft(transfer, t, w), ref)


def test_overlap_save_blocks_equal_the_whole_record_convolution(monkeypatch):
    """
    Long records are convolved in blocks; the result is the whole-record one.

    2^16-point blocks on a 300 s robot-motion record (the blocks' history is 33 s, the same
    ratio to the block as in use): the sampled kernel's ringing tails beyond the history
    leave < 2e-4 of the current's RMS (measured 1.1e-4; 2.9e-6 at the 2^21 points used in
    production on a 5e6-sample record).
    """
    from ipmc_sensor_ros.simulation.stimuli import RobotMotion

    model = SensorModel(PAPER_SAMPLES['slim'])
    t = np.arange(300_000) / 1000.0
    w = RobotMotion(seed=2).deflection(t) + 1e-4 * np.sin(2 * np.pi * 7 * t)
    whole = convolution.lti_response_fft(model.transfer, t, w)
    monkeypatch.setattr(convolution, 'OVERLAP_SAVE_FFT', 1 << 16)
    monkeypatch.setattr(convolution, 'OVERLAP_SAVE_ABOVE', 1 << 17)
    blocks = convolution.lti_response_fft(model.transfer, t, w)
    assert blocks.shape == whole.shape
    assert np.max(np.abs(blocks - whole)) < 2e-4 * np.std(whole)


@pytest.mark.parametrize('steps', ['uniform', 'jittered', 'one_odd_step'])
def test_piecewise_gradient_equals_numpy_gradient(monkeypatch, steps):
    n = 1_001
    rng = np.random.default_rng(2)
    t = np.arange(n) / 1024.0                 # exact steps: numpy's uniform-grid branch
    if steps == 'jittered':
        t = np.cumsum(1e-3 + 1e-6 * rng.random(n))
    elif steps == 'one_odd_step':             # uniform pieces in a non-uniform record
        t[n // 2:] += 0.5 / 1024.0
    w = rng.standard_normal(n)
    for chunk in (1, 2, 7, 1000, 4096):
        monkeypatch.setattr(compare_module, 'GRADIENT_CHUNK', chunk)
        assert np.array_equal(compare_module._gradient(w, t), np.gradient(w, t))


def test_running_detrended_nrmse_equals_scipy_detrend(monkeypatch):
    rng = np.random.default_rng(3)
    monkeypatch.setattr(metrics, 'CHUNK_ROWS', 1000)
    for n, trend in ((10, 0.0), (2_345, 1e-3), (20_000, 5e-2)):
        k = np.arange(n)
        m = 1e-3 * np.sin(2 * np.pi * k / 7.3) + trend * k / n + 4e-4
        e = m + 3e-5 * rng.standard_normal(n) - 2 * trend * k / n
        ed, md = detrend(e), detrend(m)
        ref = np.sqrt(np.mean((ed - md) ** 2) / np.mean(md ** 2))
        # least squares by normal equations on the centred index vs scipy's lstsq: both
        # exact to rounding; the error is ~1e-2 of the signal here, so 1e-12 relative holds
        assert metrics.detrended_nrmse(e, m) == pytest.approx(ref, rel=1e-12, abs=0)


def _noise_rms_masks(t, w, y, window_s=4.0):
    """Return :func:`metrics.noise_rms` with the previous window selection by masks (reference)."""
    p = freqresp.fundamental_response(t, w, y)
    f0, k = p.frequency_hz, p.extra['harmonics']
    span = max(2, int(round(window_s * f0))) / f0
    ss, dof, start = 0.0, 0, t[0]
    while start + span <= t[-1] + 1e-9:
        sel = (t >= start) & (t < start + span)
        _, resid, _ = freqresp.harmonic_fit(t[sel] - start, y[sel], f0, k)
        ss += float(resid @ resid)
        dof += max(int(sel.sum()) - (2 * k + 1), 1)
        start += span
    return float(np.sqrt(ss / dof))


def test_noise_rms_windows_by_bisection_equal_the_masks():
    rec = _Record(30_000, seed=4)
    args = (rec.time_s, rec.deflection_m, rec.current_a)
    with single_threaded_blas():     # the fits' thin products are slow with BLAS threads
        assert metrics.noise_rms(*args) == _noise_rms_masks(*args)


def test_long_records_get_an_fft_length_without_bluestein():
    # a prime length near 5e6 made numpy's FFT take 725 MiB more (Bluestein, measured); a
    # length whose largest prime factor is at most its square root never uses Bluestein
    for n in (999_500, 4_999_999, 100_003, 65_537):
        m = freqresp._fft_length(n)
        assert freqresp._largest_prime_factor(m) ** 2 <= m
        assert 0 < n - m < 10                      # a few samples fewer
    for n in (4_999_500, 5_000_000, 99_500, 53):    # unchanged: the same spectrum as before
        assert freqresp._fft_length(n) == n

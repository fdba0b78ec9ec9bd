# SPDX-License-Identifier: Apache-2.0
"""
Exact current of an LTI sensor model for any deflection record: linear convolution by FFT.

No reduction and no discretisation: the model's transfer H(j w) is sampled on the FFT grid
of the record padded with a raised-cosine return to zero, so nothing wraps around
(:func:`lti_response_fft`; overlap-save blocks for long records); :func:`predict_current`
adds a model's effects around it.  The reference the streaming simulators
(:mod:`.sensor`) and the workbench's predictions are held to.
"""
from __future__ import annotations

import numpy as np

from ..errors import DataError
from ..physics.model import SensorModel

__all__ = ['padded_record', 'lti_response_fft', 'predict_current', 'TRANSFER_CHUNK',
           'OVERLAP_SAVE_ABOVE', 'OVERLAP_SAVE_FFT']


def padded_record(time_s: np.ndarray, deflection_m: np.ndarray, pad_s: float):
    """
    (x, n_fft, fs, n_pad): the deflection minus its first value.

    Followed by ``pad_s`` seconds of a raised-cosine return to zero (no
    discontinuity at the circular wrap-around), and the power-of-two FFT length
    that holds it.
    """
    t = np.asarray(time_s, float)
    fs = (t.size - 1) / (t[-1] - t[0])
    w0 = np.asarray(deflection_m, float) - deflection_m[0]
    n_pad = int(np.ceil(pad_s * fs))
    ramp = w0[-1] * 0.5 * (1 + np.cos(np.pi * np.arange(1, n_pad + 1) / n_pad))
    x = np.concatenate([w0, ramp])
    return x, 1 << int(np.ceil(np.log2(x.size))), fs, n_pad


#: Frequencies at which :func:`lti_response_fft` evaluates the model transfer at a time.
TRANSFER_CHUNK = 65_536


def lti_response_fft(transfer, time_s, deflection_m, pad_s: float = 2.0) -> np.ndarray:
    """
    Return the current (A) of any LTI model ``transfer(s)`` (A/m) for any deflection record.

    Exact linear convolution by FFT, with no reduction or discretisation error:
    the record (minus its first value, since a static deflection gives no
    current) is followed by ``pad_s`` seconds of a raised-cosine return to zero,
    so the circular wrap-around carries no discontinuity.  The sensor's memory
    is short (poles at or beyond K ~ 72 s^-1 and pi^2/(4 tau_r)), so after
    ``pad_s`` the wrap-around has decayed; the first few tens of milliseconds of
    the result still carry the unknown motion before the record started, as any
    simulation from rest does.
    """
    t = np.asarray(time_s, float)
    w = np.asarray(deflection_m, float)
    if t.size < 2:
        raise DataError('need at least two samples')
    x, n, fs, n_pad = padded_record(t, w, pad_s)
    if n > OVERLAP_SAVE_ABOVE and n_pad < OVERLAP_SAVE_FFT // 4:
        return _overlap_save(transfer, x, t.size, fs)
    spectrum = np.fft.rfft(x, n)
    del x
    _apply_transfer(transfer, spectrum, n, fs)
    y = np.fft.irfft(spectrum, n)    # (scipy.fft's keeps a cached plan of 16 B per point)
    del spectrum
    return y[: t.size].copy()    # not a view holding the FFT length (up to 2x the record)


#: Records whose FFT length would exceed this are convolved in overlap-save blocks of
#: OVERLAP_SAVE_FFT points (half of each block is history), so memory stays ~100 MB whatever
#: the length (a 5e6-sample record's 2^23-point FFT took ~250 MB).  The history of 2^20
#: samples (17 min at 1 kHz) is far beyond the sensor's memory that the whole-record method
#: already relies on (``pad_s``), so both give the linear convolution to rounding.
OVERLAP_SAVE_ABOVE = 1 << 22
OVERLAP_SAVE_FFT = 1 << 21


def _apply_transfer(transfer, spectrum: np.ndarray, n: int, fs: float) -> None:
    """Multiply an rfft spectrum of ``n`` points in place by the transfer (no DC, real Nyquist)."""
    f = np.fft.rfftfreq(n, 1.0 / fs)
    # the transfer is evaluated TRANSFER_CHUNK frequencies at a time and applied in place
    # (on every frequency at once, its temporaries took ~100 B per sample)
    for a in range(0, f.size, TRANSFER_CHUNK):
        h = np.asarray(transfer(2j * np.pi * f[a:a + TRANSFER_CHUNK]), dtype=complex)
        if a == 0:
            h[0] = 0.0
        if n % 2 == 0 and a + TRANSFER_CHUNK >= f.size:
            h[-1] = h[-1].real
        spectrum[a:a + TRANSFER_CHUNK] *= h


def _overlap_save(transfer, x: np.ndarray, n_out: int, fs: float,
                  n_fft: int | None = None) -> np.ndarray:
    """Return the first ``n_out`` samples of the linear convolution of ``x`` with the model."""
    n_fft = n_fft or OVERLAP_SAVE_FFT
    # the sampled transfer's kernel is two-sided (s R(s) sampled up to Nyquist rings both
    # ways, as the whole-record method's does), so each block sees past and future input
    history, future = n_fft // 2, n_fft // 8
    block = n_fft - history - future
    h = np.ones(n_fft // 2 + 1, dtype=complex)
    _apply_transfer(transfer, h, n_fft, fs)
    y = np.empty(n_out)
    segment = np.empty(n_fft)
    for start in range(0, n_out, block):
        lo = start - history                       # the block's input: past, itself, future
        segment[:] = 0.0
        piece = x[max(lo, 0):min(lo + n_fft, x.size)]
        segment[max(lo, 0) - lo:max(lo, 0) - lo + piece.size] = piece
        out = np.fft.irfft(np.fft.rfft(segment) * h, n_fft)
        y[start:start + block] = out[history:history + min(block, n_out - start)]
    return y


def predict_current(model: SensorModel, time_s, deflection_m, pad_s: float = 2.0) -> np.ndarray:
    """
    Return the current (A) of a model with any effects for a deflection record (m).

    Order of operations: every effect's ``input_transform`` (e.g. the
    nonlinearity), then the linear dynamics by exact FFT convolution
    (:func:`lti_response_fft`), then every ``output_transform`` (e.g. offset).
    A time-varying effect (``material_at``, e.g. ``hydration_drift``) is
    simulated by :func:`~ipmc_sensor_ros.physics.pipeline.time_varying_response`: LTI
    responses at material nodes, linearly interpolated in time (the drift is slow against the
    sensor's ~0.1 s memory, so the response is quasi-static in the material).
    """
    t = np.asarray(time_s, float)
    return model.compiled.predict(t - t[0], np.asarray(deflection_m, float),
                                  lambda m, w: lti_response_fft(m.transfer, t, w, pad_s))

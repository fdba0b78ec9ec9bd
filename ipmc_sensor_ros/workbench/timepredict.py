# SPDX-License-Identifier: Apache-2.0
"""
Time records prepared for fast prediction of a model's current.

Holds the records the time-domain fit (:mod:`~ipmc_sensor_ros.workbench.timefit`) works on:
:class:`Record` (a measured record with its sample model), :func:`prepare` (FFT of the
deflection, the decimated residual rows after ``settle_s``, the log-frequency grid, the row
matrix of long records) and :func:`predict` (the model's current on a prepared record, all
samples or given rows), with the transfer-function interpolation behind it.

Speed: the deflection spectrum of each record is computed once, and the
model's transfer function is evaluated on a log-spaced grid of ``n_grid``
(512) frequencies spanning the record's FFT bins and interpolated (log-magnitude
and unwrapped phase, linear in log f) to all bins; a pure delay is applied
exactly afterwards.  For the smooth diffusion-type responses here the
interpolation error is below 1e-5 relative (2e-4 near a beam resonance; tested
against the exact prediction), far below realistic noise, at a fraction of the
cost.  Every FFT bin is kept, so input transforms (which put energy at
harmonics) are predicted exactly too.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import DataError
from ..physics.model import SensorModel
from ..simulation.convolution import padded_record
from .metrics import noise_rms

__all__ = ['Record', 'PreparedRecord', 'prepare', 'predict']


#: records with more FFT bins than this get a row matrix (:func:`_row_matrix`); below it the
#: per-bin path is cheaper than the (rows x grid) product
ROW_MATRIX_ABOVE = 16_384
#: smallest distance, in grid steps, of a singularity of H(exp(v)) from the record's band of
#: log frequencies v for the cubic interpolation (:func:`_smooth_on_grid`)
MIN_SINGULARITY_STEPS = 20.0
#: largest phase 2 pi f tau of a pure delay at the top bin for the cubic interpolation
MAX_DELAY_PHASE = 4.0


@dataclass
class Record:
    """A time record with its sample model (geometry, header-known material)."""

    path: str
    sample: str
    model: SensorModel          # base model for this record (geometry, known material, effects)
    time_s: np.ndarray
    deflection_m: np.ndarray
    current_a: np.ndarray
    #: samples the DAQ dropped, filled on the sample grid for the model's input
    #: (:func:`~.data.on_sample_grid`); never fitted or scored.  None: none.
    filled: np.ndarray | None = None
    #: the rows were taken at their stamps and interpolated onto the sample clock
    at_stamps: bool = False


@dataclass
class PreparedRecord:
    """
    A :class:`Record` made ready by :func:`prepare` for fast prediction of its current.

    Attributes
    ----------
    rec : the record prepared.
    t, w, y : its sample times (s), deflection (m) and measured current (A), float arrays.
    keep : boolean mask of the samples after ``settle_s``, those the error metrics use.
    rows : indices of the kept samples, decimated, whose residuals the fit uses.
    sigma : measurement-noise RMS of the current, A (:func:`~.metrics.noise_rms`; at least
        1e-30).
    n_fft : length of the FFT of the padded deflection (a power of two).
    bins : ``rfft`` bins where the transfer function is applied (all but DC).
    freqs : frequencies of ``bins``, Hz.
    x_pad : the deflection minus its first value, then ``pad`` samples of a raised-cosine
        return to zero, m (:func:`~ipmc_sensor_ros.simulation.sensor.padded_record`).
    pad : samples of that return to zero.
    x_bins : ``rfft(x_pad, n_fft)`` at ``bins``, m.
    grid_hz : log-spaced frequencies, Hz, where the transfer function is evaluated and
        interpolated from.
    lagrange : per bin, the first grid index and the four cubic Lagrange weights
        (:func:`_lagrange4`).
    fold : per-bin weight and phase shift to sample ``rows[0]`` (:func:`_rows_from_spectrum`;
        set on first use).
    row_matrix : complex (rows x grid) map from the transfer function on ``grid_hz`` to the
        current at ``rows`` (:func:`_row_matrix`; long records only, else None).

    """

    rec: Record
    t: np.ndarray
    w: np.ndarray
    y: np.ndarray
    keep: np.ndarray            # samples used for error metrics (after settle)
    rows: np.ndarray            # decimated sample indices used as fit residuals
    sigma: float
    n_fft: int
    bins: np.ndarray            # rfft bins where H is evaluated
    freqs: np.ndarray
    x_pad: np.ndarray           # padded (w - w0) for the linear path
    pad: int
    x_bins: np.ndarray = None   # FFT of x_pad at ``bins``
    grid_hz: np.ndarray = None  # interpolation grid of the transfer function
    lagrange: tuple = None      # (first grid index, 4 weights) per bin (_lagrange4)
    fold: np.ndarray = None     # per-bin weight and shift to p.rows[0] (_rows_from_spectrum)
    row_matrix: np.ndarray = None   # (rows, grid) map from H on the grid to the rows (_row_matrix)


def prepare(records: Sequence[Record], *, settle_s: float = 0.5, max_rows_per_record: int = 1500,
            pad_s: float = 1.0, n_grid: int = 512,
            row_matrix_above: int = ROW_MATRIX_ABOVE) -> list[PreparedRecord]:
    """
    Prepare records for :func:`~.timefit.fit_model` (FFT of the deflection, residual rows, grid).

    Records with more than ``row_matrix_above`` FFT bins also get their row matrix
    (:func:`_row_matrix`): the fit's residual rows then cost one small matrix product
    per model instead of work on every FFT bin.
    """
    out = []
    for rec in records:
        t = np.asarray(rec.time_s, float)
        w = np.asarray(rec.deflection_m, float)
        y = np.asarray(rec.current_a, float)
        keep = t >= t[0] + settle_s
        if rec.filled is not None:
            keep &= ~rec.filled
        if keep.sum() < 32:
            raise DataError(
                f'{rec.path}: fewer than 32 samples after the {settle_s} s settle time'
            )
        idx = np.flatnonzero(keep)
        step = max(1, int(np.ceil(idx.size / max_rows_per_record)))
        rows = np.arange(idx[0], t.size, step)          # one progression (fast row path),
        rows = rows[keep[rows]]                         # without the filled slots
        x, n, fs, n_pad = padded_record(t, w, pad_s)
        f_all = np.fft.rfftfreq(n, 1.0 / fs)
        bins = np.arange(1, f_all.size)
        freqs = f_all[bins]
        sigma = noise_rms(t[keep], w[keep], y[keep])
        grid = np.geomspace(freqs[0], freqs[-1], n_grid)
        out.append(
            PreparedRecord(
                rec,
                t,
                w,
                y,
                keep,
                rows,
                max(sigma, 1e-30),
                n,
                bins,
                freqs,
                x,
                n_pad,
                np.fft.rfft(x, n)[bins],
                grid,
            )
        )
        out[-1].lagrange = _lagrange4(out[-1])
        if bins.size > row_matrix_above:
            out[-1].row_matrix = _row_matrix(out[-1])
    return out


def predict(p: PreparedRecord, model: SensorModel, cache: dict | None = None,
            rows: np.ndarray | None = None) -> np.ndarray:
    """
    Predict the current of a prepared record under ``model``.

    The same operations as :func:`~ipmc_sensor_ros.simulation.sensor.predict_current`,
    on the kept bins.  ``cache`` (a dict shared across the records of one evaluation) reuses the
    transfer function between records of the same sample and FFT grid.  ``rows``
    (a subset of ``p.rows``): return the current at these samples only; without input
    transforms it is computed there directly (:func:`_rows_from_spectrum`, exact), not
    by a full inverse FFT.
    """
    if rows is not None and rows.size == 0:
        return np.zeros(0)              # a record wholly in a held-out part
    if rows is not None and model.compiled.input_transforms:
        return predict(p, model, cache)[rows]
    if rows is not None:
        matrix = p.row_matrix is not None and _smooth_on_grid(p, model)
        idx = np.searchsorted(p.rows, rows) if matrix else None

        def span_response(m: SensorModel, w: np.ndarray, lo: int, hi: int) -> np.ndarray:
            if hi <= lo:
                return np.zeros(0)
            if not matrix:
                return rows_response(m, w)[lo:hi]
            a, b = int(idx[lo]), int(idx[hi - 1]) + 1      # rows lo:hi lie in p.rows[a:b]
            out = (p.row_matrix[a:b] @ _transfer_on_grid(p, m, cache)).real
            return out[idx[lo:hi] - a]

        def rows_response(m: SensorModel, w: np.ndarray) -> np.ndarray:
            if matrix:
                return span_response(m, w, 0, rows.size)
            return _rows_from_spectrum(p, p.x_bins * _transfer_on_bins(p, m, cache), rows)

        return model.compiled.predict(p.t[rows] - p.t[0], p.w[rows], rows_response,
                                      span_response)
    spec = np.zeros(p.n_fft // 2 + 1, dtype=complex)

    def linear_response(m: SensorModel, w: np.ndarray) -> np.ndarray:
        x_bins = p.x_bins if w is p.w else np.fft.rfft(_repad(p, w), p.n_fft)[p.bins]
        spec[p.bins] = x_bins * _transfer_on_bins(p, m, cache)
        return np.fft.irfft(spec, p.n_fft)[: p.t.size]

    return model.compiled.predict(p.t - p.t[0], p.w, linear_response)


def _transfer_on_bins(
    p: PreparedRecord, model: SensorModel, cache: dict | None = None
) -> np.ndarray:
    """
    H at the record's FFT bins, interpolated from its values on the log grid.

    Smooth H (:func:`_smooth_on_grid`): cubic Lagrange interpolation of complex H in log f
    (the interpolation of the row matrix, :func:`_row_matrix`); otherwise the min-phase
    part's log-magnitude and unwrapped phase linearly in log f, the delay exactly.
    """
    key = (model, p.n_fft, float(p.freqs[0]), p.freqs.size)
    if cache is not None and key in cache:
        return cache[key]
    if p.lagrange is not None and _smooth_on_grid(p, model):
        j, w = p.lagrange
        hg = _transfer_on_grid(p, model, cache)
        out = w[0] * hg[j] + w[1] * hg[j + 1] + w[2] * hg[j + 2] + w[3] * hg[j + 3]
    else:
        out = _interpolated_transfer(p, model)
    if cache is not None:
        cache[key] = out
    return out


def _transfer_on_grid(p: PreparedRecord, model: SensorModel, cache: dict | None) -> np.ndarray:
    """H (delay included: :func:`_smooth_on_grid` holds) on the record's log grid."""
    key = ('grid', model, p.grid_hz.size, float(p.grid_hz[0]), float(p.grid_hz[-1]))
    if cache is not None and key in cache:
        return cache[key]
    out = model.transfer(2j * np.pi * p.grid_hz)
    if cache is not None:
        cache[key] = out
    return out


def _smooth_on_grid(p: PreparedRecord, model: SensorModel) -> bool:
    """
    Tell whether H is smooth enough for cubic interpolation in log f on the record's grid.

    With v = ln(omega) and grid step h, the error of cubic Lagrange interpolation of
    H(exp(v)) is about (h/r)^4 relative, r the distance of its nearest singularity from
    the band [v_min, v_max] in the complex v plane.  A pole p puts one at v = ln|p| +
    j (arg p - pi/2): pi/2 from the real axis for a real pole (the diffusive part, H1
    eq. 31 and eq. 45, and the amplifier pole), only asin(zeta) for a pole pair of damping
    zeta (a beam mode) unless it lies outside the band.  Required: r >= 20 h for every
    exact rational pole (error < 1e-5), and a pure delay tau with 2 pi f_max tau <= 4 (its
    factor exp(-j tau exp(v)) has 4th derivative ~ (omega tau)^4: error < 1e-6).
    """
    key = (model, p.grid_hz.size, float(p.grid_hz[0]), float(p.grid_hz[-1]))
    if key in _SMOOTH:
        return _SMOOTH[key]
    lg = np.log(2 * np.pi * p.grid_hz)
    h, v0, v1 = lg[1] - lg[0], lg[0], lg[-1]
    ok = 2 * np.pi * p.grid_hz[-1] * abs(model.delay_s()) <= MAX_DELAY_PHASE
    for _z, poles, _k in model.compiled.rational_factors:
        for pole in np.atleast_1d(np.asarray(poles, complex)):
            if not ok:
                break
            if pole == 0:
                ok = False
                break
            re = np.log(abs(pole))
            dx = max(0.0, re - v1, v0 - re)
            dy = abs(np.angle(pole)) - np.pi / 2
            ok = np.hypot(dx, dy) >= MIN_SINGULARITY_STEPS * h
    if len(_SMOOTH) > 10_000:
        _SMOOTH.clear()
    _SMOOTH[key] = bool(ok)
    return bool(ok)


_SMOOTH: dict = {}


def _lagrange4(p: PreparedRecord) -> tuple[np.ndarray, np.ndarray]:
    """First grid index and the 4 cubic Lagrange weights of every bin (grid uniform in log f)."""
    lg = np.log(p.grid_hz)
    pos = (np.log(p.freqs) - lg[0]) / (lg[1] - lg[0])
    j = np.clip(np.floor(pos).astype(int) - 1, 0, lg.size - 4)
    x = pos - j
    w = np.stack([-(x - 1) * (x - 2) * (x - 3) / 6, x * (x - 2) * (x - 3) / 2,
                  -x * (x - 1) * (x - 3) / 2, x * (x - 1) * (x - 2) / 6])
    return j, w


def _decimation(p: PreparedRecord) -> tuple[int, int]:
    """
    Return (k0, g): the rows lie on ``k0 + j g``, g the largest power of two dividing n_fft.

    Every row's distance from the first counts (rows skip a record's filled slots: a
    decimation read from the first two rows' step put the others a sample off).
    """
    k0 = int(p.rows[0])
    step, g = int(np.gcd.reduce(p.rows - k0)) or 1, 1
    while step % (2 * g) == 0 and p.n_fft % (2 * g) == 0:
        g *= 2
    return k0, g


def _row_matrix(p: PreparedRecord, chunk: int = 32) -> np.ndarray:
    """
    Return M (rows x grid, complex) with ``irfft(X H)[p.rows] = Re(M @ H_grid)``.

    H at every FFT bin is the cubic Lagrange interpolation in log f of its values on the
    record's log grid (4 grid points per bin), so the rows are linear in ``H_grid``: column
    i of M is the row response (:func:`_rows_from_spectrum`, folded spectrum) of the
    deflection spectrum weighted by grid point i's interpolation weights.  Interpolation
    error: with the grid spacing h = ln(f_max/f_min)/(n_grid - 1) (0.019 for a 30-min 100 Hz
    record and 512 points) and the nearest singularity of H(exp(v)) a distance r from the
    real axis (pi/2 for real poles), the error is about (h/r)^4 relative, 2e-8 for real poles.
    """
    n, (k0, g) = p.n_fft, _decimation(p)
    m_len = n // g
    k = p.bins
    xf = p.x_bins * np.where(k == n // 2, 1.0, 2.0) * np.exp(2j * np.pi * k * k0 / n)
    j, w = _lagrange4(p)
    col = (j[None, :] + np.arange(4)[:, None]).ravel()
    val = (w * xf[None, :]).ravel()
    fb = np.tile(k % m_len, 4)
    order = np.argsort(col, kind='stable')
    col, val, fb = col[order], val[order], fb[order]
    n_grid = p.grid_hz.size
    starts = np.searchsorted(col, np.arange(0, n_grid + chunk, chunk))
    pick = (p.rows - k0) // g
    out = np.empty((p.rows.size, n_grid), complex)
    for c0 in range(0, n_grid, chunk):
        c1 = min(c0 + chunk, n_grid)
        a, b = starts[c0 // chunk], starts[c0 // chunk + 1]
        z = np.zeros((c1 - c0) * m_len, complex)
        np.add.at(z, (col[a:b] - c0) * m_len + fb[a:b], val[a:b])
        seq = np.fft.ifft(z.reshape(c1 - c0, m_len), axis=1) * (m_len / n)
        out[:, c0:c1] = seq[:, pick].T
    return out


def _interpolated_transfer(p: PreparedRecord, model: SensorModel) -> np.ndarray:
    hg = model.min_phase_transfer(2j * np.pi * p.grid_hz)
    lf, lg = np.log(p.freqs), np.log(p.grid_hz)
    mag = np.interp(lf, lg, np.log(np.abs(hg)))
    phase = np.interp(lf, lg, np.unwrap(np.angle(hg)))
    return np.exp(mag + 1j * (phase - 2 * np.pi * p.freqs * model.delay_s()))


def _rows_from_spectrum(p: PreparedRecord, y_bins: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """
    Return ``irfft(y)[rows]`` without the full inverse FFT.

    Rows lie on the progression ``p.rows[0] + j g`` (:func:`_decimation`): the spectrum,
    shifted to start at ``p.rows[0]``, is folded (aliased) onto ``n_fft / g`` bins, whose
    inverse FFT is exactly the g-decimated sequence (DFT decimation identity); g-fold fewer
    FFT points.
    """
    n, (k0, g) = p.n_fft, _decimation(p)
    if p.fold is None:
        k = p.bins
        weight = np.where(k == n // 2, 1.0, 2.0)          # rfft half: conjugate pairs count twice
        p.fold = weight * np.exp(2j * np.pi * k * k0 / n)
    m_len = n // g
    z = np.zeros(-(-(n // 2 + 1) // m_len) * m_len, dtype=complex)
    z[p.bins] = y_bins * p.fold
    seq = np.fft.ifft(z.reshape(-1, m_len).sum(axis=0)).real * (m_len / n)
    return seq[(rows - k0) // g]


def _repad(p: PreparedRecord, w: np.ndarray) -> np.ndarray:
    """Pad a transformed deflection exactly as the record's own deflection was padded."""
    fs = (p.t.size - 1) / (p.t[-1] - p.t[0])
    return padded_record(p.t, w, p.pad / fs)[0]

# SPDX-License-Identifier: Apache-2.0
"""
Figures of the workbench reports: each ``plot_*`` function writes one PNG (matplotlib, Agg).

The figures follow MATLAB's ``compare`` and ``resid``:

* time overlay of the *worst* records (lowest fit %), the measurement drawn
  over the model;
* residual autocorrelation and residual / input-velocity cross-correlation,
  lags in seconds, with the 99 % band 2.576/sqrt(N) of a white residual;
* residual power spectrum (Welch) with the detected lines marked (mains hum,
  unmodelled harmonics);
* failure map: |error| / measurement sd per sample and frequency as a labelled
  heat map;
* diagnosis: held-out error of each candidate model as bars with the noise floor;
* Bode plot of measured points and model curves; parameter track with its 95 % CI.

Each ``plot_*`` function writes one PNG and returns its file name;
:func:`residual_lines` finds the spectral lines the spectrum figure marks. The
pages that hold these figures are assembled in :mod:`.report`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from .compare import BOUND99

__all__ = ['plot_bode', 'worst_first', 'plot_time_overlay', 'plot_residual_correlation',
           'plot_residual_spectrum', 'residual_lines', 'plot_failure_map', 'plot_track',
           'plot_error_bars', 'source_label']


def _plt():
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out_dir, name: str, dpi: int = 100) -> str:
    plt = _plt()
    fig.tight_layout()
    fname = f'{name}.png'
    fig.savefig(Path(out_dir) / fname, dpi=dpi)
    plt.close(fig)
    return fname


def source_label(source: str) -> str:
    """Return the file name of a record's source path (how figures and reports name it)."""
    return Path(str(source)).name


def plot_bode(out_dir: Path, name: str, points_by_sample: dict, models_by_sample: dict,
              title: str = '') -> str:
    """
    Measured points (with 2-sd error bars) and model curves, per sample.

    ``points_by_sample``: sample -> list of FrequencyPoint; ``models_by_sample``:
    sample -> {label: callable f_hz -> complex response}.
    """
    plt = _plt()
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(7, 6.5), sharex=True)
    colors = plt.rcParams['axes.prop_cycle'].by_key()['color']
    all_f = [p.frequency_hz for pts in points_by_sample.values() for p in pts]
    f_lo, f_hi = (min(all_f) / 1.5, max(all_f) * 1.5) if all_f else (0.1, 100)
    fg = np.logspace(np.log10(f_lo), np.log10(f_hi), 300)
    styles = ['-', '--', ':', '-.']
    for k, sample in enumerate(sorted(set(points_by_sample) | set(models_by_sample))):
        c = colors[k % len(colors)]
        pts = points_by_sample.get(sample, [])
        if pts:
            f = np.array([p.frequency_hz for p in pts])
            g = np.array([20 * np.log10(p.gain_a_per_m) for p in pts])
            ph = np.array([p.phase_deg for p in pts])
            eg = np.array([2 * 20 / np.log(10) * p.sd_log_mag for p in pts])
            ep = np.array([2 * np.degrees(p.sd_phase_rad) for p in pts])
            ax_m.errorbar(
                f, g, yerr=eg, fmt='o', color=c, ms=4, capsize=2, label=f'{sample} measured'
            )
            ax_p.errorbar(f, ph, yerr=ep, fmt='o', color=c, ms=4, capsize=2)
        for j, (label, fn) in enumerate(models_by_sample.get(sample, {}).items()):
            h = fn(fg)
            ax_m.semilogx(
                fg, 20 * np.log10(np.abs(h)), styles[j % 4], color=c, label=f'{sample} {label}'
            )
            ax_p.semilogx(fg, np.degrees(np.angle(h)), styles[j % 4], color=c)
    ax_m.set_ylabel('|i/w| (dB re 1 A/m)')
    ax_p.set_ylabel('phase (deg)')
    ax_p.set_xlabel('frequency (Hz)')
    ax_m.set_xscale('log')
    for ax in (ax_m, ax_p):
        ax.grid(True, which='both', alpha=0.3)
    ax_m.legend(fontsize=7, ncol=2)
    if title:
        ax_m.set_title(title, fontsize=10)
    return _save(fig, out_dir, name, dpi=110)


def worst_first(records: Sequence) -> list:
    """Return the records ordered from the lowest fit % to the highest."""
    return sorted(records, key=lambda r: (np.nan_to_num(r.fit_percent, nan=-np.inf)))


def plot_time_overlay(out_dir: Path, name: str, records: Sequence, max_records: int = 4,
                      span_s: float = 2.0, labels: Sequence[str] = ('measured', 'model'),
                      select_worst: bool = True) -> str:
    """
    Measured (drawn on top) vs predicted current and the residual.

    Last ``span_s`` s of the ``max_records`` worst records (or the first ones,
    ``select_worst=False``).
    """
    plt = _plt()
    recs = (worst_first(records) if select_worst else list(records))[:max_records]
    fig, axes = plt.subplots(len(recs), 1, figsize=(8, 2.3 * len(recs)), squeeze=False)
    for ax, r in zip(axes[:, 0], recs):
        point = getattr(r, 'point', None)             # about 5 periods of the excitation
        span = min(span_s, 5.0 / point.frequency_hz) if point is not None else span_s
        sel = r.time_s >= r.time_s[-1] - span
        t = r.time_s[sel]
        ax.plot(
            t,
            r.predicted_a[sel] * 1e6,
            lw=2.4,
            color='tab:orange',
            alpha=0.8,
            label=labels[1],
            zorder=1,
        )
        ax.plot(t, r.measured_a[sel] * 1e6, lw=0.8, color='k', label=labels[0], zorder=3)
        ax.plot(t, (r.measured_a[sel] - r.predicted_a[sel]) * 1e6, lw=0.7, color='tab:red',
                label='residual (measured - model)', zorder=2)
        ax.set_title(f'{source_label(r.source)}: fit {r.fit_percent:.1f} %', fontsize=8)
        ax.set_ylabel('current (µA)')
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc='upper right')
    axes[-1, 0].set_xlabel('time (s)')
    return _save(fig, out_dir, name)


def plot_residual_correlation(out_dir: Path, name: str, records: Sequence, max_lag: int = 25,
                              n_labelled: int = 4) -> str:
    """
    MATLAB ``resid``: residual autocorrelation and residual / input-velocity cross-correlation.

    Lags in seconds; the 99 % band of a white residual. The ``n_labelled``
    worst records are coloured and named, the others grey.
    """
    from .compare import normalised_cross_correlation as xcorr

    plt = _plt()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6))
    ordered = worst_first(records)
    for k, r in enumerate(reversed(ordered)):          # grey ones first, worst drawn last (on top)
        rank = len(ordered) - 1 - k
        dt = float(np.median(np.diff(r.time_s)))
        e = r.measured_a - r.predicted_a
        lags = np.arange(1, max_lag + 1)
        xl = np.arange(-max_lag, max_lag + 1)
        label = f'{source_label(r.source)} (fit {r.fit_percent:.1f} %)'
        style = dict(lw=1.0, ms=3, label=label) \
            if rank < n_labelled else dict(lw=0.6, ms=0, color='0.6',
                                           label='other records' if rank == n_labelled else None)
        a1.plot(lags * dt * 1e3, xcorr(e, e, lags), '.-', **style)
        a2.plot(xl * dt * 1e3, xcorr(e, np.gradient(r.deflection_m, r.time_s), xl), '.-', **style)
    if len(records):
        b = BOUND99 / np.sqrt(min(len(r.time_s) for r in records))
        for ax in (a1, a2):
            ax.axhspan(-b, b, color='tab:green', alpha=0.15, zorder=0, label='99 % band (white)')
            ax.axhline(0, color='k', lw=0.5)
            ax.grid(alpha=0.3)
    a1.set_title('residual autocorrelation: outside the band = residual not white '
                 '(unmodelled dynamics or coloured noise)', fontsize=8)
    a2.set_title('residual vs input (deflection velocity) cross-correlation: outside the band = '
                 'dynamics the model misses', fontsize=8)
    a1.set_xlabel('lag (ms)')
    a2.set_xlabel('lag (ms; > 0: residual after the input)')
    a1.set_ylabel('normalised correlation')
    a2.set_ylabel('normalised correlation')
    a1.legend(fontsize=7, loc='upper right')
    return _save(fig, out_dir, name)


def _residual_psd(records: Sequence, resolution_hz: float = 0.5):
    """Welch PSD (A^2/Hz) of every residual on the grid of the highest sample rate."""
    from scipy.signal import welch

    grid, psds = None, []
    for r in records:
        dt = float(np.median(np.diff(r.time_s)))
        e = r.measured_a - r.predicted_a
        nper = int(min(e.size, max(64, round(1.0 / (resolution_hz * dt)))))
        f, p = welch(e - e.mean(), fs=1.0 / dt, nperseg=nper)
        if grid is None or f[-1] > grid[-1]:
            psds = [np.interp(f, grid, q, right=np.nan) for q in psds] if grid is not None else []
            grid = f
        psds.append(np.interp(grid, f, p, right=np.nan))
    return grid, psds


def residual_lines(records: Sequence, threshold_db: float = 10.0) -> list[tuple[float, float]]:
    """
    Spectral lines of the pooled residual.

    Local maxima of the mean Welch PSD at least ``threshold_db`` above its
    running median (15 bins). Returns (frequency Hz, excess dB), strongest
    first; DC is ignored.
    """
    from scipy.ndimage import median_filter
    from scipy.signal import find_peaks

    if not len(records):
        return []
    f, psds = _residual_psd(records)
    mean = np.nanmean(np.vstack(psds), axis=0)
    base = median_filter(mean, size=15, mode='nearest')
    excess = 10 * np.log10(np.maximum(mean, 1e-300) / np.maximum(base, 1e-300))
    peaks, _ = find_peaks(excess, height=threshold_db)
    lines = [(float(f[k]), float(excess[k])) for k in peaks if f[k] > 0]
    return sorted(lines, key=lambda x: -x[1])


def plot_residual_spectrum(out_dir: Path, name: str, records: Sequence,
                           max_marked: int = 8) -> tuple[str, list[tuple[float, float]]]:
    """Residual PSD (each record grey, the mean black) with detected lines marked."""
    plt = _plt()
    f, psds = _residual_psd(records)
    lines = residual_lines(records)
    fig, ax = plt.subplots(figsize=(8, 3.6))
    for p in psds:
        ax.semilogy(f, np.sqrt(p) * 1e9, color='0.75', lw=0.5)
    ax.semilogy(f, np.sqrt(np.nanmean(np.vstack(psds), axis=0)) * 1e9, color='k', lw=1,
                label='mean over records')
    for k, (fl, db) in enumerate(lines[:max_marked]):
        ax.axvline(fl, color='tab:red', ls='--', lw=0.8, label='detected line' if k == 0 else None)
        ax.annotate(f'{fl:.3g} Hz', (fl, ax.get_ylim()[1]), fontsize=7, rotation=90, va='top',
                    ha='right', color='tab:red')
    ax.set_xscale('log')
    ax.set_xlabel('frequency (Hz)')
    ax.set_ylabel('residual ASD (nA/√Hz)')
    ax.set_title('residual spectrum: lines = hum or unmodelled harmonics; a smooth floor = noise',
                 fontsize=8)
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=7)
    return _save(fig, out_dir, name), lines


def plot_failure_map(out_dir: Path, name: str, records: Sequence) -> str:
    """Heat map of |error| / sd per sample and excitation frequency (magnitude and phase)."""
    plt = _plt()
    tones = [(r.sample, tone) for r in records for tone in r.tones]
    samples = sorted({sample for sample, _ in tones})
    freqs = sorted({round(tone.frequency_hz, 3) for _, tone in tones})
    zm = np.full((len(samples), len(freqs)), np.nan)
    zp = np.full_like(zm, np.nan)
    for sample, tone in tones:
        i, j = samples.index(sample), freqs.index(round(tone.frequency_hz, 3))
        zm[i, j] = abs(tone.mag_error_db) / max(tone.mag_sd_db, 1e-12)
        zp[i, j] = abs(tone.phase_error_deg) / max(tone.phase_sd_deg, 1e-12)
    fig, axes = plt.subplots(2, 1, figsize=(8, 2.4 + 1.0 * max(len(samples), 1)))
    for ax, z, what in ((axes[0], zm, 'magnitude'), (axes[1], zp, 'phase')):
        im = ax.imshow(
            np.log10(np.maximum(z, 1e-3)), aspect='auto', cmap='RdYlGn_r', vmin=-1, vmax=2
        )
        for i in range(z.shape[0]):
            for j in range(z.shape[1]):
                if np.isfinite(z[i, j]):
                    ax.text(j, i, f'{z[i, j]:.1f}', ha='center', va='center', fontsize=7)
        ax.set_xticks(range(len(freqs)))
        ax.set_xticklabels([f'{f:.3g}' for f in freqs], fontsize=7)
        ax.set_yticks(range(len(samples)))
        ax.set_yticklabels(samples, fontsize=8)
        ax.set_xlabel('excitation frequency (Hz)')
        ax.set_ylabel('sample')
        ax.set_title(f'|{what} error| / measurement sd (cells > 3 fail)', fontsize=8)
        cb = fig.colorbar(im, ax=ax)
        cb.set_label('log10(|error| / sd)', fontsize=7)
    return _save(fig, out_dir, name)


def plot_track(out_dir: Path, name: str, track: Sequence, parameter: str) -> str:
    plt = _plt()
    t = np.array([p.time_s for p in track])
    v = np.array([p.estimates[parameter] for p in track])
    lo = np.array([p.ci95[parameter][0] for p in track])
    hi = np.array([p.ci95[parameter][1] for p in track])
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.fill_between(t / 60, lo, hi, alpha=0.3, label='95 % CI')
    ax.plot(t / 60, v, 'o-', ms=3, label=parameter)
    ax.set_xlabel('time (min)')
    ax.set_ylabel(parameter)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, out_dir, name)


def plot_error_bars(out_dir: Path, name: str, labels: Sequence[str], errors: Sequence[float],
                    noise_floor: float | None = None, title: str = '') -> str:
    """Horizontal bars of held-out errors (best at the top) with the noise floor."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 1.2 + 0.32 * len(errors)))
    y = np.arange(len(errors))[::-1]
    ax.barh(y, errors, color=['tab:gray'] + ['tab:blue'] * (len(errors) - 1))
    for yy, e in zip(y, errors):
        ax.text(e, yy, f' {e:.4f}', va='center', fontsize=7)
    ax.set_yticks(y)
    ax.set_yticklabels(labels, fontsize=8)
    ax.set_xscale('log')
    if noise_floor:
        ax.axvline(noise_floor, color='k', ls='--', lw=1,
                   label=f'noise floor {noise_floor:.4f} (a perfect model)')
        ax.legend(fontsize=7, loc='lower right', bbox_to_anchor=(1.0, 1.0), frameon=False)
    ax.set_xlabel('held-out error = ||y - ŷ|| / ||y - mean y|| (lower is better)')
    ax.set_title(title, fontsize=9, loc='left')
    ax.grid(alpha=0.3, axis='x')
    return _save(fig, out_dir, name)

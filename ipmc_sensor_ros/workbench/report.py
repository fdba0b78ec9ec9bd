# SPDX-License-Identifier: Apache-2.0
"""
Reports a scientist would keep: one ``index.html`` with PNG plots (matplotlib, Agg).

Every report opens with a summary card (model, verdict, fit %, error against
the noise floor), then sections of text, tables and figures; nothing scrolls
sideways (text wraps, tables fit the page).  Figures follow MATLAB's
``compare`` and ``resid``:

* time overlay of the *worst* records (lowest fit %), the measurement drawn
  over the model;
* residual autocorrelation and residual / input-velocity cross-correlation,
  lags in seconds, with the 99 % band 2.576/sqrt(N) of a white residual;
* residual power spectrum (Welch) with the detected lines marked (mains hum,
  unmodelled harmonics);
* failure map: |error| / measurement sd per sample and frequency as a labelled
  heat map, plus the "where it fails" tables;
* diagnosis: held-out error of each candidate model as bars with the noise floor.

Each ``plot_*`` function writes one PNG and returns its file name; the
``*_report`` functions assemble the pages used by ``ipmc-model``.
"""
from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = ['Section', 'plot_bode', 'plot_time_overlay', 'plot_residual_correlation',
           'plot_residual_spectrum', 'residual_lines', 'plot_failure_map', 'plot_track',
           'plot_error_bars', 'write_report', 'compare_report', 'fit_report', 'diagnose_report',
           'track_report', 'BOUND99']

BOUND99 = 2.576  # two-sided 99 % quantile of N(0, 1): band of a white residual's correlation


@dataclass
class Section:
    """One report section: heading, wrapped text, tables (caption, columns, rows), PNG names."""

    heading: str
    text: str = ''
    images: list = field(default_factory=list)
    tables: list = field(default_factory=list)


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


def _label(source: str) -> str:
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
        ax.set_title(f'{_label(r.source)}: fit {r.fit_percent:.1f} %', fontsize=8)
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
    from .compare import _xcorr_normalised as _xcorr

    plt = _plt()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6))
    ordered = worst_first(records)
    for k, r in enumerate(reversed(ordered)):          # grey ones first, worst drawn last (on top)
        rank = len(ordered) - 1 - k
        dt = float(np.median(np.diff(r.time_s)))
        e = r.measured_a - r.predicted_a
        lags = np.arange(1, max_lag + 1)
        xl = np.arange(-max_lag, max_lag + 1)
        style = dict(lw=1.0, ms=3, label=f'{_label(r.source)} (fit {r.fit_percent:.1f} %)') \
            if rank < n_labelled else dict(lw=0.6, ms=0, color='0.6',
                                           label='other records' if rank == n_labelled else None)
        a1.plot(lags * dt * 1e3, _xcorr(e, e, lags), '.-', **style)
        a2.plot(xl * dt * 1e3, _xcorr(e, np.gradient(r.deflection_m, r.time_s), xl), '.-', **style)
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
    recs = [r for r in records if r.point is not None]
    samples = sorted({r.sample for r in recs})
    freqs = sorted({round(r.point.frequency_hz, 3) for r in recs})
    zm = np.full((len(samples), len(freqs)), np.nan)
    zp = np.full_like(zm, np.nan)
    for r in recs:
        i, j = samples.index(r.sample), freqs.index(round(r.point.frequency_hz, 3))
        zm[i, j] = abs(r.mag_error_db) / max(r.mag_sd_db, 1e-12)
        zp[i, j] = abs(r.phase_error_deg) / max(r.phase_sd_deg, 1e-12)
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


def _table_html(caption: str, columns: Sequence[str], rows: Sequence[Sequence]) -> str:
    head = ''.join(f'<th>{html.escape(str(c))}</th>' for c in columns)
    body = ''.join('<tr>' + ''.join(f'<td>{html.escape(str(v))}</td>' for v in row) + '</tr>'
                   for row in rows)
    return (f'<table><caption>{html.escape(caption)}</caption><thead><tr>{head}</tr></thead>'
            f'<tbody>{body}</tbody></table>')


_CSS = ('body{font-family:sans-serif;max-width:1000px;margin:auto;padding:0 8px}'
        'pre{background:#f6f6f6;padding:8px;font-size:12px;white-space:pre-wrap;'
        'overflow-wrap:anywhere}'
        'table{border-collapse:collapse;font-size:12px;margin:8px 0;width:100%;table-layout:auto}'
        'td,th{border:1px solid #ccc;padding:2px 6px;text-align:right;overflow-wrap:anywhere}'
        'caption{text-align:left;font-weight:bold}'
        '.card{border:2px solid #444;border-radius:6px;padding:8px 12px;background:#fafafa}'
        '.card dt{font-weight:bold;float:left;clear:left;width:11em}.card dd{margin-left:11.5em}'
        'img{max-width:100%;border:1px solid #ddd;margin:4px 0}')


def write_report(out_dir: Path, title: str, sections: Sequence, card: dict | None = None) -> Path:
    """
    Write ``index.html``: an optional summary card (label -> value) and the sections.

    :class:`Section` or tuples (heading, text, [png names]).
    """
    out_dir = Path(out_dir)
    parts = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f'<style>{_CSS}</style></head><body>',
        f'<h1>{html.escape(title)}</h1>',
    ]
    if card:
        parts.append(
            "<div class='card' id='summary'><dl>"
            + ''.join(
                f'<dt>{html.escape(str(k))}</dt><dd>{html.escape(str(v))}</dd>'
                for k, v in card.items()
            )
            + '</dl></div>'
        )
    for sec in sections:
        sec = sec if isinstance(sec, Section) else Section(*sec)
        parts.append(f'<h2>{html.escape(sec.heading)}</h2>')
        if sec.text:
            parts.append(f'<pre>{html.escape(sec.text)}</pre>')
        parts += [_table_html(*t) for t in sec.tables]
        for img in sec.images:
            parts.append(f"<p><a href='{html.escape(img)}'><img src='{html.escape(img)}' "
                         f"alt='{html.escape(img)}'></a></p>")
    parts.append('</body></html>')
    path = out_dir / 'index.html'
    path.write_text('\n'.join(parts), encoding='utf-8')
    return path


# ---------------------------------------------------------------------------
# Pages of the ipmc-model verbs
# ---------------------------------------------------------------------------
def _where_tables(where: dict) -> list:
    tables = []
    for key, cells in where.items():
        if not cells:
            continue
        cols = [c for c in cells[0] if c != 'label']
        rows = [[c['label']] + [('FAILS' if c[k] else 'ok') if k == 'flagged' else
                                (f'{c[k]:.4g}' if isinstance(c[k], float) else c[k]) for k in cols]
                for c in cells]
        tables.append((f"by {key.replace('_', ' ')}", [key.replace('_', ' ')] + cols, rows))
    return tables


def compare_verdict(cmp) -> str:
    """One line: where the model fails beyond the measurement uncertainty, per breakdown."""
    parts = []
    for key, cells in cmp.where.items():
        bad = [c['label'] for c in cells if c['flagged']]
        if bad:
            what = ', '.join(bad) if len(bad) <= 3 else f'{len(bad)} of {len(cells)}'
            parts.append(f"{key.replace('_', ' ')}s {what}")
    if not parts:
        return 'consistent with the data: nowhere beyond the measurement uncertainty'
    return (
        'fails beyond the measurement uncertainty in ' + '; '.join(parts) + ' (see Where it fails)'
    )


def compare_report(
    out_dir: Path, cmp, model_text: str, bode_points: dict, bode_models: dict
) -> Path:
    """
    Return the ``compare`` page.

    Card, Bode, worst records, residual tests, spectrum, failure map.
    """
    rows = [
        [
            _label(r.source),
            r.sample,
            f'{r.point.frequency_hz:.3g}' if r.point else '-',
            f'{r.fit_percent:.2f}',
            f'{r.error:.4f}',
            f'{r.noise_floor:.4f}',
            'yes' if r.whiteness['passed'] else 'NO',
            'yes' if r.input_correlation['passed'] else 'NO',
        ]
        for r in cmp.records
    ]
    cols = ['record', 'sample', 'f0 (Hz)', 'fit %', 'error', 'noise floor', 'white residual',
            'uncorrelated with input']
    spectrum, lines = plot_residual_spectrum(out_dir, 'residual_spectrum', cmp.records)
    line_text = ('detected lines (Hz, dB above the local floor): ' +
                 ', '.join(f'{f:.3g} ({db:.0f} dB)' for f, db in lines[:8])) if lines else \
        'no line stands 10 dB above the residual floor'
    worst = worst_first(cmp.records)
    card = {
        'model': model_text,
        'verdict': compare_verdict(cmp),
        'fit': f'{cmp.fit_percent:.2f} % (100 % = perfect; MATLAB compare)',
        'error vs noise floor': (
            f'{cmp.error:.4f} vs {cmp.noise_floor:.4f} '
            f'({cmp.error / cmp.noise_floor:.2f}x the floor; 1x = a perfect model)'
            if cmp.noise_floor > 0
            else f'{cmp.error:.4f}'
        ),
        'worst record': f'{_label(worst[0].source)} (fit {worst[0].fit_percent:.1f} %)',
        'records': str(len(cmp.records)),
    }
    sections = [
        Section(
            'Records',
            'error = ||y - ŷ|| / ||y - mean y|| of the predicted current = 1 - fit/100; '
            'noise floor = the error a perfect model would have from the measured noise',
            tables=[('per record, in numeric order', cols, rows)],
        ),
        Section(
            'Frequency response',
            '',
            [
                plot_bode(
                    out_dir,
                    'bode',
                    bode_points,
                    bode_models,
                    'measured (2 sd error bars) vs model',
                )
            ],
        ),
        Section(
            'Worst records in time',
            'measured (black) over the model (orange); residual red',
            [plot_time_overlay(out_dir, 'time_worst', cmp.records)],
        ),
        Section(
            'Residual tests (MATLAB resid)',
            '',
            [plot_residual_correlation(out_dir, 'residuals', cmp.records)],
        ),
        Section('Residual spectrum', line_text, [spectrum]),
        Section(
            'Where it fails',
            'frequency cells fail when |error| > 3 sd; other cells when '
            'error > 1.5 x noise floor + 0.01',
            [plot_failure_map(out_dir, 'failure_map', cmp.records)],
            _where_tables(cmp.where),
        ),
    ]
    return write_report(out_dir, 'ipmc-model compare', sections, card)


def fit_report(out_dir: Path, res, bode_points: dict, bode_models: dict, model_text: str) -> Path:
    card = {'model': model_text,
            'verdict': 'all fitted parameters identifiable' if not res.not_identifiable else
            'NOT identifiable: ' + ', '.join(res.not_identifiable),
            'chi2 / dof': f'{res.chi2:.4g} / {res.dof} (about 1 when the model explains the data '
                          'within its error bars)'}
    img = plot_bode(
        out_dir, 'bode', bode_points, bode_models, 'measured (2 sd error bars) vs model'
    )
    return write_report(out_dir, 'ipmc-model fit', [Section('Fit', res.summary(), [img])], card)


def diagnose_report(out_dir: Path, diag) -> Path:
    """Return the ``diagnose`` page: ranking bars with the noise floor, before/after overlays."""
    from types import SimpleNamespace

    from .compare import fit_percent
    from .timefit import predict

    labels = ['baseline (' + diag.baseline.fit.models[0].describe() + ')'] + \
        [f'+ {c.effect}' for c in diag.candidates]
    errors = [diag.baseline.error] + [c.error for c in diag.candidates]
    rows = [[k, c.effect, f'{c.error:.4f}', f'{diag.baseline.error / c.error:.2f}',
             f'{c.fit.bic - diag.baseline.fit.bic:.1f}',
             ', '.join(f'{n}={v:.4g}' for n, v in c.params.items()), '; '.join(c.flags)]
            for k, c in enumerate(diag.candidates, 1)]
    cols = ['rank', 'effect', 'held-out error', 'x better', 'ΔBIC', 'parameters', 'flags']
    card = {'model': diag.baseline.fit.models[0].describe(),
            'verdict': f"missing effect: {diag.missing_effect or 'none found'}; "
                       f"{'explained' if diag.explained else 'NOT explained'} ({diag.reason})",
            'held-out error vs noise floor': f'{diag.baseline.error:.4f} (baseline) vs '
                                             f'{diag.noise_floor:.4f}',
            'cross-validation': diag.cv}
    sections = [
        Section(
            'Ranking',
            'ΔBIC < -20: very strong evidence for the effect (Kass-Raftery); '
            'x better = baseline error / candidate error',
            [
                plot_error_bars(
                    out_dir,
                    'ranking',
                    labels,
                    errors,
                    diag.noise_floor,
                    'held-out error: baseline and baseline + each effect',
                )
            ],
            [('candidates', cols, rows)],
        )
    ]
    for rank, cand in enumerate(diag.candidates[:3], 1):
        recs = []
        for p, mb, mc in zip(diag.prepared[:3], diag.baseline.fit.models, cand.fit.models):
            y = p.y[p.keep]
            for tag, m in (('before: baseline', mb), (f'after: + {cand.effect}', mc)):
                yh = predict(p, m)[p.keep]
                recs.append(
                    SimpleNamespace(
                        source=f'{_label(p.rec.path)} ({tag})',
                        time_s=p.t[p.keep],
                        measured_a=y,
                        predicted_a=yh,
                        fit_percent=fit_percent(y, yh),
                    )
                )
        img = plot_time_overlay(out_dir, f'candidate_{rank}_{cand.effect}', recs, max_records=6,
                                span_s=1.0, select_worst=False)
        sections.append(
            Section(
                f'#{rank}: + {cand.effect} (held-out error {cand.error:.4f})',
                'measured over the model, before (baseline) and after adding the effect',
                [img],
            )
        )
    return write_report(out_dir, 'ipmc-model diagnose', sections, card)


def track_report(out_dir: Path, tracks: dict, parameter: str) -> Path:
    """``tracks``: source -> list of TrackPoint."""
    sections = [Section(_label(src), '', [plot_track(out_dir, f'track_{k}', tr, parameter)])
                for k, (src, tr) in enumerate(tracks.items())]
    return write_report(out_dir, 'ipmc-model track', sections, {'tracked parameter': parameter})

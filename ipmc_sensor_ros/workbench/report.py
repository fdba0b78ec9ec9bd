"""PNG plots and one HTML page for workbench results (matplotlib, Agg backend).

Every ``plot_*`` function writes one PNG and returns its file name; the
``write_report`` function writes ``index.html`` linking the given figures with
the text summaries.
"""
from __future__ import annotations

import html
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

__all__ = ["plot_bode", "plot_time_overlay", "plot_residuals", "plot_failure_map", "plot_track",
           "plot_error_bars", "write_report"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_bode(out_dir: Path, name: str, points_by_sample: dict, models_by_sample: dict,
              title: str = "") -> str:
    """Measured points (with 2-sd error bars) and model curves, per sample.

    ``points_by_sample``: sample -> list of FrequencyPoint; ``models_by_sample``:
    sample -> {label: callable f_hz -> complex response}.
    """
    plt = _plt()
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(7, 6.5), sharex=True)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    all_f = [p.frequency_hz for pts in points_by_sample.values() for p in pts]
    f_lo, f_hi = (min(all_f) / 1.5, max(all_f) * 1.5) if all_f else (0.1, 100)
    fg = np.logspace(np.log10(f_lo), np.log10(f_hi), 300)
    styles = ["-", "--", ":", "-."]
    for k, sample in enumerate(sorted(set(points_by_sample) | set(models_by_sample))):
        c = colors[k % len(colors)]
        pts = points_by_sample.get(sample, [])
        if pts:
            f = np.array([p.frequency_hz for p in pts])
            g = np.array([20 * np.log10(p.gain_a_per_m) for p in pts])
            ph = np.array([p.phase_deg for p in pts])
            eg = np.array([2 * 20 / np.log(10) * p.sd_log_mag for p in pts])
            ep = np.array([2 * np.degrees(p.sd_phase_rad) for p in pts])
            ax_m.errorbar(f, g, yerr=eg, fmt="o", color=c, ms=4, capsize=2, label=f"{sample} measured")
            ax_p.errorbar(f, ph, yerr=ep, fmt="o", color=c, ms=4, capsize=2)
        for j, (label, fn) in enumerate(models_by_sample.get(sample, {}).items()):
            h = fn(fg)
            ax_m.semilogx(fg, 20 * np.log10(np.abs(h)), styles[j % 4], color=c, label=f"{sample} {label}")
            ax_p.semilogx(fg, np.degrees(np.angle(h)), styles[j % 4], color=c)
    ax_m.set_ylabel("|i/w| (dB re 1 A/m)")
    ax_p.set_ylabel("phase (deg)")
    ax_p.set_xlabel("frequency (Hz)")
    ax_m.set_xscale("log")
    ax_m.grid(True, which="both", alpha=0.3)
    ax_p.grid(True, which="both", alpha=0.3)
    ax_m.legend(fontsize=7, ncol=2)
    if title:
        ax_m.set_title(title)
    fig.tight_layout()
    fname = f"{name}.png"
    fig.savefig(Path(out_dir) / fname, dpi=110)
    plt.close(fig)
    return fname


def plot_time_overlay(out_dir: Path, name: str, records: Sequence, max_records: int = 4,
                      span_s: float = 2.0, labels: Sequence[str] = ("measured", "model")) -> str:
    """Measured vs predicted current for the first records (last ``span_s`` seconds)."""
    plt = _plt()
    recs = list(records)[:max_records]
    fig, axes = plt.subplots(len(recs), 1, figsize=(8, 2.2 * len(recs)), squeeze=False)
    for ax, r in zip(axes[:, 0], recs):
        sel = r.time_s >= r.time_s[-1] - span_s
        ax.plot(r.time_s[sel], r.measured_a[sel] * 1e6, lw=1, label=labels[0])
        ax.plot(r.time_s[sel], r.predicted_a[sel] * 1e6, lw=1, label=labels[1])
        ax.plot(r.time_s[sel], (r.measured_a[sel] - r.predicted_a[sel]) * 1e6, lw=0.8, label="residual")
        ax.set_title(f"{Path(r.source).name}: fit {r.fit_percent:.1f} %", fontsize=8)
        ax.set_ylabel("current (uA)")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    fname = f"{name}.png"
    fig.savefig(Path(out_dir) / fname, dpi=100)
    plt.close(fig)
    return fname


def plot_residuals(out_dir: Path, name: str, records: Sequence, max_lag: int = 25) -> str:
    """Residual autocorrelation and residual-input cross-correlation, 99 % bounds."""
    from .compare import _xcorr_normalised

    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.2))
    for r in records:
        e = r.measured_a - r.predicted_a
        lags = np.arange(1, max_lag + 1)
        a1.plot(lags, _xcorr_normalised(e, e, lags), ".-", lw=0.7, ms=3)
        xl = np.arange(-max_lag, max_lag + 1)
        a2.plot(xl, _xcorr_normalised(e, np.gradient(r.deflection_m, r.time_s), xl), ".-", lw=0.7, ms=3)
    if records:
        b = 2.576 / np.sqrt(min(len(r.time_s) for r in records))
        for ax in (a1, a2):
            ax.axhspan(-b, b, color="0.85", zorder=0)
            ax.grid(alpha=0.3)
    a1.set_title("residual autocorrelation (99 % band)", fontsize=9)
    a2.set_title("residual vs input velocity cross-correlation", fontsize=9)
    a1.set_xlabel("lag (samples)")
    a2.set_xlabel("lag (samples)")
    fig.tight_layout()
    fname = f"{name}.png"
    fig.savefig(Path(out_dir) / fname, dpi=100)
    plt.close(fig)
    return fname


def plot_failure_map(out_dir: Path, name: str, records: Sequence) -> str:
    """Heat map of |error|/sd per sample and excitation frequency (magnitude and phase)."""
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
    fig, axes = plt.subplots(1, 2, figsize=(10, 1.2 + 0.5 * max(len(samples), 1)))
    for ax, z, title in ((axes[0], zm, "|magnitude error| / sd"), (axes[1], zp, "|phase error| / sd")):
        im = ax.imshow(np.log10(np.maximum(z, 1e-3)), aspect="auto", cmap="RdYlGn_r", vmin=-1, vmax=3)
        ax.set_xticks(range(len(freqs)))
        ax.set_xticklabels([f"{f:g}" for f in freqs], rotation=90, fontsize=7)
        ax.set_yticks(range(len(samples)))
        ax.set_yticklabels(samples, fontsize=8)
        ax.set_xlabel("frequency (Hz)")
        ax.set_title(title + " (log10; >0.5 = beyond 3 sd)", fontsize=8)
        fig.colorbar(im, ax=ax)
    fig.tight_layout()
    fname = f"{name}.png"
    fig.savefig(Path(out_dir) / fname, dpi=100)
    plt.close(fig)
    return fname


def plot_track(out_dir: Path, name: str, track: Sequence, parameter: str) -> str:
    plt = _plt()
    t = np.array([p.time_s for p in track])
    v = np.array([p.estimates[parameter] for p in track])
    lo = np.array([p.ci95[parameter][0] for p in track])
    hi = np.array([p.ci95[parameter][1] for p in track])
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.fill_between(t / 60, lo, hi, alpha=0.3, label="95 % CI")
    ax.plot(t / 60, v, "o-", ms=3, label=parameter)
    ax.set_xlabel("time (min)")
    ax.set_ylabel(parameter)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fname = f"{name}.png"
    fig.savefig(Path(out_dir) / fname, dpi=100)
    plt.close(fig)
    return fname


def plot_error_bars(out_dir: Path, name: str, labels: Sequence[str], errors: Sequence[float],
                    noise_floor: float | None = None, title: str = "") -> str:
    """Bar chart of held-out errors (e.g. the error falling as effects are added)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.bar(range(len(errors)), errors, color="tab:blue")
    ax.set_xticks(range(len(errors)))
    ax.set_xticklabels(labels, rotation=30, ha="right", fontsize=8)
    ax.set_yscale("log")
    if noise_floor:
        ax.axhline(noise_floor, color="k", ls="--", lw=1, label="noise floor")
        ax.legend(fontsize=8)
    ax.set_ylabel("normalised RMS error")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fname = f"{name}.png"
    fig.savefig(Path(out_dir) / fname, dpi=100)
    plt.close(fig)
    return fname


def write_report(out_dir: Path, title: str, sections: Iterable[tuple[str, str, Sequence[str]]]) -> Path:
    """Write ``index.html``: each section is (heading, preformatted text, [png names])."""
    out_dir = Path(out_dir)
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             "<style>body{font-family:sans-serif;max-width:1000px;margin:auto}"
             "pre{background:#f6f6f6;padding:8px;overflow-x:auto;font-size:12px}"
             "img{max-width:100%;border:1px solid #ddd;margin:4px 0}</style></head><body>",
             f"<h1>{html.escape(title)}</h1>"]
    for heading, text, images in sections:
        parts.append(f"<h2>{html.escape(heading)}</h2>")
        if text:
            parts.append(f"<pre>{html.escape(text)}</pre>")
        for img in images:
            parts.append(f"<p><a href='{html.escape(img)}'><img src='{html.escape(img)}' "
                         f"alt='{html.escape(img)}'></a></p>")
    parts.append("</body></html>")
    path = out_dir / "index.html"
    path.write_text("\n".join(parts))
    return path

# SPDX-License-Identifier: Apache-2.0
"""
Reports a scientist would keep: one ``index.html`` with PNG plots.

Every report opens with a summary card (model, verdict, fit %, error against
the noise floor), then sections of text, tables and figures; nothing scrolls
sideways (text wraps, tables fit the page).  :func:`write_report` writes the
page; the ``*_report`` functions assemble the pages used by ``ipmc-model``
(``compare``, ``fit``, ``diagnose``, ``track``) from the figures drawn in
:mod:`.plots`.
"""
from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from .plots import (plot_bode, plot_error_bars, plot_failure_map, plot_residual_correlation,
                    plot_residual_spectrum, plot_time_overlay, plot_track, source_label,
                    worst_first)

__all__ = ['Section', 'write_report', 'compare_report', 'fit_report', 'diagnose_report',
           'track_report']


@dataclass
class Section:
    """One report section: heading, wrapped text, tables (caption, columns, rows), PNG names."""

    heading: str
    text: str = ''
    images: list = field(default_factory=list)
    tables: list = field(default_factory=list)


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
            source_label(r.source),
            r.sample,
            ', '.join(f'{tone.frequency_hz:.3g}' for tone in r.tones) or '-',
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
        'worst record': f'{source_label(worst[0].source)} (fit {worst[0].fit_percent:.1f} %)',
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
    from .timepredict import predict

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
                        source=f'{source_label(p.rec.path)} ({tag})',
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
    sections = [Section(source_label(src), '', [plot_track(out_dir, f'track_{k}', tr, parameter)])
                for k, (src, tr) in enumerate(tracks.items())]
    return write_report(out_dir, 'ipmc-model track', sections, {'tracked parameter': parameter})

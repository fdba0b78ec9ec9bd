# SPDX-License-Identifier: Apache-2.0
"""The text form of a :class:`~.verdict.Diagnosis` (what ``ipmc-model diagnose`` prints)."""
from __future__ import annotations

__all__ = ['summary_text']


def _lines_text(diag) -> list[str]:
    out = []
    for d in diag.interference:
        out.append(f"interference: {d['frequency_hz']:g} Hz line (measured "
                   f"{d['measured_hz'][0]:.3f}-{d['measured_hz'][1]:.3f} Hz), level "
                   f"{d['level']:.3g} of the signal RMS in {d['records']} record(s): removed "
                   'before fitting')
    if diag.line_test:
        lt = diag.line_test
        out.append(f"line test: the current less the model's prediction from the deflection, "
                   f"false-alarm probability {lt['false_alarm_per_record']:g} per record "
                   f"({lt['lines_found']} line(s) found)")
        for d in lt.get('left_in_residual', ()):
            out.append(f"  left in the residual: {d['frequency_hz']:.3f} Hz in {d['record']}, "
                       f"level {d['level']:.3g} of the signal RMS ({d['z']:.0f} standard "
                       f"errors), on the drive's harmonic {d['drive_harmonic']}: hum or the "
                       "sensor's own response there; no record shows it off the drive's "
                       'harmonics (one at another drive frequency would tell)')
    if diag.offset_test:
        ot = diag.offset_test
        out.append(f"offset test: mean residual current {ot['mean_a'] * 1e9:.3g} nA, chi2 "
                   f"{ot['chi2']:.1f}/{ot['dof']} (p = {ot['p_value']:.2g})")
    return out


def _ranking_text(diag) -> list[str]:
    if not diag.candidates:
        return [f"first step: no effect ranked: {diag.unranked or 'none was tried'}"]
    out = [f"first step: {'rank':>4} {'effect':<24} {'error':>8} {'x better':>8} {'dBIC':>10}  "
           'params / flags']
    for k, c in enumerate(diag.candidates, 1):
        ratio = diag.baseline.error / c.error if c.error > 0 else float('inf')
        params = ', '.join(f'{n}={v:.4g}' for n, v in c.params.items())
        worse = ['held-out error above the baseline: the BIC of the fit does not carry to '
                 'data it did not see'] if c.held_out and c.error > diag.baseline.error else []
        flags = ('  [' + '; '.join([*c.flags, *worse]) + ']') if c.flags or worse else ''
        mark = ' ' if c.held_out else '*'
        out.append(f'            {k:>4} {c.effect:<24} {c.error:8.4f}{mark}{ratio:7.2f} '
                   f'{c.fit.bic - diag.baseline.fit.bic:10.1f}  {params}{flags}')
    if any(not c.held_out for c in diag.candidates):
        out.append('            (* in-sample error: the BIC rule already rejects it, '
                   'not cross-validated)')
    return out


def _steps_text(diag) -> list[str]:
    out = []
    for k, s in enumerate(diag.steps, 1):
        vals = '; '.join(f'{e}: ' + ', '.join(f'{n}={v:.4g}' for n, v in vs.items())
                         for e, vs in s.values.items() if e != 'material')
        out.append(f'step {k}: {s.action} {s.effect}: held-out error {s.error:.4f}  ({vals})')
        if s.action != 'added':
            out.append(f'        because {s.reason}')
        for t in s.ties:
            out.append(f"        tie: {t['effect']} (error {t['error']:.4f}, "
                       f"dBIC {t['delta_bic']:+.0f}{', implausible' if t['flags'] else ''}): "
                       + ', '.join(f'{n}={v:.4g}' for n, v in t['params'].items()))
    return out


def summary_text(diag) -> str:
    """Baseline, lines and offset test, first ranking, steps, correction, verdict."""
    lines = [f'baseline {diag.baseline.fit.models[0].describe()}: held-out error '
             f'{diag.baseline.error:.4f} (noise floor {diag.noise_floor:.4f}; {diag.cv})']
    lines += _lines_text(diag) + _ranking_text(diag) + _steps_text(diag)
    for name, test in diag.kept_by.items():
        lines.append(f"kept: {name} by its {test['test']} ({test['summary']})")
    if diag.correction is not None:
        lines.append('outside the catalog: ' + diag.correction.sentence())
    lines.append(f"verdict: missing effects = {diag.missing_effects or 'none'}; explained = "
                 f'{diag.explained} ({diag.reason})')
    if diag.ties:
        lines.append('ties (indistinguishable on these data): ' + ', '.join(diag.ties))
    return '\n'.join(lines)

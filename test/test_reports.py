# SPDX-License-Identifier: Apache-2.0
"""Every workbench report renders with its summary card, sections and images."""
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from ipmc_sensor_ros.workbench.compare import compare_records
from ipmc_sensor_ros.workbench.plots import residual_lines, worst_first
from ipmc_sensor_ros.workbench.report import compare_report, diagnose_report, track_report
from ipmc_sensor_ros.workbench.scenarios import crank_slider_campaign
from ipmc_sensor_ros.workbench.track import TrackPoint


def _page(index: Path) -> tuple[str, list[str], list[str]]:
    text = index.read_text(encoding='utf-8')
    headings = re.findall(r'<h2>(.*?)</h2>', text)
    images = re.findall(r"<img src='(.*?)'", text)
    return text, headings, images


def _check_images(out: Path, images: list[str]) -> None:
    assert images
    for img in images:
        assert (out / img).stat().st_size > 5000, img        # a real plot, not an empty file


@pytest.fixture(scope='module')
def h1_records():
    """Return data from H2 judged by H1 (a wrong model: its worst records are clearly worse)."""
    recs = crank_slider_campaign(samples=('slim',), frequencies_hz=(13.0, 1.0, 4.0, 2.0),
                                 duration_s=3.0, seed=2, model_effects=())
    return recs


def test_compare_report(h1_records, tmp_path):
    cmp = compare_records(h1_records, lambda r: r.model)
    pts = {'slim': [tone.point for r in cmp.records for tone in r.tones]}
    index = compare_report(
        tmp_path, cmp, 'h1', pts, {'slim': {'model': h1_records[0].model.frequency_response}}
    )
    text, headings, images = _page(index)
    assert text.index("id='summary'") < text.index('<h2>')             # the card comes first
    for key in ('model', 'verdict', 'fit', 'error vs noise floor', 'worst record'):
        assert f'<dt>{key}</dt>' in text
    assert headings == ['Records', 'Frequency response', 'Worst records in time',
                        'Residual tests (MATLAB resid)', 'Residual spectrum', 'Where it fails']
    _check_images(tmp_path, images)
    assert set(images) == {'bode.png', 'time_worst.png', 'residuals.png', 'residual_spectrum.png',
                           'failure_map.png'}
    # the card names the worst record; records table keeps the input (numeric) order
    worst = worst_first(cmp.records)[0]
    assert f'{Path(worst.source).name} (fit {worst.fit_percent:.1f} %)' in text
    rows = re.findall(r'<tr><td>(slim_[^<]*)</td>', text)
    assert rows == [Path(r.source).name for r in cmp.records]
    assert 'by frequency band' in text and 'FAILS' in text             # failure tables, H1 fails
    assert '<dd>fails beyond the measurement uncertainty in frequency bands' in text
    assert (
        'overflow-x:auto' not in text and 'white-space:pre-wrap' in text
    )  # no sideways scrolling


def test_residual_lines_find_hum_and_stay_quiet_on_white_noise():
    rng = np.random.default_rng(0)
    t = np.arange(4000) / 1000.0

    def rec(extra):
        y = rng.normal(0, 1e-8, t.size) + extra
        return SimpleNamespace(time_s=t, measured_a=y, predicted_a=np.zeros_like(y))

    hum = [rec(3e-9 * np.sin(2 * np.pi * 50 * t)) for _ in range(3)]
    lines = residual_lines(hum)
    assert lines and abs(lines[0][0] - 50.0) <= 0.5                     # Welch resolution 0.5 Hz
    assert residual_lines([rec(0.0) for _ in range(3)]) == []           # no false line


def test_diagnose_report(tmp_path):
    from ipmc_sensor_ros.workbench.diagnose import diagnose

    recs = crank_slider_campaign(samples=('slim',), frequencies_hz=(2.0, 8.0), duration_s=3.0,
                                 seed=1, model_effects=())
    diag = diagnose(recs, candidates=['surface_resistance', 'time_delay'], n_jobs=1)
    text, headings, images = _page(diagnose_report(tmp_path, diag))
    assert '<dt>verdict</dt>' in text and 'missing effect: surface_resistance' in text
    assert headings[0] == 'Ranking' and headings[1].startswith('#1: + surface_resistance')
    assert 'ranking.png' in images
    _check_images(tmp_path, images)
    assert '<th>held-out error</th>' in text and '<th>ΔBIC</th>' in text


def test_track_report(tmp_path):
    track = [TrackPoint(time_s=30.0 + 60 * k, estimates={'d': 3e-11 * 0.9 ** k},
                        ci95={'d': (2.9e-11 * 0.9 ** k, 3.1e-11 * 0.9 ** k)}, frequency_hz=6.0,
                        gain_a_per_m=0.01, phase_deg=10.0) for k in range(4)]
    text, headings, images = _page(track_report(tmp_path, {'run/long.csv': track}, 'd'))
    assert headings == ['long.csv'] and '<dt>tracked parameter</dt>' in text
    _check_images(tmp_path, images)

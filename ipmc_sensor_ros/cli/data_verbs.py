# SPDX-License-Identifier: Apache-2.0
"""Verbs that make or convert data: simulate, estimate (:mod:`.estimate_verb`), import."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..physics.beam import FIDELITIES
from ..physics.model import SensorModel
from ..physics.parameters import PAPER_SAMPLES, ParameterError
from .args import (Progress, add_data_args, add_model_args, add_output_args, effects_from_args,
                   material_from_args, natural_key, nonnegative, parse_geometry, parse_samples,
                   positive, renamed_flag, write_json)
from .estimate_verb import ESTIMATE_FORMAT, cmd_estimate, estimate_accuracy, read_estimate
from .outputs import check_free, write_complete
from .saved_models import add_model_file_args

__all__ = ['add_parsers', 'read_estimate', 'estimate_accuracy', 'ESTIMATE_FORMAT']


# ---------------------------------------------------------------------------
def _parse_frequencies(text: str, sample_rate_hz: float) -> list[float]:
    try:
        if ':' in text:
            lo, hi, n = text.split(':')
            freqs = [float(x) for x in np.geomspace(float(lo), float(hi), int(n))]
        else:
            freqs = [float(x) for x in text.split(',') if x.strip()]
    except ValueError:
        raise ParameterError(f"--frequencies: cannot read {text!r}; use 'lo:hi:n' or a comma list "
                             'in Hz') from None
    bad = [f for f in freqs if not 0 < f < sample_rate_hz / 2]
    if bad or not freqs:
        raise ParameterError(f'--frequencies: {text!r}: each must be above 0 and below half the '
                             f'--sample-rate ({sample_rate_hz / 2:g} Hz)')
    return freqs


def _frequency_text(freqs: list[float]) -> str:
    if len(freqs) == 1:
        return f'1 frequency ({freqs[0]:.4g} Hz)'
    return f'{len(freqs)} frequencies {freqs[0]:.4g}-{freqs[-1]:.4g} Hz'


def _frf_name(sample: str) -> str:
    return f'{sample}.frf.csv'


def _target_name(record, fmt: str) -> str:
    """Return the file (or bag directory) name simulate writes a record to."""
    if fmt == 'frf':
        return _frf_name(record.sample)
    name = record.path.replace('.', 'p')
    return f'{name}.csv' if fmt == 'timeseries' else name


def _check_targets(out: Path, recs, args) -> None:
    """Refuse, before anything is written, outputs that exist (without --overwrite)."""
    for name in sorted({_target_name(r, args.format) for r in recs}):
        check_free(out / name, args.overwrite)


def _cmd_simulate(args) -> int:
    from ..workbench.freqresp import fundamental_response
    from ..workbench.io import (
        FrequencyResponseData,
        TimeSeries,
        write_bag,
        write_frf,
        write_timeseries,
    )
    from ..workbench.scenarios import crank_slider_campaign

    effects = effects_from_args(args)
    material = material_from_args(args)
    samples = parse_samples(args.samples)
    freqs = _parse_frequencies(args.frequencies, args.sample_rate)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with Progress(f'simulating {len(samples) * len(freqs)} record(s)'):
        recs = crank_slider_campaign(
            effects,
            samples=samples,
            frequencies_hz=freqs,
            duration_s=args.duration,
            sample_rate_hz=args.sample_rate,
            crank_radius_m=args.crank_radius,
            material=material,
            noise_rel=args.noise_rel,
            seed=args.seed,
            fidelity=args.fidelity,
            beam_model=args.beam_model,
        )
    _check_targets(out, recs, args)
    written, points = [], {}
    for r in recs:
        ts = TimeSeries(path='', sample=r.sample, geometry=r.model.geometry, known={},
                        sample_rate_hz=args.sample_rate, time_s=r.time_s, current_a=r.current_a,
                        deflection_m=r.deflection_m)
        if args.format == 'timeseries':
            written.append(out / _target_name(r, args.format))
            write_complete(written[-1], lambda f: write_timeseries(f, ts), args.overwrite)
        elif args.format == 'bag':
            written.append(out / _target_name(r, args.format))
            write_complete(written[-1], lambda f: write_bag(f, ts, storage=args.storage),
                           args.overwrite)
        else:
            points.setdefault(r.sample, []).append(
                fundamental_response(r.time_s, r.deflection_m, r.current_a))
    for sample, pts in points.items():
        written.append(out / _frf_name(sample))
        frf = FrequencyResponseData(
            path='', sample=sample, geometry=PAPER_SAMPLES[sample], known={},
            frequency_hz=[p.frequency_hz for p in pts], gain_a_per_m=[p.gain_a_per_m for p in pts],
            phase_deg=[p.phase_deg for p in pts],
            gain_std_a_per_m=[p.gain_a_per_m * p.sd_log_mag for p in pts],
            phase_std_deg=[np.degrees(p.sd_phase_rad) for p in pts])
        write_complete(written[-1], lambda f: write_frf(f, frf), args.overwrite)
    model_text = SensorModel(PAPER_SAMPLES[samples[0]], material, effects).describe()
    print(f'wrote {len(written)} {args.format} file(s) to {out}: model {model_text}, '
          f'{_frequency_text(freqs)}, {args.duration:g} s each at {args.sample_rate:g} Hz, '
          f'noise {100 * args.noise_rel:g} % of the current RMS, seed {args.seed}')
    write_json(args.json, {'files': [str(p) for p in written], 'model': model_text})
    return 0


# ---------------------------------------------------------------------------
def _parse_columns(text: str | None) -> dict | None:
    if not text:
        return None
    out = {}
    for item in text.split(','):
        if '=' not in item:
            raise ParameterError(f'--columns: expected role=name pairs such as '
                                 f"time='Time [s]',current='Current [uA]', got {item!r}")
        role, name = (x.strip() for x in item.split('=', 1))
        if role not in ('time', 'deflection', 'current'):
            raise ParameterError(f"--columns: unknown role '{role}' (time, deflection, current)")
        out[role] = name.strip("'\"")
    return out


def _cmd_import(args) -> int:
    from ..workbench.labimport import import_lab_files

    gain = args.current_gain
    if gain is not None and not (math.isfinite(gain) and gain > 0):
        raise ParameterError(
            f'--current-gain must be a positive transimpedance in V/A, got {gain!r}'
        )
    geometry = parse_geometry(args.geometry, args.sample or '') if args.geometry else None
    files = sorted((Path(p) for p in args.files), key=natural_key)   # 1Hz before 13Hz
    written = import_lab_files(files, Path(args.out), geometry=geometry, overwrite=args.overwrite,
                               meta=Path(args.meta) if args.meta else None,
                               columns=_parse_columns(args.columns),
                               current_gain_a_per_v=None if gain is None else 1.0 / gain,
                               sample=args.sample, notice=lambda text: print(f'note: {text}'))
    for path in written:
        print(f'wrote {path}')
    print(f'imported {len(written)} file(s) into {args.out} (ipmc-timeseries/1); next: '
          f'ipmc-model compare {args.out}')
    write_json(args.json, {'files': [str(p) for p in written]})
    return 0


def add_parsers(sub, formatter) -> None:
    p = sub.add_parser(
        'simulate', formatter_class=formatter,
        help="write synthetic crank-slider measurements from the package's simulator")
    add_model_args(p)
    p.add_argument('--out', required=True, metavar='DIR', help='output directory')
    renamed_flag(p, '--bag', '--out DIR --format bag')
    p.add_argument('--samples', default='slim,short', metavar='LIST',
                   help='paper samples, comma list (big, slim, short)')
    p.add_argument('--frequencies', default='1:20:8', metavar='LO:HI:N|LIST',
                   help="crank frequencies, Hz: 'lo:hi:n' (log-spaced) or a comma list")
    p.add_argument('--duration', type=positive, default=6.0, metavar='S',
                   help='record length per frequency, s')
    p.add_argument('--sample-rate', type=positive, default=1000.0, metavar='HZ',
                   help='sample rate, Hz')
    p.add_argument('--crank-radius', type=positive, default=2e-3, metavar='M',
                   help='crank radius = deflection amplitude, m')
    p.add_argument('--noise-rel', type=nonnegative, default=0.01,
                   help='noise RMS / clean current RMS')
    p.add_argument('--seed', type=int, default=0, help='random seed of the noise')
    p.add_argument('--format', choices=('timeseries', 'frf', 'bag'), default='timeseries',
                   help='ipmc-timeseries/1 files, one ipmc-frf/1 file per sample, or rosbag2 bags')
    p.add_argument('--storage', choices=('sqlite3', 'mcap'), default='sqlite3', help='bag storage')
    p.add_argument('--fidelity', choices=FIDELITIES, default='model',
                   help='model: FFT prediction of the closed form with its effects; field: the '
                        'independent field-equation solution (base model and hydration_drift)')
    p.add_argument('--beam-model', choices=('linear', 'elastica'), default='linear',
                   help='with --fidelity field: stress profile from the small-deflection beam '
                        '(the paper, eq. 21) or the large-deflection elastica')
    add_output_args(p, report=False)
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser('estimate', formatter_class=formatter,
                       help='estimate deflection offline (same code path and params file as the '
                            'estimator node); NRMSE when the input has a measured deflection')
    add_data_args(p, frf=False)
    p.add_argument(
        '--out',
        required=True,
        metavar='DIR',
        help='output directory: <input>.estimate.csv (ipmc-estimate/1) or <input>_estimate bags; '
        'an output that exists is not replaced (see --overwrite)',
    )
    p.add_argument(
        '--params',
        metavar='FILE',
        help='ROS 2 params file of the estimator node (config/estimator.yaml); values it '
        'does not set come from the data header (geometry) or the node defaults',
    )
    add_model_file_args(p, replaces='the node defaults (--params may still set the filter, no '
                        'model or material value)')
    p.add_argument('--prefer', choices=('none', 'header', 'params'), default='none',
                   help='which wins when the data header and --params give different geometry or '
                        'material values (none: stop with an error naming both)')
    p.add_argument(
        '--format',
        choices=('timeseries', 'bag'),
        default='timeseries',
        help='output format: ipmc-estimate/1 text (estimate and measured columns) or bags',
    )
    p.add_argument('--causal', action='store_true',
                   help="the live filter's output (what the node publishes, sample by sample); "
                        'default: the smoothed estimate (every sample sees the whole record)')
    p.add_argument(
        '--storage', choices=('sqlite3', 'mcap'), default='sqlite3', help='output bag storage'
    )
    p.add_argument(
        '--estimate-topic',
        default='deflection/block',
        metavar='TOPIC',
        help='output bags: estimate topic',
    )
    add_output_args(p, report=False)
    p.set_defaults(func=cmd_estimate)

    p = sub.add_parser('import', formatter_class=formatter,
                       help='convert lab DAQ exports (CSV/TSV, free-text headers, units in column '
                            'names) into ipmc-timeseries/1 files')
    p.add_argument('files', nargs='+', help='lab files (CSV, TSV, semicolon, decimal comma)')
    p.add_argument('--out', required=True, metavar='DIR', help='output directory')
    p.add_argument('--geometry', metavar='L,W,T',
                   help='sample geometry, metres or with units (22mm,7mm,360um); else from --meta')
    p.add_argument(
        '--meta', metavar='FILE', help='run-metadata JSON/YAML with geometry (mm/µm accepted)'
    )
    p.add_argument(
        '--columns',
        metavar='ROLE=NAME,...',
        help='column names when not found automatically: time=...,deflection=...,current=...',
    )
    p.add_argument('--current-gain', type=float, metavar='V_PER_A',
                   help='current column recorded in volts: transimpedance gain of the current '
                        'amplifier, V per A (1e6 for a 1 MΩ feedback resistor)')
    p.add_argument('--sample', help='sample name written into the files')
    add_output_args(p, report=False)
    p.set_defaults(func=_cmd_import)

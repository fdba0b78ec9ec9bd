# SPDX-License-Identifier: Apache-2.0
"""
Verbs that make or convert data: ``simulate``, ``estimate``, ``import``.

``estimate`` writes ``ipmc-estimate/1`` text files (or bags): the estimate in
the column ``deflection_estimate_m`` next to the measured ``deflection_m``
when the input had one, so the two can never be mistaken for each other.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..physics.beam import FIDELITIES
from ..physics.model import SensorModel
from ..physics.parameters import PAPER_SAMPLES, ParameterError
from .args import (Progress, add_data_args, add_model_args, add_output_args, effects_from_args,
                   fmt_time_s, load_data, material_from_args, natural_key, parse_geometry,
                   parse_samples, renamed_flag, say, write_json)
from .saved_models import add_model_file_args, estimate_values

__all__ = ['add_parsers', 'read_estimate', 'estimate_accuracy', 'ESTIMATE_FORMAT']

ESTIMATE_FORMAT = 'ipmc-estimate/1'
_PARAMS_SECTIONS = ('/**', '/**/ipmc_estimator', 'ipmc_estimator', '/ipmc_estimator')


# ---------------------------------------------------------------------------
def _parse_frequencies(text: str) -> list[float]:
    try:
        if ':' in text:
            lo, hi, n = text.split(':')
            return [float(x) for x in np.geomspace(float(lo), float(hi), int(n))]
        return [float(x) for x in text.split(',') if x.strip()]
    except ValueError:
        raise ParameterError(f"--frequencies: cannot read {text!r}; use 'lo:hi:n' or a comma list "
                             'in Hz') from None


def _frequency_text(freqs: list[float]) -> str:
    if len(freqs) == 1:
        return f'1 frequency ({freqs[0]:.4g} Hz)'
    return f'{len(freqs)} frequencies {freqs[0]:.4g}-{freqs[-1]:.4g} Hz'


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
    freqs = _parse_frequencies(args.frequencies)
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
    written, points = [], {}
    for r in recs:
        name = r.path.replace('.', 'p')
        ts = TimeSeries(path='', sample=r.sample, geometry=r.model.geometry, known={},
                        sample_rate_hz=args.sample_rate, time_s=r.time_s, current_a=r.current_a,
                        deflection_m=r.deflection_m)
        if args.format == 'timeseries':
            written.append(out / f'{name}.csv')
            write_timeseries(written[-1], ts)
        elif args.format == 'bag':
            written.append(out / name)
            write_bag(written[-1], ts, storage=args.storage)
        else:
            points.setdefault(r.sample, []).append(
                fundamental_response(r.time_s, r.deflection_m, r.current_a))
    for sample, pts in points.items():
        written.append(out / f'{sample}.frf.csv')
        write_frf(written[-1], FrequencyResponseData(
            path='', sample=sample, geometry=PAPER_SAMPLES[sample], known={},
            frequency_hz=[p.frequency_hz for p in pts], gain_a_per_m=[p.gain_a_per_m for p in pts],
            phase_deg=[p.phase_deg for p in pts],
            gain_std_a_per_m=[p.gain_a_per_m * p.sd_log_mag for p in pts],
            phase_std_deg=[np.degrees(p.sd_phase_rad) for p in pts]))
    model_text = SensorModel(PAPER_SAMPLES[samples[0]], material, effects).describe()
    print(f'wrote {len(written)} {args.format} file(s) to {out}: model {model_text}, '
          f'{_frequency_text(freqs)}, {args.duration:g} s each at {args.sample_rate:g} Hz, '
          f'noise {100 * args.noise_rel:g} % of the current RMS, seed {args.seed}')
    write_json(args.json, {'files': [str(p) for p in written], 'model': model_text})
    return 0


# ---------------------------------------------------------------------------
def _explicit_params(path) -> set[str]:
    """Names a ROS 2 params file sets itself (not filled in from the defaults)."""
    from ..physics.parameters import read_yaml

    doc = read_yaml(path, 'parameters file') or {}
    return {k for key in _PARAMS_SECTIONS if isinstance(doc.get(key), dict)
            for k in (doc[key].get('ros__parameters') or {})}


def _resolve_values(data, base: dict, explicit: set[str], params: str | None, prefer: str) -> dict:
    """
    Node parameter values for one record.

    The params file's, completed from the data header (geometry, known material
    values, sample rate); a value both give differently is an error unless
    ``prefer`` says which wins.
    """
    from ..interface.specs import GEOMETRY_NAMES, MATERIAL_NAMES

    values = dict(base)
    header = {'length_m': data.geometry.length_m, 'width_m': data.geometry.width_m,
              'thickness_m': data.geometry.thickness_m}
    header.update({k: v for k, v in data.known.items() if k in MATERIAL_NAMES})
    for key, value in header.items():
        if key not in explicit:
            values[key] = value
        elif not math.isclose(float(values[key]), value, rel_tol=1e-6):
            if prefer == 'header':
                values[key] = value
            elif prefer != 'params':
                raise ParameterError(
                    f'{data.path}: {key} = {value:g} in the data header but '
                    f'{float(values[key]):g} '
                    f'in {params}; fix one, or choose with --prefer header|params'
                )
    if params and not explicit & set(GEOMETRY_NAMES):
        say(f'{data.path}: geometry from the data header ({params} gives none)')
    if 'sample_rate_hz' in explicit:
        if abs(data.sample_rate_hz / float(values['sample_rate_hz']) - 1) > 0.01:
            raise ParameterError(
                f'{data.path}: sample rate {data.sample_rate_hz:g} Hz does not match '
                f"sample_rate_hz = {float(values['sample_rate_hz']):g} Hz in {params}"
            )
    else:
        values['sample_rate_hz'] = float(data.sample_rate_hz)
    return values


def estimate_accuracy(time_s, estimate_m, measured_m, leak_corner_hz: float,
                      delay_s: float = 0.0,
                      settle: tuple[float, str] | None = None) -> tuple[float, float, str, dict]:
    """
    NRMSE of the estimated deflection.

    RMS(e - m) / RMS(m) of the estimate e and the measurement m, each with
    its mean and linear trend removed.

    A current sensor cannot see a constant deflection: the estimator's leak
    (corner ``leak_corner_hz``) removes it, and the deflection before the
    record started leaves a transient decaying as exp(-2 pi f_leak t), a slow
    drift over a short record; both are outside what the sensor can measure,
    so they are removed before comparing.  The comparison starts after the
    leak transient 5 / (2 pi f_leak) when the record is long enough, else
    covers the whole record; the measurement is delayed by ``delay_s`` (the
    estimate of a model with a time delay lags by it).  ``settle`` = (seconds,
    description), when given, replaces the leak rule
    (:meth:`~ipmc_sensor_ros.estimation.deflection.DeflectionEstimator.settling`: the
    Kalman estimator knows when it learned the level).
    Returns (nrmse, seconds used, which part was used, the level error that the NRMSE leaves
    out: :func:`~ipmc_sensor_ros.workbench.metrics.level_error`).
    """
    from ..estimation.deflection import leak_transient_s
    from ..workbench.metrics import level_error

    t = np.asarray(time_s, float)
    if settle is None:
        settle = (leak_transient_s(leak_corner_hz), 'leak transient')
    sel = t >= t[0] + settle[0] + delay_s
    if np.count_nonzero(sel) >= 10:
        what = f'after the first {fmt_time_s(settle[0])} s: {settle[1]}'
    else:
        sel = t >= t[0] + delay_s
        what = 'whole record'
    # increasing times (any record read from a file): the part used is a slice, so only
    # views are taken; the metric runs on bounded pieces (memory independent of the record)
    n_sel = int(np.count_nonzero(sel))
    first = int(np.argmax(sel))
    if sel[first:first + n_sel].all():
        sel = slice(first, first + n_sel)
    t_sel = t[sel]
    estimate = np.asarray(estimate_m, float)[sel]
    if delay_s:      # the measurement delayed by delay_s, at the used times only
        truth = np.interp(t_sel - delay_s, t, np.asarray(measured_m, float))
    else:
        truth = np.asarray(measured_m, float)[sel]
    level = level_error(estimate, truth)
    return level['nrmse'], float(t_sel[-1] - t_sel[0]), what, level


#: Rows formatted at a time when writing an ipmc-estimate/1 file.
WRITE_CHUNK_ROWS = 65_536


def _write_estimate(path: Path, data, values: dict, model_text: str, params, resets: int,
                    t, current, w, measured) -> None:
    cols = ['time_s', 'current_A', 'deflection_estimate_m']
    arrays = [t, current, w]
    if measured is not None:
        cols.append('deflection_m')
        arrays.append(measured)
    head = [
        f'# format: {ESTIMATE_FORMAT}',
        f'# source: {data.path}',
        f'# sample: {data.sample}',
        *(
            f'# {k}: {values[k]!r}'
            for k in ('length_m', 'width_m', 'thickness_m', 'sample_rate_hz')
        ),
        f'# model: {model_text}',
        f"# params: {params or 'defaults of the estimator node'}",
        f'# resets: {resets}',
        '# deflection_estimate_m: the estimate; '
        'deflection_m: the measured deflection of the input',
    ]
    # repr: the shortest text that reads back exactly; written in chunks so that memory
    # stays a few MB above the arrays themselves (a whole-file list of row strings took
    # ~600 B per row: 3 GB for 5e6 rows)
    with open(path, 'w', encoding='utf-8') as f:
        f.write('\n'.join(head + [','.join(cols)]) + '\n')
        for k in range(0, len(arrays[0]), WRITE_CHUNK_ROWS):
            rows = np.column_stack([a[k:k + WRITE_CHUNK_ROWS] for a in arrays]).tolist()
            f.write(''.join(','.join(map(repr, r)) + '\n' for r in rows))


def read_estimate(path) -> dict[str, np.ndarray]:
    """
    Return the columns of an ``ipmc-estimate/1`` file by name.

    Names: ``time_s``, ``deflection_estimate_m``...
    """
    lines = Path(path).read_text(encoding='utf-8').splitlines()
    if not lines or lines[0] != f'# format: {ESTIMATE_FORMAT}':
        raise ParameterError(f'{path}:1: not an {ESTIMATE_FORMAT} file')
    k = next(i for i, line in enumerate(lines) if not line.startswith('#'))
    cols = lines[k].split(',')
    table = np.loadtxt(lines[k + 1:], delimiter=',', ndmin=2)
    return {c: table[:, j] for j, c in enumerate(cols)}


def _cmd_estimate(args) -> int:
    """Offline estimation with the node's code path and parameters file."""
    from ..estimation.stream import estimate_record, validate_block
    from ..interface import specs as config
    from ..workbench.io import TimeSeries, write_bag

    base = (
        config.load_params_file(args.params)
        if args.params
        else config.defaults(config.ESTIMATOR_SPECS)
    )
    explicit = _explicit_params(args.params) if args.params else set()
    base, explicit = estimate_values(base, explicit, args)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = []
    for data in load_data(args, need_deflection=False):
        src = data.path
        if not isinstance(data, TimeSeries):
            raise ParameterError(
                f'{src}: a time series is needed (this is a frequency-response file)'
            )
        values = _resolve_values(data, base, explicit, args.params or args.model_file,
                                 args.prefer)
        current = validate_block(data.current_a, max_samples=max(data.current_a.size, 1))
        estimator = config.build_estimator(values)
        model_text = estimator.model.describe()
        with Progress(
            f'estimating {data.current_a.size} samples of {src} with {model_text} '
            f"(order {estimator.reduction_order}, fs {float(values['sample_rate_hz']):g} Hz, "
            f'{estimator.estimator} estimator, leak {estimator.inverse.leak_corner_hz:g} Hz)'
        ) as prog:
            prog.step('running')
            t_out, w, stream = estimate_record(estimator, data.time_s, current,
                                               max_gap_s=float(values['max_gap_s']), source=src)
        resets = stream.counters['resets']
        if not stream.kept.any():
            raise ParameterError(f'{src}: no sample passed the stream rules '
                                 f'({stream.last_rejection}); nothing written')
        if not stream.kept.all():
            say(f'{src}: {int((~stream.kept).sum())} sample(s) rejected by the stream rules '
                f'(no estimate written for them): {stream.last_rejection}')
            current = current[stream.kept]
        measured = data.deflection_m
        if measured is not None and not stream.kept.all():
            measured = measured[stream.kept]
        stem = Path(src).name.removesuffix('.csv').removesuffix('.txt')
        if args.format == 'bag':
            out = out_dir / f'{stem}_estimate'
            write_bag(out, TimeSeries(path='', sample=data.sample, geometry=data.geometry,
                                      known=data.known, sample_rate_hz=data.sample_rate_hz,
                                      time_s=t_out, current_a=current, deflection_m=w),
                      storage=args.storage, current_topic=args.current_topic,
                      deflection_topic=args.estimate_topic)
        else:
            out = out_dir / f'{stem}.estimate.csv'
            _write_estimate(out, data, values, model_text, args.params, resets, t_out, current, w,
                            measured)
        row = {'source': src, 'out': str(out), 'samples': int(t_out.size), 'resets': resets}
        msg = f'{src}: {t_out.size} estimates -> {out}'
        if resets:
            msg += (f"; {resets} filter reset(s) at time gaps > {values['max_gap_s']} s "
                    'or backward jumps')
        if measured is not None:
            # the Kalman knows when it learned the level; with resets that refers to its last
            # segment only, and the leak rule is used
            settle = (estimator.settling()
                      if estimator.estimator == 'kalman' and not resets else None)
            err, used, what, level = estimate_accuracy(
                t_out, w, measured, estimator.inverse.leak_corner_hz, estimator.delay_s,
                settle=settle
            )
            row['nrmse'] = err
            row.update(level)
            msg += (f'; NRMSE {err:.4f} = RMS(estimate - measured) / RMS(measured), means and '
                    f'linear trends removed, over {fmt_time_s(used)} s ({what}); '
                    f"as measured (nothing removed): {level['nrmse_raw']:.4f}, level error "
                    f"{level['start_error_m']:+.3g} m -> {level['end_error_m']:+.3g} m (what a "
                    'reader at rest sees, if the measured deflection is zero at rest)')
        else:
            msg += '; no measured deflection in the input: accuracy not reported'
        print(msg)
        summary.append(row)
    write_json(args.json, summary)
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
    written = import_lab_files(files, Path(args.out), geometry=geometry,
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
    p.add_argument('--duration', type=float, default=6.0, metavar='S',
                   help='record length per frequency, s')
    p.add_argument('--sample-rate', type=float, default=1000.0, metavar='HZ',
                   help='sample rate, Hz')
    p.add_argument('--crank-radius', type=float, default=2e-3, metavar='M',
                   help='crank radius = deflection amplitude, m')
    p.add_argument('--noise-rel', type=float, default=0.01, help='noise RMS / clean current RMS')
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
    add_data_args(p)
    p.add_argument(
        '--out',
        required=True,
        metavar='DIR',
        help='output directory: <input>.estimate.csv (ipmc-estimate/1) or <input>_estimate bags',
    )
    p.add_argument(
        '--params',
        metavar='FILE',
        help='ROS 2 params file of the estimator node (config/estimator.yaml); values it '
        'does not set come from the data header (geometry) or the node defaults',
    )
    add_model_file_args(p)
    p.add_argument('--prefer', choices=('none', 'header', 'params'), default='none',
                   help='which wins when the data header and --params give different geometry or '
                        'material values (none: stop with an error naming both)')
    p.add_argument(
        '--format',
        choices=('timeseries', 'bag'),
        default='timeseries',
        help='output format: ipmc-estimate/1 text (estimate and measured columns) or bags',
    )
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
    p.set_defaults(func=_cmd_estimate)

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

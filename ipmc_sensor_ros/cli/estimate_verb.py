# SPDX-License-Identifier: Apache-2.0
"""
The ``estimate`` verb: offline estimation with the node's code path and parameters file.

It writes ``ipmc-estimate/1`` text files (or bags): the estimate in the column
``deflection_estimate_m`` next to the measured ``deflection_m`` when the input had one, so
the two can never be mistaken for each other, and the flag ``deflection_beyond_limit``
(:mod:`ipmc_sensor_ros.estimation.limits`).  What it guarantees (errors naming file:line,
batches that go on, complete and exclusive outputs, one build per model): docs/reliability.md.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from ..errors import IpmcError, defect_text
from ..estimation.limits import beyond_limit, deflection_limit_m
from ..physics.parameters import ParameterError
from .args import Progress, fmt_time_s, load_data, say, write_json
from .outputs import check_free, printable, write_complete
from ..workbench.measurements import sample_label
from .saved_models import estimate_values

__all__ = ['cmd_estimate', 'read_estimate', 'estimate_accuracy', 'EstimatorCache',
           'ESTIMATE_FORMAT', 'WRITE_CHUNK_ROWS']

ESTIMATE_FORMAT = 'ipmc-estimate/1'
_PARAMS_SECTIONS = ('/**', '/**/ipmc_estimator', 'ipmc_estimator', '/ipmc_estimator')


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


def estimate_accuracy(time_s, estimate_m, measured_m, delay_s: float = 0.0,
                      settle: tuple[float, str] = (0.0, 'from the start')
                      ) -> tuple[float, float, str, dict]:
    """
    NRMSE of the estimated deflection.

    RMS(e - m) / RMS(m) of the estimate e and the measurement m, each with
    its mean and linear trend removed.

    A current sensor cannot see a constant deflection: the level before the record started
    is learned only at a rest or over the motion's corner, so mean and trend are removed
    before comparing (the raw error is reported beside, in the level dict).  The comparison
    starts after ``settle`` = (seconds, why)
    (:meth:`~ipmc_sensor_ros.estimation.deflection.DeflectionEstimator.settling`) when the
    record is long enough, else covers the whole record; the measurement is delayed by
    ``delay_s`` (the estimate of a model with a time delay lags by it).
    Returns (nrmse, seconds used, which part was used, the level error that the NRMSE leaves
    out: :func:`~ipmc_sensor_ros.workbench.metrics.level_error`).
    """
    from ..workbench.metrics import level_error

    t = np.asarray(time_s, float)
    sel = t >= t[0] + settle[0] + delay_s
    if np.count_nonzero(sel) >= 10:
        what = f'after the first {fmt_time_s(settle[0])} s, {settle[1]}'
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
                    t, current, w, measured, flagged: tuple, std, smoothed: bool) -> None:
    flags, limit_m = flagged
    cols = ['time_s', 'current_A', 'deflection_estimate_m', 'deflection_estimate_std_m']
    arrays = [t, current, w, std]
    if measured is not None:
        cols.append('deflection_m')
        arrays.append(measured)
    cols.append('deflection_beyond_limit')
    arrays.append(flags)
    head = [
        f'# format: {ESTIMATE_FORMAT}',
        f'# source: {printable(data.path)}',
        f'# sample: {sample_label(data)}',
        *(
            f'# {k}: {values[k]!r}'
            for k in ('length_m', 'width_m', 'thickness_m', 'sample_rate_hz')
        ),
        f'# model: {model_text}',
        f'# params: {params}',
        f'# resets: {resets}',
        '# estimate: ' + ('smoothed (fixed-interval: every sample sees the whole record)'
                          if smoothed else 'causal (the live filter, as the node publishes it)'),
        '# deflection_estimate_m: the estimate; deflection_estimate_std_m: its standard '
        'deviation (NaN: the leaky estimator has none); '
        'deflection_m: the measured deflection of the input',
        '# deflection_beyond_limit: 1.0 where |deflection_estimate_m| > '
        f'{limit_m!r} m = L/2 (not physically possible), '
        'else 0.0',
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


class EstimatorCache:
    """
    The estimators of a batch: each built once per set of parameter values, then copied.

    Building one (model reduction, filter design) takes ~0.5 s; a copy of the freshly built
    estimator is the same estimator in its start state and takes ~1 ms, so a directory of
    small files costs its reading and estimating, not one build per file.
    """

    def __init__(self):
        self._built: dict = {}
        self.builds = 0        #: estimators built (not copies)

    def get(self, values: dict):
        """Return a fresh estimator of ``values`` (``interface.builders.build_estimator``)."""
        import copy

        from ..interface import builders

        key = repr(sorted(values.items()))
        if key not in self._built:
            self._built[key] = builders.build_estimator(values)
            self.builds += 1
        return copy.deepcopy(self._built[key])


def _estimate_inputs(args) -> list[Path]:
    """Return the inputs of ``estimate`` (files, bags, directories expanded), in order."""
    from .args import expand_inputs, natural_key

    return sorted(expand_inputs(args.data), key=natural_key)


def _read_one(args, path: Path):
    """Read one input of ``estimate`` (as :func:`.args.load_data` reads each)."""
    import argparse

    from ..workbench.io import TimeSeries

    data = load_data(argparse.Namespace(**{**vars(args), 'data': [str(path)]}),
                     need_deflection=False)[0]
    if not isinstance(data, TimeSeries):
        raise ParameterError(f'{data.path}: a time series is needed (this is a '
                             'frequency-response file)')
    for note in data.notes:
        say(printable(note))
    return data


def _checked_current(data) -> np.ndarray:
    """Check the record's current by the stream's value rule; the error names file:line."""
    from ..errors import DataError
    from ..estimation.stream import validate_block

    try:
        return validate_block(data.current_a, max_samples=max(data.current_a.size, 1))
    except DataError as exc:
        if exc.index is None:
            raise ParameterError(f'{data.path}: {exc}') from None
        reason = str(exc).replace(f' at index {exc.index}', '')
        raise ParameterError(f'{data.where(exc.index)}: {reason}') from None


def _run(args, estimator, data, current, values, src):
    """Return (times, deflection, std, stream): the live filter, smoothed unless ``--causal``."""
    from ..estimation.records import estimate_record, smooth_record

    fresh = estimator.rebuilt() if not args.causal else None
    t_out, w, stream = estimate_record(estimator, data.time_s, current,
                                       max_gap_s=float(values['max_gap_s']), source=src)
    std = stream.record_std_m
    if stream.last_fault:               # a defect: its samples dropped, the filter reset
        say(f'{src}: {stream.last_fault}: {stream.counters["samples_dropped"]} sample(s) '
            'dropped with a filter reset (please report it)')
    if fresh is not None and stream.kept.any():
        t_out, w, std = smooth_record(fresh, stream, data.time_s, current,
                                      warn=lambda text: say(f'{src}: {text}'))
    return t_out, w, std, stream


def _estimate_one(args, path: Path, base: dict, explicit: set, cache: EstimatorCache) -> dict:
    """Estimate one input and write its output; returns its summary row."""
    from ..estimation.accounting import record_summary

    data = _read_one(args, path)
    check_free(_output_path(args, data.path), args.overwrite)      # before the work
    src = printable(data.path)
    values = _resolve_values(data, base, explicit, args.params or args.model_file,
                             args.prefer)
    current = _checked_current(data)
    estimator = cache.get(values)
    model_text = estimator.model.describe()
    with Progress(
        f'estimating {data.current_a.size} samples of {src} with {model_text} '
        f"(order {estimator.reduction_order}, fs {float(values['sample_rate_hz']):g} Hz, "
        f"{estimator.estimator} estimator, {'causal' if args.causal else 'smoothed'})"
    ) as prog:
        prog.step('running')
        t_out, w, std, stream = _run(args, estimator, data, current, values, src)
    kept = stream.kept
    if not kept.any():
        raise ParameterError(f'{src}: no sample passed the stream rules '
                             f'({stream.last_rejection}); nothing written')
    measured = data.deflection_m
    if not kept.all():
        say(f'{data.where(int(np.argmin(kept)))}: {int((~kept).sum())} sample(s) from here on '
            f'rejected by the stream rules (no estimate written for them): '
            f'{stream.last_rejection}')
        current = current[kept]
        measured = None if measured is None else measured[kept]
    limit_m = deflection_limit_m(estimator.model.geometry.length_m)
    flags = beyond_limit(w, limit_m)
    out, note = _write_output(args, data, values, model_text, stream.counters['resets'],
                              t_out, current, w, measured, (flags, limit_m), std)
    # rows given, estimated and refused per reason (estimation/accounting.py)
    rows, rows_text = record_summary(stream.counters)
    row = {'source': src, 'out': printable(out), 'samples': int(t_out.size), **rows,
           'resets': stream.counters['resets'],
           'samples_beyond_limit': int(np.count_nonzero(flags)), 'rows_text': rows_text}
    if row['samples_beyond_limit']:
        note += (f"; {row['samples_beyond_limit']} estimate(s) beyond the geometric limit "
                 f'|w| > L/2 = {limit_m:g} m (not '
                 'physically possible: offset drift, wrong model or geometry?), flagged in '
                 'column deflection_beyond_limit')
    print(_estimate_line(row, values, estimator, t_out, w, measured) + note)
    return row


def _write_output(args, data, values, model_text, resets, t_out, current, w, measured,
                  flagged, std):
    """Write the estimate of one input (text or bag); (output path, note to print)."""
    from ..workbench.io import TimeSeries, write_bag

    out = _output_path(args, data.path)
    if args.format == 'bag':
        ts = TimeSeries(path='', sample=data.sample, geometry=data.geometry, known=data.known,
                        sample_rate_hz=data.sample_rate_hz, time_s=t_out, current_a=current,
                        deflection_m=w)
        note = write_complete(out, lambda p: write_bag(
            p, ts, storage=args.storage, current_topic=args.current_topic,
            deflection_topic=args.estimate_topic), args.overwrite)
    else:
        note = write_complete(out, lambda p: _write_estimate(
            p, data, values, model_text, _params_text(args), resets, t_out, current, w, measured,
            flagged, std, not args.causal),
            args.overwrite)
    return out, (f'; {note}' if note else '')


def _params_text(args) -> str:
    """Where the node parameters came from (an estimate file's ``# params:`` line)."""
    given = args.params or 'defaults of the estimator node'
    if getattr(args, 'model_file', None):
        return f'{given}, material and effects of --model-file {args.model_file}'
    return given if args.params else f"{given} (material: the paper's Tables 1-2)"


def _output_path(args, data_path) -> Path:
    """Return where the estimate of the input ``data_path`` goes (``--out``, ``--format``)."""
    stem = Path(data_path).name.removesuffix('.csv').removesuffix('.txt')
    suffix = '_estimate' if args.format == 'bag' else '.estimate.csv'
    return Path(args.out) / f'{stem}{suffix}'


def _estimate_line(row: dict, values: dict, estimator, t_out, w, measured) -> str:
    """Return the printed line of one estimated input (and put its accuracy in ``row``)."""
    resets = row['resets']
    msg = f"{row['source']}: {row.pop('rows_text')} -> {row['out']}"
    if resets:
        msg += (f"; {resets} filter reset(s) at time gaps > {values['max_gap_s']} s "
                'or backward jumps')
    if measured is None:
        return msg + '; no measured deflection in the input: accuracy not reported'
    err, used, what, level = estimate_accuracy(t_out, w, measured, estimator.delay_s,
                                               settle=estimator.settling())
    row['nrmse'] = err
    row.update(level)
    return msg + (f'; NRMSE {100 * err:.3g} % (means and linear trends removed) over '
                  f'{fmt_time_s(used)} s ({what}); as measured (nothing removed): '
                  f"{100 * level['nrmse_raw']:.3g} %, level error "
                  f"{level['start_error_m']:+.3g} m at the start, "
                  f"{level['end_error_m']:+.3g} m at the end")


def cmd_estimate(args) -> int:
    """
    Offline estimation with the node's code path and parameters file.

    Each input is estimated on its own: one that fails is reported (naming the file and,
    for its data, the line) and the rest are estimated.  Exit status 0 if every input was
    written, 1 if some failed, 2 if none was written.
    """
    from ..interface import specs as config

    base = (config.load_params_file(args.params) if args.params
            else config.defaults(config.ESTIMATOR_SPECS))
    explicit = _explicit_params(args.params) if args.params else set()
    base, explicit = estimate_values(base, explicit, args)
    # a node output like publish_points: offline, the whole record is smoothed (or --causal)
    base = dict(base, smoothed_lag_s=0.0)
    paths = _estimate_inputs(args)
    if not (args.params or getattr(args, 'model_file', None)):
        say("material: the paper's Tables 1-2 where a data header gives none (no --params or "
            '--model-file): a sensor of your own needs its own (ipmc-model fit --save-model)')
    cache = EstimatorCache()
    summary, failed = [], []
    for path in paths:
        try:
            summary.append(_estimate_one(args, path, base, explicit, cache))
        except (IpmcError, OSError) as exc:
            text = printable(exc)
            if printable(path) not in text:
                text = f'{printable(path)}: {text}'
            print(f'ipmc-model estimate: error: {text}', file=sys.stderr)
            failed.append(printable(path))
        except Exception as exc:  # noqa: BLE001 - a defect: this input fails, the rest go on
            print(f'ipmc-model estimate: {printable(path)}: {defect_text(exc)}', file=sys.stderr)
            failed.append(printable(path))
    if len(paths) > 1 or failed:
        print(f'estimate: {len(summary)} of {len(paths)} input(s) written to '
              f'{printable(args.out)}'
              + (f"; {len(failed)} failed: {', '.join(failed)}" if failed else ''))
    write_json(args.json, summary)
    if failed:
        return 2 if not summary else 1
    return 0

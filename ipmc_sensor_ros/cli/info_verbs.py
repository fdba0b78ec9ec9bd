# SPDX-License-Identifier: Apache-2.0
"""Verbs about the model: ``info``, ``reduce``, ``eq55``, ``effects``, ``example``, ``figures``."""
from __future__ import annotations

import json
from pathlib import Path

from ..physics.effects import load_plugin
from ..physics.model import SensorModel
from ..physics.parameters import PAPER_SAMPLES, ParameterError
from .args import (
    Progress,
    add_model_args,
    add_output_args,
    effects_from_args,
    material_from_args,
    parse_geometry,
    parse_samples,
    renamed_flag,
    report_dir,
    write_json,
)

__all__ = ['add_parsers']

#: reduction accuracy targets printed next to the table (the README's design targets)
TARGET_MAG_DB, TARGET_PHASE_DEG = 0.1, 1.0


def _parse_orders(text: str) -> list[int]:
    out: list[int] = []
    try:
        for part in text.split(','):
            if '-' in part:
                lo, hi = part.split('-', 1)
                out.extend(range(int(lo), int(hi) + 1))
            else:
                out.append(int(part))
    except ValueError:
        raise ParameterError(
            f"--orders: cannot read {text!r}; use e.g. '1-8' or '2,4,6'"
        ) from None
    return out


def _cmd_reduce(args) -> int:
    from ..lti.reduction import reduction_error_table

    effects = effects_from_args(args)
    material = material_from_args(args)
    if args.geometry:
        geoms = {'custom': parse_geometry(args.geometry, 'custom')}
    else:
        geoms = {n: PAPER_SAMPLES[n] for n in parse_samples(args.samples)}
    models = {n: SensorModel(g, material, effects) for n, g in geoms.items()}
    with Progress('reducing'):
        rows = reduction_error_table(
            models, _parse_orders(args.orders), (args.band[0], args.band[1])
        )
    print(f'Stable minimum-phase reductions vs {next(iter(models.values())).describe()} over '
          f'{args.band[0]:g}-{args.band[1]:g} Hz (worst errors over the band)')
    print(f"{'sample':<8} {'order':>5} {'|mag| dB':>10} {'|phase| deg':>12}  "
          f'ok = within {TARGET_MAG_DB} dB and {TARGET_PHASE_DEG} deg')
    for r in rows:
        ok = (
            r['max_mag_error_db'] <= TARGET_MAG_DB and r['max_phase_error_deg'] <= TARGET_PHASE_DEG
        )
        print(f"{r['sample']:<8} {r['order']:>5} {r['max_mag_error_db']:>10.4f} "
              f"{r['max_phase_error_deg']:>12.4f}  {'ok' if ok else '-'}")
    write_json(args.json, {'band_hz': list(args.band), 'model': args.model, 'rows': rows})
    return 0


def _cmd_eq55(args) -> int:
    from ..lti.reduction import eq55_poles_zeros

    material = material_from_args(args)
    out = {}
    for name in parse_samples(args.samples):
        rep = eq55_poles_zeros(SensorModel.named(args.model, PAPER_SAMPLES[name], material))
        print(f"{name}: eq. 55 zeros (rad/s): {', '.join(f'{z:.5g}' for z in rep['zeros'])}")
        print(f"{name}: eq. 55 poles (rad/s): {', '.join(f'{p:.5g}' for p in rep['poles'])}")
        verdict = (
            'stable'
            if rep['inverse_stable']
            else 'UNSTABLE (right-half-plane zero(s) at '
            f"{', '.join(f'{z.real:.5g}' for z in rep['rhp_zeros'])} rad/s)"
        )
        print(f'{name}: literal inverse of eq. 55 is {verdict}')
        out[name] = rep
    write_json(args.json, out)
    return 0


def _cmd_effects(args) -> int:
    from ..physics.effects import EFFECTS, catalog_markdown

    for plugin in args.plugin or []:
        load_plugin(plugin)
    if args.markdown:
        print(catalog_markdown())
        return 0
    for eff in EFFECTS.values():
        params = ', '.join(f'{p.name} [{p.unit}] ({p.typical[0]:g}..{p.typical[1]:g})'
                           for p in eff.parameters) or '-'
        print(f"{eff.name:<22} {'LTI' if eff.lti else 'time-domain':<12} {params}")
        print(f"{'':<22} {eff.summary}")
    return 0


def _cmd_example(args) -> int:
    """Return the README's worked example: H1 on a two-sample sweep, see it fail, diagnose, fix."""
    import tempfile

    from .main import main

    work = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix='ipmc-example-'))
    data = work / 'sweep'
    steps = [
        (
            '1. measure (simulated): slim + short, crank-slider 1-20 Hz, truth = H2, 1 % noise',
            [
                'simulate',
                '--out',
                str(data),
                '--model',
                'h2',
                '--samples',
                'slim,short',
                '--seed',
                '1',
            ],
        ),
        (
            "2. compare the paper's H1 with the data",
            ['compare', str(data), '--model', 'h1', '--json', str(work / 'h1.json')],
        ),
        (
            '3. diagnose: which effect is H1 missing?',
            ['diagnose', str(data), '--model', 'h1', '--json', str(work / 'diagnosis.json')],
        ),
    ]
    for title, argv in steps:
        print(f"\n=== {title}\n$ ipmc-model {' '.join(argv)}", flush=True)
        rc = main(argv)
        if rc:
            return rc
    verdict = json.loads((work / 'diagnosis.json').read_text())['verdict']
    missing = verdict['missing_effect']
    if not missing:
        print('no missing effect found')
        return 1
    argv = [
        'compare',
        str(data),
        '--model',
        'h1',
        '--effects',
        missing,
        '--json',
        str(work / 'fixed.json'),
    ]
    print(f"\n=== 4. add it: compare H1 + {missing}\n$ ipmc-model {' '.join(argv)}", flush=True)
    rc = main(argv)
    before = json.loads((work / 'h1.json').read_text())
    after = json.loads((work / 'fixed.json').read_text())
    print(
        f"\nerror of the predicted current: H1 {before['error']:.4f} "
        f"(fit {before['fit_percent']:.1f} %)"
        f" -> H1 + {missing} {after['error']:.4f} (fit {after['fit_percent']:.1f} %): "
        f"{before['error'] / after['error']:.1f}x lower; noise floor {after['noise_floor']:.4f} "
        '(the error a perfect model would have)'
    )
    print(f'files in {work}')
    return rc


def _cmd_figures(args) -> int:
    from ..workbench.figures import reproduce_figures

    rd = report_dir(args.report)
    with Progress('reproducing Figs. 4-6'):
        numbers = reproduce_figures(rd, seed=args.seed)
    for k, v in numbers.items():
        print(f'{k:<52} {v:.4g}')
    write_json(args.json, numbers)
    if rd:
        print(f"report: {rd / 'index.html'}")
    return 0


def _cmd_info(args) -> int:
    """Show what a model file holds: the sensor, the calibration's recording effects, origin."""
    from ..physics.modelfile import load_model

    for plugin in args.plugin or []:
        load_plugin(plugin)
    saved = load_model(args.model_file)
    print(saved.describe())
    doc = saved.to_doc()
    doc['notices'] = list(saved.notices)
    write_json(args.json, doc)
    return 0


def add_parsers(sub, formatter) -> None:
    p = sub.add_parser('info', formatter_class=formatter,
                       help='show a saved model file: the sensor, the recording effects of its '
                            'calibration, where it came from')
    p.add_argument('model_file', metavar='MODEL_FILE', help='ipmc-model/1 YAML (--save-model)')
    p.add_argument('--plugin', action='append', metavar='FILE',
                   help='Python file defining effects the model uses (repeatable)')
    add_output_args(p, report=False)
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser(
        'reduce',
        formatter_class=formatter,
        help='error table of reduced (stable, minimum-phase) models against the full model',
    )
    add_model_args(p)
    p.add_argument(
        '--samples', default='big,slim,short', metavar='LIST', help='paper samples, comma list'
    )
    p.add_argument(
        '--geometry',
        metavar='L,W,T',
        help='custom geometry instead of --samples: metres or with units (22mm,7mm,360um)',
    )
    p.add_argument('--orders', default='1-8', metavar='LIST', help="orders, e.g. '1-8' or '2,4,6'")
    p.add_argument(
        '--band',
        nargs=2,
        type=float,
        default=(0.1, 50.0),
        metavar=('LOW_HZ', 'HIGH_HZ'),
        help='frequency band of the error, Hz',
    )
    add_output_args(p, report=False)
    p.set_defaults(func=_cmd_reduce)

    p = sub.add_parser(
        'eq55',
        formatter_class=formatter,
        help="poles/zeros of the paper's eq. 55 and stability of its literal inverse",
    )
    add_model_args(p, effects=False)
    p.add_argument(
        '--samples', default='big,slim,short', metavar='LIST', help='paper samples, comma list'
    )
    add_output_args(p, report=False)
    p.set_defaults(func=_cmd_eq55)

    p = sub.add_parser('effects', formatter_class=formatter, help='list the effect catalog')
    p.add_argument('--plugin', action='append', metavar='FILE',
                   help='Python file defining more effects (repeatable)')
    p.add_argument('--markdown', action='store_true', help='full documentation as Markdown')
    p.set_defaults(func=_cmd_effects)

    p = sub.add_parser('example', formatter_class=formatter,
                       help='worked example: H1 fails, diagnose, add the effect, the error falls')
    p.add_argument('--out', metavar='DIR', help='working directory (default: a new temporary one)')
    p.set_defaults(func=_cmd_example)

    p = sub.add_parser(
        'figures',
        formatter_class=formatter,
        help="reproduce the paper's Figs. 4-6 on synthetic data (numbers; plots with --report)",
    )
    renamed_flag(p, '--out', '--report')
    p.add_argument('--seed', type=int, default=0, help='random seed of the noise')
    add_output_args(p)
    p.set_defaults(func=_cmd_figures)

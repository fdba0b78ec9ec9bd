# SPDX-License-Identifier: Apache-2.0
"""
Verbs that test a model against measurements: ``fit``, ``compare``, ``track``, ``diagnose``.

Each verb: parse -> call the workbench -> print a summary -> optional JSON and report.
"""
from __future__ import annotations

from pathlib import Path

from ..estimation.config import parse_mains
from ..physics.model import SensorModel
from ..physics.parameters import ParameterError
from .args import (Progress, add_data_args, add_model_args, add_output_args, effects_from_args,
                   load_data, material_from_args, nonnegative, nonnegative_int, param_names,
                   positive, renamed_flag, report_dir, say, write_json)
from .outputs import check_free
from .saved_models import (data_files, params_file_paths, print_saved, with_recording_flag,
                           write_params_files)

__all__ = ['add_parsers']

FREE_HELP = ('parameters estimated from the data, comma list of symbols d, alpha0, C-, kappa_e, '
             'Y, r0, T or full names')


def _records(args, with_data: bool = False):
    """
    Return the time records named by the arguments.

    Each with its model (base + --effects, material) (and the loaded data files,
    ``with_data``).
    """
    from ..workbench.data import records_from

    effects, material = effects_from_args(args), material_from_args(args)   # flags before files
    data = load_data(args)
    recs = records_from(data, material, effects)
    for r in recs:
        if r.at_stamps:
            say(f'{r.path}: rows taken at their stamps (the deflection is smoother against '
                'them than against the sample clock): interpolated onto the clock')
        if r.filled is not None:
            say(f'{r.path}: {int(r.filled.sum())} row(s) missing on the sample clock: the '
                "deflection interpolated there as the model's input, not fitted or scored")
    return (recs, data) if with_data else recs


def _model_text(data, material, effects) -> str:
    return SensorModel(data[0].geometry, material, effects).describe()


def _free_names(args, fit_eff) -> tuple[str, ...]:
    """
    Return the ``--free`` names with the parameters of the fitted ``--effects``, once each.

    An effect parameter named alone (``delay_s``) and qualified (``time_delay.delay_s``) is
    one parameter.
    """
    from ..workbench.discovery import effect_free_names, free_names

    qualified = effect_free_names(fit_eff, frequency_domain=True)
    short = {q.split('.', 1)[1]: q for q in qualified}
    free = []
    for name in free_names(args.free) + qualified:
        name = short.get(name, name)
        if name not in free:
            free.append(name)
    return tuple(free)


def _cmd_fit(args) -> int:
    from ..physics.parameters import save_yaml
    from ..workbench.data import groups_from
    from ..workbench.freqfit import fit_parameters

    from ..workbench.discovery import acts_on_transfer, effects_to_fit, next_command

    effects = effects_from_args(args)
    material = material_from_args(args)
    data = load_data(args)
    groups = groups_from(data)
    for path in params_file_paths(Path(args.save), groups) if args.save else ():
        check_free(path, args.overwrite, '--save')          # before the fit
    fit_eff = effects_to_fit(args.effects)
    free = _free_names(args, fit_eff)
    for e in fit_eff:
        if not acts_on_transfer(e):
            say(f'{e}: kept at its catalog values (a frequency-response fit cannot see it; '
                'diagnose fits it in the time domain)')
    say(f"fitting {', '.join(free)} to {sum(len(g.points) for g in groups)} frequency point(s) "
        f'of {len(groups)} sample(s): '
        + '; '.join(f"{g.name}: {', '.join(f'{p.frequency_hz:.4g}' for p in g.points)} Hz"
                    for g in groups))
    with Progress('fit'):
        res = fit_parameters(groups, free, material, effects)
    print(res.summary())
    print(
        '  chi2/dof about 1: the model explains the points within their error bars (>> 1: it does '
        'not); 95% CI from the curvature of chi2; sd(ln) = relative sd of a parameter combination'
    )
    write_json(args.json, {'free': list(res.free), 'estimates': res.estimates, 'ci95': res.ci95,
                           'correlation': res.correlation, 'chi2': res.chi2, 'dof': res.dof,
                           'identifiability': res.identifiability,
                           'named_combinations': res.named_combinations,
                           'not_identifiable': res.not_identifiable, 'success': res.success,
                           'p_value': res.p_value, 'adequate': res.adequate,
                           'material': res.material.to_dict(),
                           'model': SensorModel(groups[0].geometry, res.material,
                                                res.effects).describe()})
    if args.save_model:
        from ..physics.modelfile import save_model

        save_model(args.save_model, effects=res.effects, material=res.material,
                   tool='ipmc-model fit', data_files=data_files(data), ci95=res.ci95,
                   error={'chi2': res.chi2, 'dof': res.dof, 'p_value': res.p_value},
                   extra={'adequate': bool(res.adequate)})
        print_saved(args.save_model)
        if not res.adequate:
            print(f'  saved although the fit found it inadequate (chi2/dof = '
                  f'{res.reduced_chi2:.3g}, p = {res.p_value:.2g}): the best this model does on '
                  'these records, not a calibrated sensor; the file says so wherever it is '
                  'loaded, and diagnose finds what it misses')
    if args.save:
        for path in write_params_files(Path(args.save), groups, data, res):
            print(f'saved node parameters (the fitted model; key /**/ipmc_estimator, geometry '
                  f'included) to {path}')
    if args.save_material:
        save_yaml(args.save_material, res.material)
        print(f'saved fitted material to {args.save_material}')
    print(with_recording_flag(
        'next: ' + (next_command('compare', args.data, args.save_model)
                    if res.adequate or args.save_model
                    else next_command('diagnose', args.data, None, f'--model {args.model}')),
        args.save_model))
    rd = report_dir(args.report)
    if rd:
        from ..workbench.report import fit_report

        pts = {g.name: g.points for g in groups}
        models = {}
        for g in groups:
            known = {k: v for k, v in g.known.items() if k not in free}
            models[g.name] = {
                'fitted': SensorModel(
                    g.geometry, res.material.replace(**known), effects
                ).frequency_response,
                'start': SensorModel(g.geometry, material, effects).frequency_response,
            }
        print(f'report: {fit_report(rd, res, pts, models, _model_text(data, material, effects))}')
    return 0


def _cmd_compare(args) -> int:
    from ..workbench.compare import compare_records

    recs = _records(args)
    model_text = recs[0].model.describe()
    with Progress(f'comparing {model_text} with {len(recs)} record(s)') as prog:
        position = {id(rec): k for k, rec in enumerate(recs, start=1)}

        def model_for(rec):
            prog.step(f"record {position.get(id(rec), '?')}/{len(recs)}")
            return rec.model

        cmp = compare_records(recs, model_for, settle_s=args.settle)
    print(cmp.summary())
    print('  fit % = 100 (1 - error); error = ||y - ŷ|| / ||y - mean y|| of the current; '
          'noise = error of a perfect model; dMag/dPhase = measured/model at f0 (at each tone of '
          'a multi-sine record) +- 1 sd')
    write_json(args.json, {**cmp.to_json(), 'model': model_text})
    rd = report_dir(args.report)
    if rd:
        from ..workbench.report import compare_report

        pts, curves = {}, {}
        for r, rec in zip(cmp.records, recs):
            pts.setdefault(r.sample, []).extend(tone.point for tone in r.tones)
            curves.setdefault(r.sample, {'model': rec.model.frequency_response})
        print(f'report: {compare_report(rd, cmp, model_text, pts, curves)}')
    return 0


def _cmd_track(args) -> int:
    from ..workbench.data import material_for
    from ..workbench.track import track_parameter

    effects = effects_from_args(args)
    material = material_from_args(args)
    free = param_names(args.free)
    tracks, rows = {}, []
    for ts in load_data(args):
        with Progress(f"tracking {', '.join(free)} in {args.window:g} s windows of {ts.path}"):
            tr = track_parameter(
                ts.time_s,
                ts.deflection_m,
                ts.current_a,
                ts.geometry,
                material_for(ts, material),
                free,
                effects,
                window_s=args.window,
                step_s=args.step,
                source=ts.path,
                model=(
                    SensorModel(ts.geometry, material_for(ts, material), effects)
                    if getattr(args, 'model_file', None)
                    else None
                ),
            )
        print(f'{ts.path}: (value [95 % confidence interval])')
        print(f"{'t (s)':>9} {'f0 (Hz)':>8} " + ' '.join(f'{n:>36}' for n in free))
        for p in tr:
            cells = ' '.join(_interval_cell(p.estimates[n], *p.ci95[n]) for n in free)
            model_cells = ('  model: ' + ', '.join(f'{v:.4g}' for v in p.model_estimates.values())
                           if p.model_estimates else '')
            print(f'{p.time_s:9.1f} {p.frequency_hz:8.3f} {cells}{model_cells}')
        tracks[ts.path] = tr
        rows.append({'source': ts.path, 'track': [p.__dict__ for p in tr]})
    write_json(args.json, rows)
    rd = report_dir(args.report)
    if rd:
        from ..workbench.report import track_report

        print(f'report: {track_report(rd, tracks, free[0])}')
    return 0


def _interval_cell(value: float, lo: float, hi: float) -> str:
    from ..workbench.freqfit import interval_digits

    d = interval_digits(value, lo, hi)
    return f'{value:>11.{d}g} [{lo:.{d}g}, {hi:.{d}g}]'.rjust(36)


def _cmd_diagnose(args) -> int:
    from ..physics.effects import EFFECTS
    from ..workbench.diagnose import diagnose
    from ..workbench.discovery import diagnosis_next_command, effects_to_fit, priors_from_headers

    recs, data = _records(args, with_data=True)
    free = param_names(args.free)
    mains = parse_mains(args.mains_hz)       # the node's values: auto, 0, 50, 60
    cands = [c.strip() for c in args.candidates.split(',')] if args.candidates else None
    for c in cands or []:
        if c not in EFFECTS:
            raise ParameterError(f"--candidates: unknown effect '{c}' (see: ipmc-model effects)")
    names = [n for n in (cands or EFFECTS) if not recs[0].model.has_effect(n)]
    with Progress(f'diagnosing {recs[0].model.describe()} on {len(recs)} record(s), '
                  f'{len(names)} candidate(s)') as prog:
        diag = diagnose(recs, free_material=free, candidates=cands, progress=prog.step,
                        settle_s=args.settle, fit_effects=effects_to_fit(args.effects),
                        max_effects=args.max_effects, mains=mains or None,
                        priors=priors_from_headers(data))
    print(diag.summary())
    print('  error = held-out ||y - ŷ|| / ||y - mean y||; x better = baseline error / error; '
          'dBIC = BIC change vs the baseline (< -20: very strong evidence for the effect)')
    if args.save_model:
        from ..physics.modelfile import save_model

        final = diag.final or diag.baseline
        save_model(args.save_model, diag.final_model, tool='ipmc-model diagnose',
                   data_files=data_files(data),
                   error={'held_out': final.error, 'noise_floor': diag.noise_floor},
                   extra={'missing_effects': diag.missing_effects, 'explained': diag.explained,
                          'mains_lines': [{'frequency_hz': d['frequency_hz'],
                                           'level': d['level']} for d in diag.interference]})
        print_saved(args.save_model)
    plugin = _save_plugin(args, diag, data)
    line = diagnosis_next_command(diag, args.data, args.save_model, args.model, plugin)
    print(with_recording_flag(line, args.save_model))
    write_json(args.json, diag.to_json())
    rd = report_dir(args.report)
    if rd:
        from ..workbench.report import diagnose_report

        print(f'report: {diagnose_report(rd, diag)}')
    return 0


def _save_plugin(args, diag, data) -> str | None:
    """Write the correction C(s) as a plugin (``--save-plugin``); its path, or None."""
    if not args.save_plugin:
        return None
    if diag.correction is None:
        say(f'--save-plugin {args.save_plugin}: no correction C(s) was fitted (the named '
            'effects explain the data, or none helps): nothing written')
        return None
    from ..workbench.discovery.plugin import write_plugin

    name = write_plugin(args.save_plugin, diag.correction, data_files=data_files(data))
    print(f"saved the correction C(s) as effect '{name}' to {args.save_plugin}")
    return args.save_plugin


def _add_settle(p) -> None:
    p.add_argument(
        '--settle',
        type=nonnegative,
        default=0.5,
        metavar='S',
        help='seconds left out at each record start (they depend on motion before it), s',
    )


def add_parsers(sub, formatter) -> None:
    p = sub.add_parser(
        'fit',
        formatter_class=formatter,
        help='identify material parameters from the frequency response (paper 5.2)',
        description='Fit the --free parameters to the measured frequency response '
        '(time series through the response at the excitation fundamental, or at each '
        'tone of a multi-sine drive).',
    )
    add_model_args(p)
    add_data_args(p)
    p.add_argument('--free', metavar='LIST', default='alpha0,d,kappa_e', help=FREE_HELP)
    p.add_argument(
        '--save',
        metavar='FILE',
        help='write a ROS 2 params file for the nodes (key /**/ipmc_estimator, with the '
        "data's geometry; one file per sample: FILE_<sample>.yaml when several)",
    )
    p.add_argument(
        '--save-material', metavar='FILE', help='write the fitted material as workbench YAML'
    )
    p.add_argument(
        '--save-model',
        metavar='FILE',
        help='write the whole fitted model (effects with values, material, provenance) '
        "as ipmc-model/1 YAML, read back by --model-file and the nodes' model_file",
    )
    add_output_args(p)
    p.set_defaults(func=_cmd_fit)

    p = sub.add_parser(
        'compare',
        formatter_class=formatter,
        help='fixed model vs measurements: fit %%, errors, where it fails',
        description='Predict the current of each record from its deflection and compare '
        '(MATLAB compare/resid style).',
    )
    add_model_args(p)
    add_data_args(p)
    _add_settle(p)
    add_output_args(p)
    p.set_defaults(func=_cmd_compare)

    p = sub.add_parser('track', formatter_class=formatter,
                       help='refit parameter(s) in consecutive windows (paper 5.4)')
    add_model_args(p)
    add_data_args(p)
    p.add_argument(
        '--free', metavar='LIST', default='d', help=FREE_HELP + '; refitted in every window'
    )
    renamed_flag(p, '--param', '--free')
    p.add_argument('--window', type=positive, default=60.0, metavar='S', help='window length, s')
    p.add_argument('--step', type=positive, default=None, metavar='S',
                   help='window step, s (default: the window length)')
    add_output_args(p)
    p.set_defaults(func=_cmd_track)

    p = sub.add_parser('diagnose', formatter_class=formatter,
                       help='rank the physical effects missing from the model (held-out error)')
    add_model_args(p)
    renamed_flag(p, '--base', '--model')
    add_data_args(p)
    p.add_argument(
        '--free',
        metavar='LIST',
        default='alpha0,d,kappa_e',
        help=FREE_HELP + '; refitted with each model',
    )
    p.add_argument('--candidates', metavar='LIST',
                   help='restrict to these effects, comma list (default: the whole catalog)')
    p.add_argument('--max-effects', type=nonnegative_int, default=3, metavar='N',
                   help='at most this many effects added by the stepwise search')
    p.add_argument('--mains-hz', default='auto', metavar='auto|0|50|60',
                   help='mains lines to find and remove from the current before fitting: auto '
                        'looks for both families, 50 or 60 for that one, 0 for none (the '
                        'estimator node parameter mains_hz)')
    p.add_argument('--save-model', metavar='FILE',
                   help='write the final model (effects with fitted values, material, provenance) '
                        'as ipmc-model/1 YAML')
    p.add_argument('--save-plugin', metavar='FILE',
                   help='write the correction C(s) fitted outside the catalog as an effect '
                        'plugin (Python), to load with --plugin FILE')
    _add_settle(p)
    add_output_args(p)
    p.set_defaults(func=_cmd_diagnose)

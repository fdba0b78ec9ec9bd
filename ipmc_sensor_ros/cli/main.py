"""``ipmc-model``: the model workbench on the command line.

Verbs: ``simulate`` (write synthetic measurement files), ``fit`` (identify
parameters from frequency response), ``compare`` (fixed model vs measurements,
where it fails), ``track`` (parameter over time), ``diagnose`` (which physical
effect is missing), ``reduce`` (error table of reduced models), ``eq55``
(the paper's eq. 55 and its unstable inverse), ``effects`` (the catalog),
``figures`` (paper Figs. 4-6 on synthetic data), ``example`` (the README's
worked example).  Each verb prints a table;
most take ``--json FILE`` and ``--report DIR`` (PNG plots and index.html).
"""
from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np

from ..physics.effects import load_plugin
from ..physics.model import SensorModel, parse_effects, parse_model_name
from ..physics.parameters import (PAPER_PARAMETERS, PAPER_SAMPLES, Geometry, MaterialParameters,
                                 ParameterError, load_yaml)

__all__ = ["main", "build_parser"]

SYMBOL_TO_NAME = {"T": "temperature_k", "Y": "youngs_modulus_pa", "r0": "surface_resistance_ohm",
                  "d": "diffusivity_m2_per_s", "C-": "anion_concentration_mol_per_m3",
                  "kappa_e": "permittivity_f_per_m", "alpha0": "charge_stress_coupling_j_per_c"}
MATERIAL_KEYS = tuple(MaterialParameters.__dataclass_fields__)


def _say(msg: str) -> None:
    print(f"... {msg}", file=sys.stderr, flush=True)


def _param_names(text: str) -> tuple[str, ...]:
    out = []
    for item in filter(None, (x.strip() for x in text.split(","))):
        name = SYMBOL_TO_NAME.get(item, item)
        if name not in MATERIAL_KEYS:
            raise ParameterError(f"unknown parameter '{item}'; use {sorted(SYMBOL_TO_NAME)} or "
                                 f"full names {list(MATERIAL_KEYS)}")
        out.append(name)
    return tuple(out)


def _material_from_args(args) -> MaterialParameters:
    material = PAPER_PARAMETERS
    if getattr(args, "params", None):
        material = load_material(args.params)
    for item in getattr(args, "set", None) or []:
        if "=" not in item:
            raise ParameterError(f"--set expects name=value, got {item!r}")
        k, v = item.split("=", 1)
        material = material.replace(**{_param_names(k)[0]: float(v)})
    return material


def load_material(path) -> MaterialParameters:
    """Material from a workbench YAML (``material:``) or a ROS 2 params file (ros__parameters)."""
    from ..physics.parameters import read_yaml

    data = read_yaml(path, "parameters file") or {}
    if isinstance(data, dict) and any(isinstance(v, dict) and "ros__parameters" in v
                                      for v in data.values()):
        params = next(v["ros__parameters"] for v in data.values()
                      if isinstance(v, dict) and "ros__parameters" in v)
        return MaterialParameters.from_dict({k: v for k, v in params.items() if k in MATERIAL_KEYS},
                                            where=str(path))
    return load_yaml(path)[0]


def _effects_from_args(args, base_key: str = "model") -> tuple:
    for plugin in getattr(args, "plugin", None) or []:
        names = load_plugin(plugin)
        _say(f"plugin {plugin}: effects {', '.join(names)}")
    _, base = parse_model_name(getattr(args, base_key))
    extra = parse_effects(getattr(args, "effects", "") or "")
    return tuple(parse_effects(base)) + tuple(e for e in extra if e.name not in base)


def _load_data(args):
    from ..workbench.io import read_any, read_bag

    geometry = None
    if getattr(args, "geometry", None):
        length, width, thickness = (float(v) for v in args.geometry.split(","))
        geometry = Geometry(length, width, thickness, getattr(args, "sample", "") or "")
    out = []
    for path in args.data:
        p = Path(path)
        if p.is_dir() and not (p / "metadata.yaml").exists():
            files = sorted(x for x in p.iterdir() if x.suffix in (".csv", ".txt"))
            if not files:
                raise ParameterError(f"{p}: directory holds no .csv files and is not a bag")
            out.extend(read_any(f) for f in files)
        elif p.is_dir() or p.suffix in (".mcap", ".db3"):
            out.append(read_bag(p, args.current_topic, args.deflection_topic, geometry))
        else:
            out.append(read_any(p))
    if not out:
        raise ParameterError("no data given")
    return out


def _add_model_args(p: argparse.ArgumentParser, base_flag: str = "--model") -> None:
    p.add_argument(base_flag, dest="model", default="h2",
                   help="base model: h1 (eq. 31) or h2 = h1 + surface_resistance (eq. 45)")
    p.add_argument("--effects", default="",
                   help="extra effects, e.g. 'time_delay' or 'time_delay(delay_s=0.002),nonlinearity'")
    p.add_argument("--plugin", action="append", help="Python file defining more effects (repeatable)")
    p.add_argument("--params", help="material YAML ('material:') or a ROS 2 params file of the nodes")
    p.add_argument("--set", action="append", metavar="NAME=VALUE",
                   help="override a material parameter, e.g. --set d=3e-11 (repeatable)")


def _add_data_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("data", nargs="+", help="ipmc-timeseries/1 or ipmc-frf/1 files, directories of "
                                           "them, or rosbag2 bags")
    p.add_argument("--current-topic", default="current", help="bags: current topic")
    p.add_argument("--deflection-topic", default="deflection_truth", help="bags: deflection topic")
    p.add_argument("--geometry", help="bags without ipmc.yaml sidecar: 'L,W,T' in metres")


def _add_output_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", help="write results as JSON to this file")
    p.add_argument("--report", help="write PNG plots and index.html into this directory")


def _write_json(path, obj) -> None:
    if path:
        Path(path).write_text(json.dumps(obj, indent=2, default=_json_default))


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, complex):
        return [o.real, o.imag]
    return str(o)


def _report_dir(path) -> Path | None:
    if not path:
        return None
    d = Path(path)
    d.mkdir(parents=True, exist_ok=True)
    return d


# ---------------------------------------------------------------------------
def _cmd_simulate(args) -> int:
    from ..workbench.freqresp import fundamental_response
    from ..workbench.io import FrequencyResponseData, TimeSeries, write_bag, write_frf, write_timeseries
    from ..workbench.scenarios import crank_slider_campaign

    effects = _effects_from_args(args)
    material = _material_from_args(args)
    samples = [s.strip() for s in args.samples.split(",") if s.strip()]
    for s in samples:
        if s not in PAPER_SAMPLES:
            raise ParameterError(f"--samples: unknown sample '{s}'; paper samples: {sorted(PAPER_SAMPLES)}")
    freqs = _parse_frequencies(args.frequencies)
    if args.bag:
        args.out, args.format = args.bag, "bag"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    recs = crank_slider_campaign(effects, samples=samples, frequencies_hz=freqs,
                                 duration_s=args.duration, sample_rate_hz=args.sample_rate,
                                 crank_radius_m=args.crank_radius, material=material,
                                 noise_rel=args.noise_rel, seed=args.seed, fidelity=args.fidelity,
                                 beam_model=args.beam_model)
    written = []
    points: dict = {}
    for r in recs:
        name = r.path.replace(".", "p")
        ts = TimeSeries(path="", sample=r.sample, geometry=r.model.geometry, known={},
                        sample_rate_hz=args.sample_rate, time_s=r.time_s, current_a=r.current_a,
                        deflection_m=r.deflection_m)
        if args.format == "timeseries":
            written.append(out / f"{name}.csv")
            write_timeseries(written[-1], ts)
        elif args.format == "bag":
            written.append(out / name)
            write_bag(written[-1], ts, storage=args.storage)
        else:
            points.setdefault(r.sample, []).append(
                fundamental_response(r.time_s, r.deflection_m, r.current_a))
    for sample, pts in points.items():
        written.append(out / f"{sample}.frf.csv")
        write_frf(written[-1], FrequencyResponseData(
            path="", sample=sample, geometry=PAPER_SAMPLES[sample], known={},
            frequency_hz=[p.frequency_hz for p in pts], gain_a_per_m=[p.gain_a_per_m for p in pts],
            phase_deg=[p.phase_deg for p in pts],
            gain_std_a_per_m=[p.gain_a_per_m * p.sd_log_mag for p in pts],
            phase_std_deg=[np.degrees(p.sd_phase_rad) for p in pts]))
    model_text = SensorModel(PAPER_SAMPLES[samples[0]], material, effects).describe()
    print(f"wrote {len(written)} {args.format} file(s) to {out} (model {model_text}, "
          f"{len(freqs)} frequencies {freqs[0]:g}-{freqs[-1]:g} Hz, noise {args.noise_rel:g} of RMS, "
          f"seed {args.seed})")
    _write_json(args.json, {"files": [str(p) for p in written], "model": model_text})
    return 0


def _parse_frequencies(text: str) -> list[float]:
    if ":" in text:
        lo, hi, n = text.split(":")
        return [float(x) for x in np.geomspace(float(lo), float(hi), int(n))]
    return [float(x) for x in text.split(",") if x.strip()]


def _cmd_fit(args) -> int:
    from ..physics.parameters import save_yaml
    from ..workbench.data import groups_from
    from ..workbench.fit import fit_parameters

    effects = _effects_from_args(args)
    material = _material_from_args(args)
    data = _load_data(args)
    groups = groups_from(data)
    free = _param_names(args.free)
    _say(f"fitting {', '.join(free)} to {sum(len(g.points) for g in groups)} frequency points "
         f"of {len(groups)} sample(s)")
    res = fit_parameters(groups, free, material, effects)
    print(res.summary())
    out = {"free": list(res.free), "estimates": res.estimates, "ci95": res.ci95,
           "correlation": res.correlation, "chi2": res.chi2, "dof": res.dof,
           "identifiability": res.identifiability, "named_combinations": res.named_combinations,
           "not_identifiable": res.not_identifiable, "success": res.success,
           "material": res.material.to_dict()}
    _write_json(args.json, out)
    if args.save:
        _save_node_params(args.save, res.material, args.model, effects[1:] if args.model == "h2" else effects)
        print(f"saved fitted parameters for the nodes to {args.save}")
    if args.save_material:
        save_yaml(args.save_material, res.material)
    rd = _report_dir(args.report)
    if rd:
        from ..workbench.report import plot_bode, write_report

        pts = {g.name: g.points for g in groups}
        models = {}
        for g in groups:
            fitted = SensorModel(g.geometry, res.material.replace(**{k: v for k, v in g.known.items()
                                                                     if k not in free}), effects)
            start = SensorModel(g.geometry, material, effects)
            models[g.name] = {"fitted": fitted.frequency_response, "start": start.frequency_response}
        img = plot_bode(rd, "bode", pts, models, "measured (2 sd error bars) vs model")
        write_report(rd, "ipmc-model fit", [("Fit", res.summary(), [img])])
        print(f"report: {rd / 'index.html'}")
    return 0


def _save_node_params(path, material: MaterialParameters, base: str, extra_effects) -> None:
    import yaml

    from ..physics.model import format_effect

    params = {k: v for k, v in material.to_dict().items()
              if k not in ("faraday_constant_c_per_mol", "gas_constant_j_per_mol_k",
                           "one_minus_anion_volume_fraction")}
    params["model"] = base
    params["effects"] = [format_effect(e) for e in extra_effects] or [""]
    doc = {"ipmc_estimator": {"ros__parameters": params},
           "ipmc_simulator": {"ros__parameters": copy.deepcopy(params)}}
    Path(path).write_text(yaml.safe_dump(doc, sort_keys=False))


def _cmd_compare(args) -> int:
    from ..workbench.compare import compare_records
    from ..workbench.data import records_from

    effects = _effects_from_args(args)
    material = _material_from_args(args)
    data = _load_data(args)
    recs = records_from(data, material, effects)
    _say(f"comparing {SensorModel(recs[0].model.geometry, material, effects).describe()} with "
         f"{len(recs)} record(s)")
    cmp = compare_records(recs, lambda r: r.model, settle_s=args.settle)
    print(cmp.summary())
    _write_json(args.json, {**cmp.to_json(), "model": recs[0].model.describe()})
    rd = _report_dir(args.report)
    if rd:
        from ..workbench.report import (plot_bode, plot_failure_map, plot_residuals, plot_time_overlay,
                                       write_report)

        pts, curves = {}, {}
        for r, rec in zip(cmp.records, recs):
            if r.point is not None:
                pts.setdefault(r.sample, []).append(r.point)
            curves.setdefault(r.sample, {"model": rec.model.frequency_response})
        imgs = [plot_bode(rd, "bode", pts, curves, "measured vs model"),
                plot_time_overlay(rd, "time", cmp.records),
                plot_residuals(rd, "residuals", cmp.records),
                plot_failure_map(rd, "failure_map", cmp.records)]
        write_report(rd, "ipmc-model compare", [("Comparison", cmp.summary(), imgs),
                                                ("Where it fails", json.dumps(cmp.where, indent=1), [])])
        print(f"report: {rd / 'index.html'}")
    return 0


def _cmd_track(args) -> int:
    from ..workbench.track import track_parameter

    effects = _effects_from_args(args)
    material = _material_from_args(args)
    data = _load_data(args)
    free = _param_names(args.param)
    rows = []
    for ts in data:
        from ..workbench.data import material_for

        _say(f"tracking {', '.join(free)} in {args.window:g} s windows of {ts.path}")
        tr = track_parameter(ts.time_s, ts.deflection_m, ts.current_a, ts.geometry,
                             material_for(ts, material), free, effects,
                             window_s=args.window, step_s=args.step, source=ts.path)
        print(f"{ts.path}:")
        print(f"{'t (s)':>9} {'f0 (Hz)':>8} " + " ".join(f"{n:>36}" for n in free))
        for p in tr:
            cells = " ".join(f"{p.estimates[n]:>11.4g} [{p.ci95[n][0]:.4g}, {p.ci95[n][1]:.4g}]".rjust(36)
                             for n in free)
            print(f"{p.time_s:9.1f} {p.frequency_hz:8.3f} {cells}")
        rows.append({"source": ts.path, "track": [p.__dict__ for p in tr]})
        rd = _report_dir(args.report)
        if rd:
            from ..workbench.report import plot_track, write_report

            img = plot_track(rd, f"track_{Path(ts.path).stem}", tr, free[0])
            write_report(rd, "ipmc-model track", [(ts.path, "", [img])])
    _write_json(args.json, rows)
    return 0


def _cmd_diagnose(args) -> int:
    from ..physics.effects import EFFECTS
    from ..workbench.data import records_from
    from ..workbench.diagnose import diagnose

    effects = _effects_from_args(args)
    material = _material_from_args(args)
    data = _load_data(args)
    recs = records_from(data, material, effects)
    free = _param_names(args.free)
    cands = [c.strip() for c in args.candidates.split(",")] if args.candidates else None
    for c in cands or []:
        if c not in EFFECTS:
            raise ParameterError(f"--candidates: unknown effect '{c}'")
    _say(f"diagnosing {recs[0].model.describe()} on {len(recs)} record(s); candidates: "
         f"{', '.join(n for n in (cands or EFFECTS) if not recs[0].model.has_effect(n))}")
    diag = diagnose(recs, free_material=free, candidates=cands, progress=_say)
    print(diag.summary())
    _write_json(args.json, diag.to_json())
    rd = _report_dir(args.report)
    if rd:
        _diagnose_report(rd, diag)
        print(f"report: {rd / 'index.html'}")
    return 0


def _diagnose_report(rd: Path, diag) -> None:
    from types import SimpleNamespace

    from ..workbench.modelfit import predict
    from ..workbench.report import plot_error_bars, plot_time_overlay, write_report

    labels = ["baseline"] + [c.effect for c in diag.candidates]
    errors = [diag.baseline.error] + [c.error for c in diag.candidates]
    imgs = [plot_error_bars(rd, "errors", labels, errors, diag.noise_floor,
                            "held-out error: baseline and baseline + each effect")]
    sections = [("Diagnosis", diag.summary(), imgs)]
    for rank, cand in enumerate(diag.candidates[:3], 1):
        recs = []
        for p, mb, mc in zip(diag.prepared[:3], diag.baseline.fit.models, cand.fit.models):
            yb = predict(p, mb)[p.keep]
            pc = predict(p, mc)[p.keep]
            recs.append(SimpleNamespace(source=p.rec.path + " (before: baseline)", time_s=p.t[p.keep],
                                        measured_a=p.y[p.keep], predicted_a=yb,
                                        fit_percent=100 * (1 - np.linalg.norm(p.y[p.keep] - yb)
                                                           / np.linalg.norm(p.y[p.keep] - p.y[p.keep].mean()))))
            recs.append(SimpleNamespace(source=p.rec.path + f" (after: + {cand.effect})", time_s=p.t[p.keep],
                                        measured_a=p.y[p.keep], predicted_a=pc,
                                        fit_percent=100 * (1 - np.linalg.norm(p.y[p.keep] - pc)
                                                           / np.linalg.norm(p.y[p.keep] - p.y[p.keep].mean()))))
        img = plot_time_overlay(rd, f"candidate_{rank}_{cand.effect}", recs, max_records=6, span_s=1.0)
        sections.append((f"#{rank}: + {cand.effect} (held-out error {cand.error:.4f})",
                         "residual before (baseline) and after adding the effect", [img]))
    write_report(rd, "ipmc-model diagnose", sections)


def _cmd_estimate(args) -> int:
    """Offline estimation with the node's code path and parameters file."""
    from ..interface import specs as config
    from ..estimation.deflection import estimate_record
    from ..estimation.inverse import validate_block
    from ..workbench.io import TimeSeries, read_any, read_bag, write_bag, write_timeseries

    values = config.load_params_file(args.params) if args.params else \
        config.defaults(config.ESTIMATOR_SPECS)
    src = Path(args.input)
    if src.is_dir() or src.suffix in (".mcap", ".db3"):
        geometry = None
        if args.geometry:
            length, width, thickness = (float(v) for v in args.geometry.split(","))
            geometry = Geometry(length, width, thickness)
        data = read_bag(src, args.current_topic, args.deflection_topic, geometry)
    else:
        data = read_any(src)
    if not isinstance(data, TimeSeries):
        raise ParameterError(f"{src}: a time series is needed (this is a frequency-response file)")
    if not args.params:  # geometry and rate from the data when no params file says otherwise
        values.update({"length_m": data.geometry.length_m, "width_m": data.geometry.width_m,
                       "thickness_m": data.geometry.thickness_m,
                       "sample_rate_hz": float(data.sample_rate_hz)})
    fs = float(values["sample_rate_hz"])
    if abs(data.sample_rate_hz / fs - 1) > 0.01:
        raise ParameterError(f"{src}: sample rate {data.sample_rate_hz:g} Hz does not match the "
                             f"parameter sample_rate_hz = {fs:g} Hz")
    current = validate_block(data.current_a, max_samples=max(data.current_a.size, 1))
    estimator = config.build_estimator(values)
    _say(f"estimating {data.current_a.size} samples of {src} with {estimator.model.describe()} "
         f"(order {estimator.reduction_order}, fs {fs:g} Hz, leak {values['leak_corner_hz']:g} Hz)")
    t_out, w, resets = estimate_record(estimator, data.time_s, current,
                                       max_gap_s=float(values["max_gap_s"]))
    out = Path(args.out)
    as_bag = args.format == "bag" or (args.format is None and (out.suffix in (".mcap", ".db3")
                                                               or out.suffix == ""))
    result = TimeSeries(path="", sample=data.sample, geometry=data.geometry, known=data.known,
                        sample_rate_hz=data.sample_rate_hz, time_s=t_out, current_a=current,
                        deflection_m=w)
    if as_bag:
        storage = "mcap" if (args.storage == "mcap" or out.suffix == ".mcap") else "sqlite3"
        out = out.with_suffix("") if out.suffix in (".mcap", ".db3") else out
        if t_out.size and not (0.0 <= float(np.min(t_out)) and float(np.max(t_out)) < 2.0 ** 31):
            raise ParameterError(f"{src}: sample times {float(np.min(t_out)):.6g}..{float(np.max(t_out)):.6g} s "
                                 "do not fit a ROS time stamp (0 .. 2^31 s): write a time series "
                                 "(--format timeseries) or shift the time origin")
        existed = out.exists()
        try:
            write_bag(out, result, storage=storage, current_topic=args.current_topic,
                      deflection_topic=args.estimate_topic)
        except BaseException:
            if not existed:                              # never leave a half-written bag
                import shutil
                shutil.rmtree(out, ignore_errors=True)
            raise
    else:
        write_timeseries(out, result)
    msg = f"wrote {t_out.size} estimates to {out} ({'bag' if as_bag else 'ipmc-timeseries/1'})"
    if resets:
        msg += f"; {resets} filter reset(s) at time gaps > {values['max_gap_s']} s or backward jumps"
    if data.deflection_m is not None and data.deflection_alignment is not None and not resets:
        truth = data.deflection_m
        sel = data.time_s >= data.time_s[0] + 5.0 / (2 * np.pi * float(values["leak_corner_hz"]))
        if sel.sum() > 10 and not estimator.delay_s:
            err = np.sqrt(np.mean((w[sel] - truth[sel]) ** 2)) / np.sqrt(np.mean(truth[sel] ** 2))
            msg += f"; NRMSE against the recorded deflection after the leak transient: {err:.4f}"
    print(msg)
    _write_json(args.json, {"samples": int(t_out.size), "resets": resets, "out": str(out)})
    return 0


def _cmd_reduce(args) -> int:
    from ..lti.reduction import reduction_error_table

    effects = _effects_from_args(args)
    material = _material_from_args(args)
    if args.geometry:
        length, width, thickness = (float(v) for v in args.geometry.split(","))
        geoms = {"custom": Geometry(length, width, thickness, "custom")}
    else:
        names = (args.samples or "big,slim,short").split(",")
        unknown = [n for n in names if n not in PAPER_SAMPLES]
        if unknown:
            raise ParameterError(f"--samples: unknown sample(s) {unknown}; paper samples are "
                                 f"{sorted(PAPER_SAMPLES)} (or use --geometry L,W,T in metres)")
        geoms = {n: PAPER_SAMPLES[n] for n in names}
    models = {n: SensorModel(g, material, effects) for n, g in geoms.items()}
    orders = _parse_orders(args.orders)
    rows = reduction_error_table(models, orders, (args.band[0], args.band[1]))
    print(f"Stable minimum-phase reductions vs {next(iter(models.values())).describe()} over "
          f"{args.band[0]:g}-{args.band[1]:g} Hz (worst errors)")
    print(f"{'sample':<8} {'order':>5} {'|mag| dB':>10} {'|phase| deg':>12}  target 0.1 dB / 1 deg")
    for r in rows:
        ok = r["max_mag_error_db"] <= 0.1 and r["max_phase_error_deg"] <= 1.0
        print(f"{r['sample']:<8} {r['order']:>5} {r['max_mag_error_db']:>10.4f} "
              f"{r['max_phase_error_deg']:>12.4f}  {'ok' if ok else '-'}")
    _write_json(args.json, {"band_hz": list(args.band), "model": args.model, "rows": rows})
    return 0


def _parse_orders(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        if "-" in part:
            lo, hi = part.split("-", 1)
            out.extend(range(int(lo), int(hi) + 1))
        else:
            out.append(int(part))
    return out


def _cmd_eq55(args) -> int:
    from ..lti.reduction import eq55_poles_zeros

    material = _material_from_args(args)
    names = (args.samples or "big,slim,short").split(",")
    for name in names:
        if name not in PAPER_SAMPLES:
            raise ParameterError(f"--samples: unknown sample '{name}'")
        rep = eq55_poles_zeros(SensorModel.named(args.model, PAPER_SAMPLES[name], material))
        print(f"{name}: eq. 55 zeros (rad/s): {', '.join(f'{z:.4g}' for z in rep['zeros'])}")
        print(f"{name}: eq. 55 poles (rad/s): {', '.join(f'{p:.4g}' for p in rep['poles'])}")
        verdict = "stable" if rep["inverse_stable"] else \
            f"UNSTABLE (right-half-plane zero(s) at {', '.join(f'{z.real:.4g}' for z in rep['rhp_zeros'])} rad/s)"
        print(f"{name}: literal inverse of eq. 55 is {verdict}")
    return 0


def _cmd_effects(args) -> int:
    from ..physics.effects import EFFECTS, catalog_markdown

    for plugin in args.plugin or []:
        load_plugin(plugin)
    if args.markdown:
        print(catalog_markdown())
        return 0
    for eff in EFFECTS.values():
        params = ", ".join(f"{p.name} [{p.unit}] ({p.typical[0]:g}..{p.typical[1]:g})"
                           for p in eff.parameters) or "-"
        print(f"{eff.name:<22} {'LTI' if eff.lti else 'time-domain':<12} {params}")
        print(f"{'':<22} {eff.summary}")
    return 0


def _cmd_example(args) -> int:
    """The README's worked example: H1 on a two-sample sweep, see it fail, diagnose, fix."""
    import tempfile

    work = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="ipmc-example-"))
    data = work / "sweep"
    steps = [
        ("1. measure (simulated): slim + short, crank-slider 1-20 Hz, truth = H2, 1 % noise",
         ["simulate", "--out", str(data), "--model", "h2", "--samples", "slim,short", "--seed", "1"]),
        ("2. compare the paper's H1 with the data",
         ["compare", str(data), "--model", "h1", "--json", str(work / "h1.json")]),
        ("3. diagnose: which effect is H1 missing?",
         ["diagnose", str(data), "--base", "h1", "--json", str(work / "diagnosis.json")]),
    ]
    for title, argv in steps:
        print(f"\n=== {title}\n$ ipmc-model {' '.join(argv)}", flush=True)
        rc = main(argv)
        if rc:
            return rc
    verdict = json.loads((work / "diagnosis.json").read_text())["verdict"]
    missing = verdict["missing_effect"]
    if not missing:
        print("no missing effect found")
        return 1
    print(f"\n=== 4. add it: compare H1 + {missing}\n$ ipmc-model compare {data} --model h1 "
          f"--effects {missing}", flush=True)
    rc = main(["compare", str(data), "--model", "h1", "--effects", missing,
               "--json", str(work / "fixed.json")])
    before = json.loads((work / "h1.json").read_text())
    after = json.loads((work / "fixed.json").read_text())
    print(f"\nerror of the predicted current: H1 {before['error']:.4f} (fit {before['fit_percent']:.1f} %)"
          f" -> H1 + {missing} {after['error']:.4f} (fit {after['fit_percent']:.1f} %): "
          f"{before['error'] / after['error']:.1f}x lower; noise floor {after['noise_floor']:.4f}")
    print(f"files in {work}")
    return rc


def _cmd_figures(args) -> int:
    from ..workbench.figures import reproduce_figures

    out = _report_dir(args.out)
    numbers = reproduce_figures(out, seed=args.seed)
    for k, v in numbers.items():
        print(f"{k:<48} {v:.4g}")
    _write_json(args.json, numbers)
    print(f"figures: {out / 'index.html'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ipmc-model", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="verb", required=True)

    p = sub.add_parser("simulate", help="write synthetic measurement files from the package's simulator")
    _add_model_args(p)
    out = p.add_mutually_exclusive_group(required=True)
    out.add_argument("--out", help="output directory")
    out.add_argument("--bag", metavar="DIR",
                     help="write rosbag2 bags into DIR (same as --out DIR --format bag)")
    p.add_argument("--samples", default="slim,short", help="paper samples, comma list")
    p.add_argument("--frequencies", default="1:20:8",
                   help="crank frequencies: 'lo:hi:n' (log-spaced) or a comma list, Hz")
    p.add_argument("--duration", type=float, default=6.0, help="record length per frequency, s")
    p.add_argument("--sample-rate", type=float, default=1000.0, help="Hz")
    p.add_argument("--crank-radius", type=float, default=2e-3, help="crank radius = amplitude, m")
    p.add_argument("--noise-rel", type=float, default=0.01, help="noise RMS / clean current RMS")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--format", choices=("timeseries", "frf", "bag"), default="timeseries")
    p.add_argument("--storage", choices=("sqlite3", "mcap"), default="sqlite3", help="bag storage")
    p.add_argument("--fidelity", choices=("exact", "field"), default="exact",
                   help="exact: FFT prediction of the closed form with its effects; field: the "
                        "independent field-equation solution (base model and hydration_drift)")
    p.add_argument("--beam-model", choices=("linear", "elastica"), default="linear",
                   help="with --fidelity field: stress profile from the small-deflection beam "
                        "(the paper, eq. 21) or the large-deflection elastica")
    p.add_argument("--json")
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("fit", help="identify parameters from frequency response (paper 5.2)")
    _add_model_args(p)
    _add_data_args(p)
    p.add_argument("--free", default="alpha0,d,kappa_e",
                   help="parameters to fit (symbols d, alpha0, C-, kappa_e, Y, r0, T or full names)")
    p.add_argument("--save", help="write the fitted parameters as a ROS 2 params file for the nodes")
    p.add_argument("--save-material", help="write the fitted material as workbench YAML")
    _add_output_args(p)
    p.set_defaults(func=_cmd_fit)

    p = sub.add_parser("compare", help="fixed model vs measurements: fit %%, errors, where it fails")
    _add_model_args(p)
    _add_data_args(p)
    p.add_argument("--settle", type=float, default=0.5, help="seconds left out at each record start")
    _add_output_args(p)
    p.set_defaults(func=_cmd_compare)

    p = sub.add_parser("track", help="refit a parameter in consecutive windows (paper 5.4)")
    _add_model_args(p)
    _add_data_args(p)
    p.add_argument("--param", default="d", help="parameter(s) to track")
    p.add_argument("--window", type=float, default=60.0, help="window length, s")
    p.add_argument("--step", type=float, default=None, help="window step, s (default: window)")
    _add_output_args(p)
    p.set_defaults(func=_cmd_track)

    p = sub.add_parser("diagnose", help="rank the physical effects missing from the model")
    _add_model_args(p, "--base")
    _add_data_args(p)
    p.add_argument("--free", default="alpha0,d,kappa_e", help="material parameters refitted with each model")
    p.add_argument("--candidates", help="restrict to these effects (comma list)")
    _add_output_args(p)
    p.set_defaults(func=_cmd_diagnose)

    p = sub.add_parser("estimate", help="estimate deflection offline from a bag or time series "
                                        "(same code path and params file as the estimator node)")
    p.add_argument("input", help="rosbag2 bag (dir, .mcap, .db3) or ipmc-timeseries/1 file")
    p.add_argument("--out", required=True, help="output: .csv (ipmc-timeseries/1) or a bag path")
    p.add_argument("--params", help="ROS 2 params file of the estimator node (config/estimator.yaml)")
    p.add_argument("--format", choices=("timeseries", "bag"), help="output format (default: by suffix)")
    p.add_argument("--storage", choices=("sqlite3", "mcap"), default="sqlite3", help="output bag storage")
    p.add_argument("--current-topic", default="current")
    p.add_argument("--deflection-topic", default="deflection_truth",
                   help="input bags: recorded deflection (optional, used to report the error)")
    p.add_argument("--estimate-topic", default="deflection/block", help="output bags: estimate topic")
    p.add_argument("--geometry", help="bags without ipmc.yaml sidecar: 'L,W,T' in metres")
    p.add_argument("--json")
    p.set_defaults(func=_cmd_estimate)

    p = sub.add_parser("reduce", help="error table of reduced models against the full model")
    _add_model_args(p)
    p.add_argument("--samples", help="comma list of paper samples (big,slim,short); default all")
    p.add_argument("--geometry", help="custom geometry 'L,W,T' in metres (thickness T = 2h)")
    p.add_argument("--orders", default="1-8", help="orders, e.g. '1-8' or '2,4,6'")
    p.add_argument("--band", nargs=2, type=float, default=(0.1, 50.0), metavar=("LOW_HZ", "HIGH_HZ"))
    p.add_argument("--json", help="also write the table as JSON to this file")
    p.set_defaults(func=_cmd_reduce)

    p = sub.add_parser("eq55", help="poles/zeros of the paper's eq. 55 and stability of its inverse")
    _add_model_args(p)
    p.add_argument("--samples", help="comma list of paper samples; default all")
    p.set_defaults(func=_cmd_eq55)

    p = sub.add_parser("effects", help="list the effect catalog")
    p.add_argument("--plugin", action="append")
    p.add_argument("--markdown", action="store_true", help="full documentation as Markdown")
    p.set_defaults(func=_cmd_effects)

    p = sub.add_parser("example", help="worked example: H1 fails, diagnose, add the effect, error falls")
    p.add_argument("--out", help="working directory (default: a new temporary one)")
    p.set_defaults(func=_cmd_example)

    p = sub.add_parser("figures", help="reproduce the paper's Figs. 4-6 on synthetic data")
    p.add_argument("--out", default="reports/figures")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json")
    p.set_defaults(func=_cmd_figures)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ParameterError, ValueError, OSError) as exc:
        print(f"ipmc-model {args.verb}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

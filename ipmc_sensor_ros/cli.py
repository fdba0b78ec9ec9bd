"""``ipmc-model``: command-line entry point of the model workbench.

Verbs available now: ``reduce`` (error table of the stable reductions against
the full model) and ``eq55`` (poles and zeros of the paper's eq. 55).
"""
from __future__ import annotations

import argparse
import json
import sys

from .physics.model import SensorModel, parse_model_name
from .physics.parameters import PAPER_PARAMETERS, PAPER_SAMPLES, Geometry, ParameterError, load_yaml

__all__ = ["main"]


def _parse_orders(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        if "-" in part:
            lo, hi = part.split("-", 1)
            out.extend(range(int(lo), int(hi) + 1))
        else:
            out.append(int(part))
    return out


def _models_from_args(args) -> dict[str, SensorModel]:
    material, geometry = PAPER_PARAMETERS, None
    if args.params:
        material, geometry = load_yaml(args.params)
    _, effects = parse_model_name(args.model)
    if args.geometry:
        length, width, thickness = (float(v) for v in args.geometry.split(","))
        geometries = {"custom": Geometry(length, width, thickness, "custom")}
    elif geometry is not None and not args.samples:
        geometries = {geometry.name or "sample": geometry}
    else:
        names = (args.samples or "big,slim,short").split(",")
        unknown = [n for n in names if n not in PAPER_SAMPLES]
        if unknown:
            raise ParameterError(f"--samples: unknown sample(s) {unknown}; paper samples are "
                                 f"{sorted(PAPER_SAMPLES)} (or use --geometry L,W,T in metres)")
        geometries = {n: PAPER_SAMPLES[n] for n in names}
    return {name: SensorModel(g, material, effects) for name, g in geometries.items()}


def _add_model_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", default="h2", help="base model: h1 (eq. 31) or h2 (eq. 45); default h2")
    p.add_argument("--params", help="YAML with 'material:' (and optional 'geometry:')")
    p.add_argument("--samples", help="comma list of paper samples (big,slim,short); default all")
    p.add_argument("--geometry", help="custom geometry 'L,W,T' in metres (thickness T = 2h)")


def _cmd_reduce(args) -> int:
    from .reduction import reduction_error_table

    models = _models_from_args(args)
    orders = _parse_orders(args.orders)
    rows = reduction_error_table(models, orders, (args.band[0], args.band[1]))
    print(f"Stable minimum-phase reductions vs {args.model.upper()} over "
          f"{args.band[0]:g}-{args.band[1]:g} Hz (worst errors)")
    print(f"{'sample':<8} {'order':>5} {'|mag| dB':>10} {'|phase| deg':>12}  target 0.1 dB / 1 deg")
    for r in rows:
        ok = r["max_mag_error_db"] <= 0.1 and r["max_phase_error_deg"] <= 1.0
        print(f"{r['sample']:<8} {r['order']:>5} {r['max_mag_error_db']:>10.4f} "
              f"{r['max_phase_error_deg']:>12.4f}  {'ok' if ok else '-'}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"band_hz": list(args.band), "model": args.model, "rows": rows}, fh, indent=2)
    return 0


def _cmd_eq55(args) -> int:
    from .reduction import eq55_poles_zeros

    for name, model in _models_from_args(args).items():
        rep = eq55_poles_zeros(model)
        print(f"{name}: eq. 55 zeros (rad/s): {', '.join(f'{z:.4g}' for z in rep['zeros'])}")
        print(f"{name}: eq. 55 poles (rad/s): {', '.join(f'{p:.4g}' for p in rep['poles'])}")
        verdict = "stable" if rep["inverse_stable"] else \
            f"UNSTABLE (right-half-plane zero(s) at {', '.join(f'{z.real:.4g}' for z in rep['rhp_zeros'])} rad/s)"
        print(f"{name}: literal inverse of eq. 55 is {verdict}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ipmc-model", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="verb", required=True)
    p = sub.add_parser("reduce", help="error table of reduced models against the full model")
    _add_model_args(p)
    p.add_argument("--orders", default="1-8", help="orders, e.g. '1-8' or '2,4,6'")
    p.add_argument("--band", nargs=2, type=float, default=(0.1, 50.0), metavar=("LOW_HZ", "HIGH_HZ"))
    p.add_argument("--json", help="also write the table as JSON to this file")
    p.set_defaults(func=_cmd_reduce)
    p = sub.add_parser("eq55", help="poles/zeros of the paper's eq. 55 and stability of its inverse")
    _add_model_args(p)
    p.set_defaults(func=_cmd_eq55)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ParameterError, ValueError, OSError) as exc:
        print(f"ipmc-model {args.verb}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

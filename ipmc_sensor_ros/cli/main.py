# SPDX-License-Identifier: Apache-2.0
"""
``ipmc-model``: the model workbench on the command line (parser assembly and dispatch).

The verbs live in three modules: :mod:`.data_verbs` (simulate, estimate,
import), :mod:`.model_verbs` (fit, compare, track, diagnose) and
:mod:`.info_verbs` (reduce, eq55, effects, example, figures); the shared flag
vocabulary is in :mod:`.args`.
"""
from __future__ import annotations

import argparse
import difflib
import sys

from ..errors import IpmcError, defect_text
from . import data_verbs, info_verbs, model_verbs
from .args import HelpFormatter
from .outputs import check_outputs

__all__ = ['main', 'build_parser']

DESCRIPTION = """\
IPMC sensor model workbench (Chen-Tan-Will-Ziel 2007): make, import and
estimate data, fit and test models, find missing physics.

Lab data, start to finish:
  ipmc-model import run*.csv --meta run.json --out data/
  ipmc-model compare data/ --report rep/      (is the paper's H2 good enough?)
  ipmc-model diagnose data/ --save-model m.yaml   (which effect is missing?)
  ipmc-model info m.yaml                      (the sensor; the calibration's offset, delay)
  ipmc-model estimate field/ --model-file m.yaml --out est/
  ipmc-model fit data/ --effects amplifier_bandwidth --save node.yaml   (node parameters)

Every verb prints its results; most also take --json FILE and --report DIR.
'ipmc-model VERB --help' lists a verb's flags with their defaults."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='ipmc-model', description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest='verb', required=True, metavar='VERB')
    for module in (data_verbs, model_verbs, info_verbs):
        module.add_parsers(sub, HelpFormatter)
    parser.set_defaults(verbs=sub.choices)
    return parser


def _refuse_unknown(args: argparse.Namespace, extra: list[str]) -> None:
    """Exit 2 with the verb's usage, naming each unknown argument (and a near flag)."""
    verb = args.verbs[args.verb]
    flags = [o for a in verb._actions for o in a.option_strings]
    said = []
    for token in extra:
        near = difflib.get_close_matches(token.split('=')[0], flags, n=1, cutoff=0.6)
        said.append(f'{token} (did you mean {near[0]}?)' if near and token.startswith('-')
                    else token)
    verb.error('unrecognized arguments: ' + ' '.join(said))


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:
        _refuse_unknown(args, extra)
    try:
        check_outputs(args)
        return int(args.func(args) or 0)
    except (IpmcError, OSError) as exc:    # raised on purpose: the input, named, and its place
        print(f'ipmc-model {args.verb}: error: {exc}', file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - a defect (numpy's ValueError too): one line, 3
        print(f'ipmc-model {args.verb}: {defect_text(exc)}', file=sys.stderr)
        return 3


if __name__ == '__main__':
    sys.exit(main())

# SPDX-License-Identifier: Apache-2.0
"""One flag vocabulary across every ipmc-model verb (walks the parsers; fast, no computation)."""
import argparse
import time

import pytest

from ipmc_sensor_ros.cli.args import Progress, natural_key, parse_geometry
from ipmc_sensor_ros.cli.main import build_parser, main
from ipmc_sensor_ros.physics.parameters import ParameterError

#: concept -> the one flag that names it, and what its value is
CONCEPTS = {'model': '--model', 'effects': '--effects', 'plugin': '--plugin', 'params': '--params',
            'set': '--set', 'free': '--free', 'geometry': '--geometry', 'samples': '--samples',
            'out': '--out', 'json': '--json', 'report': '--report', 'seed': '--seed',
            'settle': '--settle', 'current_topic': '--current-topic',
            'deflection_topic': '--deflection-topic', 'format': '--format', 'storage': '--storage'}
METAVARS = {'--out': 'DIR', '--report': 'DIR', '--json': 'FILE', '--params': 'FILE',
            '--save': 'FILE', '--plugin': 'FILE', '--geometry': 'L,W,T', '--model': 'h1|h2',
            '--free': 'LIST', '--samples': 'LIST', '--effects': 'LIST', '--current-topic': 'TOPIC',
            '--deflection-topic': 'TOPIC', '--estimate-topic': 'TOPIC'}
RENAMED = {'diagnose': {'--base': '--model'}, 'track': {'--param': '--free'},
           'simulate': {'--bag': '--out DIR --format bag'}, 'figures': {'--out': '--report'}}


def _verbs():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return parser, sub.choices


def _visible(p):
    return [
        a
        for a in p._actions
        if a.help != argparse.SUPPRESS and not isinstance(a, argparse._HelpAction)
    ]


def test_every_flag_has_help_and_shows_its_default():
    _, verbs = _verbs()
    for verb, p in verbs.items():
        text = p.format_help()
        for a in _visible(p):
            assert a.help and len(a.help) > 8, f'{verb} {a.option_strings or a.dest}: no help'
            if a.option_strings and a.default not in (None, False, ''):
                assert f'(default: {a.default})' in ' '.join(text.split()), (
                    verb,
                    a.option_strings,
                )


def test_one_name_per_concept_and_one_meaning_per_name():
    _, verbs = _verbs()
    seen: dict[str, tuple] = {}
    for verb, p in verbs.items():
        for a in _visible(p):
            for opt in a.option_strings:
                # the same flag means the same destination (concept) in every verb
                assert seen.setdefault(opt, (a.dest, verb))[0] == a.dest, (opt, verb, seen[opt])
            if a.dest in CONCEPTS and a.option_strings:
                assert CONCEPTS[a.dest] in a.option_strings, (verb, a.dest, a.option_strings)
            for opt, metavar in METAVARS.items():
                if opt in a.option_strings:
                    assert a.metavar == metavar, (verb, opt, a.metavar)
    # fit, track and diagnose all estimate parameters with --free; the model is always --model
    for verb in ('fit', 'track', 'diagnose'):
        assert '--free' in verbs[verb]._option_string_actions
    for verb in ('simulate', 'fit', 'compare', 'track', 'diagnose', 'reduce', 'eq55'):
        assert '--model' in verbs[verb]._option_string_actions
    # every verb that computes numbers can write them as JSON
    for verb, p in verbs.items():
        if verb not in ('effects', 'example'):
            assert '--json' in p._option_string_actions, verb


@pytest.mark.parametrize(
    'verb,old,new', [(v, o, n) for v, d in RENAMED.items() for o, n in d.items()]
)
def test_renamed_flags_stop_with_a_hint(verb, old, new, capsys):
    argv = [verb, 'x', old, 'y'] if verb in ('diagnose', 'track') else [verb, old, 'y']
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f'{old} was renamed {new}' in err


def test_top_level_help_is_plain_text():
    parser, verbs = _verbs()
    text = parser.format_help()
    assert '``' not in text and ':mod:' not in text
    for verb in verbs:
        assert verb in text


def test_natural_order_of_records():
    names = ['slim_13Hz.csv', 'slim_1Hz.csv', 'slim_2p5Hz.csv', 'slim_1p82Hz.csv', 'big_20Hz.csv']
    assert sorted(names, key=natural_key) == ['big_20Hz.csv', 'slim_1Hz.csv', 'slim_1p82Hz.csv',
                                              'slim_2p5Hz.csv', 'slim_13Hz.csv']


def test_geometry_with_units():
    g = parse_geometry('22mm,7mm,360um')
    assert (g.length_m, g.width_m, g.thickness_m) == pytest.approx((0.022, 0.007, 3.6e-4))
    assert parse_geometry('0.022,0.007,0.00036').thickness_m == pytest.approx(3.6e-4)
    with pytest.raises(ParameterError, match='--geometry'):
        parse_geometry('22,7')
    with pytest.raises(ParameterError, match='millimetres'):      # a bare 22 is 22 m: refused
        parse_geometry('22,7,0.36')


def test_progress_lines_are_rate_limited(capsys):
    import sys

    prog = Progress('work', interval_s=2.0, out=sys.stdout)
    for k in range(200):
        prog.step(f'step {k}')
    lines = capsys.readouterr().out.splitlines()
    assert lines == ['... work: step 0 [0 s]']              # one line, not 200
    with Progress('quiet', interval_s=0.2, quiet_s=0.3, heartbeat_s=0.2, out=sys.stdout):
        time.sleep(0.8)                                     # an opaque call: heartbeat lines
    out = capsys.readouterr().out
    assert 'still working' in out and 'done' in out


def test_nothing_written_unless_asked():
    parser, verbs = _verbs()
    for verb, p in verbs.items():
        for a in _visible(p):
            if a.dest in ('report', 'json', 'save', 'save_material'):
                assert a.default is None, (verb, a.dest)     # no default output location
    assert parser.parse_args(['figures']).report is None


def test_import_verb_passes_everything_to_the_library(monkeypatch, tmp_path, capsys):
    """
    The verb is a thin shell over workbench.labimport.import_lab_files.

    Stubbed here, so this tests the CLI side only: parsing of --geometry units, --columns,
    --current-gain.
    """
    import sys
    import types

    calls = []

    def fake_import(paths, out_dir, *, geometry=None, meta=None, columns=None,
                    current_gain_a_per_v=None, sample=None, notice=None, overwrite=False):
        assert callable(notice)
        calls.append(dict(paths=paths, out_dir=out_dir, geometry=geometry, meta=meta,
                          columns=columns, gain=current_gain_a_per_v, sample=sample,
                          overwrite=overwrite))
        return [out_dir / 'run1.csv']

    monkeypatch.setitem(sys.modules, 'ipmc_sensor_ros.workbench.labimport',
                        types.SimpleNamespace(import_lab_files=fake_import))
    assert (
        main(
            [
                'import',
                'a.csv',
                'b.txt',
                '--out',
                str(tmp_path),
                '--geometry',
                '22mm,7mm,360um',
                '--columns',
                'time=Time [s],current=Current [uA]',
                '--current-gain',
                '1e6',
                '--sample',
                's1',
                '--meta',
                'run.json',
            ]
        )
        == 0
    )
    (c,) = calls
    assert [p.name for p in c['paths']] == ['a.csv', 'b.txt'] and c['out_dir'] == tmp_path
    assert c['geometry'].length_m == pytest.approx(0.022) and c['geometry'].name == 's1'
    assert c['columns'] == {'time': 'Time [s]', 'current': 'Current [uA]'}
    assert (
        c['gain'] == pytest.approx(1e-6) and c['meta'].name == 'run.json' and c['sample'] == 's1'
    )
    assert c['overwrite'] is False                  # an existing output is refused by default
    assert 'run1.csv' in capsys.readouterr().out
    assert main(['import', 'a.csv', '--out', str(tmp_path), '--columns', 'volts=V']) == 2
    assert "--columns: unknown role 'volts'" in capsys.readouterr().err

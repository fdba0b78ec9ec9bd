# SPDX-License-Identifier: Apache-2.0
r"""
Documents that run: the commands of README.md and docs/*.md are executed or checked.

Convention, for every document:

``` ```console ```
    Runnable.  Lines starting with ``$ `` are commands (a trailing ``\`` continues one);
    other lines are sample output and are not checked.  The blocks of one document run in
    order in one empty temporary directory that holds links to the repository's ``config/``,
    ``examples/`` and ``test/data/`` (so ``config/estimator.yaml`` works as in a checkout),
    with ``ipmc-model``, the node executables and ``python`` on PATH running this checkout's
    code, and a ROS_DOMAIN_ID of its own (the documents run side by side).  Each command must
    exit 0 without a traceback.  ``timeout --preserve-status -s INT N <node>`` (for the
    reader: run the node for N s, then SIGINT, and exit with its status) is run until the node
    logs "ready", then sent SIGINT, and must exit 0: a node that fails to start, or does not
    stop on SIGINT, fails the test.  Keep the commands small: short records, few frequencies.
``` ```bash ``` / ``` ```sh ```
    Not run.  The first line is a comment saying why (``# needs a ROS 2 installation``,
    ``# not run by the doc test: ...``).  A block that uses ``ros2 run`` (or any ``ros2``
    command) must be followed by a console block that runs the same executables without ROS
    (the PyPI-only equivalent: ``ipmc_estimator --ros-args ...``; for ``ros2 launch`` the
    two-process demo ``python -m ipmc_sensor_ros.nodes.demo``).
Inline code
    ```ipmc-model VERB --flag ...``` in prose and tables: the verb and every flag must exist
    in the command-line parser (hidden, renamed flags do not count), so a renamed flag fails
    this test too.

Generated parts (``<!-- BEGIN GENERATED: name -->`` ... ``<!-- END GENERATED -->``) must
equal what ``python scripts/gen_docs.py`` writes.
"""
from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md'))]
EXECUTABLES = ('ipmc_estimator', 'ipmc_simulator', 'ipmc_estimator_managed',
               'ipmc_simulator_managed')
FENCE = re.compile(r'^```(\S*)[^\n]*\n(.*?)^```\s*$', re.M | re.S)
#: Longest a single documented command may take here, s (they run on small data).
COMMAND_TIMEOUT_S = 240


def _blocks(path: Path) -> list[tuple[str, str, int]]:
    """(language, body, line number) of each fenced block."""
    text = path.read_text(encoding='utf-8')
    return [(m.group(1), m.group(2), text.count('\n', 0, m.start()) + 1)
            for m in FENCE.finditer(text)]


def _commands(body: str) -> list[str]:
    out, cur = [], None
    for line in body.splitlines():
        if cur is not None:
            cur += ' ' + line.strip()
        elif line.startswith('$ '):
            cur = line[2:].strip()
        else:
            continue
        if cur.endswith('\\'):
            cur = cur[:-1].rstrip()
        else:
            out.append(cur)
            cur = None
    return out


def _workdir(tmp: Path, domain: int) -> dict:
    """Prepare the directory the commands run in; return their environment."""
    for name in ('config', 'examples'):
        (tmp / name).symlink_to(ROOT / name)
    (tmp / 'test').mkdir()
    (tmp / 'test' / 'data').symlink_to(ROOT / 'test' / 'data')
    bin_dir = tmp / '.bin'
    bin_dir.mkdir()
    entry = {'ipmc-model': 'ipmc_sensor_ros.cli.main:main',
             'ipmc_estimator': 'ipmc_sensor_ros.nodes.entry:estimator',
             'ipmc_simulator': 'ipmc_sensor_ros.nodes.entry:simulator',
             'ipmc_estimator_managed': 'ipmc_sensor_ros.nodes.entry:estimator_managed',
             'ipmc_simulator_managed': 'ipmc_sensor_ros.nodes.entry:simulator_managed'}
    for exe, target in entry.items():          # as setup.py's console_scripts
        module, func = target.split(':')
        script = bin_dir / exe
        script.write_text(f'#!{sys.executable}\nimport sys\nfrom {module} import {func}\n'
                          f'sys.exit({func}())\n')
        script.chmod(0o755)
    (bin_dir / 'python').write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
    (bin_dir / 'python').chmod(0o755)
    return dict(os.environ, PATH=f'{bin_dir}{os.pathsep}{os.environ["PATH"]}',
                PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(domain), MPLBACKEND='Agg')


_NODE_RUN = re.compile(r'^timeout --preserve-status -s INT \d+ ')


def _run_node(cmd: str, cwd: Path, env: dict, where: str) -> None:
    """
    ``timeout --preserve-status -s INT N <node>``: start the node; once it is ready, SIGINT.

    Waiting for "ready" instead of N seconds keeps the test independent of the machine's
    speed; the node must then exit 0 without a traceback.
    """
    import signal
    import threading

    proc = subprocess.Popen(['bash', '-c', 'exec ' + _NODE_RUN.sub('', cmd)], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    ready = threading.Event()

    def read():
        for line in proc.stdout:
            lines.append(line)
            if 'ready' in line:
                ready.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    end = time.monotonic() + COMMAND_TIMEOUT_S
    while not ready.wait(0.1) and proc.poll() is None and time.monotonic() < end:
        pass
    got_ready = ready.is_set()
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    reader.join(5)
    out = ''.join(lines)
    assert got_ready, f'{where}: `{cmd}` never got ready (exit {proc.returncode}):\n{out[-3000:]}'
    assert proc.returncode == 0 and 'Traceback' not in out, (
        f'{where}: `{cmd}` exited {proc.returncode} on SIGINT:\n{out[-3000:]}')


def _run(cmd: str, cwd: Path, env: dict, where: str) -> float:
    t0 = time.monotonic()
    if _NODE_RUN.match(cmd):
        _run_node(cmd, cwd, env, where)
        return time.monotonic() - t0
    proc = subprocess.run(['bash', '-c', cmd], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=COMMAND_TIMEOUT_S)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and 'Traceback' not in out, (
        f'{where}: `{cmd}` exited {proc.returncode}:\n{out[-3000:]}')
    return time.monotonic() - t0


def _run_document(doc: Path, tmp: Path, domain: int) -> tuple[str, list]:
    """Run a document's console blocks in order; return (the first failure or '', timings)."""
    env = _workdir(tmp, domain)
    spent = []
    try:
        for lang, body, line in _blocks(doc):
            if lang == 'console':
                for cmd in _commands(body):
                    spent.append((_run(cmd, tmp, env, f'{doc.name}:{line}'), cmd))
    except (AssertionError, subprocess.TimeoutExpired) as exc:
        return str(exc), spent
    return '', spent


@pytest.fixture(scope='module')
def document_runs(tmp_path_factory):
    """
    Every document run at once, each in its own directory and ROS domain.

    The documents are independent; running them side by side keeps the wall time near the
    slowest one (its nodes mostly wait for their timeout).
    """
    from concurrent.futures import ThreadPoolExecutor

    base = int(os.environ.get('ROS_DOMAIN_ID') or 150 + os.getpid() % 40)
    with ThreadPoolExecutor(max_workers=len(DOCS)) as pool:
        futures = {doc: pool.submit(_run_document, doc, tmp_path_factory.mktemp(doc.stem),
                                    (base + k) % 200 + 1)
                   for k, doc in enumerate(DOCS)}
        return {doc: f.result() for doc, f in futures.items()}


@pytest.mark.parametrize('doc', DOCS, ids=lambda p: p.name)
def test_console_commands_run(doc, document_runs):
    failure, spent = document_runs[doc]
    print(f'{doc.name}: {len(spent)} command(s), {sum(s for s, _ in spent):.1f} s; slowest: '
          + '; '.join(f'{s:.1f} s {c[:60]}' for s, c in sorted(spent, reverse=True)[:3]))
    assert not failure, failure


def test_not_run_blocks_say_why_and_ros2_has_its_pypi_equivalent():
    for doc in DOCS:
        blocks = _blocks(doc)
        for k, (lang, body, line) in enumerate(blocks):
            if lang not in ('bash', 'sh', 'shell'):
                continue
            where = f'{doc.name}:{line}'
            assert body.lstrip().startswith(('# needs ', '# not run')), \
                f'{where}: a shell block that is not run must say why on its first line'
            used = {exe for exe in EXECUTABLES if re.search(rf'ros2 run \S+ {exe}\b', body)}
            if 'ros2 ' in body and '# needs' in body.splitlines()[0]:
                assert k + 1 < len(blocks) and blocks[k + 1][0] == 'console' or \
                    k > 0 and blocks[k - 1][0] == 'console', \
                    f'{where}: ros2 commands need their PyPI-only equivalent beside them'
                near = ''.join(b for lg, b, _ in blocks[max(k - 1, 0):k + 2] if lg == 'console')
                for exe in used:
                    assert re.search(rf'\$ (timeout .*)?{exe} ', near), \
                        f'{where}: {exe} has no runnable equivalent beside its ros2 run'
                if 'ros2 launch' in body:
                    assert 'ipmc_sensor_ros.nodes.demo' in near, \
                        f'{where}: ros2 launch needs the demo (two processes) beside it'


def _parsers() -> dict[str, argparse.ArgumentParser]:
    from ipmc_sensor_ros.cli.main import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _flags(parser: argparse.ArgumentParser) -> set[str]:
    return {s for a in parser._actions if a.help != argparse.SUPPRESS for s in a.option_strings}


def test_inline_commands_use_existing_verbs_and_flags():
    parsers = _parsers()
    checked = 0
    for doc in DOCS:
        text = FENCE.sub('', doc.read_text(encoding='utf-8'))
        for span in re.findall(r'`(ipmc-model [^`]+)`', text):
            words = shlex.split(span.replace('\\|', '|'))
            if not words[1].islower():          # a placeholder: VERB
                continue
            for verb in words[1].split('|'):    # fit|diagnose: each of them
                assert verb in parsers, f'{doc.name}: `{span}`: no verb {verb!r}'
                for w in words[2:]:
                    if w.startswith('--'):
                        assert w.split('=')[0] in _flags(parsers[verb]), \
                            f'{doc.name}: `{span}`: {verb} has no flag {w}'
            checked += 1
    assert checked > 10


def test_no_two_documents_write_the_same_output():
    """
    A user runs the README's tour and a doc's commands in one directory (the repository's).

    ``estimate`` and ``diagnose`` refuse to replace a file they did not write in that run,
    so two documents writing ``est/`` or ``model.yaml`` made the second fail (and ``info``
    then read the first one's model): each document's outputs are its own.
    """
    writers = {}
    for doc in DOCS:
        for _, body, _ in _blocks(doc):
            for command in re.findall(r'^\$ (ipmc-model .*)$', body, re.M):
                for out in re.findall(r'--(?:out|save|save-model|json|report)[ =](\S+)',
                                      command):
                    writers.setdefault(out.rstrip('/'), set()).add(doc.name)
    shared = {out: sorted(docs) for out, docs in writers.items() if len(docs) > 1}
    assert len(writers) > 10 and not shared


def test_generated_parts_are_current():
    sys.path.insert(0, str(ROOT / 'scripts'))
    try:
        import gen_docs
    finally:
        sys.path.pop(0)
    stale = gen_docs.stale()
    assert not stale, f'regenerate with `python scripts/gen_docs.py`: {stale}'


def test_every_number_in_the_estimator_code_is_classified_and_few_are_tuning():
    """
    Each module-level number in estimation/ is in CODE_CONSTANTS; at most 10 are tuning.

    The scan is gen_docs's (the table in docs/estimator.md is made from it); a new constant
    fails here until it is classified, and an eleventh tuning one until another goes (issue
    27: "at most 10 tuning constants in the estimator code besides physical ones").
    """
    from ipmc_sensor_ros.estimation.config import CODE_CONSTANTS

    sys.path.insert(0, str(ROOT / 'scripts'))
    try:
        import gen_docs
    finally:
        sys.path.pop(0)
    found = {name: why for name, _, why in gen_docs.code_constants()}
    assert set(found) == set(CODE_CONSTANTS)
    assert set(CODE_CONSTANTS.values()) <= {'tuning', 'stream', 'physical', 'numerical',
                                            'limit', 'baseline'}
    assert sum(kind == 'tuning' for kind in CODE_CONSTANTS.values()) <= 10
    shown = [name for name, kind in CODE_CONSTANTS.items()
             if kind in ('tuning', 'stream', 'physical')]
    assert all(found[name] for name in shown)       # each has its reason (a #: comment)


def test_documented_block_columns_are_the_codes():
    from ipmc_sensor_ros.interface.blocks import current_columns, estimate_columns

    for doc in (ROOT / 'README.md', ROOT / 'docs' / 'ros_interface.md'):
        text = doc.read_text(encoding='utf-8')
        for columns in (current_columns(1), estimate_columns(1)):
            assert f'`{columns}`' in text, f'{doc.name}: the block columns are now {columns}'


def test_readme_is_a_front_door():
    text = (ROOT / 'README.md').read_text(encoding='utf-8')
    assert len(text.splitlines()) <= 250
    assert 'bash scripts/demo.sh' in text and 'bash scripts/test.sh' in text
    for doc in DOCS + [ROOT / 'CHANGELOG.md']:
        for phrase in ('this round', 'last round', 'this session', 'last session'):
            assert phrase not in doc.read_text(encoding='utf-8').lower(), f'{doc.name}: {phrase}'

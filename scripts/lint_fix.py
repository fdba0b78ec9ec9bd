#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Rewrite the code base to the ROS 2 (ament_flake8) style, for the lead to run once.

* quotes: a tokenize-based rewrite of double-quoted string literals to single quotes
  (flake8-quotes Q000), leaving strings that contain a single quote, docstrings
  (triple quotes) and f-strings with nested quotes alone;
* SPDX header: ``# SPDX-License-Identifier: Apache-2.0`` as the first line (after a
  shebang) of every Python file that lacks it.

Long lines (E501 > 99) are not rewritten here: run ``black -l 99`` on the files
listed by ``flake8 --select E501`` or fix them by hand; docstring style (pep257) by hand.

Usage: python scripts/lint_fix.py [paths...]   (default: ipmc_sensor_ros test launch
scripts bench setup.py), then ``pytest -m linter``.
"""
import io
import sys
import tokenize
from pathlib import Path

SPDX = '# SPDX-License-Identifier: Apache-2.0\n'


def requote(source: str) -> str:
    """``source`` with simple double-quoted literals turned into single-quoted ones."""
    out = []
    tokens = list(tokenize.generate_tokens(io.StringIO(source).readline))
    lines = source.splitlines(keepends=True)
    offsets = [0]
    for line in lines:
        offsets.append(offsets[-1] + len(line))
    edits = []
    for tok in tokens:
        if tok.type != tokenize.STRING:
            continue
        text = tok.string
        i = 0
        while i < len(text) and text[i] in 'rbuRBUfF':
            i += 1
        prefix, body = text[:i], text[i:]
        if body.startswith("'''") and '"' not in body:
            edits_q001 = prefix + '"""' + body[3:-3] + '"""'
            start = offsets[tok.start[0] - 1] + tok.start[1]
            end = offsets[tok.end[0] - 1] + tok.end[1]
            edits.append((start, end, edits_q001))
            continue
        if body.startswith('"""') or not body.startswith('"') or "'" in body:
            continue
        # f-strings: before Python 3.12 a replacement field cannot hold the outer quote
        # character, and a body without "'" holds none in its fields either
        new = prefix + "'" + body[1:-1].replace('\\"', '"') + "'"
        start = offsets[tok.start[0] - 1] + tok.start[1]
        end = offsets[tok.end[0] - 1] + tok.end[1]
        edits.append((start, end, new))
    pos = 0
    for start, end, new in edits:
        out.append(source[pos:start])
        out.append(new)
        pos = end
    out.append(source[pos:])
    return ''.join(out)


def add_spdx(source: str) -> str:
    if 'SPDX-License-Identifier' in ''.join(source.splitlines(keepends=True)[:3]):
        return source
    if source.startswith('#!'):
        first, rest = source.split('\n', 1)
        return first + '\n' + SPDX + rest
    return SPDX + source


def main(argv) -> int:
    roots = argv or ['ipmc_sensor_ros', 'test', 'launch', 'scripts', 'bench', 'setup.py']
    files = []
    for r in map(Path, roots):
        files += sorted(r.rglob('*.py')) if r.is_dir() else [r]
    for f in files:
        src = f.read_text(encoding='utf-8')
        new = add_spdx(requote(src))
        compile(new, str(f), 'exec')  # never write a file that no longer parses
        if new != src:
            f.write_text(new, encoding='utf-8')
    print(f'{len(files)} files checked')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))

#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""
Rewrite the code base to the ROS 2 (ament_flake8/ament_pep257) style; safe to rerun.

* quotes: a tokenize-based rewrite of double-quoted string literals to single quotes
  (flake8-quotes Q000), leaving strings that contain a single quote, docstrings
  (triple quotes) and f-strings with nested quotes alone;
* SPDX header: ``# SPDX-License-Identifier: Apache-2.0`` as the first line (after a
  shebang) of every Python file that lacks it;
* docstrings (ament_pep257): :func:`fix_docstrings` (D213, D209, D400/D415, D205 where
  the summary can end at a sentence or clause boundary within 99 columns); what it cannot
  do is listed for a human.

Long lines (E501 > 99) are not rewritten here: run ``black -l 99`` on the files
listed by ``flake8 --select E501`` or fix them by hand; the imperative mood (D401) by hand.

Usage: python scripts/lint_fix.py [paths...]   (default: ipmc_sensor_ros test launch
scripts bench examples setup.py), then ``pytest -m linter``.  Rerun it after merging a
branch: it is idempotent and only touches what does not conform yet.
"""
import ast
import io
import re
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


MAX_LINE = 99
# abbreviations whose period does not end a sentence
_ABBREV = ('e.g.', 'i.e.', 'eq.', 'eqs.', 'Eq.', 'Eqs.', 'cf.', 'vs.', 'Fig.', 'al.', 'approx.',
           'resp.', 'Sec.', 'No.', 'ref.', 'Ref.')
_SECTION_RULE = re.compile(r'^\s*-{3,}\s*$')


def _top_level(text: str, limit: int):
    """Yield ``(index, character)`` of ``text[:limit]`` outside brackets and inline literals."""
    depth = 0
    literal = False
    i = 0
    while i < min(len(text), limit):
        if text.startswith('``', i):
            literal = not literal
            i += 2
            continue
        c = text[i]
        if not literal:
            if c in '([{':
                depth += 1
            elif c in ')]}':
                depth = max(0, depth - 1)
            elif depth == 0:
                yield i, c
        i += 1


def _sentence_end(text: str) -> int:
    """
    Return the index just after the first sentence of ``text``, or -1.

    A sentence ends at '.', '?' or '!' followed by white space or the end, outside
    parentheses, brackets and inline literals, and not after a known abbreviation.
    """
    for i, c in _top_level(text, len(text)):
        if c in '.?!' and (i + 1 == len(text) or text[i + 1] == ' '):
            word = text[:i + 1].rsplit(' ', 1)[-1]
            if word not in _ABBREV and not re.fullmatch(r'[A-Za-z]\.', word):
                return i + 1
    return -1


def _trailing_parenthesis(text: str, end: int, limit: int):
    """
    Move a parenthesis that closes the first sentence of ``text`` into its own sentence.

    ``X (Y). Rest`` becomes ``X. Y. Rest`` when ``X.`` fits in ``limit``; return the new
    text and the index after ``X.``, or None.
    """
    if end < 0:
        end = len(text)
    sentence = text[:end].rstrip('.')
    if not sentence.endswith(')'):
        return None
    depth = 0
    for i in range(len(sentence) - 1, -1, -1):
        if sentence[i] == ')':
            depth += 1
        elif sentence[i] == '(':
            depth -= 1
            if depth == 0:
                break
    head = sentence[:i].rstrip()
    inner = sentence[i + 1:-1].strip()
    if i <= 0 or len(head) + 1 > limit or len(head) < 20 or not inner:
        return None
    word = inner.split(' ', 1)[0]
    if word.isalpha() and word.islower():
        inner = inner[0].upper() + inner[1:]
    new = f'{head}. {inner}.' + text[end:]
    return new, len(head) + 1


def _plain(line: str, indent: str) -> bool:
    """Tell whether ``line`` is plain prose at ``indent`` (safe to rewrap)."""
    s = line.strip()
    return (line.startswith(indent) and not line[len(indent):].startswith(' ')
            and not _SECTION_RULE.match(line) and not re.match(r'([-*+]|\d+[.)]|>>>|\.\.) ', s)
            and '  ' not in s[1:].replace('.  ', '. '))


def _wrap(words: list[str], indent: str, width: int) -> list[str]:
    lines, cur = [], ''
    for w in words:
        if cur and len(indent) + len(cur) + 1 + len(w) > width:
            lines.append(indent + cur)
            cur = w
        else:
            cur = f'{cur} {w}' if cur else w
    if cur:
        lines.append(indent + cur)
    return lines


def _layout(body: str, indent: str):
    """
    Return the new body of a docstring (text between the quotes) or None if unchanged.

    The second value names a problem left for a human ('' when none).
    """
    if '\n' not in body:
        text = body.strip()
        if text and text[-1] not in '.?!':
            if text[-1] in ',;:':
                return None, 'one-line summary ends with ' + text[-1]
            text += '.'
        if len(indent) + len(text) + 6 > MAX_LINE:
            # too long for one line: a summary line and a description
            new_body, problem = _layout(f'\n{indent}{text}\n{indent}', indent)
            return new_body or f'\n{indent}{text}\n{indent}', problem
        return (text if text != body.strip() else None), ''
    lines = body.split('\n')
    head = lines[0].strip()
    rest = lines[1:]
    # closing quotes on their own line (D209)
    if rest[-1].strip():
        rest.append(indent)
    rest[-1] = indent
    content = ([head] if head else []) + [ln.rstrip() for ln in rest[:-1]]
    while content and not content[0].strip():
        content.pop(0)
    if not content:
        return None, 'empty docstring'
    # first paragraph
    n = 0
    while n < len(content) and content[n].strip() and not _SECTION_RULE.match(
            content[n + 1] if n + 1 < len(content) else ''):
        n += 1
    if n == 0:
        return None, 'docstring starts with a section'
    para = [content[0].strip()] + content[1:n]
    after = content[n:]
    while after and not after[0].strip():
        after.pop(0)
    problem = ''
    split = ''
    if n == 1 and len(indent) + len(para[0]) <= MAX_LINE:
        summary = para[0]
        tail = []
    else:
        joined = ' '.join(p.strip() for p in para)
        end = _sentence_end(joined)
        split = ''
        if end < 0 or len(indent) + end > MAX_LINE:
            # the first sentence does not fit: end the summary at its last clause boundary
            # ('; ', ': ', else ', ') that fits, and start the description with the rest
            cut = _clause_end(joined, MAX_LINE - len(indent) - 1, ';:')
            if cut < 0:
                cut = _clause_end(joined, MAX_LINE - len(indent) - 1, ',')
            if cut < 0:
                moved = _trailing_parenthesis(joined, end, MAX_LINE - len(indent) - 1)
                if moved is None:
                    return None, 'multi-line summary'
                joined, end = moved
                cut = end - 1
                problem = 'summary without its closing parenthesis'
            else:
                split = joined[cut]
                end = cut + 1
                joined = joined[:cut] + '.' + joined[cut + 1:]
                problem = 'summary split at ' + repr(split)
        summary = joined[:end]
        remainder = joined[end:].strip()
        if split:
            word = remainder.split(' ', 1)[0]
            if len(word) > 1 and word.rstrip(',;:').isalpha() and word.islower():
                remainder = remainder[0].upper() + remainder[1:]
        # the lines after the summary: rewrapped when plain prose, else kept as they are
        consumed = 0
        count = 0
        for k, p in enumerate(para):
            count += len(p.strip()) + (1 if k else 0)
            if count >= end:
                consumed = k
                break
        first_tail = joined[end:len(' '.join(p.strip() for p in para[:consumed + 1]))].strip()
        if split and first_tail:
            first_tail = remainder[:len(first_tail)]
        later = para[consumed + 1:]
        if all(_plain(p, indent) for p in later):
            width = min(MAX_LINE, max(len(p) for p in content[:n]) if n > 1 else MAX_LINE)
            width = max(width, 72)
            tail = _wrap(remainder.split(), indent, width) if remainder else []
        else:
            tail = ([indent + first_tail] if first_tail else []) + later
    if summary[-1] in '?!':
        problem = 'summary ends with ' + summary[-1]
    elif summary[-1] != '.':
        if summary[-1] in ',;:' and not problem:
            problem = 'summary ends with ' + summary[-1]
        else:
            summary += '.'
    if len(indent) + len(summary) > MAX_LINE:
        problem = 'summary too long'
    new_lines = [''] + [indent + summary]
    if tail or after:
        new_lines.append('')
        new_lines += tail
        if tail and after:
            new_lines.append('')
        new_lines += after
    while len(new_lines) > 2 and not new_lines[-1].strip():
        new_lines.pop()
    if content[-1].strip() == '' and len(new_lines) > 2:
        new_lines.append('')  # a blank line after the last section (D413) stays
    new_lines.append(indent)
    new_body = '\n'.join(new_lines)
    return (new_body if new_body != body else None), problem


def _docstring_nodes(tree):
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            if node.body and isinstance(node.body[0], ast.Expr):
                val = node.body[0].value
                if isinstance(val, ast.Constant) and isinstance(val.value, str):
                    yield node, node.body[0].value


def fix_docstrings(source: str, where: str = '<source>'):
    """
    Return ``source`` with docstrings laid out for ament_pep257, and what is left to do.

    Fixes D213 (summary on the second line), D209 (closing quotes on their own line),
    D400/D415 (period after a one-line summary) and D205 where the first sentence of a
    multi-line summary fits on one line; the rest of that paragraph follows a blank line.
    """
    tree = ast.parse(source)
    lines = source.splitlines(keepends=True)
    offsets = [0]
    for line in lines:
        offsets.append(offsets[-1] + len(line))
    edits, todo = [], []
    for node, val in _docstring_nodes(tree):
        start = offsets[val.lineno - 1] + val.col_offset
        end = offsets[val.end_lineno - 1] + val.end_col_offset
        text = source[start:end]
        m = re.fullmatch(r'([rRuU]?)("""|\'\'\')(.*)\2', text, re.S)
        if not m:
            todo.append(f'{where}:{val.lineno}: docstring is not one triple-quoted literal')
            continue
        prefix, quote, body = m.groups()
        if re.search(r'\\\n', body):
            if body.startswith('\n'):
                continue
            todo.append(f'{where}:{val.lineno}: backslash-newline in docstring')
            continue
        indent = ' ' * val.col_offset if not isinstance(node, ast.Module) else ''
        new_body, problem = _layout(body, indent)
        if problem:
            todo.append(f'{where}:{val.lineno}: {problem}')
        if new_body is not None:
            edits.append((start, end, prefix + quote + new_body + quote))
    out, pos = [], 0
    for start, end, new in sorted(edits):
        out.append(source[pos:start])
        out.append(new)
        pos = end
    out.append(source[pos:])
    return ''.join(out), todo


def _clause_end(text: str, limit: int, marks: str) -> int:
    """Return the index of the last of ``marks`` + ' ' at depth 0 before ``limit``, or -1."""
    best = -1
    for i, c in _top_level(text, limit):
        if c in marks and text[i + 1:i + 2] == ' ' and i >= 30:
            best = i
    return best


def main(argv) -> int:
    roots = argv or ['ipmc_sensor_ros', 'test', 'launch', 'scripts', 'bench', 'examples',
                     'setup.py']
    todo = []
    files = []
    for r in map(Path, roots):
        files += sorted(r.rglob('*.py')) if r.is_dir() else [r]
    for f in files:
        src = f.read_text(encoding='utf-8')
        new, left = fix_docstrings(add_spdx(requote(src)), str(f))
        todo += left
        compile(new, str(f), 'exec')  # never write a file that no longer parses
        if new != src:
            f.write_text(new, encoding='utf-8')
    print('\n'.join(todo))
    print(f'{len(files)} files checked; {len(todo)} docstring summaries to review by hand (above)')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))

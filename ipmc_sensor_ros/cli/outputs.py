# SPDX-License-Identifier: Apache-2.0
r"""
How the command line writes its outputs and names files.

* **Complete or absent**: an output is written under a temporary name in a private
  directory beside it and appears under its final name only once complete, so an error
  (or a signal) never leaves an empty or half-written output behind.
* **Created exclusively**: without ``--overwrite`` an output that exists is never replaced
  (estimates, records, saved models and parameter files; ``--json`` and ``--report``, what a
  rerun gives again, are); the second writer (another run, or a second input of the same
  name in one run) refuses, naming the output and what wrote it first.  Appearing under the
  final name is atomic (``link`` for a file, ``rename`` onto a missing name for a bag
  directory), so two runs started together cannot both win.
* **Any file name**: names that are not UTF-8 (a Latin-1 ``é`` from an old instrument PC)
  are handled as bytes and shown with escapes (``caf\xe9.csv``), never an encoding error.
"""
from __future__ import annotations

import datetime
import os
import shutil
from pathlib import Path
from typing import Callable

from ..physics.parameters import ParameterError

__all__ = ['printable', 'write_complete', 'first_writer', 'check_free', 'check_outputs',
           'OUTPUT_FILE_FLAGS']

#: The flags that name one file a verb keeps (argparse dest: flag): a calibration or a model,
#: refused when it exists (without ``--overwrite``).  ``--json`` and ``--report``, the numbers
#: and plots of one run that rerunning gives again, are replaced, as a test runner's report.
OUTPUT_FILE_FLAGS = {'save': '--save', 'save_material': '--save-material',
                     'save_model': '--save-model', 'save_plugin': '--save-plugin'}


def printable(text) -> str:
    r"""
    Return ``text`` (a str or a path) safe to print and to write into a UTF-8 file.

    Bytes of a file name that are not UTF-8 (held by Python as surrogates) are shown as
    ``\xNN`` escapes.
    """
    return str(text).encode('utf-8', 'surrogateescape').decode('utf-8', 'backslashreplace')


def first_writer(path: Path) -> str:
    """Say what wrote ``path``: its ``# source:`` header line (if any) and its time."""
    when = datetime.datetime.fromtimestamp(path.stat().st_mtime).isoformat(timespec='seconds')
    source = ''
    if path.is_file():
        with open(path, 'rb') as f:
            for raw in f.read(4096).splitlines()[:12]:
                line = raw.decode('utf-8', 'backslashreplace')
                if line.startswith('# source: '):
                    source = f'from {line[10:]} '
                    break
    return f'{source}at {when}'


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    elif path.exists() or path.is_symlink():
        path.unlink()


def write_complete(final: Path, write: Callable[[Path], None], overwrite: bool) -> str:
    """
    Write an output by ``write(path)`` and give it its final name (module docstring).

    Returns '' or, with ``overwrite``, a note naming what was replaced.  ParameterError
    naming ``final`` and its first writer when it exists and ``overwrite`` is false.
    """
    check_free(final, overwrite)
    made = [p for p in (final.parent, *final.parent.parents) if not p.exists()]
    final.parent.mkdir(parents=True, exist_ok=True)
    scratch = final.parent / f'.ipmc-partial-{os.getpid()}'
    scratch.mkdir(exist_ok=True)
    part = scratch / final.name
    done = False
    try:
        write(part)
        note = f'replaced {printable(final)} (written {first_writer(final)})' \
            if final.exists() else ''
        if overwrite:
            if part.is_dir():
                _remove(final)
            os.replace(part, final)
        elif part.is_dir():
            try:
                os.rename(part, final)      # fails onto a non-empty directory
            except OSError:
                raise _exists(final) from None
        else:
            try:
                os.link(part, final)        # never replaces an existing name
            except FileExistsError:
                raise _exists(final) from None
        done = True
        return note
    finally:
        _remove(part)
        for folder in [scratch] + ([] if done else made):   # directories made for nothing
            try:
                folder.rmdir()
            except OSError:
                pass


def check_free(final: Path, overwrite: bool, flag: str = '--out') -> None:
    """Refuse ``final`` when it exists and ``overwrite`` is false (before any work is done)."""
    if final.exists() and not overwrite:
        raise _exists(final, flag)


def check_outputs(args) -> None:
    """
    Refuse, before any work, the files a verb keeps that exist (without ``--overwrite``).

    The files of :data:`OUTPUT_FILE_FLAGS`; two flags naming the same file (``--json``
    included) are refused too: the second write would lose the first, and so is a file
    whose directory does not exist (found after a diagnosis of minutes, it was lost).
    """
    named: dict[Path, str] = {}
    for dest, flag in {'json': '--json', **OUTPUT_FILE_FLAGS}.items():
        value = getattr(args, dest, None)
        if not value:
            continue
        path = Path(value).resolve()
        if path in named:
            raise ParameterError(f'{flag} {printable(value)}: the same file as {named[path]}; '
                                 'give each output its own name')
        named[path] = flag
        if not path.parent.is_dir():          # said now, not after the work it would keep
            raise ParameterError(f'{flag} {printable(value)}: no directory '
                                 f'{printable(path.parent)} to write it in')
        if dest in OUTPUT_FILE_FLAGS:
            check_free(Path(value), bool(getattr(args, 'overwrite', False)), flag)


def _exists(final: Path, flag: str = '--out') -> ParameterError:
    return ParameterError(f'{printable(final)}: exists, written {first_writer(final)}; not '
                          f'replaced (pass --overwrite to replace it, or choose another {flag})')

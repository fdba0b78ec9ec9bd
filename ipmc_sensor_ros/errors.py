# SPDX-License-Identifier: Apache-2.0
"""
The package's errors: one base class, a subclass per kind of fault.

Every error the package raises on purpose is an :class:`IpmcError` (a ``ValueError``), whose
text names the thing and the place (parameter, file:line, topic); command lines and nodes turn
it into one line and exit status 2, never a traceback.

* :class:`ParameterError` -- a parameter, a params/model file entry or a model description that
  cannot make a valid model or estimator (including a reduction that cannot be fitted).
* :class:`DataError` -- input samples or messages that break a stream rule or the block layout.
* :class:`DataFormatError` -- a measurement file or bag that cannot be read (with ``path`` and
  ``line`` / ``topic``).
"""
from __future__ import annotations

import difflib
from typing import Iterable

__all__ = ['IpmcError', 'ParameterError', 'DataError', 'DataFormatError', 'did_you_mean',
           'defect_text']


def did_you_mean(names: Iterable[str], known: Iterable[str]) -> str:
    """Return "; did you mean 'k' for 'n'?" for each name close to a known one ('' if none)."""
    known = list(known)
    return ''.join(f"; did you mean '{near[0]}' for '{name}'?" for name in names
                   for near in [difflib.get_close_matches(name, known, 1)] if near)


def defect_text(exc: BaseException) -> str:
    """
    Return one line for an exception not raised on purpose: a defect, not the user's input.

    Its type and text, and the package's innermost line it passed (where to look), so a
    command line or node says it without a traceback.
    """
    import os
    import traceback
    package = os.path.dirname(os.path.abspath(__file__))
    frames = traceback.extract_tb(exc.__traceback__) if exc.__traceback__ else []
    ours = [f for f in frames
            if os.path.abspath(f.filename).startswith(package + os.sep)] or frames
    where = ''
    if ours:
        name = os.path.abspath(ours[-1].filename)
        shown = os.path.relpath(name, package) if name.startswith(package + os.sep) else name
        where = f" at {shown.replace(os.sep, '/')}:{ours[-1].lineno}"
    return (f'internal error ({type(exc).__name__}: {exc}){where}: a defect of '
            'ipmc_sensor_ros, please report it')


class IpmcError(ValueError):
    """Base class of the package's deliberate errors."""


class ParameterError(IpmcError):
    """A parameter, configuration entry or model description that is invalid."""


class DataError(IpmcError):
    """
    Input data (samples, times, message layout) that break a rule of the stream.

    ``index`` (optional): 0-based index of the offending sample in the block checked, so
    that a caller reading a file can name its line.
    """

    def __init__(self, *args, index: int | None = None) -> None:
        super().__init__(*args)
        self.index = index


class DataFormatError(DataError):
    """
    An input file or bag that cannot be read as valid measurement data.

    Attributes
    ----------
    path : str, the file or bag (as given).
    line : int or None, 1-based line of the problem in a text file.
    topic : str or None, the bag topic concerned.
    reason : str, the message without the location prefix.

    ``str()`` is ``"<path>:<line>: <reason>"``, ``"<path>: topic '<topic>': <reason>"`` or
    ``"<path>: <reason>"``.

    """

    def __init__(self, path, line: int | None, reason: str, *, topic: str | None = None) -> None:
        self.path = str(path)
        self.line = line
        self.topic = topic
        self.reason = reason
        super().__init__(self._format())

    def _format(self) -> str:
        where = self.path
        if self.line is not None:
            where += f':{self.line}'
        if self.topic is not None:
            where += f": topic '{self.topic}'"
        return f'{where}: {self.reason}'

    def __str__(self) -> str:
        return self._format()

    def __reduce__(self):  # picklable despite the keyword-only argument
        return (_rebuild_data_format_error, (self.path, self.line, self.reason, self.topic))


def _rebuild_data_format_error(path, line, reason, topic):
    return DataFormatError(path, line, reason, topic=topic)

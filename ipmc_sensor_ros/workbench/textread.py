# SPDX-License-Identifier: Apache-2.0
"""
Streaming reader of numeric text tables: regular files only, bounded size and rows.

Shared by the ``ipmc-timeseries/1`` / ``ipmc-frf/1`` readers and the lab
import.  A file is opened without blocking and refused unless it is a regular
file (a FIFO, ``/dev/zero`` or a socket is refused at once: no hang, no
unbounded memory), its size is checked against ``max_bytes`` and its data rows
against ``max_rows``.  Header lines are read one by one; data rows are read in
chunks of :data:`CHUNK_BYTES` and parsed by ``numpy.loadtxt`` when the chunk
holds only ASCII number characters (the common case, linear time), else line
by line, which gives the exact error (file:line, column, cell).

Numbers are ASCII decimals only (``[+-]digits[.digits][e[+-]digits]``):
Unicode digits, underscores, NaN and Inf are refused.

A data row is a line with its line end.  A last line without one is a row still being
written (a recorder appending to the file, or a copy taken mid-write: ``-6.937703375`` cut
from ``-6.9377033751e-07`` is still a number) and is not read: the complete rows are, and
:attr:`TextSource.incomplete_line` names the line so the reader can say so.  A file written
without a final line end loses its last row, named, never a row with a wrong value.
"""
from __future__ import annotations

import io as _io
import os
import re
import stat
from typing import Callable, Iterator, Sequence

import numpy as np

from .measurements import DataFormatError, PathLike

__all__ = ['MAX_BYTES', 'MAX_ROWS', 'CHUNK_BYTES', 'TextSource', 'parse_number', 'read_table']

#: Default size limit of a text file, bytes (about 30 million 3-column rows).
MAX_BYTES = 2 * 1024**3
#: Default limit on data rows (about 2.8 h at 1 kHz; 240 MB for 3 columns).
MAX_ROWS = 10_000_000
#: Bytes read per chunk of data rows.
CHUNK_BYTES = 1 << 22
#: Longest accepted line, bytes.
MAX_LINE_BYTES = 1 << 20

_NUMBER = re.compile(r'[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?', re.ASCII)
_NONFINITE = {'nan', 'inf', 'infinity'}
_NUMERIC_BYTES = b'0123456789+-.eE \t\r\n'


def parse_number(text: str, decimal: str = '.') -> float | None:
    """Finite float of an ASCII decimal number string (``decimal`` ',' allowed), or None."""
    s = text.strip()
    if decimal != '.':
        if '.' in s:
            return None
        s = s.replace(decimal, '.')
    if not _NUMBER.fullmatch(s):
        return None
    v = float(s)
    return v if np.isfinite(v) else None


def cell_error(path, lineno: int, cell: str, column: str, decimal: str = '.') -> DataFormatError:
    """Return the error for a cell :func:`parse_number` refused."""
    s = cell.strip()
    if not s:
        return DataFormatError(path, lineno, f'empty cell in column {column}')
    if s.lower().lstrip('+-') in _NONFINITE:
        return DataFormatError(path, lineno, f'NaN/Inf cell {s!r} in column {column} '
                               '(every value must be a finite number)')
    if _NUMBER.fullmatch(s.replace(decimal, '.') if decimal != '.' else s):
        return DataFormatError(path, lineno, f'NaN/Inf: cell {s!r} in column {column} '
                               'overflows to infinity')
    return DataFormatError(path, lineno, f'non-numeric cell {s!r} in column {column}')


def _open_regular(path: PathLike, max_bytes: int | None):
    """Open ``path`` for binary reading if it is a regular file within ``max_bytes``."""
    try:
        fd = os.open(os.fspath(path), os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError:
        raise DataFormatError(path, None, 'file not found') from None
    except IsADirectoryError:
        fd = None
    except OSError as exc:
        raise DataFormatError(path, None, f'cannot read file: {exc.strerror or exc}') from None
    mode = os.fstat(fd).st_mode if fd is not None else stat.S_IFDIR
    if not stat.S_ISREG(mode):
        if fd is not None:
            os.close(fd)
        if stat.S_ISDIR(mode):
            raise DataFormatError(path, None, 'is a directory, expected a text file '
                                  '(bags are read with read_bag or read_any)')
        kind = ('a FIFO (named pipe)' if stat.S_ISFIFO(mode) else
                'a character device' if stat.S_ISCHR(mode) else
                'a block device' if stat.S_ISBLK(mode) else
                'a socket' if stat.S_ISSOCK(mode) else 'not a regular file')
        raise DataFormatError(path, None, f'not a regular file ({kind}): refusing to read it '
                              '(copy the data into a file first)')
    size = os.fstat(fd).st_size
    if max_bytes is not None and size > max_bytes:
        os.close(fd)
        raise DataFormatError(path, None, f'file is {size} bytes, above the limit of '
                              f'{max_bytes} bytes (max_bytes)')
    os.set_blocking(fd, True)
    return os.fdopen(fd, 'rb')


#: How an encoding is named in messages.
_ENCODING_NAMES = {'utf-8': 'UTF-8', 'cp1252': 'Windows-1252'}


class TextSource:
    """
    A UTF-8 text file read as header lines, then chunks of whole data lines.

    Use as a context manager.  ``lineno`` is the number of lines consumed.  With
    ``fallback_encoding`` (lab exports: Windows PCs write ``cp1252``), a line that is not UTF-8
    is decoded with it instead, and so is every later line; ``encoding`` then names it so the
    caller can say so.
    """

    def __init__(self, path: PathLike, *, max_bytes: int | None = MAX_BYTES,
                 fallback_encoding: str | None = None) -> None:
        self.path = path
        self.max_bytes = max_bytes
        self.encoding = 'utf-8'
        self._fallback = fallback_encoding
        self._file = _open_regular(path, max_bytes)
        self._buf = b''
        self._offset = 0  # file offset of _buf[0]
        self._eof = False
        self.lineno = 0
        #: 1-based line of a last data line without a line end, not read (module docstring)
        self.incomplete_line: int | None = None

    def __enter__(self) -> 'TextSource':
        return self

    def __exit__(self, *exc) -> None:
        self._file.close()

    def _fill(self) -> bool:
        if self._eof:
            return False
        data = self._file.read(CHUNK_BYTES)
        if not data:
            self._eof = True
            return False
        read = self._offset + len(self._buf) + len(data)
        if self.max_bytes is not None and read > self.max_bytes:
            raise DataFormatError(self.path, None, f'file grew above the limit of '
                                  f'{self.max_bytes} bytes (max_bytes) while being read')
        if self._offset == 0 and not self._buf and data.startswith(b'\xef\xbb\xbf'):
            data, self._offset = data[3:], 3  # byte-order mark written by some editors
        self._buf += data
        return True

    def _check(self, raw: bytes, first_line: int) -> str:
        try:
            text = raw.decode(self.encoding)
        except UnicodeDecodeError as exc:
            line = first_line + raw.count(b'\n', 0, exc.start)
            shown = _ENCODING_NAMES.get(self.encoding, self.encoding)
            error = DataFormatError(self.path, line, f'not {shown} text (binary file?): '
                                    f'byte 0x{raw[exc.start]:02x} at offset '
                                    f'{self._offset + exc.start} cannot be decoded')
            if self._fallback is None or self.encoding == self._fallback:
                raise error from None
            self.encoding = self._fallback
            try:
                text = raw.decode(self.encoding)
            except UnicodeDecodeError:
                raise error from None
        if '\x00' in text:
            pos = text.index('\x00')
            raise DataFormatError(self.path, first_line + text.count('\n', 0, pos),
                                  'binary file: NUL byte in text')
        return text

    def _too_long(self) -> DataFormatError:
        return DataFormatError(self.path, self.lineno + 1, f'line longer than {MAX_LINE_BYTES} '
                               'bytes (not a text table?)')

    def next_line(self) -> str | None:
        """Return the next line without its line end, or None at the end of the file."""
        while True:
            cut = self._buf.find(b'\n')
            if cut >= 0 or len(self._buf) > MAX_LINE_BYTES or not self._fill():
                break
        if cut > MAX_LINE_BYTES or (cut < 0 and len(self._buf) > MAX_LINE_BYTES):
            raise self._too_long()
        if cut < 0:
            if not self._buf:
                return None
            cut = len(self._buf)
        raw = self._buf[:cut]
        text = self._check(raw, self.lineno + 1)
        self._buf = self._buf[cut + 1:]
        self._offset += cut + 1
        self.lineno += 1
        return text[:-1] if text.endswith('\r') else text

    def unread(self, line: str) -> None:
        """Put back the line just returned by :meth:`next_line` (read again next)."""
        raw = (line + '\n').encode('utf-8')
        self._buf = raw + self._buf
        self._offset -= len(raw)
        self.lineno -= 1

    def chunks(self) -> Iterator[tuple[int, bytes]]:
        r"""(1-based line of the first line, bytes of whole lines each ending in '\n')."""
        while True:
            if len(self._buf) < CHUNK_BYTES:
                self._fill()
            while b'\n' not in self._buf and not self._eof:
                if len(self._buf) > MAX_LINE_BYTES:
                    raise self._too_long()
                self._fill()
            if not self._buf:
                return
            cut = self._buf.rfind(b'\n') + 1
            if self._eof and cut < len(self._buf):
                tail = self._buf[cut:]
                self._check(tail, self.lineno + self._buf.count(b'\n', 0, cut) + 1)
                if tail.strip():
                    self.incomplete_line = self.lineno + self._buf.count(b'\n', 0, cut) + 1
                self._buf = self._buf[:cut]
                if not cut:
                    return
            raw = self._buf[:cut]
            self._check(raw, self.lineno + 1)
            first = self.lineno + 1
            self._buf = self._buf[cut:]
            self._offset += cut
            self.lineno += raw.count(b'\n')
            yield first, raw


#: check(block, prev_row, first_line) -> None; raises at the first bad row
BlockCheck = Callable[[np.ndarray, 'np.ndarray | None', int], None]


def _fast_block(raw: bytes, ncol: int, delimiter: str, decimal: str) -> np.ndarray | None:
    """All rows of ``raw`` as an (n, ncol) array, or None if any line needs a closer look."""
    allowed = _NUMERIC_BYTES + delimiter.encode() + decimal.encode()
    if raw.translate(None, allowed):  # blank lines: loadtxt skips them, the shape check sees it
        return None
    if raw.count(b'\r') != raw.count(b'\r\n'):
        return None
    if decimal != '.':
        if b'.' in raw:
            return None
        raw = raw.replace(decimal.encode(), b'.')
    try:
        block = np.loadtxt(_io.BytesIO(raw), delimiter=delimiter, comments=None, ndmin=2,
                           dtype=float)
    except ValueError:
        return None
    if block.shape != (raw.count(b'\n'), ncol) or not np.isfinite(block).all():
        return None
    return block


def _slow_block(path, raw: bytes, first: int, columns: Sequence[str], delimiter: str,
                decimal: str, state: dict, encoding: str = 'utf-8',
                empty_last: bool = False) -> tuple[np.ndarray, DataFormatError | None]:
    """Rows parsed line by line up to the first error (returned, not raised)."""
    ncol = len(columns)
    rows: list[list[float]] = []
    # a byte the encoding cannot decode becomes U+FFFD: that row is then refused as not numeric
    for k, text in enumerate(raw.decode(encoding, errors='replace').split('\n')[:-1]):
        lineno = first + k
        if text.endswith('\r'):
            text = text[:-1]
        s = text.strip()
        if not s:
            state.setdefault('blank', lineno)
            continue
        if 'blank' in state:
            return _rows(rows, ncol), DataFormatError(
                path, state['blank'], 'blank line between data rows (data rows must be contiguous)'
            )
        if s.startswith('#'):
            return _rows(rows, ncol), DataFormatError(
                path, lineno, 'header/comment line after the column header '
                '(header lines must come first)')
        cells = text.split(delimiter)
        if len(cells) != ncol:
            hint = ''
            if delimiter == ',' and ';' in text:
                hint = " (cells are separated by ',', not ';')"
            return _rows(rows, ncol), DataFormatError(
                path, lineno, f'wrong number of cells: expected {ncol} '
                f'({delimiter.join(columns)}), got {len(cells)}{hint}')
        row = []
        last = empty_last and not cells[-1].strip()
        for cell, column in zip(cells[:-1] if last else cells, columns):
            v = parse_number(cell, decimal)
            if v is None:
                return _rows(rows, ncol), cell_error(path, lineno, cell, column, decimal)
            row.append(v)
        rows.append(row + [float('nan')] if last else row)
    return _rows(rows, ncol), None


def _rows(rows: list, ncol: int) -> np.ndarray:
    return np.array(rows, dtype=float).reshape(len(rows), ncol)


def read_table(source: TextSource, columns: Sequence[str], check: BlockCheck | None = None, *,
               delimiter: str = ',', decimal: str = '.', max_rows: int | None = MAX_ROWS,
               header_line: int | None = None,
               empty_last: bool = False) -> tuple[list[np.ndarray], int]:
    """
    Read the data rows left in ``source``: (one array per column, line of the first row).

    Rows are contiguous; empty lines are allowed only at the end.  ``check``
    sees each parsed block with the previous row, in file order, so the first
    problem in the file is the one reported.  At least two rows are needed.
    ``empty_last``: the last column is the empty cell after a delimiter that ends each line
    (spreadsheet exports); empty, it reads as NaN.
    """
    ncol = len(columns)
    parts: list[list[np.ndarray]] = [[] for _ in columns]
    state: dict = {}
    prev: np.ndarray | None = None
    first_row_line: int | None = None
    n = 0
    for first, raw in source.chunks():
        fast = 'blank' not in state and not empty_last
        block = _fast_block(raw, ncol, delimiter, decimal) if fast else None
        error = None
        if block is None:
            block, error = _slow_block(source.path, raw, first, columns, delimiter, decimal, state,
                                       source.encoding, empty_last)
        if block.shape[0]:
            if first_row_line is None:
                first_row_line = first  # a blank line before a row is an error: rows start here
            if check is not None:
                check(block, prev, first_row_line + n)
            prev = block[-1]
        n += block.shape[0]
        if max_rows is not None and n > max_rows:
            raise DataFormatError(source.path, first_row_line + max_rows, f'more than {max_rows} '
                                  'data rows (max_rows); split the recording')
        if error is not None:
            raise error
        for j in range(ncol):
            parts[j].append(np.ascontiguousarray(block[:, j]))
    if n == 0:
        raise DataFormatError(source.path, header_line, 'no data rows after the column '
                              'header (at least 2 are needed)')
    if n < 2:
        raise DataFormatError(source.path, first_row_line, 'only 1 data row; at least 2 are '
                              'needed')
    out = []
    for j in range(ncol):
        out.append(np.concatenate(parts[j]))
        parts[j] = []
    return out, first_row_line


def increasing_check(path, column: str, unit: str, index: int = 0,
                     repeats: bool = False) -> BlockCheck:
    """
    Return a :func:`read_table` check that column ``index`` strictly increases.

    ``column`` names it, in ``unit``; ``repeats``: a value equal to the one before passes
    (a lab import drops such rows itself, counted).  The error names the line, both values
    and the previous line.
    """
    def check(block: np.ndarray, prev: np.ndarray | None, line0: int) -> None:
        t = block[:, index] if prev is None else np.concatenate(([prev[index]], block[:, index]))
        offset = 0 if prev is None else 1
        k = first_bad(np.diff(t) < 0 if repeats else np.diff(t) <= 0)
        if k is None:
            return
        lineno = line0 + k + 1 - offset
        now, before = repr(float(t[k + 1])), repr(float(t[k]))
        if t[k + 1] == t[k]:
            raise DataFormatError(path, lineno, f'duplicate time {now} {unit} (same as line '
                                  f'{lineno - 1}); {column} must be strictly increasing')
        rule = (f'{column} must not go back (a repeated time is left out, counted; one going '
                'back is a second run or a clock that wrapped: split the file there)'
                if repeats else f'{column} must be strictly increasing')
        raise DataFormatError(path, lineno, f'time decreases: {now} {unit} after {before} {unit} '
                              f'on line {lineno - 1}; {rule}')
    return check


def first_bad(mask: np.ndarray) -> int | None:
    """Index of the first True of ``mask``, or None."""
    if not mask.any():
        return None
    return int(np.argmax(mask))

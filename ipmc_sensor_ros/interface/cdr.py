# SPDX-License-Identifier: Apache-2.0
"""
One-sample blocks on the wire: the CDR bytes of a one-row ``Float64MultiArray``, without ROS.

DDS carries ROS 2 messages as CDR (XCDR1): a 4-byte encapsulation header (``00 01 00 00``
little-endian, ``00 00 00 00`` big-endian), then the fields in order, each primitive of n
bytes aligned to n from the end of the header; a string is a uint32 length (with its NUL)
and the characters; a sequence a uint32 count and the elements.  Padding bytes carry no data
(serialisers leave whatever was in their buffer there).

A one-sample block of a given column layout (:mod:`ipmc_sensor_ros.interface.blocks`) is then
a constant prefix (header, the two dimensions, the data offset and length) followed by its one
row of float64.  :class:`OneSampleCodec` reads such a message with one comparison of the prefix
(padding skipped) and one ``struct`` unpack, and writes one by appending the packed row: what
the estimator node does with one-sample messages (rclpy's conversion of the message object cost
more than the estimate) and the bag reader with one-sample recordings.  Every other message
reads as ``None`` and takes the general path with its precise layout checks.  Tested against
rclpy's serialiser (byte for byte, padding zeroed) in ``test/test_nodes_unit.py``.
"""
from __future__ import annotations

import struct

from .blocks import SAMPLE_LABEL

__all__ = ['CdrWalk', 'OneSampleCodec', 'LITTLE_ENDIAN_HEADER']

#: Encapsulation header of little-endian plain CDR (what x86 and ARM publishers send).
LITTLE_ENDIAN_HEADER = b'\x00\x01\x00\x00'


class CdrWalk:
    """
    Offsets of a CDR serialisation, field by field: where each starts, which bytes are padding.

    Optionally writes the fields (``out``, little-endian) as it goes.
    """

    def __init__(self, write: bool = False):
        self.pos = 4
        self.pads: list[int] = []
        self.out = bytearray(LITTLE_ENDIAN_HEADER) if write else None

    def field(self, size: int, count: int = 1, fmt: str = '', *values) -> int:
        """Skip (or write) ``count`` primitives of ``size`` bytes; return where the first is."""
        while (self.pos - 4) % size:
            self.pads.append(self.pos)
            self.pos += 1
            if self.out is not None:
                self.out.append(0)
        start = self.pos
        self.pos += size * count
        if self.out is not None:
            self.out += struct.pack('<' + fmt, *values) if fmt else bytes(size * count)
        return start

    def string(self, text: str) -> None:
        """Skip (or write) a string: its length with the NUL, then the characters and the NUL."""
        data = text.encode() + b'\x00'
        self.field(4, 1, 'I', len(data))
        self.pos += len(data)
        if self.out is not None:
            self.out += data

    def spans(self, end: int) -> list[tuple[int, int]]:
        """Return the data spans of bytes 0 .. end - 1 as (start, stop) pairs, padding excluded."""
        out, start = [], 0
        for p in [q for q in self.pads if q < end] + [end]:
            if p > start:
                out.append((start, p))
            start = p + 1
        return out


class OneSampleCodec:
    """
    Read and write one-sample blocks of one column layout as (little-endian) CDR bytes.

    ``columns`` is the block's column label (``time_s,current_A``, ...): one time and
    ``width - 1`` values per row.  :meth:`decode` returns the row as floats or ``None`` for any
    other message (another layout, length or byte order); :meth:`encode` returns the bytes of a
    row, byte for byte what a ROS 2 serialiser writes (padding zeroed).
    """

    def __init__(self, columns: str):
        width = len(columns.split(','))
        walk = CdrWalk(write=True)
        walk.field(4, 1, 'I', 2)                        # layout.dim: two dimensions
        for label, size in ((SAMPLE_LABEL, 1), (columns, width)):
            walk.string(label)
            walk.field(4, 2, 'II', size, width)         # size, stride
        walk.field(4, 2, 'II', 0, width)                # layout.data_offset, len(data)
        self._cut = walk.field(8, width)                # data: the one row (zeros)
        self.columns = columns
        self.size = walk.pos
        self._prefix = bytes(walk.out[:self._cut])
        self._spans = walk.spans(self._cut)
        self._row = struct.Struct('<' + 'd' * width)

    def decode(self, raw: bytes) -> tuple[float, ...] | None:
        """Return the row (time, values...) of a one-sample block, or None for any other."""
        if len(raw) != self.size:
            return None
        prefix = self._prefix
        if not raw.startswith(prefix):                  # padding bytes not zero: compare data
            for a, b in self._spans:
                if raw[a:b] != prefix[a:b]:
                    return None
        return self._row.unpack_from(raw, self._cut)

    def encode(self, *row: float) -> bytes:
        """Return the serialised one-sample block of ``row`` (time, values...)."""
        return self._prefix + self._row.pack(*row)

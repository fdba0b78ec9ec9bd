# SPDX-License-Identifier: Apache-2.0
"""
One source per stream: which publisher of a topic a node follows, without ROS.

Two publishers on one topic are two streams: their samples interleave, each stamp lands between
the other's, and a stream rule that judges a sample against the previous one refuses both.  A
node therefore follows one publisher, identified by the GID that the middleware delivers with
each message (``MessageInfo['publisher_gid']``), and ignores (and counts) the others:

* the first publisher heard is followed;
* a message of another publisher is ignored while the followed one is alive: it sent a message
  less than ``stale_after_s`` ago (steady clock).  Once it has been silent for longer (a driver
  restarted under a new GID, a publisher replaced), the next publisher heard is followed: a
  *switch*, counted and said;
* messages of the followed publisher that never arrived are counted from its publication
  sequence numbers (``MessageInfo['publication_sequence_number']``): a jump from n to n + m
  means m - 1 messages lost between it and the node (a reader queue that overflowed, a lost
  best-effort sample), which the middleware's own message-lost event does not always report.

A middleware that gives no GID (None) makes every message one source's, and no sequence
numbers no loss count: nothing is ignored then.  The ROS shell is
:class:`ipmc_sensor_ros.nodes.estimator_node.EstimatorNode`.
"""
from __future__ import annotations

__all__ = ['SourceSelector', 'IGNORED', 'SWITCHED', 'gid_text', 'MAX_NAMED_SOURCES']

#: :meth:`SourceSelector.admit` codes besides n >= 0 (messages lost before this one).
IGNORED, SWITCHED = -1, -2

#: Ignored publishers remembered by name and count (the oldest is forgotten beyond this: a
#: peer creating publisher after publisher must not grow the node's memory).
MAX_NAMED_SOURCES = 16


def gid_text(gid: bytes | None) -> str:
    """Return a publisher GID as hex (the way ``ros2 topic info -v`` shows it), or '?'."""
    return '?' if gid is None else gid.hex('.')


class SourceSelector:
    """
    Follows one publisher of a stream (module docstring).

    Parameters
    ----------
    stale_after_s : float
        Silence of the followed publisher after which another one is followed, s.

    """

    def __init__(self, stale_after_s: float):
        self.stale_after_s = float(stale_after_s)
        self.followed: bytes | None = None
        self.previous: bytes | None = None     # followed before the last switch
        self.ignored: dict[bytes, int] = {}    # publisher GID -> messages ignored
        self.names: dict[bytes, str] = {}      # publisher GID -> node name, where known
        self._seen_s = 0.0
        self._seq: int | None = None

    def admit(self, gid: bytes | None, seq: int | None, now_s: float) -> int:
        """
        Decide one message of publisher ``gid`` with sequence number ``seq`` at ``now_s``.

        Returns the number of messages of the followed publisher lost before this one
        (0 normally), ``IGNORED`` (another publisher's: counted in :attr:`ignored`) or
        ``SWITCHED`` (taken: the followed publisher changed to ``gid``).
        """
        code = 0
        if gid != self.followed:
            if gid is None:
                return 0
            if self.followed is not None and now_s - self._seen_s <= self.stale_after_s:
                n = self.ignored.get(gid)
                if n is None and len(self.ignored) >= MAX_NAMED_SOURCES:
                    oldest = next(iter(self.ignored))
                    del self.ignored[oldest]
                    self.names.pop(oldest, None)
                self.ignored[gid] = (n or 0) + 1
                return IGNORED
            if self.followed is not None:
                self.previous, code = self.followed, SWITCHED
            self.followed, self._seq = gid, None
        self._seen_s = now_s
        if seq is not None:
            last, self._seq = self._seq, seq
            if code == 0 and last is not None and seq > last + 1:
                return seq - last - 1
        return code

    def forget(self) -> None:
        """Follow the next publisher heard (a new stream, e.g. a managed node activated)."""
        self.followed = None
        self._seq = None

    def name(self, gid: bytes | None) -> str:
        """Return the node name of publisher ``gid`` where known, with its GID."""
        node = self.names.get(gid) if gid is not None else None
        return f'{node} (gid {gid_text(gid)})' if node else f'gid {gid_text(gid)}'

    def describe_ignored(self) -> str:
        """Return the ignored publishers and their message counts, one line."""
        return ', '.join(f'{self.name(g)}: {n}' for g, n in self.ignored.items())

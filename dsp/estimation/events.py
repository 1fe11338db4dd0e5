"""Event counters and range logs without a fixed slot count.

A filter names its signals (one saturating format each) and its other events; the
registry lays them out in one ``int64`` array per trial::

    [sat_<signal> for each signal] [other events] [min, max for each signal]

so ``ev[i]`` counts the clamps of signal ``i``, the other events follow, and the range log
of signal ``i`` sits at ``ev[base + 2 i]``, ``ev[base + 2 i + 1]`` (``base`` = number of
counters). The operators of :mod:`dsp.qops` take ``(ev, i, base)``. Unlike
``dsp.qops`` (``RANGE_SLOTS = 8``, kept for the TACAN core) the size follows the filter.
"""
from __future__ import annotations

import numpy as np

_IMAX = np.iinfo(np.int64).max
_IMIN = np.iinfo(np.int64).min


class EventRegistry:
    """Layout of the event/range array of one filter.

    Parameters
    ----------
    signals : sequence of str
        Signals with a saturating format (each gets ``sat_<name>`` and a range log).
    events : sequence of str
        Other counted events (``implausible``, ``chol_fail``, ...).
    """

    def __init__(self, signals, events):
        signals, events = tuple(signals), tuple(events)
        names = tuple(f"sat_{s}" for s in signals) + events
        if len(set(names)) != len(names):
            raise ValueError(f"event names must be unique, not {names}")
        self.signals = signals
        self.events = events
        self.names = names
        self.base = len(names)
        self.size = self.base + 2 * len(signals)
        self._index = {n: i for i, n in enumerate(names)}
        self._sig = {s: i for i, s in enumerate(signals)}

    def index(self, name: str) -> int:
        """Counter index of an event (``sat_x``, ``implausible``, ...)."""
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"no event {name!r}; events are {self.names}") from None

    def signal(self, name: str) -> int:
        """Index of a signal (its ``sat_`` counter and its range slot)."""
        try:
            return self._sig[name]
        except KeyError:
            raise KeyError(f"no signal {name!r}; signals are {self.signals}") from None

    def new(self, shape_prefix=()) -> np.ndarray:
        """A zeroed event array with empty range logs."""
        ev = np.zeros(tuple(shape_prefix) + (self.size,), np.int64)
        ev[..., self.base::2] = _IMAX
        ev[..., self.base + 1::2] = _IMIN
        return ev

    def counts(self, ev) -> dict:
        """Counters summed over any leading (trial) axes: ``{name: int}``."""
        ev = np.asarray(ev).reshape(-1, self.size)
        return {n: int(ev[:, i].sum()) for i, n in enumerate(self.names)}

    def ranges(self, ev, fracs: dict | None = None) -> dict:
        """Logged ``(min, max)`` per signal over all trials, ``None`` if never stored; with
        ``fracs`` (``{signal: fraction bits}``) as real values."""
        ev = np.asarray(ev).reshape(-1, self.size)
        out = {}
        for s, i in self._sig.items():
            lo = int(ev[:, self.base + 2 * i].min())
            hi = int(ev[:, self.base + 2 * i + 1].max())
            if lo > hi:
                out[s] = None
            elif fracs is not None:
                out[s] = (lo * 2.0 ** -fracs[s], hi * 2.0 ** -fracs[s])
            else:
                out[s] = (lo, hi)
        return out

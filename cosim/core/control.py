"""The DSP -> FPGA control path and the DSP-side view of FPGA timestamps.

* :class:`ControlPath` -- register writes from the DSP to the FPGA with a latency, in the
  ``writes=`` format of :func:`cosim.backends.pysim.run_stream` /
  ``VerilatorStreamSim.run``, and as constant-value segments for vectorised models (the
  closed loops of the GNSS and monopulse receivers: NCO words, gains, thresholds).
* :func:`unwrap_timestamps` -- the DSP-side unwrapping of the FPGA's wrapping timestamps.

Cycles are FPGA clock cycles counted from reset. The FPGA -> DSP FIFO link is
:mod:`cosim.core.link`.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from dsp.fixed import check_int as _int

__all__ = ["ControlPath", "Segment", "unwrap_timestamps"]


# -- DSP -> FPGA control path -----------------------------------------------------------------
class Segment(NamedTuple):
    """Cycles ``start <= c < stop`` during which the registers hold ``values``."""

    start: int
    stop: int
    values: dict


class ControlPath:
    """Register writes from the DSP to the FPGA, taking effect ``latency_cycles`` later.

    A write issued by the DSP at cycle ``c`` (bus transaction, clock-domain crossing and
    register stage included in ``latency_cycles``) changes the FPGA register from cycle
    ``c + latency_cycles`` on. The DSP is sequential: writes are issued in time order
    (equal cycles allowed; the later write wins when two hit one register in the same
    cycle).

    Causality: a write the DSP issues in response to data it read at cycle ``r`` can only
    be issued at ``c >= r``, so it takes effect at ``>= r + latency_cycles``. Pass
    ``read_cycle=r`` to :meth:`write` to have that checked (add the DSP's processing time to
    ``c`` yourself).

    Parameters
    ----------
    latency_cycles : int
        FPGA cycles from issue to effect (>= 0; 0 means the register holds the new value
        in the very cycle the write is issued, which models an upset of the register
        itself rather than a bus write -- a real DSP write takes several cycles).
    initial : dict of str -> int, optional
        Register values after reset (used before the first write; registers missing here
        show ``None`` in :meth:`segments` until written).

    Examples
    --------
    >>> ctl = ControlPath(latency_cycles=10, initial={"freq": 100})
    >>> ctl.write(500, "freq", 120)
    510
    >>> ctl.writes()
    [(510, 'freq', 120)]
    >>> ctl.segments(1000)
    [Segment(start=0, stop=510, values={'freq': 100}), Segment(start=510, stop=1000, values={'freq': 120})]
    """

    def __init__(self, latency_cycles: int, initial: dict | None = None):
        self._latency = _int("control path latency_cycles", latency_cycles, 0)
        self._initial = {}
        for name, value in (initial or {}).items():
            self._initial[self._check_name(name)] = self._check_value(name, value)
        self._writes: list[tuple[int, str, int]] = []
        self._last_issue = 0

    @staticmethod
    def _check_name(register) -> str:
        if not isinstance(register, str) or not register:
            raise ValueError(f"register must be a port name (non-empty str), not {register!r}")
        return register

    @staticmethod
    def _check_value(register, value) -> int:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ValueError(f"value written to {register!r} must be an integer, not {value!r}")
        return int(value)

    @property
    def latency_cycles(self) -> int:
        return self._latency

    def write(self, cycle_issued: int, register: str, value: int, *,
              read_cycle: int | None = None) -> int:
        """Record a write issued at ``cycle_issued``; return the cycle it takes effect.

        Parameters
        ----------
        cycle_issued : int
            FPGA cycle at which the DSP issues the write (>= the previous write's).
        register : str
            Port name as the Verilog export spells it (e.g. ``"freq"``, ``"ctrl__step"``).
        value : int
        read_cycle : int, optional
            Cycle at which the DSP read the data this write responds to; checked:
            ``cycle_issued >= read_cycle``.
        """
        c = _int("cycle_issued", cycle_issued, 0)
        register = self._check_name(register)
        value = self._check_value(register, value)
        if read_cycle is not None and c < _int("read_cycle", read_cycle, 0):
            raise ValueError(
                f"causality: a write responding to data read at cycle {int(read_cycle)} "
                f"cannot be issued before it (issued at {c}); it takes effect at >= "
                f"{int(read_cycle) + self._latency}")
        if c < self._last_issue:
            raise ValueError(f"writes must be issued in time order: cycle {c} after "
                             f"cycle {self._last_issue}")
        self._last_issue = c
        eff = c + self._latency
        self._writes.append((eff, register, value))
        return eff

    def __len__(self) -> int:
        return len(self._writes)

    def writes(self) -> list[tuple[int, str, int]]:
        """``(cycle, port_name, value)`` in effect order: the ``writes=`` argument of
        :func:`cosim.backends.pysim.run_stream` and ``VerilatorStreamSim.run`` (both apply a write
        before the clock edge of its cycle, in list order)."""
        return list(self._writes)

    def values_at(self, cycle: int) -> dict:
        """Register values in force during ``cycle``."""
        cycle = _int("cycle", cycle, 0)
        vals = dict(self._initial)
        for eff, reg, v in self._writes:
            if eff > cycle:
                break
            vals[reg] = v
        return vals

    def segments(self, n_cycles: int) -> list[Segment]:
        """Split ``0 .. n_cycles - 1`` at every cycle where a write takes effect.

        Returns
        -------
        list of Segment
            ``(start, stop, values)`` covering ``[0, n_cycles)`` without gaps, ``values``
            holding every register known (initial or written; ``None`` before a register's
            first write if it has no initial value). Writes at or after ``n_cycles`` are
            left out. Run a vectorised model chunk by chunk with these values.
        """
        n_cycles = _int("n_cycles", n_cycles, 0)
        names = dict.fromkeys(self._initial)
        names.update(dict.fromkeys(reg for _, reg, _ in self._writes))
        vals = {name: self._initial.get(name) for name in names}
        out: list[Segment] = []
        start = 0
        for eff, reg, v in self._writes:
            if eff >= n_cycles:
                break
            if eff > start:
                out.append(Segment(start, eff, dict(vals)))
                start = eff
            vals[reg] = v
        if n_cycles > start:
            out.append(Segment(start, n_cycles, dict(vals)))
        return out


# -- timestamps --------------------------------------------------------------------------------
def unwrap_timestamps(ts, ts_bits: int, last: int | None = None) -> tuple[np.ndarray, int | None]:
    """Unwrap FPGA timestamps that wrap modulo ``2**ts_bits`` (DSP side, batch by batch).

    Assumption: consecutive timestamps (including the last of the previous batch and the
    first of this one) are less than half a wrap apart (``2**(ts_bits - 1)`` ticks, 107 s for
    32 bits at 20 MHz); each step is taken as the signed difference modulo ``2**ts_bits`` in
    ``[-2**(ts_bits-1), 2**(ts_bits-1))``. Steps longer than that (an outage of more than half
    a wrap) are unwrapped wrongly; :mod:`dsp.tacan.fifo_rx` adds plausibility checks.

    Parameters
    ----------
    ts : array of int
        Wrapped timestamps, ``0 <= ts < 2**ts_bits``, in arrival order.
    ts_bits : int
        Timestamp field width (1..62).
    last : int, optional
        Unwrapped value of the previous batch's last timestamp (the second return value of
        the previous call); None for the first batch, whose first timestamp is taken as is.

    Returns
    -------
    unwrapped : ndarray of int64
    last : int or None
        The last unwrapped timestamp (pass it to the next call); unchanged if ``ts`` is
        empty.
    """
    bits = _int("ts_bits", ts_bits, 1)
    if bits > 62:
        raise ValueError(f"ts_bits must be an integer in [1, 62], not {ts_bits}")
    t = np.asarray(ts)
    if t.size and t.dtype.kind not in "iu":
        raise ValueError(f"timestamps must be integers, not dtype {t.dtype}")
    t = t.astype(np.int64).ravel()
    m = np.int64(1) << np.int64(bits)
    if t.size == 0:
        return t, last
    if t.min() < 0 or t.max() >= m:
        raise ValueError(f"timestamps must lie in [0, 2**{bits}), not "
                         f"{int(t.min() if t.min() < 0 else t.max())}")
    if last is None:
        prev, base = t[0], t[0]
    else:
        base = np.int64(_int_any("last", last))
        prev = base % m
    half = m >> np.int64(1)
    d = np.diff(t, prepend=prev)
    d = (d + half) % m - half
    out = base + np.cumsum(d)
    return out, int(out[-1])


def _int_any(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, not {value!r}")
    return int(value)

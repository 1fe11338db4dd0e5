"""The streaming closed-loop pipeline: signal blocks -> front end -> FIFO -> DSP -> registers.

::

    signal blocks --> FrontendSession.step --> FIFO words read by the DSP (ready pattern)
          ^                                          |
          |                                          v
    session.write(reg, value, cycle)  <--  dsp(call) every loop period, at its service time

The front end is a :class:`cosim.core.session.FrontendSession` on any backend (the bit-exact
model, ``amaranth.sim``, Verilator); the FIFO's DSP side reads with the ``ready`` pattern of
a :class:`~cosim.core.link.DspServiceConfig`, the same pattern on every backend. Every state --
front end, FIFO, pending peaks and writes, the DSP's own -- is carried across blocks, so a
record fed in any number of blocks gives the same bits.

Timing of the loop (cycles from reset). The DSP runs once per *loop period* of
``services_per_call`` FIFO services. Call ``k`` covers the services ``g0 .. g1`` with
``g0 = k * services_per_call``, ``g1 = g0 + services_per_call - 1``:

* it gets the words read in those services' read windows (``read cycle < window_end``,
  ``window_end = g1 * period + latency + window_cycles``);
* it runs at ``issue = window_end + compute_cycles`` (the DSP's processing time); the
  pipeline steps the front end exactly up to that cycle, then calls the DSP;
* each write it returns is issued at ``issue`` and reaches the HDL register at
  ``issue + control_latency_cycles`` (:class:`~cosim.core.control.ControlPath`), i.e. it is applied
  before that cycle's clock edge, never earlier -- whatever the block boundaries.

The DSP is called every loop period, also inside a stall of the FIFO service
(:attr:`DspServiceConfig.stalls`: it then gets the words of the unstalled reads only, maybe
none); a policy that must not act while stalled checks ``call.window_end`` against the
stalls. The writes ``(cycle, register, value)`` (effect cycles) are part of the result and of its
digest, so two backends or two blockings compare on them as on the words.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from dsp.fixed import check_int as _int
from .control import ControlPath
from .link import DspServiceConfig
from .session import FrontendSession

__all__ = ["ServiceCall", "Pipeline", "PipelineResult"]


@dataclass
class ServiceCall:
    """What the DSP callback gets each loop period.

    Attributes
    ----------
    index : int
        Call number (0, 1, ...).
    words, cycles : ndarray of int64
        FIFO words read in this loop period's service windows, and their read cycles.
    window_end : int
        End (exclusive) of the period's last read window.
    issue_cycle : int
        Cycle at which the DSP issues its writes (``window_end + compute_cycles``).
    effect_cycle : int
        Cycle from which a write issued now holds in the FPGA register.
    session : FrontendSession
        The front end (for ``read``; writes go through the return value).
    """

    index: int
    words: np.ndarray
    cycles: np.ndarray
    window_end: int
    issue_cycle: int
    effect_cycle: int
    session: FrontendSession


@dataclass
class PipelineResult:
    """A pipeline run. ``words``/``cycles`` are empty when the pipeline was built with
    ``keep_words=False`` (the digest covers them either way)."""

    words: np.ndarray
    cycles: np.ndarray
    writes: list
    n_cycles: int
    n_words: int
    n_calls: int
    overflow_count: int | None
    digest: dict = field(default_factory=dict)


class Pipeline:
    """Closed loop of a front-end session and a DSP callback (see the module doc).

    Parameters
    ----------
    session : FrontendSession
        Freshly opened (cycle 0); the pipeline steps it and owns its writes.
    service : DspServiceConfig
        How the DSP reads the FIFO (its ``ready`` pattern, from reset).
    dsp : callable, optional
        ``dsp(call: ServiceCall) -> iterable of (register, value)`` or None; called every
        loop period with the words read. None: an open loop (words are only collected).
    services_per_call : int
        FIFO services per DSP call (the loop period, >= 1).
    compute_cycles : int
        Cycles from the end of the last read window to the DSP issuing its writes (>= 0).
    control_latency_cycles : int
        Cycles from issue to the register holding the new value (>= 0).
    initial : dict, optional
        Register values after reset (for :class:`ControlPath`; not written to the session).
    keep_words : bool
        Keep every word read in the result (default); False keeps only the digest (long
        runs).
    overflow_port : str or None
        Port read at the end for :attr:`PipelineResult.overflow_count`.
    """

    def __init__(self, session: FrontendSession, service: DspServiceConfig, dsp=None, *,
                 services_per_call: int = 1, compute_cycles: int = 0,
                 control_latency_cycles: int = 40, initial: dict | None = None,
                 keep_words: bool = True, overflow_port: str | None = "overflow_count"):
        if not isinstance(session, FrontendSession):
            raise ValueError(f"session must be a FrontendSession, not {type(session).__name__}")
        if session.cycle != 0:
            raise ValueError(f"the session must be fresh (at cycle 0), not at {session.cycle}")
        if not isinstance(service, DspServiceConfig):
            raise ValueError(f"service must be a DspServiceConfig, not {type(service).__name__}")
        self.session = session
        self.service = service
        self.dsp = dsp
        self.services_per_call = _int("services_per_call", services_per_call, 1)
        self.compute_cycles = _int("compute_cycles", compute_cycles, 0)
        self.control = ControlPath(control_latency_cycles, initial=initial)
        self.keep_words = bool(keep_words)
        self.overflow_port = overflow_port
        self._k = 0
        self._scheduled: list[tuple[int, str, int]] = []
        self._buf_w: list[np.ndarray] = []
        self._buf_c: list[np.ndarray] = []
        self._all_w: list[np.ndarray] = []
        self._all_c: list[np.ndarray] = []
        self._hw, self._hc = hashlib.sha256(), hashlib.sha256()
        self.n_words = 0

    # -- timing --------------------------------------------------------------------------
    def window_end(self, k: int) -> int:
        """End (exclusive) of the last read window of call ``k``'s loop period."""
        s = self.service
        g1 = (k + 1) * self.services_per_call - 1
        return g1 * s.period_cycles + s.latency_cycles + s.window_cycles

    def issue_cycle(self, k: int) -> int:
        return self.window_end(k) + self.compute_cycles

    @property
    def cycle(self) -> int:
        return self.session.cycle

    # -- running -------------------------------------------------------------------------
    def feed(self, samples) -> None:
        """Offer ``samples`` (one per cycle) and run the loop over their cycles."""
        x = np.asarray(samples)
        if x.ndim != 1:
            raise ValueError(f"samples must be one-dimensional, not of shape {x.shape}")
        self._advance(x, x.size)

    def idle(self, n_cycles: int) -> None:
        """Run ``n_cycles`` without input (e.g. to flush the pipeline at the end)."""
        self._advance(None, _int("n_cycles", n_cycles, 0))

    def _advance(self, x, n: int) -> None:
        end = self.cycle + n
        pos = 0
        while True:
            while self.cycle == self.issue_cycle(self._k):
                self._call()
            if self.cycle >= end:
                break
            # An open loop (no DSP callback) has nothing to decide: one step to the end.
            stop = end if self.dsp is None else min(end, self.issue_cycle(self._k))
            m = stop - self.cycle
            r = self.session.step(None if x is None else x[pos:pos + m], self.service,
                                  n_cycles=m)
            pos += m
            self._collect(r.words, r.cycles)
            if self.dsp is None:    # count the loop periods passed (nothing to decide)
                while self.issue_cycle(self._k) < self.cycle:
                    self._k += 1
                self._buf_w, self._buf_c = [], []

    def _collect(self, words, cycles) -> None:
        if not words.size:
            return
        words = np.ascontiguousarray(words, np.int64)
        cycles = np.ascontiguousarray(cycles, np.int64)
        self._buf_w.append(words)
        self._buf_c.append(cycles)
        self._hw.update(words.tobytes())
        self._hc.update(cycles.tobytes())
        self.n_words += words.size
        if self.keep_words:
            self._all_w.append(words)
            self._all_c.append(cycles)

    def _call(self) -> None:
        k = self._k
        wend = self.window_end(k)
        issue = self.issue_cycle(k)
        w = np.concatenate(self._buf_w) if self._buf_w else np.zeros(0, np.int64)
        c = np.concatenate(self._buf_c) if self._buf_c else np.zeros(0, np.int64)
        mine = c < wend
        rest_w, rest_c = w[~mine], c[~mine]
        self._buf_w = [rest_w] if rest_w.size else []
        self._buf_c = [rest_c] if rest_c.size else []
        self._k += 1
        if self.dsp is None:
            return
        call = ServiceCall(index=k, words=w[mine], cycles=c[mine], window_end=wend,
                           issue_cycle=issue,
                           effect_cycle=issue + self.control.latency_cycles,
                           session=self.session)
        out = self.dsp(call)
        last_read = int(c[mine][-1]) if mine.any() else None
        for reg, value in (out or ()):
            eff = self.control.write(issue, reg, int(value), read_cycle=last_read)
            self.session.write(reg, int(value), cycle=eff)

    def schedule(self, writes) -> None:
        """Register writes planned before the run (an open-loop control sequence),
        ``(effect cycle, register, value)``, e.g. :meth:`ControlPath.writes`; they are
        listed first in :attr:`writes`."""
        for c, reg, value in writes:
            self.session.write(reg, int(value), cycle=int(c))
            self._scheduled.append((int(c), reg, int(value)))

    # -- result --------------------------------------------------------------------------
    @property
    def writes(self) -> list[tuple[int, str, int]]:
        """Writes made so far, ``(effect cycle, register, value)``: the scheduled ones,
        then the DSP's in issue order."""
        return self._scheduled + self.control.writes()

    def result(self) -> PipelineResult:
        hwr = hashlib.sha256()
        for c, reg, v in self.writes:
            hwr.update(f"{c},{reg},{v};".encode())
        digest = {"words": self._hw.hexdigest()[:16], "cycles": self._hc.hexdigest()[:16],
                  "writes": hwr.hexdigest()[:16]}
        digest["all"] = hashlib.sha256("".join(digest.values()).encode()).hexdigest()[:16]
        ovf = None if self.overflow_port is None else self.session.read(self.overflow_port)
        cat = (lambda a: np.concatenate(a) if a else np.zeros(0, np.int64))
        return PipelineResult(words=cat(self._all_w), cycles=cat(self._all_c),
                              writes=self.writes, n_cycles=self.cycle, n_words=self.n_words,
                              n_calls=self._k, overflow_count=ovf, digest=digest)

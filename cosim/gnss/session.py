"""The bit-exact GNSS channel as a persistent session, and the register view of any session.

:class:`GnssModelSession` is the ``model`` backend of :func:`cosim.backends.factory.open_frontend`
for :class:`hdl.gnss.params.GnssChannelParams`: the bit-exact channel
(:class:`~hdl.gnss.model.GnssChannelModel`, its state carried) and its record FIFO
(:func:`~hdl.model.fifo.fifo_model_events`, its state carried). It has the ports of
:class:`hdl.gnss.channel.GnssChannel`, so the same port writes drive the model, the
Amaranth simulation and Verilator:

* ``reg_we``, ``reg_addr``, ``reg_data`` (write): the register bus. Every cycle in which
  ``reg_we`` is 1 is a bus write of ``reg_data`` to register ``reg_addr`` (a value set at
  cycle ``c`` holds from ``c`` until changed; ``reg_we`` held high writes every cycle, as in
  the HDL). The shadow register has it from the next cycle; it becomes active at the next
  dump boundary (:mod:`hdl.gnss.model`).
* ``overflow_count`` (read): records the FIFO dropped.

The DSP thinks in registers, not bus cycles: :class:`GnssRegisterSession` wraps a session
of any backend and takes writes to ``carr_freq``, ``code_freq``, ``prn`` and ``slew``
(:attr:`hdl.gnss.params.GnssChannelParams.registers`). A register write taking effect at
cycle ``e`` is the bus pulse ``reg_we = 1`` with its address and data at bus cycle ``b =
max(e, previous b + 1)`` and ``reg_we = 0`` at ``b + 1`` (the bus takes one write per
cycle, so two registers written for the same cycle go out on consecutive cycles, in the
order written).
:func:`open_gnss` opens one.
"""
from __future__ import annotations

import numpy as np

from ..backends.factory import open_frontend
from ..core.session import BusModelSession, FrontendSession, RegisterSession, fifo_step

__all__ = ["GnssModelSessionBase", "GnssModelSession", "GnssRegisterSession", "open_gnss",
           "check_channel_params"]


class GnssModelSessionBase(BusModelSession):
    """What the bit-exact channel and array sessions share: the parameters and the model,
    the bus ports' widths, the bus writes given (:attr:`bus_writes`), and the records the
    model has made that have not yet reached the FIFO's input (carried from step to step)
    before they go through the FIFO (:func:`~cosim.core.session.fifo_step`, its state
    carried). A subclass gives :meth:`_records`: the records of one step's samples and bus
    writes.

    Parameters
    ----------
    params : GnssChannelParams
    model
        The bit-exact model (its state carried from step to step).
    addr_bits : int
        Width of ``reg_addr``.
    """

    backend = "model"
    #: Order the records by their FIFO input cycle (the array's channels make them out of
    #: order; a single channel makes them in order).
    sort_records = False

    def __init__(self, params, model, addr_bits: int):
        super().__init__()
        self.params, self.model = params, model
        self._widths = {"reg_we": 1, "reg_addr": addr_bits, "reg_data": params.reg_data_width}
        self._fifo = params.fifo        # derived properties: computed once, not per step
        self._carry_wc = np.zeros(0, np.int64)
        self._carry_w = np.zeros((0, self._fifo.record_words), np.int64)
        #: Bus writes ``(cycle, reg, value)`` the model has been given.
        self.bus_writes: list[tuple[int, int, int]] = []
        self.n_records = 0

    def _records(self, x, bus, cycles):
        """``(cycles, words)``: the FIFO input cycles and the words of the records the model
        makes from the samples ``x`` (input at ``cycles``) and the bus writes ``bus``."""
        raise NotImplementedError

    def _add(self, rc, new) -> None:
        """Records ``(cycles, words)`` to the ones carried to the FIFO's input."""
        self.n_records += new.shape[0]
        wc = np.concatenate([self._carry_wc, np.asarray(rc, np.int64)])
        w = np.concatenate([self._carry_w, new])
        if self.sort_records:
            order = np.argsort(wc, kind="stable")
            wc, w = wc[order], w[order]
        self._carry_wc, self._carry_w = wc, w

    def _step(self, queue, ready, n, writes):
        start, stop = self.cycle, self.cycle + n
        x = self.params.unpack_samples(queue[:n])   # payload words -> samples (I/Q if complex)
        self._check_step(x)
        bus = self._step_bus(writes, start, stop)
        self.bus_writes += bus
        rec = self._records(x, bus, np.arange(start, start + len(x), dtype=np.int64))
        if rec is not None:
            self._add(*rec)
        now = self._carry_wc < stop
        wc, w = self._carry_wc[now], self._carry_w[now]
        self._carry_wc, self._carry_w = self._carry_wc[~now], self._carry_w[~now]
        words, cycles, self._fifo_state = fifo_step(wc, w, ready, n, start, self._fifo,
                                                    self._fifo_state)
        return words, cycles, len(x)

    def _check_step(self, x) -> None:
        """Refuse a step's samples ``x`` the session cannot take (default: none refused)."""

    def _step_bus(self, writes, start: int, stop: int) -> list:
        """The bus writes ``(cycle, reg, value)`` of the step over cycles ``start .. stop``
        (default: those of the port writes ``writes``)."""
        return self._bus_cycles(writes, start, stop)


class GnssModelSession(GnssModelSessionBase):
    """The bit-exact model of :class:`hdl.gnss.channel.GnssChannel` as a session (module
    doc). Samples are offered one per cycle while queued; cycles without a queued sample
    have ``i.valid`` low. The input words are the ``i`` port's payloads, as for the HDL
    backends: the ADC words (real input) or the packed ``(I, Q)`` pairs of
    :meth:`~hdl.gnss.params.GnssChannelParams.pack_samples` (complex input).

    Parameters
    ----------
    params : GnssChannelParams
        A single channel (``channel_bits == 0``).
    log_ranges : bool
        Accepted for :func:`cosim.backends.factory.open_frontend`; the GNSS model keeps no range log
        (its accumulators are sized never to overflow), so it must be False.
    """

    what = "GNSS channel model"

    def __init__(self, params, *, log_ranges: bool = False):
        from hdl.gnss.model import GnssChannelModel
        check_channel_params(params)
        if params.channel_bits:
            raise ValueError(f"GnssModelSession models one channel (channel_bits 0), not "
                             f"channel_bits {params.channel_bits}")
        if log_ranges:
            raise ValueError("the GNSS channel model keeps no range log (log_ranges=False)")
        super().__init__(params, GnssChannelModel(params), 2)

    def _records(self, x, bus, cycles):
        r = self.model.step(x, bus, cycles=cycles)
        return r.cycles, r.words(self.params)


def check_channel_params(params) -> None:
    """``params`` must be a :class:`hdl.gnss.params.GnssChannelParams`."""
    from hdl.gnss.params import GnssChannelParams
    if not isinstance(params, GnssChannelParams):
        raise ValueError(f"params must be a GnssChannelParams, not {type(params).__name__}")


class GnssRegisterSession(RegisterSession):
    """Register-level writes (``carr_freq``, ``code_freq``, ``prn``, ``slew``) on a GNSS
    channel session of any backend, as bus pulses (module doc;
    :class:`cosim.core.session.RegisterSession`).

    Parameters
    ----------
    inner : FrontendSession
        A fresh session of :class:`hdl.gnss.channel.GnssChannel` (model, pysim or
        verilator); this session owns it (closing this closes it).
    params : GnssChannelParams
    """

    def __init__(self, inner: FrontendSession, params):
        super().__init__(inner, params.registers)
        self.params = params

    def step(self, in_words=None, ready=None, *, n_cycles=None):
        """:meth:`cosim.core.session.FrontendSession.step`; ``in_words`` are the ``i``
        port's payloads, and for a complex-input channel also an ``(n, 2)`` array of
        ``(I, Q)`` ADC words, packed here (:meth:`GnssChannelParams.pack_samples`)."""
        if in_words is not None and self.params.complex_input and np.ndim(in_words) == 2:
            in_words = self.params.pack_samples(in_words)
        return super().step(in_words, ready, n_cycles=n_cycles)


def open_gnss(backend: str, params, **kw) -> GnssRegisterSession:
    """A GNSS channel on ``backend`` (``model``, ``pysim``, ``verilator``) with register-level
    writes: :func:`cosim.backends.factory.open_frontend` wrapped in a
    :class:`GnssRegisterSession`."""
    return GnssRegisterSession(open_frontend(backend, params, **kw), params)

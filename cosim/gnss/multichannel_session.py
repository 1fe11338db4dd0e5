"""The 12-channel GNSS array as a persistent session: one ADC stream, one record FIFO.

:class:`GnssArrayModelSession` is the bit-exact array (:class:`hdl.gnss.model.GnssArrayModel`:
``channels`` channels on one input, the arbiter, one FIFO, its state carried) with the ports
of :class:`hdl.gnss.channel.GnssChannelArray` (``reg_we``, ``reg_addr`` = ``4 * channel +
reg``, ``reg_data``, ``overflow_count``), so the same port writes drive it, the Amaranth
simulation and Verilator. :func:`open_gnss_array` opens the array on a backend behind a
register session whose registers are named per channel (:func:`register_name`:
``ch3.carr_freq``); a single channel (``channels == 1``) is the plain channel of
:func:`cosim.gnss.session.open_gnss` (registers ``carr_freq``, ...).

The arbiter grants a record only once no lower channel's record can still be pending before
it (:class:`hdl.gnss.model.Arbiter`): records of the last samples wait until the input is
declared ended (:meth:`GnssArrayModelSession.end_input`), after which only idle cycles may
be stepped.
"""
from __future__ import annotations

import numpy as np

from ..core.session import BusModelSession, RegisterSession, fifo_step

__all__ = ["GnssArrayModelSession", "array_registers", "register_name", "open_gnss_array",
           "array_channel_params", "check_parallel"]


def register_name(channels: int, channel: int, reg: str) -> str:
    """The register session's name of register ``reg`` of ``channel`` (plain ``reg`` for a
    single channel, ``ch<channel>.<reg>`` in an array)."""
    return reg if channels == 1 else f"ch{channel}.{reg}"


def array_channel_params(params, channels: int):
    """``params`` of one channel, as the array numbers its records (``channel_bits`` set for
    ``channels > 1``; :func:`hdl.gnss.channel.array_params`)."""
    from hdl.gnss.channel import array_params
    if isinstance(channels, bool) or not isinstance(channels, (int, np.integer)) \
            or not 1 <= channels <= 64:
        raise ValueError(f"--channels must be an integer in [1, 64], not {channels!r}")
    if channels == 1:
        return params
    return array_params(params, int(channels))


def array_registers(params, channels: int):
    """The register map of an array of ``channels`` (:attr:`GnssChannelParams.registers` of
    every channel at ``4 * channel + reg``, names by :func:`register_name`)."""
    from dsp.register_map import Register, RegisterMap
    regs = []
    for ch in range(channels):
        for r in params.registers.registers:
            regs.append(Register(register_name(channels, ch, r.name), 4 * ch + r.address,
                                 r.width, r.signed, r.minimum, r.maximum, r.parts))
    return RegisterMap(f"GNSS array of {channels}", tuple(regs))


class GnssArrayModelSession(BusModelSession):
    """The bit-exact :class:`hdl.gnss.channel.GnssChannelArray` as a session (module doc).

    Parameters
    ----------
    params : GnssChannelParams
        With the array's ``channel_bits`` (:func:`array_channel_params`).
    channels : int
        2..64.
    parallel : bool
        The channels on numba's threads (:class:`hdl.gnss.model.GnssArrayModel`; the same
        bits).
    """

    backend = "model"
    what = "GNSS channel array model"

    def __init__(self, params, channels: int, parallel: bool = False):
        from hdl.gnss.model import GnssArrayModel
        from hdl.gnss.params import GnssChannelParams
        if not isinstance(params, GnssChannelParams):
            raise ValueError(f"params must be a GnssChannelParams, not {type(params).__name__}")
        if isinstance(channels, bool) or not isinstance(channels, (int, np.integer)) \
                or not 2 <= channels <= 64 or (1 << params.channel_bits) < channels:
            raise ValueError(f"an array session needs 2..64 channels that its channel_bits "
                             f"({params.channel_bits}) can number, not {channels!r}")
        super().__init__()
        self.params, self.channels = params, int(channels)
        self.model = GnssArrayModel(params, self.channels, parallel=bool(parallel))
        addr_bits = 2 + max(1, (self.channels - 1).bit_length())
        self._widths = {"reg_we": 1, "reg_addr": addr_bits, "reg_data": params.reg_data_width}
        self._fifo = params.fifo
        rw = self._fifo.record_words
        self._carry_wc = np.zeros(0, np.int64)
        self._carry_w = np.zeros((0, rw), np.int64)
        self._ended = False
        self.bus_writes: list[tuple[int, int, int]] = []
        self.n_records = 0
        self._direct: list[tuple[int, int, int]] = []     # bus writes not on the ports
        self._we_cycle = -1                                 # cycle of the last of them

    def bus_write(self, cycle: int, addr: int, value: int) -> None:
        """A register write on the bus at ``cycle`` without its four port writes (the
        pulse of :func:`cosim.core.session.write_register`: ``reg_we`` high in ``cycle``
        only), ``value`` already checked by the register map
        (:class:`GnssArrayRegisterSession`'s path on the model). Writes come in cycle
        order, one per cycle, none in a cycle already run; the ports read as the pulse
        leaves them."""
        if cycle < self.cycle or (self._direct and cycle <= self._direct[-1][0]):
            raise ValueError(f"internal: bus write at cycle {cycle} out of order (session "
                             f"at {self.cycle})")
        self._direct.append((int(cycle), int(addr), int(value)))

    def _read(self, port):
        if port == "reg_we" and self._we_cycle == self.cycle - 1:
            return 1
        return super()._read(port)

    def end_input(self) -> None:
        """No sample follows: the records still waiting for the arbiter are granted (their
        cycles are final, as no later record can compete), so the next idle steps read
        them out of the FIFO."""
        if not self._ended:
            self._ended = True
            self._add(*self.model.flush_words())

    def _add(self, rc, new) -> None:
        self.n_records += new.shape[0]
        wc = np.concatenate([self._carry_wc, np.asarray(rc, np.int64)])
        w = np.concatenate([self._carry_w, new])
        order = np.argsort(wc, kind="stable")
        self._carry_wc, self._carry_w = wc[order], w[order]

    def _step(self, queue, ready, n, writes):
        start, stop = self.cycle, self.cycle + n
        x = self.params.unpack_samples(queue[:n])   # payload words -> samples (I/Q if complex)
        if x.size and self._ended:
            raise ValueError("the array's input was declared ended (end_input): no more "
                             "samples")
        bus = self._bus_cycles(writes, start, stop)
        checked = False
        if self._direct and self._direct[0][0] < stop:
            k = 0
            while k < len(self._direct) and self._direct[k][0] < stop:
                k += 1
            now, self._direct = self._direct[:k], self._direct[k:]
            _, self._bus["reg_addr"], self._bus["reg_data"] = now[-1]
            self._we_cycle = now[-1][0]
            checked = not bus
            bus = sorted(bus + now, key=lambda w: w[0]) if bus else now
        self.bus_writes += bus
        if x.size or bus:
            cyc = np.arange(start, start + len(x), dtype=np.int64)
            self._add(*self.model.step_words(x, bus, cycles=cyc, checked=checked))
        now = self._carry_wc < stop
        wc, w = self._carry_wc[now], self._carry_w[now]
        self._carry_wc, self._carry_w = self._carry_wc[~now], self._carry_w[~now]
        words, cycles, self._fifo_state = fifo_step(wc, w, ready, n, start, self._fifo,
                                                    self._fifo_state)
        return words, cycles, len(x)


class GnssArrayRegisterSession(RegisterSession):
    """Per-channel register writes (:func:`array_registers`) on an array session of any
    backend, as bus pulses (:class:`cosim.core.session.RegisterSession`)."""

    def __init__(self, inner, params, channels: int):
        super().__init__(inner, array_registers(params, channels))
        self.channels = channels
        self._direct = isinstance(inner, GnssArrayModelSession)

    def _bus_write(self, b: int, a: int, v: int) -> None:
        """On the model, each register write goes to the bus as one
        :meth:`GnssArrayModelSession.bus_write` (the same cycle and value as the four port
        writes of :func:`~cosim.core.session.write_register`, without them); on the HDL
        backends as port writes."""
        if self._direct:
            self.inner.bus_write(b, a, v)
        else:
            super()._bus_write(b, a, v)

    def end_input(self) -> None:
        """The input has ended (:meth:`GnssArrayModelSession.end_input`; the HDL backends
        need nothing)."""
        if hasattr(self.inner, "end_input"):
            self.inner.end_input()


def check_parallel(parallel: bool, backend: str) -> None:
    """``--parallel`` (the model's channels on threads) goes with ``--backend model`` only."""
    if parallel and backend != "model":
        raise ValueError(f"--parallel shares the bit-exact model's channels among threads: it "
                         f"needs --backend model, not {backend!r}")


def open_gnss_array(backend: str, params, channels: int, parallel: bool = False):
    """``channels`` GNSS channels on one input stream on ``backend`` (``model``, ``pysim``,
    ``verilator``) with per-channel register writes (module doc). ``params``: the array's
    (:func:`array_channel_params`); ``parallel``: the model's channels on numba's threads
    (the model backend only; a single channel has nothing to share)."""
    from ..backends.factory import BACKENDS, open_stream_session
    from .session import open_gnss
    if backend not in BACKENDS:
        raise ValueError(f"--backend must be one of {', '.join(BACKENDS)}, not {backend!r}")
    check_parallel(parallel, backend)
    if channels == 1:
        return open_gnss(backend, params)
    if backend == "model":
        inner = GnssArrayModelSession(params, channels, parallel)
    else:
        from hdl.gnss.channel import GnssChannelArray
        inner = open_stream_session(backend, GnssChannelArray(params, channels),
                                    name=f"gnss_channel_array{channels}",
                                    inputs={"reg_we": 0, "reg_addr": 0, "reg_data": 0})
    return GnssArrayRegisterSession(inner, params, channels)

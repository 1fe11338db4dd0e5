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

from ..core.session import RegisterSession
from .session import GnssModelSessionBase, check_channel_params, open_gnss

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


class GnssArrayModelSession(GnssModelSessionBase):
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

    what = "GNSS channel array model"
    sort_records = True

    def __init__(self, params, channels: int, parallel: bool = False):
        from hdl.gnss.model import GnssArrayModel
        check_channel_params(params)
        if isinstance(channels, bool) or not isinstance(channels, (int, np.integer)) \
                or not 2 <= channels <= 64 or (1 << params.channel_bits) < channels:
            raise ValueError(f"an array session needs 2..64 channels that its channel_bits "
                             f"({params.channel_bits}) can number, not {channels!r}")
        channels = int(channels)
        super().__init__(params, GnssArrayModel(params, channels, parallel=bool(parallel)),
                         2 + max(1, (channels - 1).bit_length()))
        self.channels = channels
        self._ended = False
        self._direct: list[tuple[int, int, int]] = []     # bus writes not on the ports
        self._we_cycle = -1                                 # cycle of the last of them
        self._checked = False                               # this step's writes all direct

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

    def _check_step(self, x) -> None:
        if x.size and self._ended:
            raise ValueError("the array's input was declared ended (end_input): no more "
                             "samples")

    def _step_bus(self, writes, start, stop):
        """The port writes' bus writes and the direct ones (:meth:`bus_write`) of the step,
        in cycle order; a step whose writes are all direct needs no second value check."""
        bus = self._bus_cycles(writes, start, stop)
        self._checked = False
        if self._direct and self._direct[0][0] < stop:
            k = 0
            while k < len(self._direct) and self._direct[k][0] < stop:
                k += 1
            now, self._direct = self._direct[:k], self._direct[k:]
            _, self._bus["reg_addr"], self._bus["reg_data"] = now[-1]
            self._we_cycle = now[-1][0]
            self._checked = not bus
            bus = sorted(bus + now, key=lambda w: w[0]) if bus else now
        return bus

    def _records(self, x, bus, cycles):
        if x.size or bus:
            return self.model.step_words(x, bus, cycles=cycles, checked=self._checked)
        return None


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

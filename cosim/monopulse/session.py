"""The bit-exact model of the monopulse front end as a persistent session
(:class:`cosim.core.session.BusModelSession`): the ``model`` backend for
:class:`hdl.monopulse.params.MonopulseFrontendParams`, with the same ports and the same bits
as the ``pysim`` / ``verilator`` sessions of :class:`hdl.monopulse.frontend.MonopulseFrontEnd`.
"""
from __future__ import annotations

import numpy as np

from ..core.session import BusModelSession, fifo_step

__all__ = ["MonopulseModelSession"]


class MonopulseModelSession(BusModelSession):
    """:class:`~hdl.monopulse.model.MonopulseFrontendModel` (state carried) and the FIFO
    model (:func:`~hdl.model.fifo.fifo_model_events`, state carried) as a session.

    Input words are :func:`~hdl.monopulse.params.pack_input` words, one offered per cycle
    while queued. Writes are port writes on :data:`cosim.core.session.BUS_PORTS` (as the
    HDL sessions take them; :func:`cosim.core.session.write_register` makes one bus write); a
    register write happens in every cycle ``reg_we`` is high, with the ``reg_addr`` /
    ``reg_data`` of that cycle. Each step processes the snapshots that reach the correction stage before its last cycle (a later
    write may still precede their block boundary); a record written to the FIFO after the
    step waits for the next. Reads: ``overflow_count`` and the bus ports.

    Parameters
    ----------
    params : MonopulseFrontendParams
    log_ranges : bool
        Accepted for the :func:`cosim.backends.factory.open_frontend` interface; this model
        keeps no range log (ValueError if True).
    """

    backend = "model"
    what = "monopulse front-end model"

    def __init__(self, params, *, log_ranges: bool = False):
        from hdl.monopulse.model import MonopulseFrontendModel
        if log_ranges:
            raise ValueError("the monopulse front-end model keeps no range log "
                             "(log_ranges=False)")
        super().__init__()
        self.params = params
        self.model = MonopulseFrontendModel(params)
        self._carry_c = np.zeros(0, np.int64)
        self._carry_w = np.zeros((0, params.record_words), np.int64)
        self.n_records = 0

    def _bus_writes(self, writes, start: int, stop: int) -> list[tuple[int, int, int]]:
        """Port writes of the step -> register writes (cycle, reg, value). A held
        ``reg_we`` rewrites the same value each cycle, which changes nothing, so a write is
        emitted where ``reg_we`` rises or the address/data change while it is high."""
        out = []
        bus = self._bus
        k = 0
        while k < len(writes):
            c = writes[k][0]
            while k < len(writes) and writes[k][0] == c:
                bus[writes[k][1]] = writes[k][2]
                k += 1
            if bus["reg_we"]:
                out.append((c, bus["reg_addr"], bus["reg_data"]))
        return out

    def _step(self, queue, ready, n, writes):
        from hdl.monopulse.params import unpack_input
        p = self.params
        start, stop = self.cycle, self.cycle + n
        words = queue[:n]
        x, chips = unpack_input(words, p)
        reg = self._bus_writes(writes, start, stop)
        r = self.model.step(x, chips, reg, cycles=start + np.arange(x.shape[0]),
                            horizon=stop)
        self.n_records += len(r.values)
        w = np.array([p.record.to_words(v, p.fifo_width) for v in r.values],
                     np.int64).reshape(-1, p.record_words)
        wc = np.r_[self._carry_c, r.cycles]
        w = np.concatenate([self._carry_w, w])
        now = wc < stop
        self._carry_c, self._carry_w = wc[~now], w[~now]
        wc, w = wc[now], w[now]
        words, cycles, self._fifo_state = fifo_step(wc, w, ready, n, start, p.fifo,
                                                    self._fifo_state)
        return words, cycles, x.shape[0]

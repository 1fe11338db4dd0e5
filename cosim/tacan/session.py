"""The bit-exact model of the TACAN front end as a persistent session
(:class:`cosim.core.session.FrontendSession`), the ``model`` backend of
:func:`cosim.backends.factory.open_frontend` for :class:`hdl.tacan.params.TacanFrontendParams`."""
from __future__ import annotations

import numpy as np

from dsp.tacan.standard import SOURCE_PULSE
from hdl.model.fifo import FifoState
from hdl.tacan.fifo_merge import fifo_write_cycles

from ..core.session import FrontendSession, fifo_step

__all__ = ["TacanModelSession"]


class TacanModelSession(FrontendSession):
    """The bit-exact model of :class:`hdl.tacan.frontend.TacanFrontEnd` as a session.

    :class:`~hdl.tacan.model.TacanFrontendModel` (its state carried) gives the peaks
    and the cycle each leaves its search, :func:`~hdl.tacan.fifo_merge.fifo_write_cycles` the
    cycle each is written to the FIFO (with two searches, ``config.pair_peak``, a pair word
    may wait a cycle behind a pulse word); the FIFO model
    (:func:`~hdl.model.fifo.fifo_model_events`, its state carried) gives what the DSP reads.
    A peak written after the step's last cycle waits for the next step. ``freq`` writes take
    effect from the first ADC sample offered at or after their cycle (the NCO samples the
    port with each valid sample), as in the HDL. Ports: ``freq`` (write/read),
    ``overflow_count`` (read).

    Parameters
    ----------
    params : TacanFrontendParams
    log_ranges : bool
        Keep the model's range log (:meth:`ranges`).
    """

    backend = "model"

    def __init__(self, params, *, log_ranges: bool = False, fast: bool | None = None):
        from hdl.tacan.model import TacanFrontendModel
        super().__init__()
        self.params = params
        self.model = TacanFrontendModel(params, log_ranges=log_ranges, fast=fast)
        self._fe_state = None
        self._fifo_state = FifoState()
        # Words emitted but not yet written to the FIFO: emit cycles, words, sources.
        self._carry_ec = np.zeros(0, np.int64)
        self._carry_w = np.zeros(0, np.int64)
        self._carry_src = None if params.pair_peak is None else np.zeros(0, np.int8)
        self._last_pulse = -1      # emit cycle of the last pulse word written (two searches)
        self._n_samples = 0
        # Runs of samples offered on consecutive cycles: sample s0 + j at cycle c0 + j.
        self._run_s = np.zeros(0, np.int64)
        self._run_c = np.zeros(0, np.int64)
        self._ch_idx: list[int] = []   # freq changes by ADC sample index
        self._ch_val: list[int] = []
        self._changes = None           # the same as int64 arrays, for the model
        self._freq = int(params.nco_freq_word)
        self.n_peaks = 0

    def _check_port(self, port) -> None:
        if port != "freq":
            raise KeyError(f"the TACAN front-end model has one writable port, 'freq', "
                           f"not {port!r}")

    def _read(self, port):
        if port == "overflow_count":
            return self._fifo_state.overflow
        if port == "freq":
            return self._freq
        raise KeyError(f"the TACAN front-end model reads 'freq' and 'overflow_count', "
                       f"not {port!r}")

    def ranges(self) -> dict:
        return self.model.ranges()

    @property
    def fifo_state(self) -> FifoState:
        return self._fifo_state

    def _add_change(self, idx: int, value: int) -> None:
        if self._ch_idx and self._ch_idx[-1] == idx:     # same sample: the later write wins
            self._ch_val[-1] = value
        else:
            self._ch_idx.append(idx)
            self._ch_val.append(value)
        self._changes = None

    def _step(self, queue, ready, n, writes):
        p = self.params
        start, stop = self.cycle, self.cycle + n
        x = queue[:n]
        n0 = self._n_samples
        for c, _port, v in writes:   # sample index of the first sample at or after cycle c
            if v < 0 or v >= 1 << p.nco_phase_bits:
                raise ValueError(f"freq words must lie in [0, 2**{p.nco_phase_bits}), not {v}")
            self._add_change(n0 + min(c - start, x.size), v)
            self._freq = v
        if x.size:
            if not (self._run_c.size and self._run_c[-1] - self._run_s[-1] == start - n0):
                self._run_s = np.r_[self._run_s, np.int64(n0)]
                self._run_c = np.r_[self._run_c, np.int64(start)]
            if self._changes is None and self._ch_idx:
                self._changes = (np.array(self._ch_idx, np.int64),
                                 np.array(self._ch_val, np.int64))
            changes = self._changes
            pk, self._fe_state = self.model.run(x, self._fe_state, freq_changes=changes)
            self._n_samples += x.size
            self.n_peaks += len(pk)

            def adc_cycles(adc_idx):
                r = np.searchsorted(self._run_s, adc_idx, side="right") - 1
                return self._run_c[r] + (adc_idx - self._run_s[r])
            ec = np.r_[self._carry_ec, self.model.emit_cycles(pk, adc_cycles=adc_cycles)]
            w = np.r_[self._carry_w, self.model.words(pk)]
            src = None if pk.source is None else np.r_[self._carry_src, pk.source]
        else:
            ec, w, src = self._carry_ec, self._carry_w, self._carry_src
        # The words leave their searches at ec; the merge (two searches) may delay a pair
        # word by one cycle behind a pulse word of the same cycle, which may have been
        # written in the previous step (_last_pulse). Words written from `stop` on wait, with
        # their emit cycles: a pulse of a later step can still collide with them.
        wc = fifo_write_cycles(ec, src, last_pulse=self._last_pulse)
        order = np.argsort(wc, kind="stable")
        ec, w, wc = ec[order], w[order], wc[order]
        now = wc < stop
        if src is not None:
            src = src[order]
            pulses = ec[now & (src == SOURCE_PULSE)]
            if pulses.size:
                self._last_pulse = int(pulses[-1])
            self._carry_src = src[~now]
        self._carry_ec, self._carry_w = ec[~now], w[~now]
        wc, w = wc[now], w[now]
        words, cycles, self._fifo_state = fifo_step(wc, w, ready, n, start, p.fifo,
                                                    self._fifo_state)
        return words, cycles, x.size

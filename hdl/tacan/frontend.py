"""TACAN FPGA front end: DDC -> CIC -> FIR -> envelope -> peak search -> FIFO, one clock.

With ``config.pair_peak`` a second peak search (the pulse-pair detection) runs on the same
envelope stream beside the single-pulse one, and both write into the one FIFO, each word
tagged with its search in the payload's top bit (the merge: :meth:`TacanFrontEnd._merge`).
Parameters and word lengths are in :mod:`hdl.tacan.params`, the bit-exact model in
:mod:`hdl.tacan.model`.
"""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from dsp.tacan.standard import SOURCE_PAIR, SOURCE_PULSE

from ..cic import Cic
from ..common import check_params
from ..ddc import Ddc
from ..envelope import Envelope
from ..fifo import DspFifo
from ..fir import Fir
from .peak import PeakSearch
from .params import TacanFrontendParams

__all__ = ["TacanFrontEnd"]


class TacanFrontEnd(wiring.Component):
    """The TACAN front end from ADC samples to tagged peak words for the DSP.

    Parameters
    ----------
    params : TacanFrontendParams
        Rates, structure and every word length (each block's params come from it).

    Ports
    -----
    i : In(stream.Signature(signed(adc_bits), always_ready=True))
        ADC samples at the clock rate; gaps in ``valid`` are allowed (each valid sample
        steps the NCO once; the CIC keeps the R-th, 2R-th, ... valid sample).
    freq : In(unsigned(nco_phase_bits), init=params.nco_freq_word)
        NCO frequency word, sampled with each valid ADC sample. Its ``init`` (the digital IF
        word) is what ``amaranth.sim`` uses when a testbench does not drive it; in the
        exported Verilog it is a plain input that the surrounding design (or the DSP's
        control register) must drive, as the Verilator runs do with ``inputs={"freq": ...}``.
    o : Out(stream.Signature(StructLayout({"payload": unsigned(amp + ts [+ 1]),
            "tag": unsigned(2)})))
        FIFO words towards the DSP, with a real ``ready``. Data word (tag 0): payload =
        ``amplitude | timestamp << amp_width`` (amplitude in envelope LSBs,
        ``TacanFrontendParams.scale_to_fs`` FS each -- the peak's, with the peak search's
        pair-partner readout the partner's, with its pulse-pair detection the mean of the
        pair's two envelope values; timestamp = ADC tick of the peak's
        envelope sample mod ``2**ts_bits``); with both searches (``config.pair_peak``)
        ``| source << (amp_width + ts_bits)``, source 0 = the single-pulse search
        (``peak``), 1 = the pair search (``pair_peak``: amplitude = the pair's mean,
        timestamp = its second pulse). Marker (tag 2): payload = peaks dropped just
        before it. ``params.latency`` cycles from the ADC sample that completes the envelope
        sample closing a pulse (``peak.emit_delay`` envelope samples later with the readout
        or the pair detection) to ``o.valid`` (empty FIFO); a pair word of the second search
        ``params.pair_peak_latency + FIFO_LATENCY`` cycles after the ADC sample completing
        the envelope sample ``pair_peak.emit_delay`` after the pair's closing one, one
        cycle more when a pulse word is written in the same cycle.
    overflow_count : Out(unsigned(fifo_count_bits))
        Peaks dropped because the FIFO was full (saturating), the cycle after the drop.
    """

    def __init__(self, params: TacanFrontendParams | None = None):
        params = params if params is not None else TacanFrontendParams()
        self.params = params = check_params(self, params, TacanFrontendParams)
        self._fifo = DspFifo(params.fifo)   # its output layout is the top's
        super().__init__({
            "i": In(stream.Signature(signed(params.adc_bits), always_ready=True)),
            "freq": In(unsigned(params.nco_phase_bits), init=params.nco_freq_word),
            "o": Out(stream.Signature(self._fifo.out_layout)),
            "overflow_count": Out(unsigned(params.fifo_count_bits)),
        })

    @property
    def latency(self) -> int:
        return self.params.latency

    def elaborate(self, platform):
        p = self.params
        m = Module()
        m.submodules.ddc = ddc = Ddc(p.ddc)
        m.submodules.cic = cic = Cic(p.cic)
        m.submodules.fir = fir = Fir(p.fir)
        m.submodules.envelope = env = Envelope(p.envelope)
        m.submodules.peak = peak = PeakSearch(p.peak)
        m.submodules.fifo = fifo = self._fifo

        wiring.connect(m, wiring.flipped(self.i), ddc.i)
        m.d.comb += ddc.freq.eq(self.freq)
        wiring.connect(m, ddc.o, cic.i)
        wiring.connect(m, cic.o, fir.i)
        wiring.connect(m, fir.o, env.i)
        wiring.connect(m, env.o, peak.i)
        # Adapter: the FIFO stores raw bits; the peak's struct is packed as it lays it out
        # (amplitude at the LSB), which is the documented word format.
        if p.peak.partner_offset:   # the pair partner's envelope is the amplitude reported
            pay = Cat(peak.o.payload.partner, peak.o.payload.timestamp)
        else:   # amplitude (with the pair detection: the pair's mean) | timestamp
            pay = peak.o.payload.as_value()
        if p.pair_peak is None:
            m.d.comb += [fifo.i.valid.eq(peak.o.valid), fifo.i.payload.eq(pay)]
        else:
            m.submodules.pair_peak = pair = PeakSearch(p.pair_peak)
            # both searches see every envelope transfer (their inputs are always_ready)
            m.d.comb += [pair.i.valid.eq(env.o.valid), pair.i.payload.eq(env.o.payload)]
            self._merge(m, fifo, Cat(pay, Const(SOURCE_PULSE, 1)), peak.o.valid,
                        Cat(pair.o.payload.as_value(), Const(SOURCE_PAIR, 1)), pair.o.valid)
        wiring.connect(m, fifo.o, wiring.flipped(self.o))
        m.d.comb += self.overflow_count.eq(fifo.overflow_count)
        return m

    @staticmethod
    def _merge(m, fifo, pulse, pulse_valid, pair, pair_valid):
        """The two searches into the one FIFO input (:func:`hdl.tacan.fifo_merge.fifo_write_cycles`):
        a pulse word is written at once; a pair word too, unless a pulse word comes in the same
        cycle, then it waits one cycle in ``hold``. The searches emit at least ``decimation
        >= 2`` cycles apart (checked by the params), so the cycle after a collision has
        neither a pulse word nor a new pair word."""
        hold = Signal.like(fifo.i.payload)
        hold_valid = Signal()
        m.d.sync += [hold.eq(pair), hold_valid.eq(pulse_valid & pair_valid)]
        m.d.comb += [fifo.i.valid.eq(pulse_valid | pair_valid | hold_valid),
                     fifo.i.payload.eq(Mux(pulse_valid, pulse, Mux(hold_valid, hold, pair)))]

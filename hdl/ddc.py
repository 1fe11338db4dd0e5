"""Digital down-converter: NCO + real mixer, one NCO step per valid ADC sample."""
from __future__ import annotations

from amaranth.hdl import Module, Signal, signed
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from .mixer import Mixer, iq_layout
from .model.ddc import DdcParams
from .nco import Nco


class Ddc(wiring.Component):
    """Digital down-converter ``y[n] = x[n] * exp(-j*phi[n])`` (see :mod:`hdl.model.ddc`).

    Parameters
    ----------
    params : DdcParams

    Ports
    -----
    i : In(stream.Signature(signed(adc_width), always_ready=True))
        Real ADC samples; every valid one steps the NCO once. Gaps are allowed.
    freq : In(unsigned(phase_bits))
        NCO frequency word, sampled with each valid input (run-time writable).
    o : Out(stream.Signature(iq_layout(out_width), always_ready=True))
        Baseband I/Q, ``params.latency`` cycles after the input sample.
    """

    def __init__(self, params: DdcParams):
        if not isinstance(params, DdcParams):
            self._MustUse__silence = True  # never elaborated: no 'created but never used'
            raise ValueError(f"Ddc needs a DdcParams, not {params!r}")
        self.params = params
        super().__init__({
            "i": In(stream.Signature(signed(params.adc_width), always_ready=True)),
            "freq": In(params.freq_width),
            "o": Out(stream.Signature(iq_layout(params.out_width), always_ready=True)),
        })

    @property
    def latency(self) -> int:
        return self.params.latency

    def elaborate(self, platform):
        p = self.params
        m = Module()
        m.submodules.nco = nco = Nco(p.nco)
        m.submodules.mixer = mixer = Mixer(p.mixer)

        m.d.comb += [nco.i.valid.eq(self.i.valid), nco.freq.eq(self.freq)]

        # The NCO pipeline runs every cycle, so a plain delay line of its latency lines the
        # sample up with its LO whatever the gaps in valid.
        x = self.i.payload
        for k in range(p.nco.latency):
            xd = Signal(signed(p.adc_width), name=f"x_d{k + 1}")
            m.d.sync += xd.eq(x)
            x = xd

        m.d.comb += [
            mixer.i.valid.eq(nco.o.valid),
            mixer.i.payload.x.eq(x),
            mixer.i.payload.lo.eq(nco.o.payload),
        ]
        wiring.connect(m, mixer.o, wiring.flipped(self.o))
        return m

"""Digital down-converter: NCO + real mixer, one NCO step per valid ADC sample.

The NCO is either the DDC's own (the default) or outside it (``external_lo=True``): then the
DDC takes the LO on a port, so that one :class:`hdl.nco.Nco` drives the mixers of several
channels sampled together (a 4-channel monopulse front end: one LO, four phase-coherent
channels): drive each DDC's ``lo.valid`` / ``lo.payload`` from the NCO's ``o`` (a stream
with a ``ready`` member cannot be fanned out with ``wiring.connect``; one DDC alone can be
connected with ``wiring.connect(m, nco.o, ddc.lo)``).
"""
from __future__ import annotations

from amaranth.hdl import Module, Signal, signed
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from .common import check_bool, check_params, iq_layout, lo_layout
from .mixer import Mixer
from .model.ddc import DdcParams
from .nco import Nco


class Ddc(wiring.Component):
    """Digital down-converter ``y[n] = x[n] * exp(-j*phi[n])`` (see :mod:`hdl.model.ddc`).

    Parameters
    ----------
    params : DdcParams
    external_lo : bool
        False (default): the DDC contains its NCO (``Nco(params.nco)``) and has a ``freq``
        port. True: no NCO inside; the LO comes in on the ``lo`` port instead, from an
        ``Nco(params.nco)`` outside whose ``i.valid`` is driven by the same ADC valid as this
        DDC's ``i.valid`` (its ``o`` then carries the LO of each sample ``params.nco.latency``
        cycles after the sample, which is where the DDC's delay line puts the sample). Same
        latency and, for the same NCO, the same bits as the internal NCO.

    Ports
    -----
    i : In(stream.Signature(signed(adc_width), always_ready=True))
        Real ADC samples; every valid one steps the NCO once. Gaps are allowed.
    freq : In(unsigned(phase_bits)), only if not ``external_lo``
        NCO frequency word, sampled with each valid input (run-time writable).
    lo : In(stream.Signature(lo_layout(amp_bits), always_ready=True)), only if ``external_lo``
        The LO ``{"cos", "sin"}`` of the sample taken on ``i`` ``params.nco.latency`` cycles
        earlier; each ``lo.valid`` produces one output.
    o : Out(stream.Signature(iq_layout(out_width), always_ready=True))
        Baseband I/Q, ``params.latency`` cycles after the input sample.
    """

    def __init__(self, params: DdcParams, *, external_lo: bool = False):
        self.params = params = check_params(self, params, DdcParams)
        self.external_lo = check_bool(self, "external_lo", external_lo)
        members = {"i": In(stream.Signature(signed(params.adc_width), always_ready=True))}
        if external_lo:
            members["lo"] = In(stream.Signature(lo_layout(params.nco.amp_bits), always_ready=True))
        else:
            members["freq"] = In(params.freq_width)
        members["o"] = Out(stream.Signature(iq_layout(params.out_width), always_ready=True))
        super().__init__(members)

    @property
    def latency(self) -> int:
        return self.params.latency

    def elaborate(self, platform):
        p = self.params
        m = Module()
        m.submodules.mixer = mixer = Mixer(p.mixer)
        if self.external_lo:
            lo = self.lo
        else:
            m.submodules.nco = nco = Nco(p.nco)
            m.d.comb += [nco.i.valid.eq(self.i.valid), nco.freq.eq(self.freq)]
            lo = nco.o

        # The NCO pipeline runs every cycle, so a plain delay line of its latency lines the
        # sample up with its LO whatever the gaps in valid.
        x = self.i.payload
        for k in range(p.nco.latency):
            xd = Signal(signed(p.adc_width), name=f"x_d{k + 1}")
            m.d.sync += xd.eq(x)
            x = xd

        m.d.comb += [
            mixer.i.valid.eq(lo.valid),
            mixer.i.payload.x.eq(x),
            mixer.i.payload.lo.eq(lo.payload),
        ]
        wiring.connect(m, mixer.o, wiring.flipped(self.o))
        return m

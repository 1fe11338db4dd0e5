"""Digital down-converter (NCO + real mixer) parameters and the bit-exact numpy model.

Each valid ADC sample ``x[n]`` steps the NCO once and leaves as
``y[n] = requantize(x[n] * exp(-j*phi[n]))`` (see :mod:`hdl.model.nco` for ``phi[n]`` and
:mod:`hdl.model.mixer` for the scaling), ``latency`` cycles later.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dsp.fixed import shift_right

from .mixer import MixerParams, check_int_range
from .nco import NcoModel, NcoParams, NcoState


@dataclass(frozen=True)
class DdcParams:
    """Parameters of the DDC.

    Parameters
    ----------
    nco : NcoParams
        The local oscillator; ``amp_bits`` must equal ``mixer.lo_width``.
    mixer : MixerParams
        The mixer; must have real input (``complex_input=False``); ``in_width`` is the ADC
        width.
    """

    nco: NcoParams = field(default_factory=NcoParams)
    mixer: MixerParams = field(default_factory=MixerParams)

    def __post_init__(self):
        if not isinstance(self.nco, NcoParams):
            raise ValueError(f"DDC nco must be an NcoParams, not {self.nco!r}")
        if not isinstance(self.mixer, MixerParams):
            raise ValueError(f"DDC mixer must be a MixerParams, not {self.mixer!r}")
        if self.mixer.complex_input:
            raise ValueError("DDC mixer must take the real ADC stream (complex_input=False), "
                             "not complex_input=True")
        if self.mixer.lo_width != self.nco.amp_bits:
            raise ValueError(
                "DDC mixer lo_width must equal the NCO amp_bits, not "
                f"lo_width={self.mixer.lo_width} with amp_bits={self.nco.amp_bits}")
        if self.nco.phase_port:
            raise ValueError("DDC has no phase offset port: use NcoParams(phase_port=False), "
                             "not phase_port=True")

    @property
    def adc_width(self) -> int:
        """Signed width of the input ``i`` (the ADC word)."""
        return self.mixer.in_width

    @property
    def out_width(self) -> int:
        """Signed width of each of ``o.payload.i`` / ``.q``."""
        return self.mixer.out_width

    @property
    def freq_width(self) -> int:
        return self.nco.phase_bits

    @property
    def latency(self) -> int:
        """Cycles from an accepted ADC sample to its ``o.valid``."""
        return self.nco.latency + self.mixer.latency


class DdcModel:
    """Bit-exact model of :class:`hdl.ddc.Ddc`, vectorised, chunkable."""

    def __init__(self, params: DdcParams):
        self.params = params
        self.nco = NcoModel(params.nco)

    def initial_state(self) -> NcoState:
        return self.nco.initial_state()

    def run(self, x, freq_word, state: NcoState | None = None
            ) -> tuple[np.ndarray, np.ndarray, NcoState]:
        """Down-convert the valid ADC samples ``x``.

        Parameters
        ----------
        x : array of int
            ADC samples (signed ``adc_width`` integers), one per NCO step.
        freq_word : int or array of int, shape (len(x),)
            NCO frequency word in force at each sample (``freq`` port).
        state : NcoState, optional
            From the previous chunk (default: after reset).

        Returns
        -------
        i, q : ndarray of int64
        state : NcoState
        """
        x = check_int_range("DDC input x", x, self.params.adc_width)
        a, st = self.nco.addresses(len(x), freq_word, state)
        # Same arithmetic as MixerModel.run, written out to avoid temporaries on the hot path.
        pi = self.nco.cos_table[a]
        pi *= x
        pq = self.nco.sin_table[a]
        pq *= x
        i, q = self._requantize(pi, pq)
        return i, q, st

    def mix(self, x, cos, sin) -> tuple[np.ndarray, np.ndarray]:
        """Down-convert ``x`` with an outside LO: the model of ``Ddc(external_lo=True)``.

        Parameters
        ----------
        x : array of int
            ADC samples (signed ``adc_width`` integers).
        cos, sin : array of int, shape (len(x),)
            The LO of each sample, e.g. ``NcoModel(params.nco).run(len(x), freq_word)``
            shared by the channels (signed ``nco.amp_bits`` integers).

        Returns
        -------
        i, q : ndarray of int64
            The same bits as :meth:`run` when ``cos, sin`` come from ``NcoModel(params.nco)``.
        """
        x = check_int_range("DDC input x", x, self.params.adc_width)
        cos = check_int_range("DDC LO cos", cos, self.params.nco.amp_bits)
        sin = check_int_range("DDC LO sin", sin, self.params.nco.amp_bits)
        if not (cos.shape == sin.shape == x.shape):
            raise ValueError(f"DDC LO cos/sin must have the shape of x {x.shape}, "
                             f"not {cos.shape}/{sin.shape}")
        return self._requantize(cos * x, sin * x)

    def _requantize(self, pi: np.ndarray, pq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(x cos, x sin)`` products -> the mixer's ``(i, q)`` (``q`` negated); in place."""
        p = self.params.mixer
        np.negative(pq, out=pq)
        fmt = p.out_format
        i = fmt.fit(shift_right(pi, p.drop_bits, p.rounding))[0]
        q = fmt.fit(shift_right(pq, p.drop_bits, p.rounding))[0]
        return i, q

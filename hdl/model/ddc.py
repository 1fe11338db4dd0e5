"""Digital down-converter (NCO + real mixer) parameters and the bit-exact numpy model.

Each valid ADC sample ``x[n]`` steps the NCO once and leaves as
``y[n] = requantize(x[n] * exp(-j*phi[n]))`` (see :mod:`hdl.model.nco` for ``phi[n]`` and
:mod:`hdl.model.mixer` for the scaling), ``latency`` cycles later.

:class:`DdcCicKernel` is the compiled fast path of a DDC feeding a CIC decimator (the
TACAN front end's first two blocks): NCO, mixer and the CIC integrators fused in one pass
over the ADC samples (the CIC runs at the DDC's rate, so fusing them saves the
full-rate I/Q temporaries); the same bits as :class:`DdcModel` then
:func:`hdl.model.cic.cic_model` where it applies (:meth:`DdcCicKernel.exact`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from dsp.fixed import shift_right
from dsp.jit import njit_cached

from .cic import CicParams
from .mixer import MixerParams, check_int_range
from .nco import NcoModel, NcoParams, NcoState
from .rounding import rnd, round_consts


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


# -- compiled DDC -> CIC fast path ----------------------------------------------------------

class DdcCicKernel:
    """A :class:`DdcModel` followed by a CIC decimator, compiled and fused
    (:func:`ddc_cic_kernel`): NCO, mixer and CIC sample by sample in int64, integrators and
    combs as the hardware (wrapping mod 2**64, exact because the unpruned CIC's result fits
    its full width), ``freq`` writes applied at given samples.

    Parameters
    ----------
    ddc : DdcParams
    cic : CicParams
        Two channels (I/Q) of ``ddc.out_width`` input.
    """

    def __init__(self, ddc: DdcParams, cic: CicParams):
        self.ddc, self.cic = ddc, cic
        nco = NcoModel(ddc.nco)
        self.cos = np.ascontiguousarray(nco.cos_table, dtype=np.int64)
        self.msin = np.ascontiguousarray(-nco.sin_table, dtype=np.int64)
        self.mix_rc = round_consts(ddc.mixer.drop_bits, ddc.mixer.rounding)
        self.cic_rc = round_consts(cic.out_shift, cic.rounding)

    @staticmethod
    def exact(ddc: DdcParams, cic: CicParams) -> bool:
        """Whether the kernel gives :class:`DdcModel` + ``cic_model``'s bits for every input
        that cannot saturate the mixer or the CIC (the caller's headroom check): no NCO
        dither (the kernel has no LFSR), no CIC pruning (the sum must be exact), products
        and the CIC's full width within int64 with margin."""
        return (ddc.nco.dither_bits == 0 and not cic.prune and cic.full_width <= 50
                and ddc.mixer.product_width <= 50)

    def run(self, x, acc0: int, fw: int, integ, combs, ch_idx, ch_val, mrng
            ) -> tuple[np.ndarray, np.ndarray, int]:
        """CIC outputs of the whole decimation groups of ``x`` (int64 ADC codes).

        ``acc0``: NCO phase before the first sample; ``fw``: NCO word at the first sample,
        replaced by ``ch_val[j]`` from sample ``ch_idx[j]`` on; ``integ`` (2, N) and
        ``combs`` (2, N, M): CIC registers, updated in place; ``mrng``: [min i, max i,
        min q, max q] of the mixer outputs, updated in place. Returns ``(i, q, phase after
        the last sample)``; raises ``ValueError`` if an ADC code is out of range.
        """
        d, c = self.ddc, self.cic
        count = len(x) // c.rate
        ci = np.empty(count, np.int64)
        cq = np.empty(count, np.int64)
        top = d.adc_width - 1
        ph = ddc_cic_kernel(x, acc0, fw, (1 << d.nco.phase_bits) - 1, d.nco.trunc_bits,
                            self.cos, self.msin, self.mix_rc, -(1 << top), (1 << top) - 1,
                            c.rate, integ, combs, self.cic_rc, ci, cq, ch_idx, ch_val, mrng)
        if ph < 0:
            raise ValueError(f"ADC codes must be signed {d.adc_width}-bit integers")
        return ci, cq, int(ph)


@njit_cached(nogil=True)
def ddc_cic_kernel(x, ph, fw, pmask, trunc, cos_t, msin_t, mix_rc, lo, hi,
                    rate, integ, combs, cic_rc, yi, yq, ch_idx, ch_val, mrng):
    """NCO + mixer + CIC on whole decimation groups, sample by sample as the hardware.

    ``ph``: phase of the first sample; ``fw``: NCO word at the first sample, replaced by
    ``ch_val[j]`` from sample ``ch_idx[j]`` on (strictly increasing; register writes);
    ``msin_t = -sin``; ``integ`` (2, N) and ``combs``
    (2, N, M) are the CIC registers (updated in place; ``combs[c, s, 0]`` is the newest
    delayed value). The integrators wrap mod 2**64, which is exact mod 2**B_max: the
    combed value fits ``B_max`` bits (no pruning). ``yi``/``yq`` get the rounded CIC
    outputs. Returns the phase after the last sample, or -1 if an input is out of
    ``[lo, hi]`` (the outputs are then invalid).
    """
    n_st = integ.shape[1]
    m_dl = combs.shape[2]
    if n_st == 3 and m_dl == 1 and mix_rc[0] == 0 and mix_rc[4] == 0:
        return _ddc_cic3(x, ph, fw, pmask, trunc, cos_t, msin_t, mix_rc, lo, hi,
                         rate, integ, combs, cic_rc, yi, yq, ch_idx, ch_val, mrng)
    count = x.shape[0] // rate
    ii = integ[0].copy()
    iq = integ[1].copy()
    bad = False
    nch = ch_idx.shape[0]
    j = 0
    nxt = ch_idx[0] if nch > 0 else -1
    for k in range(count):
        xs = x[k * rate:(k + 1) * rate]
        for r in range(rate):
            if k * rate + r == nxt:
                fw = ch_val[j] & pmask
                j += 1
                nxt = ch_idx[j] if j < nch else -1
            xv = np.int64(xs[r])
            bad |= (xv < lo) | (xv > hi)
            a = ph >> trunc
            vi = rnd(xv * cos_t[a], mix_rc)
            vq = rnd(xv * msin_t[a], mix_rc)
            mrng[0] = min(mrng[0], vi)
            mrng[1] = max(mrng[1], vi)
            mrng[2] = min(mrng[2], vq)
            mrng[3] = max(mrng[3], vq)
            ph = (ph + fw) & pmask
            for s in range(n_st):
                vi += ii[s]
                ii[s] = vi
                vq += iq[s]
                iq[s] = vq
        # decimated sample: the combs
        vi = ii[n_st - 1]
        vq = iq[n_st - 1]
        for s in range(n_st):
            oi = combs[0, s, m_dl - 1]
            oq = combs[1, s, m_dl - 1]
            for d in range(m_dl - 1, 0, -1):
                combs[0, s, d] = combs[0, s, d - 1]
                combs[1, s, d] = combs[1, s, d - 1]
            combs[0, s, 0] = vi
            combs[1, s, 0] = vq
            vi -= oi
            vq -= oq
        yi[k] = rnd(vi, cic_rc)
        yq[k] = rnd(vq, cic_rc)
    integ[0] = ii
    integ[1] = iq
    return -1 if bad else ph


@numba.njit(inline="always")
def _ddc_cic3(x, ph, fw, pmask, trunc, cos_t, msin_t, mix_rc, lo, hi,
              rate, integ, combs, cic_rc, yi, yq, ch_idx, ch_val, mrng):
    """:func:`ddc_cic_kernel` for N = 3, M = 1 (the default), registers in locals, and a
    mixer rounding without left shift or toward-zero bias (the fewer terms matter here)."""
    _, rs, c0, em, _ = mix_rc
    count = x.shape[0] // rate
    i1, i2, i3 = integ[0, 0], integ[0, 1], integ[0, 2]
    q1, q2, q3 = integ[1, 0], integ[1, 1], integ[1, 2]
    ci1, ci2, ci3 = combs[0, 0, 0], combs[0, 1, 0], combs[0, 2, 0]
    cq1, cq2, cq3 = combs[1, 0, 0], combs[1, 1, 0], combs[1, 2, 0]
    bad = False
    nch = ch_idx.shape[0]
    j = 0
    nxt = ch_idx[0] if nch > 0 else -1
    mn_i, mx_i, mn_q, mx_q = mrng[0], mrng[1], mrng[2], mrng[3]
    for k in range(count):
        xs = x[k * rate:(k + 1) * rate]
        for r in range(rate):
            if k * rate + r == nxt:
                fw = ch_val[j] & pmask
                j += 1
                nxt = ch_idx[j] if j < nch else -1
            xv = np.int64(xs[r])
            bad |= (xv < lo) | (xv > hi)
            a = ph >> trunc
            pi = xv * cos_t[a]
            pq = xv * msin_t[a]
            vi = (pi + c0 + ((pi >> rs) & em)) >> rs
            vq = (pq + c0 + ((pq >> rs) & em)) >> rs
            mn_i = min(mn_i, vi)
            mx_i = max(mx_i, vi)
            mn_q = min(mn_q, vq)
            mx_q = max(mx_q, vq)
            ph = (ph + fw) & pmask
            i1 += vi
            i2 += i1
            i3 += i2
            q1 += vq
            q2 += q1
            q3 += q2
        d1 = i3 - ci1
        ci1 = i3
        d2 = d1 - ci2
        ci2 = d1
        yi[k] = rnd(d2 - ci3, cic_rc)
        ci3 = d2
        d1 = q3 - cq1
        cq1 = q3
        d2 = d1 - cq2
        cq2 = d1
        yq[k] = rnd(d2 - cq3, cic_rc)
        cq3 = d2
    integ[0, 0], integ[0, 1], integ[0, 2] = i1, i2, i3
    integ[1, 0], integ[1, 1], integ[1, 2] = q1, q2, q3
    combs[0, 0, 0], combs[0, 1, 0], combs[0, 2, 0] = ci1, ci2, ci3
    combs[1, 0, 0], combs[1, 1, 0], combs[1, 2, 0] = cq1, cq2, cq3
    mrng[0], mrng[1], mrng[2], mrng[3] = mn_i, mx_i, mn_q, mx_q
    return -1 if bad else ph

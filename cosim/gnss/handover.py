"""The acquisition of a GNSS run on the flowing record, and the record the tracking sees.

The run's signal starts at t = 0 with the receiver searching: the search
(:func:`dsp.gnss.dwell.sequential_search`, the schedule of
:meth:`~cosim.gnss.config.GnssRunConfig.acq_schedule`: the dwell extends until the PRN is
detected or ``acq_limit_ms`` of signal is consumed) reads the record from its first sample,
each dwell on the stretch after the previous one. After the deciding look the next
``R = max(refine_ms, min(200, 20 T))`` ms (``T`` the detecting dwell's coherent ms: the
longer the dwell needed, the weaker the signal; the squared prompts of the Doppler
refinement lose more at a low C/N0) refine the Doppler and the code phase (:func:`dsp.gnss.dwell.refine`). Tracking starts on the sample after
them, ``n_start``: the hand-over is the refined Doppler and code phase propagated there --
the code phase by the refined Doppler over the ``R`` ms (``f dt / 1540`` chips beyond whole
code periods), the Doppler (the refinement's mean over its window) by
``handover_doppler_rate_hz_s`` over half the window. The search's own computing time is not
simulated (the samples it reads are the ones before ``n_start``).

:class:`RecordFrom` is the record from ``n_start`` on as the tracking sees it: sample 0 and
time 0 at ``n_start``, the truth read at the same instants, so the tracking and its scoring
are those of a record that starts when tracking does. :func:`acquired_record` builds it
from a run's signal: the generator is made ``acquisition_span_ms`` longer than the
tracking's ``duration_s``.

:func:`array_handover_writes` starts channel ``k`` of a
:class:`hdl.gnss.channel.GnssChannelArray` on satellite ``k`` of a list (PRN, Doppler, code
phase, e.g. from ``python -m cosim gnss-acquire``): for every channel its PRN, then the
writes of :func:`handover_writes` (carrier word of IF + Doppler, code
word of the chip rate + code Doppler, the slew that puts the prompt on the code phase).
The bus takes one write per cycle, so the channels' writes go out on consecutive cycles
from ``start_cycle``: ``4 * channels`` cycles, all before the first dump boundary (a code
period later), where every channel applies its own at once.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from dsp.gnss.ca_code import CODE_LENGTH, CODE_PERIOD_S, L1_HZ, CHIP_RATE_HZ, check_prn

from .config import GnssRunConfig
from .signal import GnssSignalConfig, GnssSignalGenerator

__all__ = ["handover_writes", "Satellite", "array_handover_writes", "RecordFrom", "acquire_handover",
           "AcquisitionFailed",
           "acquired_record", "acquisition_span_ms",
           "refine_length_ms", "REFINE_COHERENT", "REFINE_MAX_MS"]

#: The refinement spans at least this many coherent lengths of the detecting dwell, and at
#: most REFINE_MAX_MS unless refine_ms asks for more.
REFINE_COHERENT, REFINE_MAX_MS = 20, 200


def refine_length_ms(run: GnssRunConfig, coherent_ms: int) -> int:
    """The refinement after a detection by a dwell of ``coherent_ms`` (module docstring)."""
    return int(max(run.refine_ms, min(REFINE_MAX_MS, REFINE_COHERENT * coherent_ms)))
CARRIER_PER_CHIP = L1_HZ / CHIP_RATE_HZ


def acquisition_span_ms(run: GnssRunConfig) -> int:
    """The most signal the acquisition of ``run`` can consume (ms): the limit plus the
    longest refinement."""
    t_max = max(d.coherent_ms for d in run.acq_schedule())
    return int(run.acq_limit_ms + refine_length_ms(run, t_max))


class RecordFrom:
    """The record of ``gen`` from sample ``n0`` on, with sample 0 and time 0 there and the
    configuration ``cfg`` (its ``duration_s`` the tracking's): ``analog`` / ``samples`` /
    ``quantise`` / ``truth_at`` as :class:`~cosim.gnss.signal.GnssSignalGenerator`'s. The
    truth's carrier phase includes the IF phase the mixer has run through by ``n0`` (so
    ``n f_dig / fs + s phase`` is still the signal's phase at sample ``n``)."""

    def __init__(self, gen: GnssSignalGenerator, n0: int, cfg: GnssSignalConfig):
        n0 = int(n0)
        if n0 < 0 or n0 + cfg.n_samples > gen.cfg.n_samples:
            raise ValueError(f"the record holds {gen.cfg.n_samples} samples, not "
                             f"{n0} + {cfg.n_samples}")
        self.gen, self.n0, self.cfg = gen, n0, cfg
        self.t0_s = n0 / gen.cfg.fs_hz
        self.sign = gen.sign
        self._if_phase = math.fmod(n0 * gen.f_ratio, 1.0)

    def analog(self, n0: int, n: int) -> np.ndarray:
        if n0 < 0 or n < 0:
            raise ValueError(f"sample range must be non-negative, not n0={n0}, n={n}")
        return self.gen.analog(self.n0 + n0, n)

    def quantise(self, x):
        return self.gen.quantise(x)

    def samples(self, n0: int, n: int):
        return self.quantise(self.analog(n0, n))

    def truth_at(self, t_s) -> dict:
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        r = self.gen.truth_at(t + self.t0_s)
        r["t_s"] = t
        r["carrier_phase_cycles"] = r["carrier_phase_cycles"] + self.sign * self._if_phase
        return r


class AcquisitionFailed(ValueError):
    """The search did not find the PRN within ``--acq-limit-ms``: a result of the run (the
    signal is too weak for the search), not bad input. ``acquisition`` holds the search's
    record for the JSON; the commands report it with exit 1 (a ValueError for callers
    that treat any refusal alike)."""

    def __init__(self, message: str, acquisition: dict):
        super().__init__(message)
        self.acquisition = acquisition


def acquire_handover(gen, run: GnssRunConfig) -> tuple[dict, dict]:
    """Acquire the signal of ``gen`` from its first sample, refine, hand over (module
    docstring). Returns the acquisition's record for the JSON and the hand-over
    (``doppler_hz``, ``code_phase_chips`` at sample ``n_start``, and ``n_start``).
    ValueError if the record is shorter than the search needs; :class:`AcquisitionFailed`
    if the PRN is not detected within the limit."""
    from dsp.gnss.dwell import Baseband, refine, sequential_search
    sig = gen.cfg
    N = int(round(sig.fs_hz * CODE_PERIOD_S))
    span = acquisition_span_ms(run)
    if sig.n_samples < span * N:
        raise ValueError(f"the record ({sig.duration_s:g} s) is shorter than the acquisition "
                         f"may need ({span} ms: --acq-limit-ms and the refinement)")

    def read(a, n):
        return gen.samples(a, n)[0].astype(np.float64)

    bb = Baseband(read, sig.n_samples, sig.fs_hz, sig.digital_if_hz, sig.spectrum_inverted)
    r = sequential_search(bb.ms, bb.fs_d, sig.prn, run.acq_schedule(), run.acq_limit_ms,
                          run.acq_pfa, run.acq_max_doppler_hz)
    t_dw = r.start_ms * CODE_PERIOD_S
    truth = gen.truth_at([t_dw])
    out = {"detected": r.detected, "search": "fixed" if run.acq_coherent_ms else "sequential",
           "dwell": r.dwell, "noncoherent": r.noncoherent, "alignment_ms": r.alignment_ms,
           "t_detect_s": r.t_detect_ms * CODE_PERIOD_S, "metric": r.metric,
           "peak": r.peak, "threshold": r.threshold, "pfa": r.pfa, "n_tests": r.n_tests,
           "bin_width_hz": r.bin_width_hz, "search_rate_hz": bb.fs_d,
           "doppler_found_hz": r.doppler_hz, "doppler_dwell_true_hz": float(truth["doppler_hz"][0]),
           "code_phase_dwell_chips": r.code_phase_chips,
           "code_phase_dwell_true_chips": float(truth["code_phase_chips"][0])}
    if not r.detected:
        raise AcquisitionFailed(
            f"acquisition did not find PRN {sig.prn} within {r.t_detect_ms} ms of signal "
            f"(last look {r.dwell} at {r.noncoherent} sums: peak / threshold "
            f"{r.metric:.2f}, pfa {run.acq_pfa:g} per search): C/N0 too low for this "
            f"search; a longer --acq-limit-ms lets the dwell extend further", out)
    R = refine_length_ms(run, r.coherent_ms)
    k = r.t_detect_ms                                  # the refinement's first ms
    cp = (r.code_phase_chips + r.doppler_hz / CARRIER_PER_CHIP
          * (k - r.start_ms) * CODE_PERIOD_S) % CODE_LENGTH
    f, cp = refine(read(k * N, R * N), sig.fs_hz, sig.prn, sig.digital_if_hz,
                   sig.spectrum_inverted, r.doppler_hz, cp, r.bin_width_hz, R)
    dt = R * CODE_PERIOD_S
    n_start = (k + R) * N
    f_start = f + run.handover_doppler_rate_hz_s * dt / 2
    cp_start = (cp + f * dt / CARRIER_PER_CHIP) % CODE_LENGTH
    t_start = n_start / sig.fs_hz
    ts = gen.truth_at([t_start])
    out.update(refine_ms=R, t_start_s=t_start, doppler_refined_hz=f_start,
               doppler_true_hz=float(ts["doppler_hz"][0]), code_phase_found_chips=cp_start,
               code_phase_true_chips=float(ts["code_phase_chips"][0]))
    return out, {"doppler_hz": f_start, "code_phase_chips": cp_start, "n_start": n_start}


def acquired_record(sig: GnssSignalConfig, run: GnssRunConfig):
    """The run's generator (``sig`` made :func:`acquisition_span_ms` longer), its
    acquisition and the record the tracking sees: ``(acq, hand, RecordFrom)``; the
    hand-over is at the view's sample 0 (``hand["n_start"]`` of the generator's record)."""
    span_s = acquisition_span_ms(run) * CODE_PERIOD_S
    gen = GnssSignalGenerator(sig.replace(duration_s=sig.duration_s + span_s))
    acq, hand = acquire_handover(gen, run)
    view = RecordFrom(gen, hand["n_start"], sig)
    return acq, hand, view


def handover_writes(p, doppler_hz: float, code_phase_chips: float, inverted: bool = False):
    """Register writes at reset (effect cycles 0, 1, 2) that start channel ``p`` on an
    acquisition: carrier word (IF + Doppler), code word (chip rate + Doppler / 1540) and
    the slew (samples of code hold) that puts the prompt on ``code_phase_chips`` (the
    received code phase at sample 0)."""
    s = -1.0 if inverted else 1.0
    cw = p.carr_word(p.if_hz + s * doppler_hz)
    kw = p.code_word(CHIP_RATE_HZ * (1 + doppler_hz / L1_HZ))
    n_code = CODE_LENGTH * p.fs_hz / CHIP_RATE_HZ
    slew = int(round((-code_phase_chips * p.fs_hz / CHIP_RATE_HZ - p.half_spacing)
                     % n_code)) % int(round(n_code))
    if slew >= 1 << p.slew_bits:
        raise ValueError(f"the code slew of {slew} samples does not fit slew_bits "
                         f"{p.slew_bits}: use slew_bits >= {slew.bit_length()}")
    return [(0, "carr_freq", cw), (1, "code_freq", kw), (2, "slew", slew)]



class Satellite(NamedTuple):
    """An acquired satellite: what a channel is handed over to."""

    prn: int
    doppler_hz: float           #: carrier Doppler, Hz
    code_phase_chips: float     #: received code phase at sample 0, chips


def array_handover_writes(p, sats, *, inverted: bool = False,
                          start_cycle: int = 0) -> list[tuple[int, int, int]]:
    """Bus writes ``(cycle, address, value)`` (address ``4 * channel + register``) that hand
    channel ``k`` over to ``sats[k]``.

    Parameters
    ----------
    p : GnssChannelParams
        The channels' parameters (real or complex input; the carrier word is
        ``carr_word(if_hz +- doppler)``, the sign turned when ``inverted``).
    sats : sequence of Satellite or (prn, doppler_hz, code_phase_chips)
        One per channel, channel 0 first.
    inverted : bool
        The Doppler sign is turned (a real recording with an inverted spectrum:
        :attr:`cosim.gnss.files.SampleFile.doppler_sign_inverted`; a complex one is read as
        ``I - jQ`` and needs no turn).
    start_cycle : int
        Cycle of the first write (>= 0).
    """
    from hdl.gnss.params import GnssChannelParams
    if not isinstance(p, GnssChannelParams):
        raise ValueError(f"array hand-over needs a GnssChannelParams, not {p!r}")
    sats = [Satellite(*s) for s in sats]
    if not 1 <= len(sats) <= 64:
        raise ValueError(f"array hand-over needs 1 to 64 satellites (one per channel), not "
                         f"{len(sats)}")
    if isinstance(start_cycle, bool) or not isinstance(start_cycle, int) or start_cycle < 0:
        raise ValueError(f"start_cycle must be an integer >= 0, not {start_cycle!r}")
    regs = p.registers
    out, c = [], start_cycle
    for ch, s in enumerate(sats):
        check_prn(s.prn)
        writes = [(0, "prn", s.prn)] + handover_writes(p, float(s.doppler_hz),
                                                       float(s.code_phase_chips), inverted)
        for _, name, v in writes:
            out.append((c, 4 * ch + regs[name].address, int(v)))
            c += 1
    return out

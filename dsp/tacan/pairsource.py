"""Which pair reports the bearing DSP measures on when the front end runs both searches.

The pair search (:data:`dsp.tacan.frontend.BOTH_PAIR_SEARCH`) reports, besides the pulse
pairs, reports that are not a pair: *noise pairs* (two noise peaks one spacing apart whose
sum passes its threshold, ~460 a second on noise alone) and *half pairs* (one pulse and the
noise one spacing before or after it; the side-lobe and balance checks pass them when that
noise reaches about half the pulse). Their reports lie at ~0.5-0.8 of a pulse's amplitude
and how many of them the filter takes depends on the amplitude it predicts (the noise-report
rule of :class:`dsp.tacan.peakbias.PeakBias` drops them only where it predicts 1.8
thresholds or more, the innovation gate the further below its prediction; half pairs are
the likelier the weaker the pulse), so they bend the envelope the filter fits -- an
amplitude nonlinearity whose harmonics leak into the bearing as an error that depends on the
bearing. Measured (golden chain, 3 s, seed 1, X mode, 6 dB, bearings 0 / 60 / 120 deg):
12.5 % of the pair reports are not pairs; the bearing's mean error is -0.13 / +0.17 / -0.05
deg with them, -0.03 / +0.04 / -0.02 deg with them left out by the truth.

Away from the noise floor the single-pulse search sees both pulses of nearly every pair, and
of hardly any noise pair or half pair: a pair report is *confirmed* when the single-pulse
search reported a pulse at both its pulses (within the decoder's tolerance). The share of
confirmed pair reports, the *paired fraction* (:func:`paired_fraction`), is what the DSP
observes of where it is: ~0.24 at 0 dB, ~0.54 at 3 dB, ~0.81 at 6 dB (golden chain, X and
Y). At or above :attr:`dsp.tacan.receiver.ReceiverConfig.confirm_pairs_above` the DSP
measures on the confirmed pair reports only, expected with their own bias curve
(:attr:`dsp.tacan.peakbias.PeakBias.confirmed`: a confirmed report near the threshold lies
higher over its pulse than the average one); below it, near the floor, the single-pulse
search misses most pulses (confirming would drop most pairs, in the envelope's troughs
first) and it measures on every pair report. Either way each report is one measurement at
its pair's centre (:func:`pair_centres`).
"""
from __future__ import annotations

import numpy as np

from .scoring import match_nearest
from .standard import pair_spacing_s

#: What the DSP measured on (``BearingTrack.measured_on``).
MEASURED_ON = ("pulses", "pairs", "confirmed pairs")


def confirmed_pairs(pair_times_s, pulse_times_s, mode: str, tol_s: float) -> np.ndarray:
    """Per pair report (timestamped at its second pulse): whether the single-pulse search
    reported a pulse within ``tol_s`` of both its pulses (``t - pair_spacing_s(mode)`` and
    ``t``). ``pulse_times_s`` need not be sorted."""
    tp = np.sort(np.asarray(pulse_times_s, dtype=np.float64))
    t = np.asarray(pair_times_s, dtype=np.float64)
    if t.size == 0 or tp.size == 0:
        return np.zeros(t.shape, bool)
    _, second = match_nearest(tp, t, tol_s)
    _, first = match_nearest(tp, t - pair_spacing_s(mode), tol_s)
    return first & second


def paired_fraction(confirmed: np.ndarray) -> float | None:
    """The share of confirmed pair reports (None without pair reports)."""
    c = np.asarray(confirmed, bool)
    return float(np.count_nonzero(c) / c.size) if c.size else None


def choose_pairs(pair_times_s, pulse_times_s, mode: str, tol_s: float,
                 confirm_above: float | None) -> tuple[np.ndarray, float | None, str]:
    """The pair reports the DSP measures on: ``(keep, paired_fraction, measured_on)`` --
    the confirmed ones when the paired fraction is at least ``confirm_above`` (None: never),
    else all."""
    c = confirmed_pairs(pair_times_s, pulse_times_s, mode, tol_s)
    f = paired_fraction(c)
    if confirm_above is not None and f is not None and f >= confirm_above:
        return c, f, "confirmed pairs"
    return np.ones(c.shape, bool), f, "pairs"


def pair_centres(times_s, amplitudes, mode: str, *, ticks=None, tick_hz: float | None = None):
    """Pair reports as the amplitude measurements of the two-search DSP: each report (at its
    second pulse, ``t``) one measurement at the pair's centre, ``t - pair_spacing_s(mode) /
    2`` (with ``ticks``: ``round(spacing * tick_hz / 2)`` ticks earlier), where the mean of
    the two pulses' envelope is the envelope to first order. Returns ``(times_s,
    amplitudes, ticks)``; the order is kept.

    Taken as its two pulses instead (:func:`dsp.tacan.receiver.expand_pairs`), a pulse that
    two reports share is kept once, with the earlier report's amplitude -- in the reference
    bursts, trains of pulses one pair spacing apart (X auxiliary 12 us, Y main 30 us, Y
    auxiliary every other pulse of a 15 us train), each pulse then carries the envelope half
    a spacing before it. Those bursts come at fixed rotation phases, so the shift is a
    bearing bias: measured +0.003 deg (X) and +0.007 deg (Y) against the single-pulse
    search at 20 dB, every bearing (0.3 x the bound in Y)."""
    half = 0.5 * pair_spacing_s(mode)
    t = np.asarray(times_s, dtype=np.float64)
    amps = np.asarray(amplitudes)
    if ticks is None:
        return t - half, amps, None
    d = int(round(half * tick_hz))
    tk = np.asarray(ticks).astype(np.int64) - d
    return tk / tick_hz, amps, tk

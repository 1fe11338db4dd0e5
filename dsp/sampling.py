"""Sampling of a real IF signal: where an analog IF lands after the ADC (bandpass
sampling folds it into the first Nyquist zone, inverting the spectrum from even zones)."""
from __future__ import annotations

import math
from typing import NamedTuple


class FoldedIf(NamedTuple):
    """An analog IF as sampled."""

    digital_if_hz: float     #: frequency in [0, fs/2] it appears at
    inverted: bool           #: the spectrum is inverted there (an even Nyquist zone)


def fold_frequency(f_hz: float, fs_hz: float) -> FoldedIf:
    """Where the frequency ``f_hz`` lands after sampling at ``fs_hz``, and whether the
    spectrum is inverted there."""
    r = math.fmod(f_hz, fs_hz)
    if r <= fs_hz / 2:
        return FoldedIf(r, False)
    return FoldedIf(fs_hz - r, True)


class SampledIf:
    """Where a signal configuration's IF lands after sampling: for a class with ``if_hz``
    and ``fs_hz`` (:func:`fold_frequency`)."""

    @property
    def digital_if_hz(self) -> float:
        return fold_frequency(self.if_hz, self.fs_hz).digital_if_hz

    @property
    def spectrum_inverted(self) -> bool:
        return fold_frequency(self.if_hz, self.fs_hz).inverted

"""What the TACAN standard (MIL-STD-291C) fixes: modulation frequencies, pulse width and the
reference-burst pulse codes.

The DSP decodes against these; the signal generator (:mod:`cosim.tacan.signal`) imports them
from here, so the generator and the receiver cannot disagree on the standard.

Pulse codes
-----------
=========  =======================================  ========================================
mode       main reference (15 Hz)                   auxiliary reference (135 Hz)
=========  =======================================  ========================================
X          12 pulse pairs (12 us), pairs 30 us apart  6 pulse pairs (12 us), pairs 24 us apart
Y          13 single pulses, 30 us apart            13 single pulses, 15 us apart
=========  =======================================  ========================================
"""
from __future__ import annotations

import numpy as np

__all__ = ["F15", "F135", "PULSE_WIDTH_S", "burst_offsets", "pair_spacing_s"]

#: Bearing modulation: the coarse (15 Hz) and fine (135 Hz) components, Hz.
F15 = 15.0
F135 = 135.0
#: Pulse half-amplitude width (s), MIL-STD-291C 3.5 +- 0.5 us.
PULSE_WIDTH_S = 3.5e-6

_US = 1e-6


def burst_offsets(mode: str, kind: str) -> np.ndarray:
    """Pulse offsets (s) from the first pulse of a reference burst (MIL-STD-291C)."""
    if mode == "X":
        if kind == "main":
            starts = np.arange(12) * 30 * _US
            return np.sort(np.concatenate([starts, starts + 12 * _US]))
        if kind == "aux":
            starts = np.arange(6) * 24 * _US
            return np.sort(np.concatenate([starts, starts + 12 * _US]))
    elif mode == "Y":
        if kind == "main":
            return np.arange(13) * 30 * _US
        if kind == "aux":
            return np.arange(13) * 15 * _US
    raise ValueError(f"mode must be 'X' or 'Y' and kind 'main' or 'aux', not {mode!r}/{kind!r}")


def pair_spacing_s(mode: str) -> float:
    """Spacing of the two pulses of a pair: 12 us (X) or 30 us (Y)."""
    return {"X": 12 * _US, "Y": 30 * _US}[mode]


#: Which search reported a peak when the front end runs two (``FrontendConfig.pair_peak``,
#: ``Peaks.source``, the FIFO word's source bit): the single-pulse search, the pair search.
SOURCE_PULSE, SOURCE_PAIR = 0, 1

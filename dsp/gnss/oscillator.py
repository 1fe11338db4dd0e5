"""Receiver oscillator model: the power-law h-parameters of ``S_y(f) = h0 + h_1 / f +
h_2 / f^2`` (IEEE Std 1139) and the tables the toolkit ships. The DSP's Kalman loops take
their clock process noise from it; the signal generator's phase noise
(:mod:`cosim.gnss.oscillator`) draws from it.

Tables (h0, h-1, h-2): the "typical" crystal-oscillator values of Brown & Hwang,
*Introduction to Random Signals and Applied Kalman Filtering*, 4th ed. (Wiley, 2012),
section 9.3, p. 327 (Table 9.2, the clock models of the GPS chapter): "tcxo" is the book's
(low-quality) temperature-compensated crystal, "ocxo" its oven-controlled crystal. The
same values, with that citation, are in independent open-source GNSS code (navtools'
clock models, Auburn GAVLab; D. Sturdivant's sturdr ``clock.hpp``), which also lists the
book's high-quality TCXO (2e-21, 1e-22, 2e-20), rubidium (2e-22, 4.5e-26, 1e-30) and
cesium (2e-22, 5e-27, 1.5e-33) rows. (The INS paper cites O'Driscoll & Lachapelle 2011 for its
oscillator table, which is empty in the paper's text; we have not checked that paper.)

=========  ========  ========  ========
class      h0        h-1       h-2
=========  ========  ========  ========
TCXO       2e-19     7e-21     2e-20
OCXO       2e-25     7e-25     6e-25
=========  ========  ========  ========

(Checked here against those two code bases, not against a copy of the book: confirm in the
book before quoting them in a publication.) What the generator draws from them -- the Allan
variance ``h0 / (2 tau) + 2 ln2 h-1 + (2 pi^2 / 3) h-2 tau`` and the frequency-noise PSD
``h0 + h-1 / f + h-2 / f^2`` of each table -- is tested in
``tests/cosim/gnss/test_gnss_oscillator.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Oscillator", "OSCILLATORS", "oscillator"]


@dataclass(frozen=True)
class Oscillator:
    """Power-law coefficients of ``S_y(f)`` (1/Hz), all >= 0."""

    h0: float
    h_1: float
    h_2: float
    name: str = "custom"

    def __post_init__(self):
        for k in ("h0", "h_1", "h_2"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v) or v < 0:
                raise ValueError(f"oscillator {k} must be a finite number >= 0, not {v!r}")

    def allan_variance(self, tau_s):
        """``sigma_y^2(tau)`` of the three power laws (the continuous-time values)."""
        tau = np.asarray(tau_s, dtype=np.float64)
        return self.h0 / (2 * tau) + 2 * math.log(2) * self.h_1 + 2 * math.pi ** 2 / 3 * self.h_2 * tau


#: Brown & Hwang (4th ed., 2012) section 9.3, p. 327, Table 9.2 values (module docstring).
OSCILLATORS = {
    "tcxo": Oscillator(2e-19, 7e-21, 2e-20, "tcxo"),
    "ocxo": Oscillator(2e-25, 7e-25, 6e-25, "ocxo"),
}


def oscillator(spec) -> Oscillator | None:
    """``None``, an :class:`Oscillator`, or a table name (``"tcxo"``, ``"ocxo"``)."""
    if spec is None or isinstance(spec, Oscillator):
        return spec
    if isinstance(spec, str) and spec.lower() in OSCILLATORS:
        return OSCILLATORS[spec.lower()]
    raise ValueError(f"oscillator must be None, an Oscillator or one of "
                     f"{sorted(OSCILLATORS)}, not {spec!r}")

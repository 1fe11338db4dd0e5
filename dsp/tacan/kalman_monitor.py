"""The state monitor of :class:`dsp.tacan.kalman.EnvelopeKalman` and the upsets of the
bit-error studies.

The DSP checks its own state between reference bursts: :meth:`StateMonitor.checkpoint`
remembers it, :meth:`StateMonitor.state_jump` and :meth:`StateMonitor.covariance_fault` say
whether it has changed since in a way the filter cannot change it (a corrupted memory
word), and :meth:`StateMonitor.recover` answers a failed check. The bit-error studies flip
state bits through :meth:`StateMonitor.schedule_upsets`. A mixin: it reads the filter's
state, configuration and compiled step (:mod:`dsp.tacan.kalman_kernel`).
"""
from __future__ import annotations

import math

import numpy as np

from .bearing import PHASE_BITS
from .phase_ops import SIN_LUT
from .kalman_kernel import EVENT_INDEX, run_serial, step_consts

__all__ = ["StateMonitor"]


class StateMonitor:
    """Continuity checks, recovery and upset injection for :class:`EnvelopeKalman` (which
    provides ``x``, ``P``, ``r``, ``fixed``, ``kalman``, the event counters and the compiled
    step's constants)."""

    def _block_tr(self, P=None) -> np.ndarray:
        """Per trial, the covariance's trace over each of the state's three blocks -- the
        15 Hz pair, the 135 Hz pair, the DC level -- in units of ``r`` ((B, 3)): invariant
        under the model's rotations. ``P``: its float readout, when the caller has it."""
        d = np.diagonal(self.P_float() if P is None else P, axis1=1, axis2=2)
        return np.stack([d[:, 0] + d[:, 1], d[:, 2] + d[:, 3], d[:, 4]], axis=1)

    def checkpoint(self) -> None:
        """Remember the state for :meth:`state_jump`, :meth:`covariance_fault` and
        :meth:`recover` (the stored ``x`` and ``P``, the block traces of ``P``, the
        re-initialisation count) and restart the time and phase advance."""
        self._ck = (self.x_float(), self._block_tr(), self._ev[:, EVENT_INDEX["reinit"]].copy(),
                    self.x.copy(), self.P.copy())
        self._adv = [0, 0] if self.fixed is not None else [0.0, 0.0]
        self._elapsed_s = 0.0
        self._elapsed_ticks = 0

    def _judged(self) -> np.ndarray:
        """Trials whose change since the checkpoint can be judged: not re-initialised since
        (the warm-up is judged too: a state corrupted there would be carried past it)."""
        return self._ev[:, EVENT_INDEX["reinit"]] == self._ck[2]

    def covariance_fault(self) -> np.ndarray:
        """Per trial: the covariance changed since the :meth:`checkpoint` in a way the filter
        cannot change it. Between checkpoints ``P`` only rotates (which keeps each block's
        trace), grows by the process noise (``q_rates`` times the time, per state) and
        shrinks with each update; so a block trace above its checkpoint value plus 1.5 x
        the process noise (and rounding), or an off-diagonal term beyond the Cauchy-Schwarz
        bound ``P_ij^2 <= P_ii P_jj`` of a covariance, is a corrupted word. A float
        readout, for monitoring only; False where :meth:`state_jump` is not judged."""
        if self._ck is None:
            return np.zeros(self.batch, bool)
        grow = 1.5 * self._elapsed_s * self._q_block()
        lsb = 0.0 if self.fixed is None else math.ldexp(64.0, -self.fixed.P.frac)
        tr0 = self._ck[1]
        P = self.P_float()
        up = (self._block_tr(P) > tr0 * (1 + 1e-6) + grow + lsb).any(axis=1)
        d = np.maximum(np.diagonal(P, axis1=1, axis2=2), 0.0)
        cs = (P * P > d[:, :, None] * d[:, None, :] * (1 + 1e-6) + lsb * lsb).any(axis=(1, 2))
        return (up | cs) & self._judged()

    def state_jump(self) -> np.ndarray:
        """Per trial: how far the state has moved since the :meth:`checkpoint` beyond what
        the transition model explains, against what the measurements since can move it.

        Between two checkpoints the state may only rotate (the model) and take the
        measurements' corrections ``K * innovation``. Rotated back, the change of each
        block (15 Hz pair, 135 Hz pair, DC) is the sum of those corrections, whose variance
        is the information the block gained: ``r`` times (its covariance trace then, plus
        the process noise since, minus its trace now). A state word changed by anything
        else -- an upset of the DSP's memory -- moves a block by far more. Returned: the
        largest block change in standard deviations of that variance (~1.5-2 in normal
        operation: the largest of three). 0 where it cannot be judged (no checkpoint, or the
        filter re-initialised since). A float readout, for monitoring only."""
        if self._ck is None:
            return np.zeros(self.batch)
        x0, tr0 = self._ck[:2]
        if self.fixed is None:
            ang = np.array(self._adv, dtype=np.float64)
        else:
            ang = np.array(self._adv, dtype=np.float64) * (2.0 * math.pi / 2.0 ** PHASE_BITS)
        x = self.x_float()
        pred = x0.copy()
        for b, a in enumerate(ang):          # x_pred = A x0: R(a) = [[c, s], [-s, c]]
            c, s = math.cos(a), math.sin(a)
            u, v = x0[:, 2 * b], x0[:, 2 * b + 1]
            pred[:, 2 * b], pred[:, 2 * b + 1] = c * u + s * v, -s * u + c * v
        d = x - pred
        d2 = np.stack([d[:, 0] ** 2 + d[:, 1] ** 2, d[:, 2] ** 2 + d[:, 3] ** 2, d[:, 4] ** 2],
                      axis=1)
        # the information gained: trace then, plus the process noise since, minus trace now
        # (floored at 1e-4 of the trace then: no update since, or rounding)
        tr = self._block_tr()
        gained = np.maximum(tr0 + self._elapsed_s * self._q_block() - tr, 1e-4 * np.abs(tr0))
        var = np.maximum(self.r, 0.0)[:, None] * gained
        z = np.full(d2.shape, np.inf)
        np.divide(d2, var, out=z, where=var > 0)
        z[d2 == 0] = 0.0
        return np.where(self._judged(), np.sqrt(z.max(axis=1)), 0.0)

    def _q_block(self) -> np.ndarray:
        """The process noise per second over each block's trace (units of r)."""
        q_rot, q_dc = self.kalman.q_rates()
        return np.array([2 * q_rot, 2 * q_rot, q_dc])

    def recover(self, faulty) -> None:
        """The answer to a failed continuity check (:meth:`state_jump`,
        :meth:`covariance_fault`) on the trials of ``faulty``, each counted as
        ``state_faults``: the state and covariance stored at the :meth:`checkpoint`, which
        passed its own check, are restored and predicted to now -- the core's own
        prediction, one step over the time since, as through a gap: the measurements since
        are lost, nothing else. A trial whose previous check failed too (its checkpoint is
        not trusted: e.g. a state refitted to garbage that the good pulses now pull back)
        is re-initialised instead (counted as ``reinit``; warm-up again)."""
        m = np.asarray(faulty, bool)
        again = m & self._failed
        self._failed = m.copy()
        if not m.any():
            return
        self._ev[m, EVENT_INDEX["state_faults"]] += 1
        if again.any():
            self.reset(again)
            self._ev[again, EVENT_INDEX["reinit"]] += 1
        back = m & ~again
        if not back.any():
            return
        x, P = self._ck[3][back], self._ck[4][back]
        t = np.array([self._elapsed_ticks if self.fixed is not None else self._elapsed_s],
                     dtype=np.int64 if self.fixed is not None else np.float64)
        sc = np.empty((1, 7), self.x.dtype)
        step_consts(SIN_LUT, t, np.ones(1, self.x.dtype) if self.fixed is None
                     else np.array([1 << self.fixed.P.frac], np.int64), self._ci, self._cv, sc)
        nb = int(back.sum())
        no_y = np.full((nb, 1), self._cv[7], self.x.dtype)      # no measurement: predict
        cnt, ev = self._cnt[back].copy(), self._ev[back].copy()   # counters untouched
        run_serial(x, P, self._r[back].copy(), cnt, ev, sc, no_y, self._ci, self._cv,
                    self._bt, self._gt, self._bs, self._nq)
        self.x[back], self.P[back] = x, P

    # -- upsets (bit-error studies) -------------------------------------------------------
    #: Words of the state as the DSP stores it: ``x[0..4]``, then the upper triangle of
    #: ``P`` row by row (``P`` is symmetric, one word per pair).
    STATE_WORDS = tuple(("x", i, i) for i in range(5)) + tuple(
        ("P", i, j) for i in range(5) for j in range(i, 5))

    def schedule_upsets(self, steps, words, bits) -> None:
        """Flip state bits during later :meth:`run` calls (single-event upsets of the DSP's
        memory; fixed point only). Upset ``k`` flips bit ``bits[k]`` of the stored word
        ``words[k]`` (an index into :attr:`STATE_WORDS`; a ``P`` word flips both mirrored
        entries) of every trial just before update number ``steps[k]`` (counted like
        :attr:`n_updates`). Replaces any schedule not yet applied."""
        if self.fixed is None:
            raise ValueError("upsets flip bits of the fixed-point state: use a KalmanFixedConfig")
        st = np.asarray(steps, dtype=np.int64).ravel()
        wd = np.asarray(words, dtype=np.int64).ravel()
        bt = np.asarray(bits, dtype=np.int64).ravel()
        if not (st.size == wd.size == bt.size):
            raise ValueError("steps, words and bits must have the same length")
        if st.size and (np.any(np.diff(st) < 0) or st[0] < self.n_updates):
            raise ValueError(f"upset steps must be sorted and >= n_updates ({self.n_updates})")
        if wd.size and (wd.min() < 0 or wd.max() >= len(self.STATE_WORDS)):
            raise ValueError(f"upset words must lie in 0..{len(self.STATE_WORDS) - 1}")
        widths = np.array([self.fixed.x.width if n == "x" else self.fixed.P.width
                           for n, _, _ in self.STATE_WORDS])
        if bt.size and (bt.min() < 0 or np.any(bt >= widths[wd])):
            raise ValueError("upset bit positions must lie inside the word (0 = LSB)")
        self._upsets = (st, wd, bt, 0)

    def _flip(self, word: int, bit: int) -> None:
        name, i, j = self.STATE_WORDS[word]
        w = (self.fixed.x if name == "x" else self.fixed.P).width
        arr = self.x[:, i] if name == "x" else self.P[:, i, j]
        u = (arr & np.int64((1 << w) - 1)) ^ np.int64(1 << bit)
        v = np.where(u >= np.int64(1 << (w - 1)), u - np.int64(1 << w), u)
        if name == "x":
            self.x[:, i] = v
        else:
            self.P[:, i, j] = v
            self.P[:, j, i] = v
        self.upsets_applied += 1

"""Pulse-peak search: its parameters (:class:`PeakParams`, the word widths and latencies of
the HDL block :class:`hdl.tacan.peak.PeakSearch` included), the state it carries across
chunks (:class:`PeakState`) and its result (:class:`PeakResult`). The algorithm is
described in :mod:`dsp.tacan.peak`."""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from dsp.fixed import check_width

__all__ = ["PeakParams", "PeakState", "PeakResult"]


@dataclass(frozen=True)
class PeakParams:
    """Parameters of the peak search (those of :class:`hdl.peak.PeakSearch`: the word widths
    and the pipeline's latency are part of the block's specification, the golden model
    reads the algorithm's fields only).

    Parameters
    ----------
    amp_width : int
        Width of the unsigned envelope input and of the output amplitude (bits).
        Default 19 = ``EnvelopeParams().out_width``.
    ts_bits : int
        Width of the output timestamp (bits); it wraps modulo ``2**ts_bits``.
    ts_step : int
        Input-clock ticks per envelope sample (timestamp increment per sample), >= 1.
    block_log2 : int
        log2 of the noise-floor block length in samples (1..20).
    clip_log2 : int
        Samples are clipped at ``nu << clip_log2`` before averaging (0..8).
    smooth_log2 : int
        Noise-floor smoothing ``nu += (m - nu) >> smooth_log2`` (0..16).
    clip_to_floor : bool
        A sample over the clip level counts as the current floor ``nu`` instead of the clip
        level (False: ``min(e, nu << clip_log2)``). Pulses then leave the floor where it is --
        the block mean is a censored mean of the noise -- so the threshold does not rise
        after a burst of pulses. Measured on the TACAN golden chain at 0 dB (4 records of 3 s
        per bearing, threshold raised 3.0 -> 3.25 to keep the noise-only false-alarm rate):
        bearing 270 deg RMSE 1.22 -> 0.61 deg, mean error +1.08 -> +0.26 deg; 90 deg and
        10 dB unchanged within the spread. On noise alone the floor settles ~8.5 % lower
        than the clipped mean's (``E[e | e < 2 nu]`` against ``E[min(e, 2 nu)]``).
    floor_frac : bool
        The integer floor keeps ``smooth_log2`` fraction bits (``F``, see the module doc):
        ``F += m - (F >> smooth_log2)``, ``nu = F >> smooth_log2``, instead of ``nu += (m -
        nu) >> smooth_log2``, whose truncation leaves ``nu`` up to ``2**smooth_log2`` LSB below
        the mean of ``m`` (negligible at ``smooth_log2`` 2, ~14 % of the pair detector's floor
        at 10). The HDL's floor register is ``smooth_log2`` bits wider. No effect on the float
        variant (no rounding there).
    thr_mult, thr_frac : int
        Threshold factor ``thr_mult * 2**-thr_frac`` times the noise floor (default 3.0).
    thr_min : int
        Lowest threshold (envelope LSBs), >= 0.
    hold : int
        Consecutive below-threshold samples that close a pulse, >= 1.
    max_len : int
        Samples after which an open pulse is emitted anyway, > hold.
    partner_offset : int
        Pair-partner readout distance ``D`` in samples (0: off, else 1..4096; TACAN X mode:
        12 us, Y mode: 30 us of envelope samples). Adds ``partner`` and ``partner_late`` to
        each pulse (see the module doc) and delays the output by ``D`` input samples.
    pair_offset : int
        Pulse-pair detection at spacing ``D`` samples (0: off, else 1..4096; not with
        ``partner_offset``): the search runs on ``e[n] + e[n - D]`` and reports pairs (see the
        module doc); delays the output by ``D`` input samples.
    pair_keep : int
        Pair detection: a pair-sum peak is dropped when a side lobe exceeds it by more
        than ``8 / pair_keep`` (1..8 eighths; see the module doc).
    pair_balance : int
        Pair detection, both pulses present (0: off, else 1..8 sixteenths): a pair-sum peak
        ``s = e[n_max] + e[n_max - D]`` is dropped unless ``16 min(e[n_max], e[n_max - D]) >=
        pair_balance * s`` (see the module doc).
    pair_spread : int
        Pair detection, pulse spacing ``D +- w`` (0: off, else ``w`` = 1..64 samples, <= D): a
        pair-sum peak is dropped unless ``s[n_max] >= max(e[n_max + w] + e[n_max - D - w],
        e[n_max - w] + e[n_max - D + w])``, i.e. the pair sum at spacing ``D`` through the
        pair's centre is not below those at ``D +- 2 w`` (see the module doc).
    """

    amp_width: int = 19
    ts_bits: int = 32
    ts_step: int = 4
    block_log2: int = 10
    clip_log2: int = 1
    smooth_log2: int = 2
    clip_to_floor: bool = False
    floor_frac: bool = False
    thr_mult: int = 48
    thr_frac: int = 4
    thr_min: int = 16
    hold: int = 5
    max_len: int = 128
    partner_offset: int = 0
    pair_offset: int = 0
    pair_keep: int = 6
    pair_balance: int = 0
    pair_spread: int = 0

    def __post_init__(self):
        check_width("peak amp_width", self.amp_width, minimum=1, maximum=40)
        check_width("peak ts_bits", self.ts_bits, minimum=1, maximum=62)
        _check_int("peak ts_step", self.ts_step, 1, (1 << self.ts_bits) - 1)
        _check_int("peak block_log2", self.block_log2, 1, 20)
        _check_int("peak clip_log2", self.clip_log2, 0, 8)
        _check_int("peak smooth_log2", self.smooth_log2, 0, 16)
        if not isinstance(self.clip_to_floor, bool):
            raise ValueError(f"peak clip_to_floor must be True or False, not {self.clip_to_floor!r}")
        if not isinstance(self.floor_frac, bool):
            raise ValueError(f"peak floor_frac must be True or False, not {self.floor_frac!r}")
        _check_int("peak thr_frac", self.thr_frac, 0, 16)
        _check_int("peak thr_mult", self.thr_mult, 1, (1 << 20) - 1)
        _check_int("peak thr_min", self.thr_min, 0, (1 << self.amp_width) - 1)
        _check_int("peak hold", self.hold, 1, 1 << 16)
        _check_int("peak partner_offset", self.partner_offset, 0, 4096)
        _check_int("peak pair_offset", self.pair_offset, 0, 4096)
        _check_int("peak pair_keep", self.pair_keep, 1, 8)
        _check_int("peak pair_balance", self.pair_balance, 0, 8)
        _check_int("peak pair_spread", self.pair_spread, 0, 64)
        if self.pair_offset and self.pair_spread > self.pair_offset:
            raise ValueError(f"peak pair_spread ({self.pair_spread}) must not exceed "
                             f"pair_offset ({self.pair_offset})")
        if self.pair_offset and self.partner_offset:
            raise ValueError("peak pair_offset and partner_offset exclude each other (the pair "
                             "detection reads its partners itself)")
        if isinstance(self.max_len, bool) or not isinstance(self.max_len, int) \
                or self.max_len <= self.hold or self.max_len > 1 << 20:
            raise ValueError(f"peak max_len must be an integer > hold ({self.hold}) and "
                             f"<= 2**20, not {self.max_len!r}")
        if self.pair_offset and (self.pair_balance or self.pair_spread):
            step = int(self.ts_step).bit_length() - 1
            depth_log2 = self.pair_check_depth.bit_length() - 1
            if int(self.ts_step) != 1 << step or self.ts_bits - step < depth_log2:
                raise ValueError(
                    f"peak pair checks (pair_balance, pair_spread) need ts_step a power of two "
                    f"and ts_bits - log2(ts_step) >= {depth_log2} (the HDL reads the peak's "
                    f"index mod {self.pair_check_depth} from its timestamp), not ts_step "
                    f"{self.ts_step}, ts_bits {self.ts_bits}")

    # -- derived ---------------------------------------------------------------------------
    @property
    def block_len(self) -> int:
        return 1 << self.block_log2

    @property
    def thr_factor(self) -> float:
        return self.thr_mult * 2.0 ** -self.thr_frac

    @property
    def acc_width(self) -> int:
        """Noise accumulator: ``nu*(2**s - 1)*L + sum(min(e, clip)) < 2**(amp + log2 L + s)``."""
        return self.amp_width + self.block_log2 + self.smooth_log2

    @property
    def floor_width(self) -> int:
        """The HDL's noise-floor register: ``nu`` (``amp_width``), or with ``floor_frac``
        ``F < 2**(amp_width + smooth_log2)``."""
        return self.amp_width + (self.smooth_log2 if self.floor_frac else 0)

    @property
    def thr_width(self) -> int:
        """Unsigned width of a threshold ``max(thr_min, nu*thr_mult >> thr_frac)``."""
        return max(self.amp_width + self.thr_mult.bit_length() - self.thr_frac, self.amp_width, 1)

    @property
    def search_params(self) -> "PeakParams":
        """The parameters the search itself runs with: these, or with ``pair_offset`` those of
        the search on the pair sum (one bit wider, partner readout at ``D``)."""
        if not self.pair_offset:
            return self
        return replace(self, amp_width=self.amp_width + 1, partner_offset=self.pair_offset,
                       pair_offset=0, pair_keep=PeakParams.pair_keep,
                       pair_balance=0, pair_spread=0)

    @property
    def pair_history(self) -> int:
        """Input samples the pair detection keeps from one chunk to the next: ``D`` (the
        ``e[n - D]`` of the sum), with the pair checks ``2 D + max_len + pair_spread`` (the
        envelope around a peak ``n_max`` emitted up to ``D + max_len`` samples after it)."""
        D = self.pair_offset
        if not (self.pair_balance or self.pair_spread):
            return D
        return 2 * D + self.max_len + self.pair_spread

    @property
    def pair_checks(self) -> bool:
        """Pair detection with a pair check (``pair_balance`` or ``pair_spread``) on."""
        return bool(self.pair_offset and (self.pair_balance or self.pair_spread))

    @property
    def pair_check_depth(self) -> int:
        """Words of the HDL's envelope history for the pair checks: the power of two >=
        ``pair_history + search_params.latency``. A peak ``n_max`` is emitted by the inner
        search ``search_params.latency + 1`` cycles (sum stage + inner search) after the
        input transfer of sample ``end_index + D``, where the taps are read; up to
        ``search_params.latency`` inputs after that sample are written before the read (the
        read does not see the write of its own cycle), so the newest written sample is at
        most ``end_index + D + search_params.latency`` and the oldest tap ``n_max - D - w >=
        end_index - max_len + 1 - D - w``."""
        need = self.pair_history + self.search_params.latency
        return 1 << (need - 1).bit_length()

    @property
    def emit_delay(self) -> int:
        """Input samples after a pulse's closing sample (``end_index``) before it is emitted
        (the partner readout's or pair detection's ``D``, else 0)."""
        return self.partner_offset or self.pair_offset

    @property
    def det_delay(self) -> int:
        """Cycles the detector runs behind the noise-floor path (threshold pipeline: new
        ``nu`` 1 cycle after the block sum, the partial products +1, their sum or ``thr_min``
        +1, registered compare +1)."""
        return 4

    @property
    def latency(self) -> int:
        """Cycles from the input transfer of sample ``end_index + emit_delay`` (a pulse's
        closing sample, ``emit_delay`` later) to the output transfer: the input register, the
        detector ``det_delay`` behind, the output register; a search reading through its
        partner delay line (the pair detection's inner search too) two more (the line's read
        data registered in the fabric, then the compare register); the pair detection its
        sum stage, its constant-product register and its output register, the pair checks
        one cycle more (the envelope history's registered read). :mod:`hdl.peak` says why."""
        return (1 + (2 if self.partner_offset or self.pair_offset else 0) + self.det_delay + 1
                + (3 if self.pair_offset else 0) + (1 if self.pair_checks else 0))

    @property
    def in_layout(self) -> list[tuple[str, int, bool]]:
        return [("e", self.amp_width, False)]

    @property
    def out_layout(self) -> list[tuple[str, int, bool]]:
        """Packed output payload, LSB first (for ``cosim.pysim.unpack_fields``)."""
        out = [("amplitude", self.amp_width, False), ("timestamp", self.ts_bits, False)]
        if self.partner_offset:
            out += [("partner", self.amp_width, False), ("partner_late", 1, False)]
        return out

    def threshold(self, nu: int) -> int:
        """Integer threshold of a block whose noise floor is ``nu``."""
        return max(self.thr_min, (int(nu) * self.thr_mult) >> self.thr_frac)


def _check_int(name, value, lo, hi):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
            or not lo <= int(value) <= hi:
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], not {value!r}")


@dataclass
class PeakState:
    """Everything the search carries from one chunk to the next (initial value = reset).

    ``n`` samples seen; ``nu`` current noise floor (meaningful once ``n >= L``); ``nuf``
    the floor with its ``smooth_log2`` fraction bits (``F``, ``nu = nuf >> smooth_log2``) in
    the integer model with ``floor_frac``, else 0; ``bsum`` partial sum of the current block; an open pulse has ``start`` (its first
    ``n``), ``pmax``/``nmax`` (max so far and its ``n``), ``below`` and ``length``.
    Values are Python ints in the integer model and floats in the float model.
    """

    n: int = 0
    nu: float = 0
    nuf: int = 0
    bsum: float = 0
    open: bool = False
    start: int = 0
    pmax: float = 0
    nmax: int = 0
    below: int = 0
    length: int = 0
    # pair-partner readout (partner_offset D > 0): the open pulse's ahead/behind values, the
    # input samples seen and the last ones kept (x[n - D] .. x[n_in - 1], a tuple)
    pa: float = 0
    pb: float = 0
    n_in: int = 0
    hist: tuple = ()
    # pulse-pair detection (pair_offset D > 0): the last D input samples (zeros before the
    # first), the e[n - D] of the pair sum
    pair_hist: tuple = ()


@dataclass
class PeakResult:
    """Emitted pulses in order. ``index``: ``n`` of the peak; ``end_index``: ``n`` of the
    closing sample (the HDL emits ``params.latency`` cycles after that sample's transfer)."""

    amplitude: np.ndarray
    timestamp: np.ndarray
    index: np.ndarray
    end_index: np.ndarray
    thresholds: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: with ``partner_offset``: max(ahead, behind) and whether ahead won (empty when off)
    partner: np.ndarray = field(default_factory=lambda: np.zeros(0))
    partner_late: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

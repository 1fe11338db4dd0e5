"""TACAN signal in space at the digital IF: pulse schedule, bearing modulation, noise, ADC.

Conventions (written down once, used by the generator, the receivers and the tests)
----------------------------------------------------------------------------------
* Times are seconds from the first ADC sample (sample ``n`` is at ``n / fs``).
* A *reference time* is the peak time of the first pulse of its burst.
* Main reference bursts repeat every 1/15 s starting at ``first_main_ref_s``; auxiliary
  bursts follow each main reference at ``k / 135`` s, ``k = 1..8`` (the ninth coincides with
  the next main burst and is left out, MIL-STD-291C).
* Bearing convention: a beacon at bearing ``theta`` (radial from the beacon, degrees
  clockwise from magnetic north) is heard with the pulse-amplitude envelope::

      a(t) = a0 * (1 + A sin(2 pi 15 (t - t_M) - theta) + B sin(2 pi 135 (t - t_M) - 9 theta))

  where ``t_M`` is any main reference time. The positive-going zero crossing of the 15 Hz
  component lags the main reference by ``theta`` (of a 15 Hz cycle), and the 135 Hz
  component's lags the most recent auxiliary (or main) reference by ``9 theta mod 360``. At
  ``theta = 90`` deg both components are at their minimum at every reference: the TACAN
  paper's worst case (references in the envelope trough).

Pulse codes (MIL-STD-291C): :mod:`dsp.tacan.standard` (burst offsets, pair spacing, the
modulation frequencies and the pulse width live there, with the DSP that decodes them).

Random replies/squitter are pulse pairs (12 us in X, 30 us in Y) placed uniformly at random
with a minimum spacing (dead time) in the time left free by the reference groups and their
guard intervals, with exactly as many per rotation as keep the duty cycle constant at
``pairs_per_s`` (3600 pulse pairs/s: 180 main + 720 auxiliary + 2700 random in X mode).

Noise and SNR
-------------
SNR is the peak pulse power ``a0**2 / 2`` (unmodulated carrier amplitude ``a0``) over the
noise power in ``noise_bw_hz`` (2 MHz), as in the TACAN paper's test set-up, where the noise
source itself had that bandwidth. The noise is white Gaussian passed through a 4th-order
Butterworth band-pass of that bandwidth centred on the IF (the analog IF filter); its
passband density is ``N0 = (a0**2 / 2) / (SNR * noise_bw_hz)``.

Bandpass sampling
-----------------
The analog IF ``if_hz`` is sampled at ``fs_hz``; the band ``if_hz +- noise_bw_hz / 2`` must
lie inside one Nyquist zone. The samples are generated directly at the folded (digital) IF,
which gives the same samples as sampling the analog IF.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from dsp.jit import njit_cached
from dsp.sampling import SampledIf
# The standard (frequencies, pulse width, burst codes) is the DSP's: imported, not restated.
from dsp.tacan.standard import F15, F135, PULSE_WIDTH_S, burst_offsets, pair_spacing_s  # noqa: F401

FWHM_TO_SIGMA = 1.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))

KIND_RANDOM, KIND_MAIN, KIND_AUX, KIND_IDENT, KIND_ECHO = 0, 1, 2, 3, 4
KIND_NAMES = {KIND_RANDOM: "random", KIND_MAIN: "main", KIND_AUX: "aux",
              KIND_IDENT: "identity", KIND_ECHO: "echo"}


@dataclass(frozen=True)
class Multipath:
    """One specular echo: delayed, scaled copy of every pulse.

    ``bearing_deg`` is the bearing the echo is radiated towards (its own modulation phase);
    None means the direct path's bearing.
    """

    delay_s: float = 2e-6
    rel_amplitude: float = 0.3
    phase_rad: float = 0.0
    bearing_deg: float | None = None

    def __post_init__(self):
        if not (math.isfinite(self.delay_s) and self.delay_s > 0):
            raise ValueError(f"multipath delay_s must be > 0, not {self.delay_s}")
        if not (math.isfinite(self.rel_amplitude) and 0 <= self.rel_amplitude < 1):
            raise ValueError(f"multipath rel_amplitude must be in [0, 1), not {self.rel_amplitude}")
        if self.bearing_deg is not None and not math.isfinite(self.bearing_deg):
            raise ValueError(f"multipath bearing_deg must be finite, not {self.bearing_deg}")


@dataclass(frozen=True)
class TacanSignalConfig(SampledIf):
    """Everything that defines a TACAN IF scenario. Defaults: docs/explanation/tacan.md.

    Parameters
    ----------
    bearing_deg : float
        True bearing (deg), any finite value (taken mod 360).
    mode : {"X", "Y"}
    mod_15, mod_135 : float
        Modulation depths A and B (0.21 nominal; 0.07-0.30 each in service; A + B < 1).
    snr_db : float or None
        Peak pulse power over noise power in ``noise_bw_hz``; None = no noise.
    duration_s : float
        Length of the record (s).
    seed : int
        Seeds the schedule, the carrier phases and the noise (independent streams).
    fs_hz, if_hz : float
        ADC sample rate and analog IF (bandpass sampled): 20 MS/s, 63 MHz -> 3 MHz.
    noise_bw_hz : float
        Bandwidth of the noise (and the SNR reference bandwidth), 2 MHz.
    adc_bits : int
        ADC word length (two's complement codes).
    amplitude : float or None
        Unmodulated pulse peak amplitude as a fraction of ADC full scale; None = AGC: the
        largest pulse plus 4 noise sigma lands at 90 % of full scale.
    pulse_width_s : float
        Pulse half-amplitude width (3.5 us).
    pairs_per_s : float
        Constant duty cycle in pulse pairs per second (3600).
    first_main_ref_s : float
        Time of the first main reference (s).
    min_pair_gap_s : float
        Dead time: minimum spacing between the starts of two random pairs (s).
    ref_guard_s : float
        No random pulse within this time before or after a reference group (s).
    identity : bool
        Add identity (morse) pairs at 1350 pairs/s, keyed on for ``identity_on_s`` out of
        every ``identity_period_s``; random pairs are thinned to keep the duty cycle.
    multipath : Multipath or None
    """

    bearing_deg: float = field(default=90.0, metadata={"help": "true bearing (deg, -360..360)"})
    mode: str = field(default="X", metadata={"help": "TACAN channel mode (case-insensitive)",
                                             "choices": ("X", "Y"), "case": "upper"})
    mod_15: float = field(default=0.21, metadata={"help": "15 Hz modulation depth A (fraction, > 0)"})
    mod_135: float = field(default=0.21, metadata={
        "help": "135 Hz modulation depth B (fraction, > 0, A + B < 1)"})
    snr_db: float | None = field(default=10.0, metadata={
        "help": "SNR of the pulses (dB, in the 2 MHz noise band), or 'none' for no noise",
        "none": ("none", "inf")})
    duration_s: float = field(default=3.0, metadata={"help": "record length (s)"})
    seed: int = field(default=1, metadata={"help": "random seed (>= 0)"})
    fs_hz: float = field(default=20e6, metadata={
        "help": "ADC sample rate = FPGA clock (Hz); the IF band must sit in one Nyquist zone"})
    if_hz: float = field(default=63e6, metadata={"help": "analog IF (Hz), bandpass sampled"})
    noise_bw_hz: float = 2e6
    adc_bits: int = field(default=12, metadata={"help": "ADC word length (bits, 1..24)"})
    amplitude: float | None = None
    pulse_width_s: float = PULSE_WIDTH_S
    pairs_per_s: float = 3600.0
    first_main_ref_s: float = 5e-3
    min_pair_gap_s: float = 50e-6
    ref_guard_s: float = 60e-6
    identity: bool = False
    identity_on_s: float = 0.125
    identity_period_s: float = 0.5
    multipath: Multipath | None = None
    rotation_hz: float = field(default=F15, metadata={
        "help": "antenna rotation rate (Hz; 15 nominal, 14.25..15.75 accepted); the fine "
                "(135 Hz) component and the reference bursts follow it"})

    def __post_init__(self):
        def finite(name):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number, not {v!r}")
            return float(v)

        if not -360 <= finite("bearing_deg") <= 360:
            raise ValueError(f"bearing_deg must be in [-360, 360] deg, not {self.bearing_deg!r}")
        if self.mode not in ("X", "Y"):
            raise ValueError(f"mode must be 'X' or 'Y', not {self.mode!r}")
        a, b = finite("mod_15"), finite("mod_135")
        if not (0 <= a < 1 and 0 <= b < 1 and a + b < 1):
            raise ValueError(
                f"modulation depths must satisfy 0 <= A, B and A + B < 1 "
                f"(the envelope must stay positive), not A={a}, B={b}")
        if self.snr_db is not None:
            finite("snr_db")
        if finite("duration_s") <= 0:
            raise ValueError(f"duration_s must be > 0, not {self.duration_s}")
        if finite("fs_hz") <= 0:
            raise ValueError(f"fs_hz must be > 0, not {self.fs_hz}")
        if finite("if_hz") <= 0:
            raise ValueError(f"if_hz must be > 0, not {self.if_hz}")
        if finite("noise_bw_hz") <= 0:
            raise ValueError(f"noise_bw_hz must be > 0, not {self.noise_bw_hz}")
        if finite("pulse_width_s") <= 0:
            raise ValueError(f"pulse_width_s must be > 0, not {self.pulse_width_s}")
        if isinstance(self.adc_bits, bool) or not isinstance(self.adc_bits, (int, np.integer)) \
                or not 1 <= self.adc_bits <= 24:
            raise ValueError(f"adc_bits must be an integer in [1, 24], not {self.adc_bits!r}")
        if self.amplitude is not None and not (finite("amplitude") > 0):
            raise ValueError(f"amplitude must be > 0 (fraction of ADC full scale), not {self.amplitude}")
        if finite("pairs_per_s") <= 0:
            raise ValueError(f"pairs_per_s must be > 0, not {self.pairs_per_s}")
        if finite("first_main_ref_s") < 0:
            raise ValueError(f"first_main_ref_s must be >= 0, not {self.first_main_ref_s}")
        if finite("min_pair_gap_s") <= 0:
            raise ValueError(f"min_pair_gap_s must be > 0, not {self.min_pair_gap_s}")
        if not 0.95 * F15 <= finite("rotation_hz") <= 1.05 * F15:
            raise ValueError(f"rotation_hz must be within 5 % of {F15:g} Hz "
                             f"({0.95 * F15:g}..{1.05 * F15:g}), not {self.rotation_hz!r}")
        if finite("ref_guard_s") < 0:
            raise ValueError(f"ref_guard_s must be >= 0, not {self.ref_guard_s}")
        # Bandpass sampling: the occupied band must sit inside one Nyquist zone.
        half = self.noise_bw_hz / 2
        lo_zone = math.floor((self.if_hz - half) / (self.fs_hz / 2))
        hi_zone = math.floor((self.if_hz + half) / (self.fs_hz / 2))
        if self.if_hz - half <= 0 or lo_zone != hi_zone or \
                (self.if_hz + half) == (hi_zone + 1) * self.fs_hz / 2:
            raise ValueError(
                f"sample rate {self.fs_hz / 1e6:g} MS/s is too low for the IF: the band "
                f"{(self.if_hz - half) / 1e6:g}-{(self.if_hz + half) / 1e6:g} MHz straddles a "
                f"Nyquist zone edge (multiple of fs/2 = {self.fs_hz / 2e6:g} MHz)")

    # -- derived ---------------------------------------------------------------------------
    @property
    def pulse_sigma_s(self) -> float:
        return self.pulse_width_s * FWHM_TO_SIGMA

    @property
    def n_samples(self) -> int:
        return int(round(self.duration_s * self.fs_hz))

    @property
    def snr_linear(self) -> float | None:
        return None if self.snr_db is None else 10.0 ** (self.snr_db / 10.0)

    def matched_filter_rel_sigma(self) -> float:
        """Relative amplitude noise of an ideal matched-filter pulse-amplitude estimate.

        ``var(a_hat) / a0**2 = 1 / (2 SNR B sigma_t sqrt(pi))`` for a Gaussian pulse of
        standard deviation ``sigma_t`` in noise of density ``N0 = a0^2 / (2 SNR B)``: the
        amplitude noise the Cramer-Rao bound of the bearing is computed from.
        """
        if self.snr_db is None:
            return 0.0
        return 1.0 / math.sqrt(2.0 * self.snr_linear * self.noise_bw_hz * self.pulse_sigma_s
                                * math.sqrt(math.pi))

    def replace(self, **changes) -> "TacanSignalConfig":
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d.update(changes)
        return TacanSignalConfig(**d)


@dataclass
class TacanTruth:
    """What the generator put in, for scoring the receivers."""

    config: TacanSignalConfig
    pulse_times_s: np.ndarray       # peak time of every direct-path pulse, sorted
    pulse_amplitudes: np.ndarray    # peak amplitude (fraction of full scale)
    pulse_kinds: np.ndarray         # KIND_* codes
    main_ref_times_s: np.ndarray
    aux_ref_times_s: np.ndarray
    amplitude: float                # a0, unmodulated pulse peak (fraction of full scale)
    noise_rms: float                # rms of the band-limited noise (fraction of full scale)
    digital_if_hz: float
    n_clipped: int = 0              # ADC samples that hit the rails

    @property
    def bearing_deg(self) -> float:
        return float(self.config.bearing_deg % 360.0)

    def summary(self) -> dict:
        c = self.config
        return {"bearing_deg": self.bearing_deg, "mode": c.mode, "n_pulses": int(len(self.pulse_times_s)),
                "n_main_refs": int(len(self.main_ref_times_s)), "n_aux_refs": int(len(self.aux_ref_times_s)),
                "amplitude": self.amplitude, "noise_rms": self.noise_rms, "n_clipped": self.n_clipped,
                "digital_if_hz": self.digital_if_hz}


@dataclass
class TacanSignal:
    samples: np.ndarray   # ADC codes, int16/int32, two's complement
    truth: TacanTruth


def envelope_gain(t_s, cfg: TacanSignalConfig, t_main_s: float, bearing_deg: float | None = None):
    """The bearing modulation ``1 + A sin(...) + B sin(...)`` at times ``t_s`` (convention above)."""
    th = math.radians(cfg.bearing_deg if bearing_deg is None else bearing_deg)
    dt = np.asarray(t_s, dtype=np.float64) - t_main_s
    f = float(cfg.rotation_hz)
    return (1.0 + cfg.mod_15 * np.sin(2 * np.pi * f * dt - th)
            + cfg.mod_135 * np.sin(2 * np.pi * (9 * f) * dt - 9 * th))


# ---------------------------------------------------------------------------------------------
# Pulse schedule
# ---------------------------------------------------------------------------------------------
def _streams(seed: int):
    ss = np.random.SeedSequence(int(seed))
    sched, phase, noise = ss.spawn(3)
    return (np.random.default_rng(sched), np.random.default_rng(phase),
            np.random.default_rng(noise))


def pulse_schedule(cfg: TacanSignalConfig, rng: np.random.Generator | None = None):
    """Every direct-path pulse: (times_s, kinds, main_ref_times_s, aux_ref_times_s).

    Deterministic for a given ``cfg.seed`` (uses the schedule stream of the seed).
    """
    if rng is None:
        rng = _streams(cfg.seed)[0]
    T = cfg.duration_s
    margin = 6 * cfg.pulse_sigma_s  # whole pulses only
    main_off = burst_offsets(cfg.mode, "main")
    aux_off = burst_offsets(cfg.mode, "aux")
    pair = pair_spacing_s(cfg.mode)

    f_rot = float(cfg.rotation_hz)
    n_lo = math.floor(-cfg.first_main_ref_s * f_rot) - 1
    n_hi = math.ceil((T - cfg.first_main_ref_s) * f_rot) + 1
    mains = cfg.first_main_ref_s + np.arange(n_lo, n_hi + 1) / f_rot
    auxs = (mains[:, None] + np.arange(1, 9)[None, :] / (9 * f_rot)).ravel()

    def keep(starts, offs):
        ok = (starts - margin >= 0) & (starts + offs[-1] + margin <= T)
        return starts[ok]

    main_t = keep(mains, main_off)
    aux_t = keep(auxs, aux_off)

    times = [(main_t[:, None] + main_off[None, :]).ravel(), (aux_t[:, None] + aux_off[None, :]).ravel()]
    kinds = [np.full(main_t.size * main_off.size, KIND_MAIN, np.uint8),
             np.full(aux_t.size * aux_off.size, KIND_AUX, np.uint8)]

    # Busy intervals: every reference group (also the ones cut by the record edges) + guard.
    g = cfg.ref_guard_s
    busy = [(s - g, s + main_off[-1] + g) for s in mains] + [(s - g, s + aux_off[-1] + g) for s in auxs]

    # Identity: pairs at 1350/s keyed on for identity_on_s of every identity_period_s.
    ident_t = np.empty(0)
    if cfg.identity:
        t_id = np.arange(0, T, 1 / 1350.0)
        keyed = (t_id % cfg.identity_period_s) < cfg.identity_on_s
        t_id = t_id[keyed]
        clash = np.zeros(t_id.size, bool)
        for lo, hi in busy:
            clash |= (t_id + pair >= lo) & (t_id <= hi)
        ident_t = t_id[~clash & (t_id - margin >= 0) & (t_id + pair + margin <= T)]
        times.append(np.concatenate([ident_t, ident_t + pair]))
        kinds.append(np.full(2 * ident_t.size, KIND_IDENT, np.uint8))
        busy += [(t - cfg.min_pair_gap_s / 2, t + pair + cfg.min_pair_gap_s / 2) for t in ident_t]

    # Free intervals for random pairs (pair start s: [s, s + pair] inside a free interval).
    busy.sort()
    free = []
    cur = margin
    end = T - margin - pair
    for lo, hi in busy:
        if lo - pair > cur:
            free.append((cur, min(lo - pair, end)))
        cur = max(cur, hi)
        if cur >= end:
            break
    if cur < end:
        free.append((cur, end))
    free = [(lo, hi) for lo, hi in free if hi > lo]

    ref_pulses_per_s = f_rot * main_off.size + 8 * f_rot * aux_off.size
    n_target = cfg.pairs_per_s * 2 * T - ref_pulses_per_s * T - 2 * ident_t.size
    n_random = max(0, int(round(n_target / 2)))
    lengths = np.array([hi - lo for lo, hi in free])
    total = float(lengths.sum()) if lengths.size else 0.0
    d = cfg.min_pair_gap_s
    slack = total - n_random * d
    if slack <= 0:
        raise ValueError(
            f"pairs_per_s={cfg.pairs_per_s:g} does not fit: {n_random} random pairs need "
            f"{n_random * d * 1e3:.1f} ms of dead time in {total * 1e3:.1f} ms left free by the "
            f"reference groups; lower pairs_per_s or min_pair_gap_s")
    u = np.sort(rng.uniform(0.0, slack, n_random)) + np.arange(n_random) * d
    # Map the concatenated free line back onto the intervals.
    edges = np.concatenate([[0.0], np.cumsum(lengths)])
    idx = np.clip(np.searchsorted(edges, u, side="right") - 1, 0, len(free) - 1)
    starts = np.array([lo for lo, _ in free])[idx] + (u - edges[idx])
    times.append(np.concatenate([starts, starts + pair]))
    kinds.append(np.full(2 * starts.size, KIND_RANDOM, np.uint8))

    t = np.concatenate(times)
    k = np.concatenate(kinds)
    order = np.argsort(t, kind="stable")
    return t[order], k[order], main_t, aux_t


# ---------------------------------------------------------------------------------------------
# IF samples
# ---------------------------------------------------------------------------------------------
_CHUNK = 1 << 20  # fixed: the noise stream is drawn in chunks of this size (determinism)


@njit_cached(nogil=True)
def _adc_codes(x, full, out) -> int:
    """The ADC: ``clip(rint(x * full), -full, full - 1)`` into ``out`` (round half to even,
    as ``np.rint``), returning how many samples clipped; one pass, no temporaries."""
    lo, hi = -full, full - 1
    n = 0
    for k in range(x.shape[0]):
        v = np.rint(x[k] * full)
        if v > hi:
            v = hi
            n += 1
        elif v < lo:
            v = lo
            n += 1
        out[k] = v
    return n


def _noise_filter(cfg: TacanSignalConfig):
    from scipy import signal as sps
    f0 = cfg.digital_if_hz
    lo, hi = f0 - cfg.noise_bw_hz / 2, f0 + cfg.noise_bw_hz / 2
    sos = sps.butter(4, [lo, hi], btype="bandpass", fs=cfg.fs_hz, output="sos")
    return sos


def noise_enbw_hz(cfg: TacanSignalConfig) -> float:
    """Noise-equivalent bandwidth of the noise filter (Hz), normalised to its centre gain."""
    from scipy import signal as sps
    sos = _noise_filter(cfg)
    imp = np.zeros(1 << 16)
    imp[0] = 1.0
    h = sps.sosfilt(sos, imp)
    _, g0 = sps.sosfreqz(sos, worN=[cfg.digital_if_hz], fs=cfg.fs_hz)
    return float(cfg.fs_hz / 2 * np.sum(h * h) / abs(g0[0]) ** 2)


@dataclass(frozen=True)
class UnitNoise:
    """A record's IF noise before its scaling: the seed's noise stream (white, unit
    variance) through the IF noise filter, warmed up as :func:`generate` does, float64, one
    value per ADC sample. It depends on :func:`noise_key` alone -- not on the SNR, the mode,
    the bearing or the ADC -- so records that share the key (a benchmark grid's modes and
    SNRs at one seed) draw and filter it once: :func:`generate` given it scales it exactly
    as it scales the noise it draws itself (the same bits)."""

    key: tuple
    values: np.ndarray


def noise_key(cfg: TacanSignalConfig) -> tuple:
    """What :class:`UnitNoise` depends on: the seed, the sample rate, the filter's band
    (digital IF, noise bandwidth) and the record length."""
    return (int(cfg.seed), float(cfg.fs_hz), float(cfg.digital_if_hz), float(cfg.noise_bw_hz),
            int(cfg.n_samples))


def _noise_chunks(cfg: TacanSignalConfig, rng_noise):
    """The filtered unit noise chunk by chunk (:data:`_CHUNK` samples, the last shorter):
    the filter warmed up on 4096 samples so that the record starts in steady state."""
    from scipy import signal as sps
    sos = _noise_filter(cfg)
    _, zi = sps.sosfilt(sos, rng_noise.standard_normal(4096), zi=np.zeros((sos.shape[0], 2)))
    n = cfg.n_samples
    for c0 in range(0, n, _CHUNK):
        nz, zi = sps.sosfilt(sos, rng_noise.standard_normal(min(n, c0 + _CHUNK) - c0), zi=zi)
        yield nz


def unit_noise(cfg: TacanSignalConfig) -> UnitNoise:
    """The :class:`UnitNoise` of ``cfg`` (480 MB for a 3 s record at 20 MHz)."""
    return UnitNoise(noise_key(cfg), np.concatenate(list(_noise_chunks(cfg, _streams(cfg.seed)[2]))))


def generate(cfg: TacanSignalConfig, noise: UnitNoise | None = None) -> TacanSignal:
    """Generate the ADC samples and the truth for a scenario.

    Runs in chunks (bounded memory); the same ``cfg`` (seed included) gives the same bits.
    ``noise``: the record's :func:`unit_noise`, drawn once for several records (the same
    bits as without it).
    """
    return generate_adc_variants(cfg, (cfg.adc_bits,), noise)[cfg.adc_bits]


def generate_adc_variants(cfg: TacanSignalConfig, adc_bits, noise: UnitNoise | None = None) -> dict:
    """The same analog record digitised by ADCs of several word lengths (one generation).

    Returns ``{bits: TacanSignal}``; ``result[cfg.adc_bits]`` equals :func:`generate`
    bit for bit, and every variant is what ``generate(replace(cfg, adc_bits=bits))`` gives
    (the analog signal and the AGC loading do not depend on the ADC word length).
    ``noise``: as :func:`generate`'s.
    """
    bits_list = []
    for b in adc_bits:
        if isinstance(b, bool) or not isinstance(b, (int, np.integer)) or not 1 <= b <= 24:
            raise ValueError(f"adc_bits must be integers in 1..24, not {b!r}")
        if int(b) not in bits_list:
            bits_list.append(int(b))
    if not bits_list:
        raise ValueError("adc_bits must not be empty")
    rng_sched, rng_phase, rng_noise = _streams(cfg.seed)
    t_p, kinds, main_t, aux_t = pulse_schedule(cfg, rng_sched)
    t_ref = main_t[0] if main_t.size else cfg.first_main_ref_s
    amp_rel = envelope_gain(t_p, cfg, t_ref)
    phases = rng_phase.uniform(0, 2 * np.pi, t_p.size)

    snr = cfg.snr_linear
    echo = cfg.multipath
    peak_rel = (1 + cfg.mod_15 + cfg.mod_135) * (1 + (echo.rel_amplitude if echo else 0))
    noise_over_a = 0.0 if snr is None else math.sqrt(noise_enbw_hz(cfg) / cfg.noise_bw_hz / (2 * snr))
    a0 = cfg.amplitude if cfg.amplitude is not None else 0.9 / (peak_rel + 4 * noise_over_a)
    noise_rms = a0 * noise_over_a

    # Complex envelope contributions: direct pulses and (optionally) their echoes.
    src_t = [t_p]
    src_c = [a0 * amp_rel * np.exp(1j * phases)]
    if echo is not None:
        amp_e = envelope_gain(t_p, cfg, t_ref, echo.bearing_deg)
        src_t.append(t_p + echo.delay_s)
        src_c.append(a0 * echo.rel_amplitude * amp_e * np.exp(1j * (phases + echo.phase_rad)))
    all_t = np.concatenate(src_t)
    all_c = np.concatenate(src_c)
    order = np.argsort(all_t, kind="stable")
    all_t, all_c = all_t[order], all_c[order]

    fs = cfg.fs_hz
    n = cfg.n_samples
    sig = cfg.pulse_sigma_s
    half = int(math.ceil(5 * sig * fs))
    k_off = np.arange(-half, half + 1)
    w = 2 * np.pi * cfg.digital_if_hz / fs
    sign = -1.0 if cfg.spectrum_inverted else 1.0
    fulls = {b: 1 << (b - 1) for b in bits_list}
    outs = {b: np.empty(n, dtype=np.int16 if b <= 16 else np.int32) for b in bits_list}
    n_clips = dict.fromkeys(bits_list, 0)

    if noise is not None and noise.key != noise_key(cfg):
        raise ValueError(f"the unit noise given is another record's: key {noise.key} != "
                         f"{noise_key(cfg)} (seed, fs, digital IF, noise bandwidth, samples)")
    chunks = None if snr is None or noise is not None else _noise_chunks(cfg, rng_noise)
    # White input density so that the filter's passband density is N0 = P / (SNR B).
    sigma_w = 0.0 if snr is None else math.sqrt((a0 * a0 / 2) / (snr * cfg.noise_bw_hz) * fs / 2)
    centre = np.rint(all_t * fs).astype(np.int64)
    for c0 in range(0, n, _CHUNK):
        c1 = min(n, c0 + _CHUNK)
        x = np.zeros(c1 - c0)
        j0 = np.searchsorted(centre, c0 - half, side="left")
        j1 = np.searchsorted(centre, c1 + half, side="right")
        if j1 > j0:
            # Only the pulses' support is computed: most of the record is noise alone.
            idx = centre[j0:j1, None] + k_off[None, :]
            tt = idx / fs - all_t[j0:j1, None]
            val = np.real(all_c[j0:j1, None] * np.exp(-0.5 * (tt / sig) ** 2 + 1j * sign * w * idx))
            ok = (idx >= c0) & (idx < c1)
            x += np.bincount(idx[ok] - c0, weights=val[ok], minlength=c1 - c0)
        if snr is not None:
            x += (next(chunks) if noise is None else noise.values[c0:c1]) * sigma_w
        for b, full in fulls.items():
            n_clips[b] += int(_adc_codes(x, float(full), outs[b][c0:c1]))

    result = {}
    for b in bits_list:
        c = cfg if b == cfg.adc_bits else replace(cfg, adc_bits=b)
        truth = TacanTruth(config=c, pulse_times_s=t_p, pulse_amplitudes=a0 * amp_rel,
                           pulse_kinds=kinds, main_ref_times_s=main_t, aux_ref_times_s=aux_t,
                           amplitude=a0, noise_rms=noise_rms, digital_if_hz=cfg.digital_if_hz,
                           n_clipped=n_clips[b])
        result[b] = TacanSignal(samples=outs[b], truth=truth)
    return result


def pulse_observations(cfg: TacanSignalConfig, bearings_deg=None, rel_sigma: float | None = None,
                       time_jitter_s: float = 0.0):
    """Pulse-level fast path: what an ideal front end would report, for DSP-only studies.

    The IF is not generated: every direct-path pulse of ``pulse_schedule(cfg)`` is reported
    at its true time (plus optional common jitter) with amplitude
    ``a0 * (1 + A sin + B sin) + N(0, (rel_sigma * a0)^2)``. ``rel_sigma`` defaults to the
    matched-filter bound ``cfg.matched_filter_rel_sigma()``. Several bearings share one
    pulse timeline (one batch of trials, independent noise each).

    Returns ``(times_s (N,), amplitudes (B, N), truth_amplitudes (B, N))`` with ``a0 = 1``.
    """
    rng_sched, _, rng_noise = _streams(cfg.seed)
    t_p, kinds, main_t, _ = pulse_schedule(cfg, rng_sched)
    b = np.atleast_1d(np.asarray(cfg.bearing_deg if bearings_deg is None else bearings_deg,
                                 dtype=np.float64))
    if not np.all(np.isfinite(b)):
        raise ValueError("bearings must be finite numbers")
    sigma = cfg.matched_filter_rel_sigma() if rel_sigma is None else float(rel_sigma)
    t_ref = main_t[0] if main_t.size else cfg.first_main_ref_s
    amps = np.stack([envelope_gain(t_p, cfg, t_ref, bd) for bd in b])
    noisy = amps + rng_noise.standard_normal(amps.shape) * sigma
    times = t_p + (rng_noise.standard_normal(t_p.size) * time_jitter_s if time_jitter_s else 0.0)
    order = np.argsort(times, kind="stable")
    return times[order], noisy[:, order], amps[:, order]

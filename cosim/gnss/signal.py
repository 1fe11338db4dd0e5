"""GPS L1 C/A signal at a digital IF: code, navigation data, Doppler, noise, oscillator, ADC.

Signal model (written down once; the correlator, the fast path and the tests use it)
----------------------------------------------------------------------------------
Sample ``n`` is at ``t = n / fs``. Before the ADC::

    x[n] = A d(t) c(chi(t)) cos(2 pi (f_dig t + s phi(t))) + w[n],     A = 1

* ``chi(t) = code_phase_chips + 1.023e6 t + phi_m(t) / 1540`` is the received code phase
  (chips, unwrapped), ``c`` the PRN's C/A code (+1/-1, ``dsp.gnss.ca_code``) at chip
  ``floor(chi) mod 1023``: rectangular chips, not band-limited.
* ``phi_m(t) = -(r(t) - r(0)) / lambda`` (cycles) is the motion's carrier phase
  (``cosim.gnss.dynamics``); carrier Doppler ``f_D = -r' / lambda``, code Doppler
  ``f_D / 1540`` exactly (both come from the same ``r(t)``).
* ``phi(t) = carrier_phase_cycles + phi_m(t) + phi_osc(t)``, ``phi_osc`` the receiver
  oscillator's phase noise (``cosim.gnss.oscillator``; it is applied to the carrier only,
  its effect on the code, ``x(t) 1.023e6`` chips, and on the sample clock are neglected).
* ``f_dig`` is the IF as sampled (folded when bandpass sampling); ``s = -1`` if that
  folding inverts the spectrum, else ``+1``.
* ``d(t)`` is the 50 bit/s navigation data, +1/-1 seeded random bits, bit ``b`` on the
  received code from ``chi = 20460 b`` to ``20460 (b + 1)``: bit edges fall on code epochs.

C/N0 and the noise
------------------
The carrier power is ``C = A^2 / 2``. ``w`` is real white Gaussian noise whose one-sided
PSD is ``N0`` over the whole sampled band ``[0, fs/2]`` (no front-end filter), so its
variance is ``sigma^2 = N0 fs / 2 = (A^2 / 2) / (C/N0) * fs / 2``. A correlator that sums
``M = T fs`` samples times a unit replica gets, per I or Q arm, a signal ``A M / 2`` and a
noise variance ``sigma^2 M / 2``: ``|P|^2 / (2 var) = (C/N0) T``, the textbook post-correlation
SNR.

ADC and AGC
-----------
A ``b``-bit midrise uniform quantiser of step ``Delta``: ``q = floor(x / Delta)`` clipped to
``[-2^(b-1), 2^(b-1) - 1]``; the sample delivered is the odd integer ``2 q + 1`` (the value
``(q + 1/2) Delta`` in units of ``Delta / 2``; 2 bits: +-1, +-3, as MAX2769-class front
ends). The AGC is ideal and static: it knows the input rms ``sigma_in`` (signal plus noise)
and sets ``Delta`` to the step minimising the mean-square error for a Gaussian input (Max,
"Quantizing for minimum distortion", IRE Trans. IT-6, 1960, uniform-quantiser table:
``Delta / sigma = 0.9957, 0.5860, 0.3352, 0.1881`` for 2-5 bits), or for 6 bits and more the
full scale ``2^(b-1) Delta`` at ``4 sigma_in``; ``agc_full_scale_sigma`` overrides the full
scale. A sample whose ``q`` had to be clipped is counted (1 bit: no clipping, count 0).

Random streams
--------------
``SeedSequence(seed, spawn_key=(k, ...))``: k = 0 noise (one child per fixed chunk of
``NOISE_CHUNK`` samples, so any block is generated without the rest of the record),
1 navigation bits, 2 dynamics, 3 oscillator. Same seed, same bits; blocks concatenated equal
the record generated in one go.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from dsp.jit import njit_cached
from dsp.sampling import SampledIf

from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, CODE_PERIOD_S, L1_HZ, ca_code_levels, check_prn
from hdl.gnss.params import DEFAULT_FS_HZ, DEFAULT_IF_HZ

from .dynamics import CsvProfile, JerkProcess, PolynomialProfile
from ..core.validate import check_float
from .oscillator import OscillatorPhase
from dsp.gnss.oscillator import oscillator

#: C/A main-lobe (null-to-null) bandwidth, Hz.
CA_MAIN_LOBE_HZ = 2 * CHIP_RATE_HZ
#: Carrier / code frequency ratio.
CARRIER_PER_CHIP = round(L1_HZ / CHIP_RATE_HZ)  # 1540
#: Navigation data: 50 bit/s = 20 code periods per bit.
NAV_BIT_RATE_HZ = 50.0
CHIPS_PER_BIT = 20 * CODE_LENGTH
#: Noise is drawn in chunks of this many samples, each from its own seeded child stream.
NOISE_CHUNK = 1 << 16
STREAM_NOISE, STREAM_NAV, STREAM_DYNAMICS, STREAM_OSC = 0, 1, 2, 3
#: Max (1960) minimum-MSE uniform step / sigma for a Gaussian input, by ADC bits.
MAX_STEP_SIGMA = {2: 0.9957, 3: 0.5860, 4: 0.3352, 5: 0.1881}


def agc_step_sigma(adc_bits: int, agc_full_scale_sigma: float | None = None) -> float:
    """The AGC's quantiser step ``Delta`` in units of the input rms (module docstring):
    Max's minimum-MSE step for 2-5 bits, full scale at 4 sigma from 6 bits on, any step for
    1 bit (the sign; 1 returned), or full scale at ``agc_full_scale_sigma``."""
    b = adc_bits
    if agc_full_scale_sigma is not None:
        return agc_full_scale_sigma / 2 ** (b - 1)
    if b == 1:
        return 1.0
    if b in MAX_STEP_SIGMA:
        return MAX_STEP_SIGMA[b]
    return 4.0 / 2 ** (b - 1)


@njit_cached(nogil=True)
def if_kernel(n0, f_ratio, sign, phase0, chip0, chips_per_sample, motion, phi, code, bits,
               bit0, sigma, noise, amp, out):
    """One pass over a block: code x data x carrier (+ noise), the model of the docstring.

    ``motion`` is the motion's carrier phase (cycles, for the code), ``phi`` the carrier
    phase excluding the initial phase (motion + oscillator).
    """
    for i in range(out.shape[0]):
        n = n0 + i
        chi = chip0 + n * chips_per_sample + motion[i] / 1540.0
        c = code[np.int64(np.floor(chi)) % 1023]
        b = bits[np.int64(np.floor(chi / 20460.0)) - bit0]
        f = n * f_ratio
        ph = (f - np.floor(f)) + sign * (phase0 + phi[i])
        v = amp * c * b * np.cos(2.0 * np.pi * ph)
        if sigma > 0:
            v += sigma * noise[i]
        out[i] = v


def _num(name, v, allow_none=False):
    if v is None and allow_none:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a number, not {v!r}")
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, not {v!r}")
    return float(v)


#: C/N0 a run may ask for (dB-Hz), every GNSS command and study (``gnss``, ``ins``,
#: ``sweep gnss``; the INS paper's loops had it first): 10 dB-Hz is far under the tracking
#: threshold of every loop here (the acquisition benchmark goes down to 26 dB-Hz, the INS
#: Table 2 study to 20); above 70 dB-Hz the noise is far below the 2-bit ADC's step and the
#: figures those of a noiseless run (``cn0_dbhz=None`` is that run).
CN0_RANGE_DBHZ = (10.0, 70.0)


def check_cn0(name: str, value) -> float:
    """A C/N0 within :data:`CN0_RANGE_DBHZ` (ValueError naming ``name``)."""
    return check_float(name, value, *CN0_RANGE_DBHZ, unit="dB-Hz")


@dataclass(frozen=True)
class GnssSignalConfig(SampledIf):
    """A GPS L1 C/A scenario at a digital IF.

    Parameters
    ----------
    prn : int
        Satellite PRN, 1-32.
    if_hz, fs_hz : float
        IF (Hz) and ADC sample rate (S/s): by default the channel's frequency plan,
        4.1304 MHz at 16.384 MS/s (:data:`hdl.gnss.params.DEFAULT_FS_HZ`,
        :data:`~hdl.gnss.params.DEFAULT_IF_HZ`).
    bandpass : bool
        Allow an IF above fs/2 (bandpass sampling); the main lobe must still sit in one
        Nyquist zone.
    adc_bits : int
        ADC word length, 1-16 (2 by default).
    cn0_dbhz : float or None
        C/N0 (dB-Hz, definition in the module docstring); None = no noise.
    duration_s : float
        Record length (s), > 0.
    dynamics : PolynomialProfile, JerkProcess or CsvProfile
        Line-of-sight profile (``cosim.gnss.dynamics``); static by default.
    nav_data : bool
        Modulate 50 bit/s random navigation data.
    code_phase_chips : float
        Received code phase at t = 0, in [0, 1023).
    carrier_phase_cycles : float
        Received carrier phase at t = 0 (cycles).
    oscillator : None, "tcxo", "ocxo" or Oscillator
        Receiver oscillator phase noise (``cosim.gnss.oscillator``); None = ideal.
    osc_step_s : float
        Grid of the oscillator phase (s).
    agc_full_scale_sigma : float or None
        ADC full scale in input rms; None = the default AGC rule (module docstring).
    signal_present : bool
        False: noise only (the same noise, ``N0`` still referred to ``A = 1``), for an
        absent-satellite case or to measure the correlator's noise alone.
    seed : int
    """

    prn: int = 1
    if_hz: float = DEFAULT_IF_HZ
    fs_hz: float = DEFAULT_FS_HZ
    bandpass: bool = False
    adc_bits: int = 2
    cn0_dbhz: float | None = 45.0
    duration_s: float = 1.0
    dynamics: object = field(default_factory=PolynomialProfile)
    nav_data: bool = True
    code_phase_chips: float = 0.0
    carrier_phase_cycles: float = 0.0
    oscillator: object = None
    osc_step_s: float = 1e-3
    agc_full_scale_sigma: float | None = None
    signal_present: bool = True
    seed: int = 1

    def __post_init__(self):
        check_prn(self.prn)
        fs = _num("fs_hz", self.fs_hz)
        if fs < CA_MAIN_LOBE_HZ:
            raise ValueError(f"sample rate must be >= the C/A main-lobe bandwidth "
                             f"{CA_MAIN_LOBE_HZ / 1e6:g} MHz, not {fs / 1e6:g} MS/s")
        f_if = _num("if_hz", self.if_hz)
        half = CA_MAIN_LOBE_HZ / 2
        if not isinstance(self.bandpass, bool):
            raise ValueError(f"bandpass must be True or False, not {self.bandpass!r}")
        if not self.bandpass:
            if not (half < f_if < fs / 2 - half):
                raise ValueError(
                    f"IF must keep the C/A main lobe (IF +- {half / 1e6:g} MHz) inside the first "
                    f"Nyquist zone (0, fs/2 = {fs / 2e6:g} MHz), not IF = {f_if / 1e6:g} MHz "
                    f"(sampled as it is, without bandpass sampling)")
        else:
            lo, hi = f_if - half, f_if + half
            zone = math.floor(lo / (fs / 2))
            if lo <= 0 or hi >= (zone + 1) * fs / 2:
                raise ValueError(
                    f"with bandpass sampling the C/A main lobe {lo / 1e6:g}-{hi / 1e6:g} MHz must "
                    f"lie inside one Nyquist zone (multiples of fs/2 = {fs / 2e6:g} MHz), not "
                    f"straddle an edge (IF = {f_if / 1e6:g} MHz)")
        b = self.adc_bits
        if isinstance(b, bool) or not isinstance(b, (int, np.integer)) or not 1 <= b <= 16:
            raise ValueError(f"adc_bits must be an integer in [1, 16], not {b!r}")
        if self.cn0_dbhz is not None:
            check_cn0("--cn0-dbhz", self.cn0_dbhz)
        if _num("duration_s", self.duration_s) <= 0:
            raise ValueError(f"duration_s must be > 0, not {self.duration_s!r}")
        if not isinstance(self.dynamics, (PolynomialProfile, JerkProcess, CsvProfile)):
            raise ValueError(f"dynamics must be a PolynomialProfile, JerkProcess or CsvProfile, "
                             f"not {type(self.dynamics).__name__}")
        if not isinstance(self.signal_present, bool):
            raise ValueError(f"signal_present must be True or False, not {self.signal_present!r}")
        if not isinstance(self.nav_data, bool):
            raise ValueError(f"nav_data must be True or False, not {self.nav_data!r}")
        cp = _num("code_phase_chips", self.code_phase_chips)
        if not 0 <= cp < CODE_LENGTH:
            raise ValueError(f"code_phase_chips must be in [0, {CODE_LENGTH}), not {cp!r}")
        _num("carrier_phase_cycles", self.carrier_phase_cycles)
        oscillator(self.oscillator)
        if _num("osc_step_s", self.osc_step_s) <= 0:
            raise ValueError(f"osc_step_s must be > 0, not {self.osc_step_s!r}")
        if self.agc_full_scale_sigma is not None and \
                not _num("agc_full_scale_sigma", self.agc_full_scale_sigma) > 0:
            raise ValueError(f"agc_full_scale_sigma must be > 0, not {self.agc_full_scale_sigma!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, not {self.seed!r}")

    # -- derived ---------------------------------------------------------------------------
    @property
    def n_samples(self) -> int:
        return int(round(self.duration_s * self.fs_hz))

    @property
    def n_epochs(self) -> int:
        """Whole code periods (1 ms) in the record."""
        return int(math.floor(self.duration_s / CODE_PERIOD_S + 1e-9))

    @property
    def noise_sigma(self) -> float:
        """Noise rms before the ADC (signal amplitude A = 1), 0 without noise."""
        if self.cn0_dbhz is None:
            return 0.0
        n0 = 0.5 / 10.0 ** (self.cn0_dbhz / 10.0)
        return math.sqrt(n0 * self.fs_hz / 2)

    @property
    def adc_step(self) -> float:
        """The AGC's quantiser step ``Delta`` (same units as the analog input)."""
        sig_in = math.sqrt(self.noise_sigma ** 2 + (0.5 if self.signal_present else 0.0))
        return agc_step_sigma(self.adc_bits, self.agc_full_scale_sigma) * sig_in

    def replace(self, **changes) -> "GnssSignalConfig":
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d.update(changes)
        return GnssSignalConfig(**d)


@dataclass
class GnssTruth:
    """Per code epoch ``k`` (receiver time ``t_k = k`` ms, the epoch's start), what the
    generator put in. ``carrier_phase_cycles`` is the received carrier phase excluding the IF
    (initial + motion + oscillator), ``doppler_hz`` / ``doppler_rate_hz_s`` the motion's,
    ``code_phase_chips`` the received code phase in [0, 1023), ``nav_bit`` the bit on the
    received code at ``t_k`` (+1/-1)."""

    t_s: np.ndarray
    carrier_phase_cycles: np.ndarray
    doppler_hz: np.ndarray
    doppler_rate_hz_s: np.ndarray
    code_phase_chips: np.ndarray
    nav_bit: np.ndarray
    osc_phase_cycles: np.ndarray
    code_chips_total: np.ndarray       # unwrapped code phase
    n_clipped: int = 0
    noise_sigma: float = 0.0
    adc_step: float = 0.0


@dataclass
class GnssSignal:
    samples: np.ndarray     # ADC output, odd integers 2q+1 (int16; int32 for 16 bits)
    truth: GnssTruth


class GnssSignalGenerator:
    """A realised scenario: any block of samples, and the truth at any time.

    The dynamics, oscillator and navigation bits are drawn once here (arrays on a 1 ms or
    ``osc_step_s`` grid); samples are computed on demand, so a long record is produced in
    blocks of bounded memory.
    """

    def __init__(self, cfg: GnssSignalConfig):
        self.cfg = cfg
        ss = lambda *k: np.random.SeedSequence(int(cfg.seed), spawn_key=k)  # noqa: E731
        margin = 2 * CODE_PERIOD_S
        self.traj = cfg.dynamics.realise(cfg.duration_s + margin, np.random.default_rng(ss(STREAM_DYNAMICS)))
        self.osc = OscillatorPhase(oscillator(cfg.oscillator), cfg.duration_s + margin, cfg.osc_step_s,
                                   np.random.default_rng(ss(STREAM_OSC)))
        self.code = ca_code_levels(cfg.prn).astype(np.float64)
        self._ss = ss
        # Navigation bits over the code-phase range of the record (+- a bit of margin).
        tg = np.linspace(0.0, cfg.duration_s + margin, int(cfg.duration_s / CODE_PERIOD_S) + 3)
        chi = self._chips(tg)
        self.bit0 = int(math.floor(chi.min() / CHIPS_PER_BIT)) - 1
        nb = int(math.floor(chi.max() / CHIPS_PER_BIT)) - self.bit0 + 2
        if cfg.nav_data:
            self.bits = 1.0 - 2.0 * np.random.default_rng(ss(STREAM_NAV)).integers(0, 2, nb)
        else:
            self.bits = np.ones(nb)
        self.f_ratio = cfg.digital_if_hz / cfg.fs_hz
        self.sign = -1.0 if cfg.spectrum_inverted else 1.0
        self.sigma = cfg.noise_sigma
        self.step = cfg.adc_step

    # -- the truth -------------------------------------------------------------------------
    def _motion_cycles(self, t):
        from dsp.gnss.ephemeris import L1_WAVELENGTH_M
        return -self.traj.delta_range_m(t) / L1_WAVELENGTH_M

    def _chips(self, t, motion=None):
        m = self._motion_cycles(t) if motion is None else motion
        return self.cfg.code_phase_chips + CHIP_RATE_HZ * t + m / CARRIER_PER_CHIP

    def truth_at(self, t_s) -> dict:
        """The truth at receiver times ``t_s`` (s): the fields of :class:`GnssTruth`."""
        from dsp.gnss.ephemeris import L1_WAVELENGTH_M
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        m = self._motion_cycles(t)
        d = self.traj.evaluate(t)
        osc = self.osc.phase_cycles(t)
        chi = self._chips(t, m)
        return {"t_s": t,
                "carrier_phase_cycles": self.cfg.carrier_phase_cycles + m + osc,
                "doppler_hz": -d[1] / L1_WAVELENGTH_M,
                "doppler_rate_hz_s": -d[2] / L1_WAVELENGTH_M,
                "code_phase_chips": np.mod(chi, CODE_LENGTH),
                "nav_bit": self.bits[np.floor(chi / CHIPS_PER_BIT).astype(np.int64) - self.bit0],
                "osc_phase_cycles": osc,
                "code_chips_total": chi}

    def epoch_truth(self, n_clipped: int = 0) -> GnssTruth:
        t = np.arange(self.cfg.n_epochs) * CODE_PERIOD_S
        return GnssTruth(**self.truth_at(t), n_clipped=int(n_clipped), noise_sigma=self.sigma,
                         adc_step=self.step)

    # -- samples ---------------------------------------------------------------------------
    def _noise(self, n0: int, n: int) -> np.ndarray:
        out = np.empty(n)
        c0, c1 = n0 // NOISE_CHUNK, (n0 + n - 1) // NOISE_CHUNK
        pos = 0
        for c in range(c0, c1 + 1):
            z = np.random.default_rng(self._ss(STREAM_NOISE, c)).standard_normal(NOISE_CHUNK)
            a = max(n0 - c * NOISE_CHUNK, 0)
            b = min(n0 + n - c * NOISE_CHUNK, NOISE_CHUNK)
            out[pos:pos + b - a] = z[a:b]
            pos += b - a
        return out

    def analog(self, n0: int, n: int) -> np.ndarray:
        """Samples ``n0 .. n0 + n - 1`` before the ADC (float64)."""
        if n0 < 0 or n < 0:
            raise ValueError(f"sample range must be non-negative, not n0={n0}, n={n}")
        idx = np.arange(n0, n0 + n, dtype=np.int64)
        t = idx / self.cfg.fs_hz
        m = self._motion_cycles(t)
        phi = m + self.osc.phase_cycles(t) if self.osc.active else m
        noise = self._noise(n0, n) if self.sigma > 0 else np.zeros(0)
        x = np.empty(n)
        if_kernel(n0, self.f_ratio, self.sign, self.cfg.carrier_phase_cycles,
                   self.cfg.code_phase_chips, CHIP_RATE_HZ / self.cfg.fs_hz, m, phi,
                   self.code, self.bits, self.bit0, self.sigma, noise,
                   1.0 if self.cfg.signal_present else 0.0, x)
        return x

    def quantise(self, x: np.ndarray) -> tuple[np.ndarray, int]:
        """The ADC (module docstring): odd-integer codes and the number of clipped samples."""
        b = self.cfg.adc_bits
        q = np.floor(x * (1.0 / self.step))
        lo, hi = -2.0 ** (b - 1), 2.0 ** (b - 1) - 1
        n_clip = 0 if b == 1 else int(np.count_nonzero(q < lo) + np.count_nonzero(q > hi))
        np.clip(q, lo, hi, out=q)
        return (2 * q + 1).astype(np.int16 if b <= 15 else np.int32), n_clip

    def samples(self, n0: int, n: int) -> tuple[np.ndarray, int]:
        """ADC codes of samples ``n0 .. n0 + n - 1`` and how many clipped."""
        return self.quantise(self.analog(n0, n))

    def block(self, k: int, block_samples: int) -> tuple[np.ndarray, int]:
        """Block ``k`` of ``block_samples`` (the last one may be short)."""
        n0 = k * block_samples
        return self.samples(n0, max(0, min(block_samples, self.cfg.n_samples - n0)))

    def blocks(self, block_samples: int = 1 << 18):
        """Iterate over the record in blocks: ``(codes, n_clipped)``."""
        for k in range(-(-self.cfg.n_samples // block_samples)):
            yield self.block(k, block_samples)


class SampleStream:
    """Reads ``stream(n0, n)`` of a generator's samples (analog or ADC codes), generated
    in blocks: what a correlator consuming epoch after epoch uses. Reads stop at the
    record's end (a short or empty array).

    The stream holds a window of the record, ``[w0, w1)``. A read inside it is a slice; a
    read that runs past its end keeps the window's tail from ``n0`` on and generates only
    the samples after ``w1``, up to the next multiple of ``block_samples`` at or after
    ``n0 + n`` (so with ``block_samples`` a multiple of :data:`NOISE_CHUNK` every noise
    chunk is drawn once); any other read (backwards, or a jump) is generated afresh from
    ``n0``. The window ``[n0, end)`` never holds more than ``block_samples`` plus the
    read's samples, whatever the record's length: memory is bounded by the block, not the
    duration. The samples served do not depend on ``block_samples`` (the generator's
    samples are a function of their index only).
    """

    def __init__(self, gen: GnssSignalGenerator, adc: bool = True, block_samples: int = 1 << 18):
        if isinstance(block_samples, bool) or not isinstance(block_samples, (int, np.integer)) \
                or block_samples < 1:
            raise ValueError(f"block_samples must be an integer >= 1, not {block_samples!r}")
        self.gen, self.adc, self.block = gen, bool(adc), int(block_samples)
        self.n_clipped = 0      # clipped samples among those generated, each counted once
        self._w0, self._buf = 0, np.zeros(0)
        self._counted_to = 0

    @property
    def held_samples(self) -> int:
        """Samples the stream holds now (its window)."""
        return int(self._buf.size)

    def _make(self, a: int, b: int) -> np.ndarray:
        """Samples ``a .. b - 1``, their clips counted once (those past ``_counted_to``)."""
        x = self.gen.analog(a, b - a)
        if not self.adc:
            return x
        new = min(b - a, max(0, self._counted_to - a))      # already counted before
        if new == 0:
            codes, clip = self.gen.quantise(x)
        else:
            old, _ = self.gen.quantise(x[:new])
            codes, clip = self.gen.quantise(x[new:])
            codes = np.concatenate([old, codes])
        self.n_clipped += clip
        self._counted_to = max(self._counted_to, b)
        return codes

    def __call__(self, n0: int, n: int) -> np.ndarray:
        total = self.gen.cfg.n_samples
        n = max(0, min(n, total - n0))   # the record ends where it ends
        w0, w1 = self._w0, self._w0 + self._buf.size
        if not (w0 <= n0 and n0 + n <= w1):
            end = min(total, -(-(n0 + n) // self.block) * self.block)
            if w0 <= n0 <= w1:          # sequential: keep the tail, generate what follows
                tail = self._buf[n0 - w0:]
                self._buf = np.concatenate([tail, self._make(w1, end)])
            else:
                self._buf = self._make(n0, end)
            self._w0 = n0
        return self._buf[n0 - self._w0:n0 - self._w0 + n]


def generate(cfg: GnssSignalConfig, block_samples: int = 1 << 18) -> GnssSignal:
    """The whole record and its per-epoch truth (in blocks, then joined)."""
    g = GnssSignalGenerator(cfg)
    parts, clip = [], 0
    for codes, c in g.blocks(block_samples):
        parts.append(codes)
        clip += c
    return GnssSignal(np.concatenate(parts), g.epoch_truth(clip))

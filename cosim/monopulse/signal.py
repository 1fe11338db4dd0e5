"""Monopulse IF signal: 4 channels of a cooperative BPSK target, noise, ADCs, truth.

Signal model (written down once; the golden chain, the fast path and the tests use it)
------------------------------------------------------------------------------------
Waveform (decision): the target transmits a BPSK direct-sequence spread carrier, chips
``c(n) = +-1`` seeded random (an independent stream per measurement block, returned as the
receiver's replica), rectangular, at ``chip_rate_hz`` (10 Mchip/s by default), one chip per
snapshot: the snapshot rate is the chip rate and ``decimation = fs / chip_rate`` (10) ADC
samples make one snapshot. Code timing is taken as acquired (chip edges on the ADC grid at
snapshot boundaries; acquisition is the search stage's job, not modelled here). No Doppler.

Carrier and IF: RF carrier ``carrier_hz`` (10 GHz, X band, by default; the geometry is in
wavelengths so it only fixes ``lambda = c / carrier`` for reporting), down-converted to a
real IF ``if_hz`` (20 MHz) sampled at ``fs_hz`` (100 MS/s) by 4 ADCs. Sample ``m`` (global
index, ``t = m / fs``) of channel ``i`` in snapshot ``n = m // decimation``::

    x_i[m] = Re{ A h_i(n) exp(j theta_c) c(n) exp(j 2 pi f_IF t) } + |g_i| sigma_w w_i[m]

with ``A = 1``, ``h_i(n) = g_i AF(u_n, v_n; u0, v0) exp(-j phi_i(u_n, v_n))`` the channel
response of ``cosim.monopulse.array`` (the target direction ``(u_n, v_n)`` taken at the
snapshot's centre time, the steering ``(u0, v0)`` that of the snapshot's measurement block),
``theta_c`` a common carrier phase (seeded), ``w_i`` independent unit white Gaussian noise.
The channel mismatch ``g_i`` scales signal and noise alike (noise set at the LNA).

SNR (definition): per-channel signal power over noise power **in the snapshot band**, i.e.
at the output of the DDC's integrate-and-dump over one chip (noise bandwidth = chip rate),
for the target at the steering direction with ideal phase shifters (``|AF| = 1``). With the
DDC ``z(n) = (1/D) sum 2 x[m] exp(-j 2 pi f_IF t)`` the snapshot signal is ``A h c`` and the
snapshot noise is circular with variance ``4 sigma_w^2 |g_i|^2 / D``, so::

    sigma_w^2 = A^2 D / (4 SNR)        (SNR at the ADC, over fs/2: SNR 2 chip_rate / fs)

so the paper's -8 dB per snapshot becomes -15 dB over the ADC band, and the matched filter
over N snapshots gives SNR N (8192: 31.1 dB, the paper's figure). The real per-channel SNR
of a target off the steering direction is ``SNR |AF|^2``.

The DDC's integrate-and-dump nulls the ``2 f_IF`` image exactly when ``2 f_IF D / fs`` is an
integer; the configuration requires it (20 MHz at 100 MS/s, D = 10: 4).

ADC: ``adc_bits``-bit midtread quantiser, step ``Delta = FS / 2^(b-1)``, full scale
``FS = adc_full_scale_sigma sigma_in`` with ``sigma_in^2 = A^2/2 + sigma_w^2`` the nominal
input power (an ideal static AGC, common to the 4 ADCs); codes ``round(x / Delta)`` clipped to
``[-2^(b-1), 2^(b-1) - 1]``, each clipped sample counted per channel. ``adc_bits=None``: no
ADC (float samples).

Blocks and random streams
-------------------------
Measurement block ``k`` is snapshots ``[k N, (k+1) N)``; its steering ``(u0, v0)`` is given per
block (the closed loop writes it) and applied at the block boundary. Streams:
``SeedSequence(seed, spawn_key=(0, k, i))`` noise of block k, channel i; ``(1, k)`` chips of
block k; ``(2,)`` carrier phase; ``(3,)`` the fast path. Any block is generated on its own;
blocks concatenated equal the record generated in one call.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dsp.jit import njit_cached

from .array import N_CHANNELS, ArrayConfig, angles_from_uv, check_visible
from .trajectory import ConstantRate

STREAM_NOISE, STREAM_CHIPS, STREAM_PHASE, STREAM_FAST = 0, 1, 2, 3
SPEED_OF_LIGHT = 299_792_458.0


@njit_cached(nogil=True)
def _if_kernel(env_re, env_im, m0, f_ratio, decimation, out):
    """``out[i, m] += Re{env[m // D, i] exp(j 2 pi f_IF t)}`` (one LO per sample, 4 channels)."""
    for m in range(out.shape[1]):
        n = m // decimation
        f = (m0 + m) * f_ratio
        ph = 2.0 * np.pi * (f - np.floor(f))
        c = np.cos(ph)
        s = np.sin(ph)
        for i in range(out.shape[0]):
            out[i, m] += env_re[n, i] * c - env_im[n, i] * s


def _num(name, v, lo=None, strict=True):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number, not {v!r}")
    if lo is not None and (v <= lo if strict else v < lo):
        raise ValueError(f"{name} must be {'>' if strict else '>='} {lo:g}, not {v!r}")
    return float(v)


@dataclass(frozen=True)
class MonopulseSignalConfig:
    """A monopulse scenario at IF (model and definitions in the module docstring).

    Parameters
    ----------
    array : ArrayConfig
        Geometry, phase shifters, channel mismatch.
    trajectory : callable
        ``t_s -> (u, v)`` (``cosim.monopulse.trajectory``).
    fs_hz, if_hz, carrier_hz : float
        ADC rate (100 MS/s), IF (20 MHz), RF carrier (10 GHz).
    chip_rate_hz : float
        BPSK chip rate = snapshot rate (10 Mchip/s); ``fs / chip_rate`` an integer >= 2.
    snapshots : int
        Snapshots per measurement block N (8192).
    snr_db : float or None
        Per-subarray SNR in the snapshot band (-8 dB); None = no noise.
    adc_bits : int or None
        ADC word length 2-16 (12); None = no ADC.
    adc_full_scale_sigma : float
        ADC full scale over the nominal input rms (4).
    carrier_phase_rad : float or None
        Common carrier phase; None = seeded uniform.
    seed : int
    """

    array: ArrayConfig = field(default_factory=ArrayConfig)
    trajectory: object = field(default_factory=ConstantRate)
    fs_hz: float = 100e6
    if_hz: float = 20e6
    carrier_hz: float = 10e9
    chip_rate_hz: float = 10e6
    snapshots: int = 8192
    snr_db: float | None = -8.0
    adc_bits: int | None = 12
    adc_full_scale_sigma: float = 4.0
    carrier_phase_rad: float | None = None
    seed: int = 1

    def __post_init__(self):
        if not isinstance(self.array, ArrayConfig):
            raise ValueError(f"array must be an ArrayConfig, not {self.array!r}")
        if not callable(self.trajectory):
            raise ValueError(f"trajectory must be callable t_s -> (u, v), not "
                             f"{self.trajectory!r}")
        fs = _num("fs_hz", self.fs_hz, 0)
        rc = _num("chip_rate_hz", self.chip_rate_hz, 0)
        _num("carrier_hz", self.carrier_hz, 0)
        d = fs / rc
        if abs(d - round(d)) > 1e-9 * d or round(d) < 2:
            raise ValueError(f"fs_hz / chip_rate_hz (the decimation) must be an integer >= 2, "
                             f"not {d!r}")
        d = round(d)
        f_if = _num("if_hz", self.if_hz, 0)
        if not rc < f_if < fs / 2 - rc:
            raise ValueError(f"IF must keep the BPSK main lobe (IF +- chip rate "
                             f"{rc / 1e6:g} MHz) inside (0, fs/2 = {fs / 2e6:g} MHz), not "
                             f"IF = {f_if / 1e6:g} MHz")
        k = 2 * f_if * d / fs
        if abs(k - round(k)) > 1e-9:
            raise ValueError(f"2 IF decimation / fs must be an integer (the integrate-and-dump "
                             f"DDC then nulls the 2 IF image exactly), not {k!r}")
        n = self.snapshots
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"snapshots must be an integer >= 1, not {n!r}")
        if self.snr_db is not None:
            _num("snr_db", self.snr_db)
        b = self.adc_bits
        if b is not None and (isinstance(b, bool) or not isinstance(b, (int, np.integer))
                              or not 2 <= b <= 16):
            raise ValueError(f"adc_bits must be an integer in [2, 16] or None, not {b!r}")
        _num("adc_full_scale_sigma", self.adc_full_scale_sigma, 0)
        if self.carrier_phase_rad is not None:
            _num("carrier_phase_rad", self.carrier_phase_rad)
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) \
                or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, not {self.seed!r}")

    # Derived quantities, in one place.
    @property
    def decimation(self) -> int:
        return round(self.fs_hz / self.chip_rate_hz)

    @property
    def samples_per_block(self) -> int:
        return self.snapshots * self.decimation

    @property
    def block_s(self) -> float:
        """Measurement block duration (s)."""
        return self.snapshots / self.chip_rate_hz

    @property
    def wavelength_m(self) -> float:
        return SPEED_OF_LIGHT / self.carrier_hz

    @property
    def snr_linear(self) -> float:
        return 0.0 if self.snr_db is None else 10 ** (self.snr_db / 10)

    @property
    def sigma_w(self) -> float:
        """Real IF noise std per sample (unit channel gain), ``sqrt(A^2 D / (4 SNR))``."""
        return 0.0 if self.snr_db is None else math.sqrt(self.decimation / (4 * self.snr_linear))

    @property
    def adc_step(self) -> float | None:
        if self.adc_bits is None:
            return None
        sigma_in = math.sqrt(0.5 + self.sigma_w ** 2)
        return self.adc_full_scale_sigma * sigma_in / (1 << (self.adc_bits - 1))

    @property
    def carrier_phase(self) -> float:
        if self.carrier_phase_rad is not None:
            return float(self.carrier_phase_rad)
        rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(STREAM_PHASE,)))
        return float(rng.uniform(-np.pi, np.pi))

    def snapshot_times(self, block: int) -> np.ndarray:
        """Centre times (s) of the N snapshots of ``block``."""
        n = block * self.snapshots + np.arange(self.snapshots)
        return (n * self.decimation + (self.decimation - 1) / 2) / self.fs_hz

    def block_centre_s(self, block) -> np.ndarray:
        """Truth epoch of a measurement: the centre of its block (s)."""
        return (np.asarray(block, float) + 0.5) * self.block_s

    def chips(self, block: int) -> np.ndarray:
        """The replica of ``block``: N chips +-1 (int8)."""
        rng = np.random.default_rng(np.random.SeedSequence(self.seed,
                                                           spawn_key=(STREAM_CHIPS, block)))
        return (2 * rng.integers(0, 2, self.snapshots, dtype=np.int8) - 1).astype(np.int8)


@dataclass
class MonopulseRecord:
    """IF samples of K measurement blocks and their truth.

    ``samples`` (4, K N D): ADC codes (int16) or floats (no ADC); ``scale`` converts codes to
    the model's volts (``adc_step``, 1.0 without ADC). ``replica`` (K, N) chips; ``steering``
    (K, 2) ``(u0, v0)``; ``u``, ``v``, ``az``, ``el`` (K,) truth at block centres ``t_s``;
    ``snap_u``, ``snap_v`` (K, N) truth per snapshot; ``clipped`` (4,) ADC clip counts.
    """

    samples: np.ndarray
    scale: float
    replica: np.ndarray
    steering: np.ndarray
    first_block: int
    t_s: np.ndarray
    u: np.ndarray
    v: np.ndarray
    az: np.ndarray
    el: np.ndarray
    snap_u: np.ndarray
    snap_v: np.ndarray
    clipped: np.ndarray


def steering_array(steering, n_blocks):
    """The beam steering ``(u0, v0)`` per block, shape ``(n_blocks, 2)``, from one direction
    or one per block (ValueError for another shape or a direction outside the visible
    region)."""
    s = np.asarray(steering, float)
    if s.shape == (2,):
        s = np.broadcast_to(s, (n_blocks, 2))
    if s.shape != (n_blocks, 2):
        raise ValueError(f"steering must be (u0, v0) or one (u0, v0) per block, shape "
                         f"({n_blocks}, 2), not shape {s.shape}")
    check_visible(s[:, 0], s[:, 1], "steering direction")
    return np.array(s)


def block_truth(cfg: MonopulseSignalConfig, first_block: int, n_blocks: int):
    """Per-snapshot truth (K, N) ``u``, ``v`` and block-centre truth (K,)."""
    blocks = np.arange(first_block, first_block + n_blocks)
    t = np.stack([cfg.snapshot_times(int(k)) for k in blocks])
    su, sv = cfg.trajectory(t)
    tc = cfg.block_centre_s(blocks)
    u, v = cfg.trajectory(tc)
    return su, sv, tc, np.asarray(u, float), np.asarray(v, float)


def channel_snapshots(cfg, steering, su, sv):
    """Noise-free channel responses ``h_i(n)`` (K, N, 4) for the per-block steering."""
    out = np.empty(su.shape + (N_CHANNELS,), complex)
    for k in range(su.shape[0]):  # one steering per block: a loop over blocks, not samples
        out[k] = cfg.array.channel_response(su[k], sv[k], steering[k, 0], steering[k, 1])
    return out


def generate(cfg: MonopulseSignalConfig, steering, first_block: int = 0,
             n_blocks: int = 1) -> MonopulseRecord:
    """IF samples of blocks ``first_block .. first_block + n_blocks - 1``.

    ``steering``: ``(u0, v0)`` for all blocks or (n_blocks, 2), one per block.
    """
    if isinstance(first_block, bool) or not isinstance(first_block, (int, np.integer)) \
            or first_block < 0:
        raise ValueError(f"first_block must be an integer >= 0, not {first_block!r}")
    if isinstance(n_blocks, bool) or not isinstance(n_blocks, (int, np.integer)) or n_blocks < 1:
        raise ValueError(f"n_blocks must be an integer >= 1, not {n_blocks!r}")
    steering = steering_array(steering, n_blocks)
    su, sv, tc, u, v = block_truth(cfg, first_block, n_blocks)
    az, el = angles_from_uv(u, v)
    h = channel_snapshots(cfg, steering, su, sv)  # (K, N, 4)
    N, D = cfg.snapshots, cfg.decimation
    chips = np.stack([cfg.chips(first_block + k) for k in range(n_blocks)])
    b = h * (np.exp(1j * cfg.carrier_phase) * chips)[..., None]  # (K, N, 4) complex envelope
    x = np.zeros((N_CHANNELS, n_blocks * N * D))
    if cfg.snr_db is not None:
        gabs = np.abs(cfg.array.channel_gains)
        for i in range(N_CHANNELS):
            for k in range(n_blocks):
                rng = np.random.default_rng(np.random.SeedSequence(
                    cfg.seed, spawn_key=(STREAM_NOISE, first_block + k, i)))
                x[i, k * N * D:(k + 1) * N * D] = \
                    (gabs[i] * cfg.sigma_w) * rng.standard_normal(N * D)
    env = np.ascontiguousarray(b.reshape(n_blocks * N, N_CHANNELS))
    _if_kernel(np.ascontiguousarray(env.real), np.ascontiguousarray(env.imag),
               first_block * N * D, cfg.if_hz / cfg.fs_hz, D, x)
    clipped = np.zeros(N_CHANNELS, np.int64)
    if cfg.adc_bits is None:
        samples, scale = x, 1.0
    else:
        scale = cfg.adc_step
        q = np.round(x / scale)
        hi = (1 << (cfg.adc_bits - 1)) - 1
        lo_ = -(1 << (cfg.adc_bits - 1))
        clipped = np.sum((q > hi) | (q < lo_), axis=1).astype(np.int64)
        samples = np.clip(q, lo_, hi).astype(np.int16)
    return MonopulseRecord(samples=samples, scale=scale, replica=chips, steering=steering,
                           first_block=first_block, t_s=tc, u=u, v=v, az=az, el=el,
                           snap_u=su, snap_v=sv, clipped=clipped)

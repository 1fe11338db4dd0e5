"""The GPS L1 C/A signal of a whole constellation at one receiver: every visible
satellite's code, carrier and LNAV message summed into one ADC stream, with its truth.

The physics (light time, clocks, motion, C/N0) is :mod:`cosim.gnss.constellation_geometry`'s;
the derivation, the interpolation error and the figures are in
``docs/explanation/gps_constellation_signal.md``.

Satellites
----------
From broadcast ephemerides (a RINEX file through :mod:`cosim.gnss.rinex_nav`, or
:func:`dsp.gnss.nominal_orbits.nominal_constellation`): per PRN the healthy ephemeris valid at
the start (:func:`dsp.gnss.ephemeris.select_ephemeris`), *quantised* to its LNAV grid, is used
for the whole record (it must stay valid to the record's end, at most
:data:`MAX_DURATION_S`), both for the orbit and clock and for the message, so a receiver that
decodes the message computes the positions the generator used. The satellites in the record
are those above the elevation mask at some instant of a scan every 10 s of the record (start
and end included); a satellite sounds while it is above the mask (its amplitude is 0 on the
grid points below).

Signal (receiver time ``s = n / fs``; all ranges in m, ``lambda = c / L1``)
-------------------------------------------------------------------------
Code range ``P(s) = c tau + c dt_r(s) - c dt_sv(t_tx) + I + T`` (the pseudorange, ``c (t_r
- t_sv)``), phase range ``Phi(s) = c tau + c dt_r - c dt_sv - I + T`` (the ionosphere
delays the code and advances the carrier). The satellite's code and data are clocked by its
own time ``t_sv = tow0 + s - P / c``; the received code phase is ``chi = 1.023e6 (t_sv -
F)`` chips from the start ``F`` of the first LNAV frame the generator encoded
(:func:`dsp.gnss.lnav.encode_frames`, TOW from ``F``), chip ``floor(chi) mod 1023``, data bit
``floor(chi / 20460)`` (bit edges on code epochs; LNAV bit 0 is +1, 1 is -1). The carrier
phase is ``-Phi / lambda`` cycles on top of the IF: real ``A d c cos(2 pi (f_IF n / fs + sgn
phase))`` (``sgn = -1`` for an inverted spectrum), complex ``a d c exp(j 2 pi (f_IF n / fs +
phase))`` (stored as ``I - jQ`` when inverted). Doppler is ``-Phi' / lambda``.

Noise, C/N0 and the ADC follow :mod:`cosim.gnss.synthetic_file`: unit-variance white noise
per real component (``N0 = 2 / fs``), ``C = (C/N0) N0``, ``A = sqrt(2 C)`` (real),
``a = sqrt(C)`` (complex); C/N0 by elevation
(:class:`cosim.gnss.constellation_geometry.Cn0Model`). The AGC step is set once from the satellites' C/N0 at the start.

Interpolation
-------------
The geometry is computed exactly on a grid of ``grid_s`` (1 ms) of receiver time, in pages of
:data:`PAGE_POINTS` points (each page the same arrays whatever the block that needs it). In
the kernel ``P - c dt_r`` and ``Phi - c dt_r`` are cubic Hermite interpolated from their grid
values and rates (light-time rate, satellite clock rate; the atmosphere's rate by central
differences), ``c dt_r`` linearly on the clock's own grid (the oscillator model is linear
between its points), the amplitude linearly.

Bit errors
----------
``bit_error_rate`` p > 0 flips each encoded LNAV bit (one 20 ms data bit of one satellite)
independently with probability p before it is modulated: a channel error the receiver must
catch by parity. :attr:`NavStream.flipped` lists the flipped bits (indices from the frame
start) and :meth:`ConstellationSignal.flipped_bits` their transmit times inside the record.

Random streams: noise as :func:`cosim.gnss.synthetic_file.noise_block` (``spawn_key (0, c,
component)``), the oscillator from ``spawn_key (3,)``, the bit errors of PRN ``k`` from
``spawn_key (4, k)`` (the same flips for a PRN whatever the other satellites). Same seed,
same samples, for any block length.
"""
from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, field, fields

import numpy as np

from dsp.gnss.ca_code import CHIP_RATE_HZ, ca_code_levels
from dsp.gnss.ephemeris import C_LIGHT, CHIP_M, L1_WAVELENGTH_M, WEEK_S, Ephemeris, KlobucharParameters, \
    UtcParameters, select_ephemeris
from dsp.gnss.lnav import encode_frames

from ..core.validate import check_float
from .constellation_kernels import constellation_kernel, interpolate_ranges
from .constellation_geometry import ClockRealisation, Cn0Model, ReceiverClock, \
    StaticReceiver, TrajectoryReceiver, atmosphere, check_motion, geometry
from .files import BLOCK_SAMPLES, FORMATS, AdcMap, samples_per_ms, write_samples
from .signal import CHIPS_PER_BIT, agc_step_sigma
from .synthetic_file import adc_levels, noise_block

#: Grid points per page of precomputed geometry.
PAGE_POINTS = 1000
#: Longest record (s): one ephemeris per satellite serves the whole record.
MAX_DURATION_S = 3600.0
#: How far outside the record the truth may be asked for (s).
TRUTH_MARGIN_S = 0.5
#: Interval of the visibility scan (s).
SCAN_S = 10.0
STREAM_OSC = 3
STREAM_BIT_ERRORS = 4


@dataclass(frozen=True)
class ConstellationConfig:
    """A constellation scenario (module notes).

    Parameters
    ----------
    ephemerides : sequence of Ephemeris
        Candidates (e.g. ``RinexNav.ephemerides`` or the nominal constellation).
    week, tow_s : int, float
        GPS week and time of week the receiver clock reads at sample 0.
    receiver : StaticReceiver or TrajectoryReceiver
    fs_hz, if_hz : float
        Sample rate (a whole number of samples per ms) and IF: real output keeps the C/A
        main lobe (IF +- 1.023 MHz) inside (0, fs/2), complex output inside (-fs/2, fs/2).
    complex_output : bool
        Complex (I/Q) samples; otherwise real.
    duration_s : float
    clock : ReceiverClock
    mask_deg : float
        Elevation mask (degrees, [0, 90)).
    cn0 : Cn0Model
    iono, tropo : callable or None
        ``iono(lat_deg, lon_deg, az_deg, el_deg, tow_s) -> m`` of L1 group delay,
        ``tropo(el_deg, h_m) -> m``, called with arrays (None: off).
    klobuchar, utc : KlobucharParameters, UtcParameters or None
        Broadcast in subframe 4 page 18 (default: zero coefficients, no UTC).
    prns : tuple of int or None
        Only these PRNs (None: all).
    nav_data, noise, inverted : bool
        LNAV data modulated (else every bit +1); white noise added; spectrum inverted.
    bit_error_rate : float
        Probability in [0, 0.5] that an LNAV bit is flipped before modulation (module notes).
    grid_s : float
        Geometry grid step (s).
    seed : int
    """

    ephemerides: tuple
    week: int
    tow_s: float
    receiver: object
    fs_hz: float = 4.092e6
    if_hz: float = 0.0
    complex_output: bool = True
    duration_s: float = 1.0
    clock: ReceiverClock = field(default_factory=ReceiverClock)
    mask_deg: float = 10.0
    cn0: Cn0Model = field(default_factory=Cn0Model)
    iono: object = None
    tropo: object = None
    klobuchar: KlobucharParameters | None = None
    utc: UtcParameters | None = None
    prns: tuple | None = None
    nav_data: bool = True
    noise: bool = True
    inverted: bool = False
    grid_s: float = 1e-3
    seed: int = 1
    bit_error_rate: float = 0.0

    def __post_init__(self):
        eph = tuple(self.ephemerides)
        if not eph or not all(isinstance(e, Ephemeris) for e in eph):
            raise ValueError("ephemerides must be a non-empty sequence of Ephemeris")
        object.__setattr__(self, "ephemerides", eph)
        if isinstance(self.week, bool) or not isinstance(self.week, (int, np.integer)) \
                or self.week < 0:
            raise ValueError(f"week must be a GPS week number, not {self.week!r}")
        check_float("tow_s", self.tow_s, 0.0, WEEK_S)
        if not isinstance(self.receiver, (StaticReceiver, TrajectoryReceiver)):
            raise ValueError(f"receiver must be a StaticReceiver or TrajectoryReceiver, not "
                             f"{type(self.receiver).__name__}")
        for name in ("complex_output", "nav_data", "noise", "inverted"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False, not {getattr(self, name)!r}")
        fs = check_float("fs_hz", self.fs_hz, 0.0, None, lo_open=True)
        samples_per_ms(fs)
        f_if = check_float("if_hz", self.if_hz)
        half = CHIP_RATE_HZ
        if self.complex_output and not (abs(f_if) + half < fs / 2):
            raise ValueError(f"if_hz {f_if:g} Hz: a complex stream must keep the C/A main lobe "
                             f"(IF +- {half:g} Hz) inside (-fs/2, fs/2) = +-{fs / 2:g} Hz")
        if not self.complex_output and not (half < f_if < fs / 2 - half):
            raise ValueError(f"if_hz {f_if:g} Hz: a real stream must keep the C/A main lobe "
                             f"(IF +- {half:g} Hz) inside (0, fs/2 = {fs / 2:g} Hz)")
        check_float("duration_s", self.duration_s, 0.0, MAX_DURATION_S, lo_open=True)
        if not isinstance(self.clock, ReceiverClock):
            raise ValueError("clock must be a ReceiverClock")
        check_float("mask_deg", self.mask_deg, 0.0, 89.999)
        if not isinstance(self.cn0, Cn0Model):
            raise ValueError("cn0 must be a Cn0Model")
        for name in ("iono", "tropo"):
            if getattr(self, name) is not None and not callable(getattr(self, name)):
                raise ValueError(f"{name} must be a callable delay model or None")
        if self.klobuchar is not None and not isinstance(self.klobuchar, KlobucharParameters):
            raise ValueError("klobuchar must be KlobucharParameters or None")
        if self.utc is not None and not isinstance(self.utc, UtcParameters):
            raise ValueError("utc must be UtcParameters or None")
        if self.prns is not None:
            p = tuple(self.prns)
            if not p or any(isinstance(x, bool) or not isinstance(x, (int, np.integer))
                            or not 1 <= x <= 32 for x in p):
                raise ValueError(f"prns must be GPS PRNs 1..32, not {self.prns!r}")
            object.__setattr__(self, "prns", tuple(sorted(set(int(x) for x in p))))
        check_float("grid_s", self.grid_s, 1e-5, 0.01)
        check_float("bit_error_rate", self.bit_error_rate, 0.0, 0.5)
        if self.bit_error_rate > 0 and not self.nav_data:
            raise ValueError("bit_error_rate needs nav_data: without data there are no bits "
                             "to flip")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) \
                or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, not {self.seed!r}")

    @property
    def n_samples(self) -> int:
        return int(round(self.duration_s * self.fs_hz))

    def replace(self, **changes) -> "ConstellationConfig":
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d.update(changes)
        return ConstellationConfig(**d)


@dataclass
class ConstellationTruth:
    """The scenario at receiver times ``s`` (T,) for the satellites ``prns`` (arrays (T, S)).

    ``tow_rx`` the receiver clock's reading, ``t_gps`` true GPS time of reception (s of the
    week of the config; may leave [0, 604800) near a week end), ``t_tx`` the geometric
    transmission time, ``t_sv`` the satellite time of the code received (``tow_rx - P /
    c``), ``geometric_range_m`` ``c tau`` (Sagnac included), ``pseudorange_m`` ``P``,
    ``carrier_phase_cycles`` ``-Phi / lambda`` (unwrapped), ``doppler_hz`` ``-Phi' /
    lambda``, ``code_phase_chips`` ``chi mod 1023``, ``nav_bit`` +1/-1, ``sounding`` above
    the mask, receiver ECEF position/velocity (T, 3), clock bias (s) and drift (s/s)."""

    s: np.ndarray
    prns: tuple
    tow_rx: np.ndarray
    t_gps: np.ndarray
    t_tx: np.ndarray
    t_sv: np.ndarray
    geometric_range_m: np.ndarray
    pseudorange_m: np.ndarray
    carrier_phase_cycles: np.ndarray
    doppler_hz: np.ndarray
    code_phase_chips: np.ndarray
    nav_bit: np.ndarray
    cn0_dbhz: np.ndarray
    elevation_deg: np.ndarray
    azimuth_deg: np.ndarray
    sounding: np.ndarray
    sv_clock_s: np.ndarray
    iono_m: np.ndarray
    tropo_m: np.ndarray
    rx_position_m: np.ndarray
    rx_velocity_mps: np.ndarray
    rx_clock_bias_s: np.ndarray
    rx_clock_drift: np.ndarray


@dataclass(frozen=True)
class NavStream:
    """One satellite's LNAV bits (uint8 0/1) as modulated, bit ``i`` sent at GPS time
    (``week``, ``tow + 0.02 i``); ``flipped``: the indices of the bits the errors flipped."""

    prn: int
    week: int
    tow: float
    bits: np.ndarray
    flipped: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def encoded(self) -> np.ndarray:
        """The bits before the bit errors."""
        b = self.bits.copy()
        b[self.flipped] ^= 1
        return b


class ConstellationSignal:
    """The scenario realised: any block of samples, the truth at any time (module notes).
    Raises ``ValueError`` before any work when no satellite is valid or above the mask, or
    the receiver's motion is impossible."""

    def __init__(self, cfg: ConstellationConfig):
        self.cfg = cfg
        self.is_complex = cfg.complex_output
        self.clock = ClockRealisation(cfg.clock, cfg.duration_s + 1.0, np.random.default_rng(
            np.random.SeedSequence(int(cfg.seed), spawn_key=(STREAM_OSC,))))
        dt0 = self.clock.at(np.array([0.0, cfg.duration_s]))[0]
        check_motion(cfg.receiver, -float(np.max(dt0)) - 0.1,
                     cfg.duration_s - float(np.min(dt0)) + 0.1)
        cands = self._candidates()
        scan = np.unique(np.append(np.arange(0.0, cfg.duration_s, SCAN_S), cfg.duration_s))
        g = geometry(cands, cfg.tow_s, cfg.receiver, self.clock, scan)
        el_max = g.elevation_deg.max(axis=0)
        keep = el_max >= cfg.mask_deg
        if not keep.any():
            i = int(np.argmax(el_max))
            raise ValueError(f"no satellite above the {cfg.mask_deg:g} deg elevation mask during "
                             f"the record (highest: G{cands[i].prn:02d} at {el_max[i]:.1f} deg, "
                             f"of {len(cands)} with a valid ephemeris)")
        self.ephemerides = tuple(e for e, k in zip(cands, keep) if k)
        self.prns = tuple(e.prn for e in self.ephemerides)
        self.code = [ca_code_levels(p).astype(np.float64) for p in self.prns]
        self._nav = self._encode(g.t_tx[:, keep] + g.sv_clock_s[:, keep])
        n0 = 2.0 / cfg.fs_hz
        self.amp_per_sqrt_cn0 = math.sqrt((1.0 if self.is_complex else 2.0) * n0)
        el0 = g.elevation_deg[0, keep]
        c0 = np.where(el0 >= cfg.mask_deg, 10 ** (cfg.cn0(el0) / 10), 0.0)
        share = float(np.sum(c0 * self.amp_per_sqrt_cn0 ** 2 / 2))
        self.rms = math.sqrt((1.0 if cfg.noise else 0.0) + share)
        self._pages = OrderedDict()

    def _candidates(self):
        cfg = self.cfg
        prns = sorted({e.prn for e in cfg.ephemerides})
        if cfg.prns is not None:
            prns = [p for p in prns if p in cfg.prns]
        out = []
        for p in prns:
            e = select_ephemeris(cfg.ephemerides, p, cfg.week, cfg.tow_s)
            if e is None:
                continue
            if not e.valid_at(cfg.week, cfg.tow_s + cfg.duration_s):
                raise ValueError(f"G{p:02d}: the ephemeris valid at the start (toe {e.toe:.0f} s "
                                 f"of week {e.week}) runs out of its fit interval before the "
                                 f"record's end (tow {cfg.tow_s + cfg.duration_s:.0f} s); "
                                 f"start the record nearer a toe or shorten it")
            out.append(e.quantised())
        if not out:
            raise ValueError(f"no healthy ephemeris valid at GPS week {cfg.week}, tow "
                             f"{cfg.tow_s:g} s among {len(cfg.ephemerides)} given"
                             + (f" for PRNs {list(cfg.prns)}" if cfg.prns else ""))
        return out

    def _encode(self, t_sv):
        cfg = self.cfg
        lo = cfg.week * WEEK_S + float(np.min(t_sv)) - 1.0
        hi = cfg.week * WEEK_S + float(np.max(t_sv)) + 1.0
        f_abs = math.floor(lo / 30.0) * 30.0
        n_frames = int(math.ceil((hi - f_abs) / 30.0))
        wk, tow = int(f_abs // WEEK_S), f_abs - (f_abs // WEEK_S) * WEEK_S
        kl = cfg.klobuchar or KlobucharParameters((0.0,) * 4, (0.0,) * 4)
        self.frame_tow = f_abs - cfg.week * WEEK_S   # F, s of the config's week
        self.chi0 = CHIP_RATE_HZ * (cfg.tow_s - self.frame_tow)
        out = []
        for e in self.ephemerides:
            b = encode_frames(e, kl, wk, tow, n_frames, utc=cfg.utc)
            flip = np.zeros(0, np.int64)
            if cfg.bit_error_rate > 0:
                rng = np.random.default_rng(np.random.SeedSequence(
                    int(cfg.seed), spawn_key=(STREAM_BIT_ERRORS, int(e.prn))))
                flip = np.flatnonzero(rng.random(b.size) < cfg.bit_error_rate)
                b[flip] ^= 1
            out.append(NavStream(e.prn, wk, tow, b, flip))
        self._levels = [1.0 - 2.0 * ns.bits.astype(np.float64) if cfg.nav_data
                        else np.ones(ns.bits.size) for ns in out]
        return out

    def nav_stream(self, prn: int) -> NavStream:
        """The LNAV bits the generator modulates on ``prn`` (from the frame start on)."""
        return self._nav[self.prns.index(prn)]

    def flipped_bits(self) -> dict:
        """PRN -> transmit times (s of the week) of the flipped bits the record receives."""
        t = self.truth_at(np.array([0.0, self.cfg.duration_s])).t_sv
        out = {}
        for j, ns in enumerate(self._nav):
            t0 = ns.tow + (ns.week - self.cfg.week) * WEEK_S + 0.02 * ns.flipped
            keep = (t0 + 0.02 > t[0, j]) & (t0 < t[1, j])
            out[ns.prn] = [float(x) for x in t0[keep]]
        return out

    # -- geometry pages -----------------------------------------------------------------
    def _ranges(self, s):
        cfg = self.cfg
        g = geometry(self.ephemerides, cfg.tow_s, cfg.receiver, self.clock, s)
        iono, tropo = atmosphere(g, cfg.iono, cfg.tropo)
        base = g.range_m - C_LIGHT * g.sv_clock_s
        dbase = g.range_rate - C_LIGHT * g.sv_clock_rate
        return g, iono, tropo, base, dbase

    def page(self, p: int) -> dict:
        """Page ``p``: the grid ``s0 + k h`` (``s0 = p PAGE_POINTS h``, ``k = 0..PAGE_POINTS``)
        with per satellite the code and phase ranges less ``c dt_r`` and their rates, and the
        amplitude."""
        if p in self._pages:
            self._pages.move_to_end(p)
            return self._pages[p]
        cfg, h = self.cfg, self.cfg.grid_s
        k = np.arange(p * PAGE_POINTS - 1, (p + 1) * PAGE_POINTS + 2)
        g, iono, tropo, base, dbase = self._ranges(k * h)
        d_atm = lambda x: (x[2:] - x[:-2]) / (2 * h)  # noqa: E731
        inner = slice(1, -1)
        cn0 = cfg.cn0(g.elevation_deg[inner])
        amp = np.where(g.elevation_deg[inner] >= cfg.mask_deg,
                       self.amp_per_sqrt_cn0 * 10 ** (cn0 / 20), 0.0)
        pg = {"s0": float(k[1] * h),
              "gcode": np.ascontiguousarray((base + iono + tropo)[inner].T),
              "dgcode": np.ascontiguousarray((dbase[inner] + d_atm(iono + tropo)).T),
              "gphase": np.ascontiguousarray((base - iono + tropo)[inner].T),
              "dgphase": np.ascontiguousarray((dbase[inner] + d_atm(tropo - iono)).T),
              "amp": np.ascontiguousarray(amp.T)}
        self._pages[p] = pg
        while len(self._pages) > 3:
            self._pages.popitem(last=False)
        return pg

    def interpolated_ranges(self, s) -> np.ndarray:
        """``(T, S, 2)``: the code and phase ranges ``P``, ``Phi`` at receiver times ``s`` as
        the sample kernel interpolates them (for the interpolation-error check)."""
        s = np.atleast_1d(np.asarray(s, dtype=np.float64))
        out = np.empty((s.size, len(self.prns), 2))
        pidx = np.floor(s / self.cfg.grid_s).astype(np.int64) // PAGE_POINTS
        for p in np.unique(pidx):
            m = pidx == p
            pg = self.page(int(p))
            for j in range(len(self.prns)):
                r = np.empty((int(m.sum()), 2))
                interpolate_ranges(s[m], pg["s0"], self.cfg.grid_s, pg["gcode"][j],
                                   pg["dgcode"][j], pg["gphase"][j], pg["dgphase"][j],
                                   self.clock.step_s, self.clock.cdt_m, r)
                out[m, j] = r
        return out

    # -- truth ---------------------------------------------------------------------------
    def truth_at(self, s) -> ConstellationTruth:
        """The exact (not interpolated) truth at receiver times ``s`` (s since sample 0)."""
        cfg = self.cfg
        s = np.atleast_1d(np.asarray(s, dtype=np.float64))
        if s.size == 0 or not np.all(np.isfinite(s)) or s.min() < -TRUTH_MARGIN_S \
                or s.max() > cfg.duration_s + TRUTH_MARGIN_S:
            raise ValueError(f"truth times must be finite, within the record (0 .. "
                             f"{cfg.duration_s:g} s) +- {TRUTH_MARGIN_S:g} s")
        g, iono, tropo, base, dbase = self._ranges(s)
        cdt = (C_LIGHT * g.clock_bias_s)[:, None]
        P = base + iono + tropo + cdt
        Phi = base - iono + tropo + cdt
        dt = 1e-3
        _, i2, t2, _, _ = self._ranges(g.s + dt)
        _, i1, t1, _, _ = self._ranges(g.s - dt)
        dphi = dbase + ((t2 - i2) - (t1 - i1)) / (2 * dt) + (C_LIGHT * g.clock_drift)[:, None]
        chi = self.chi0 + CHIP_RATE_HZ * g.s[:, None] - P / CHIP_M
        bi = np.floor(chi / CHIPS_PER_BIT).astype(np.int64)
        bits = np.stack([lv[bi[:, j]] for j, lv in enumerate(self._levels)], axis=1)
        cn0 = cfg.cn0(g.elevation_deg)
        return ConstellationTruth(
            s=g.s, prns=self.prns, tow_rx=cfg.tow_s + g.s, t_gps=g.t, t_tx=g.t_tx,
            t_sv=cfg.tow_s + g.s[:, None] - P / C_LIGHT, geometric_range_m=g.range_m,
            pseudorange_m=P, carrier_phase_cycles=-Phi / L1_WAVELENGTH_M,
            doppler_hz=-dphi / L1_WAVELENGTH_M, code_phase_chips=np.mod(chi, 1023.0),
            nav_bit=bits, cn0_dbhz=cn0, elevation_deg=g.elevation_deg,
            azimuth_deg=g.azimuth_deg, sounding=g.elevation_deg >= cfg.mask_deg,
            sv_clock_s=g.sv_clock_s, iono_m=iono, tropo_m=tropo, rx_position_m=g.rx_pos,
            rx_velocity_mps=g.rx_vel, rx_clock_bias_s=g.clock_bias_s,
            rx_clock_drift=g.clock_drift)

    def epoch_truth(self, step_s: float = 1e-3) -> ConstellationTruth:
        """The truth every ``step_s`` over the record."""
        return self.truth_at(np.arange(0.0, self.cfg.duration_s + step_s / 2, step_s))

    # -- samples -------------------------------------------------------------------------
    def analog(self, n0: int, n: int) -> np.ndarray:
        """Samples ``n0 .. n0 + n - 1`` before the ADC (float64, or complex128 ``I + jQ``
        before any inversion); the record ends where it ends."""
        cfg = self.cfg
        if n0 < 0 or n < 0:
            raise ValueError(f"sample range must be non-negative, not n0={n0}, n={n}")
        n = max(0, min(n, cfg.n_samples - n0))
        re = noise_block(cfg.seed, n0, n, 0) if cfg.noise else np.zeros(n)
        im = (noise_block(cfg.seed, n0, n, 1) if cfg.noise else np.zeros(n)) \
            if self.is_complex else np.zeros(0)
        if n == 0:
            return re + 1j * im if self.is_complex else re
        idx = np.arange(n0, n0 + n, dtype=np.int64)
        pidx = np.floor((idx / cfg.fs_hz) / cfg.grid_s).astype(np.int64) // PAGE_POINTS
        cuts = np.flatnonzero(np.diff(pidx)) + 1
        starts = np.concatenate(([0], cuts))
        ends = np.concatenate((cuts, [n]))
        sign = -1.0 if (cfg.inverted and not self.is_complex) else 1.0
        for a, b in zip(starts, ends):
            pg = self.page(int(pidx[a]))
            for j in range(len(self.prns)):
                constellation_kernel(
                    int(n0 + a), cfg.fs_hz, cfg.if_hz / cfg.fs_hz, sign, pg["s0"], cfg.grid_s,
                    pg["gcode"][j], pg["dgcode"][j], pg["gphase"][j], pg["dgphase"][j],
                    pg["amp"][j], self.clock.step_s, self.clock.cdt_m, self.chi0,
                    self.code[j], self._levels[j], re[a:b],
                    im[a:b] if self.is_complex else im)
        return re + 1j * im if self.is_complex else re

    def adc_step(self, amap: AdcMap):
        """The AGC step of ``amap`` (None when it does not quantise)."""
        if amap.bits is None or amap.kind == "float":
            return None
        return agc_step_sigma(amap.bits) * self.rms

    def samples(self, n0: int, n: int, adc_map: AdcMap | None = None) -> np.ndarray:
        """Samples as stored by ``adc_map`` (None: the analog values; complex: ``I - jQ``
        when inverted)."""
        x = self.analog(n0, n)
        if self.is_complex and self.cfg.inverted:
            x = np.conj(x)
        if adc_map is None:
            return x
        step = self.adc_step(adc_map)
        if not self.is_complex:
            return adc_levels(x, adc_map, step)
        return adc_levels(x.real, adc_map, step) + 1j * adc_levels(x.imag, adc_map, step)

    def blocks(self, block_samples: int = BLOCK_SAMPLES, adc_map: AdcMap | None = None):
        """The record in blocks of ``block_samples`` (the last may be short)."""
        if isinstance(block_samples, bool) or not isinstance(block_samples, (int, np.integer)) \
                or block_samples < 1:
            raise ValueError(f"block_samples must be a positive integer, not {block_samples!r}")
        for a in range(0, self.cfg.n_samples, block_samples):
            yield self.samples(a, block_samples, adc_map)


def write_constellation(path, fmt: str, cfg, adc_map=None,
                        block_samples: int = BLOCK_SAMPLES) -> ConstellationSignal:
    """Write the scenario's record (``cfg`` a :class:`ConstellationConfig`, or its realised
    :class:`ConstellationSignal`) to ``path`` in file format ``fmt``
    (:data:`cosim.gnss.files.FORMATS`; complex formats for ``complex_output``, ``int8`` for
    real) with the ADC map ``adc_map`` (the format's default when None), block by block;
    return the realised signal (its truth is the answer)."""
    sig = cfg if isinstance(cfg, ConstellationSignal) else None
    cfg = cfg if sig is None else sig.cfg
    if fmt not in FORMATS:
        raise ValueError(f"fmt must be one of {', '.join(FORMATS)}, not {fmt!r}")
    if FORMATS[fmt][1] != cfg.complex_output:
        raise ValueError(f"format {fmt} stores {'complex' if FORMATS[fmt][1] else 'real'} "
                         f"samples but the scenario's output is "
                         f"{'complex' if cfg.complex_output else 'real'}")
    amap = adc_map if isinstance(adc_map, AdcMap) else AdcMap.parse(adc_map, fmt)
    sig = sig or ConstellationSignal(cfg)
    write_samples(path, fmt, sig.blocks(block_samples, amap), amap)
    return sig

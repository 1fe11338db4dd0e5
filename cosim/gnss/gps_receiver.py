"""The GPS receiver's back end: tracked channels -> observables -> a position fix per epoch.

Input: a multi-channel run (:func:`cosim.gnss.multichannel.track_file`) on a recording;
every assignment goes through :func:`cosim.gnss.navigation.channel_navigation` (bit sync,
frame sync, LNAV decoding, the TOW of each bit edge).

Measurement epochs
------------------
Every ``1 / rate_hz`` s (1 or 10 Hz) of the recording's sample clock, at whole-ms samples
``N`` (the receiver's clock *is* the sample counter). At ``N`` a channel is usable when its
TOW is known by then (:attr:`~cosim.gnss.navigation.ChannelNav.tow_sample`: a causal
receiver), ``N`` is inside its locked records, and it has an ephemeris: hot start
(``ephemerides`` given, e.g. a RINEX file: :func:`dsp.gnss.ephemeris.select_ephemeris` at
the epoch) or cold start (the channel's own decoded ephemeris, from
:attr:`~cosim.gnss.navigation.ChannelNav.eph_sample` on).

Receiver time
-------------
``t_rx(N) = T0 + N / fs`` (s of week; ``T0`` kept as whole seconds plus a fraction). At the
first epoch with a usable channel, ``T0`` is set so that the *latest* transmit time among
the usable channels (the nearest satellite) is ``initial_travel_s`` (70 ms; a satellite at
zenith is 67 ms away, at the horizon 86 ms) before ``t_rx``: every apparent travel time then
lies within the 60-100 ms that :func:`dsp.gnss.observables.pseudoranges_from_channels`
accepts. After each valid fix the receiver clock is *steered*: ``T0 -= b / c`` with ``b``
the fix's clock bias, so the next epoch's receiver time is GPS time up to the clock drift
over one epoch; the bias solved at each epoch (before steering) is reported as the RINEX
epoch's clock offset.

Observables per usable channel (:class:`dsp.gnss.observables.ObservationEpoch`)
--------------------------------------------------------------------------------
Pseudorange from the counts (``tow_sf, n_bits, n_codes, chips``,
:meth:`~cosim.gnss.navigation.ChannelNav.counts`) by
:func:`dsp.gnss.observables.pseudoranges_from_channels`; carrier phase ``L1C = -`` the
carrier NCO's accumulated Doppler phase (cycles), LLI bit 0 on a channel's first epoch and
when its last lock window was not in lock; Doppler the tracker's at the record; C/N0 the last
lock window's.

Navigation
----------
Satellite time of transmission ``t_tx`` (:func:`dsp.gnss.observables.transmit_time`) ->
GPS time (:func:`dsp.gnss.ephemeris.system_time`) -> position, velocity and clock
(:func:`dsp.gnss.ephemeris.satellite_states`) -> :func:`dsp.gnss.pvt.solve` with the
Klobuchar coefficients (the RINEX header's or the decoded page 18's, if any) and
Saastamoinen. Fewer than four usable satellites give the solver's ``no fix`` status.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dsp.gnss.ephemeris import WEEK_S, satellite_states, select_ephemeris, system_time
from dsp.gnss.observables import ObservationEpoch, pseudoranges_from_channels, transmit_time
from dsp.gnss.pvt import PvtConfig, solve

from .navigation import channel_navigation

__all__ = ["GpsConfig", "GpsEpoch", "GpsRun", "ReceiverTime", "fix_epoch", "navigate",
           "RATES_HZ"]

#: Measurement rates offered (Hz).
RATES_HZ = (1.0, 10.0)


@dataclass(frozen=True)
class GpsConfig:
    """How the back end runs (module doc)."""

    rate_hz: float = 1.0
    initial_travel_s: float = 0.070
    troposphere: bool = True
    pvt: PvtConfig = field(default_factory=PvtConfig)

    def __post_init__(self):
        if self.rate_hz not in RATES_HZ:
            raise ValueError(f"--rate must be one of {', '.join(f'{r:g}' for r in RATES_HZ)} "
                             f"Hz, not {self.rate_hz!r}")
        if not 0.06 < self.initial_travel_s < 0.1:
            raise ValueError(f"initial_travel_s must be within (0.06, 0.1) s, not "
                             f"{self.initial_travel_s!r}")


@dataclass
class GpsEpoch:
    """One measurement epoch: its sample, receiver time, observables and solution."""

    sample: int
    week: int
    tow_s: float                      #: receiver time before steering at this epoch
    obs: ObservationEpoch | None
    solution: object                  #: dsp.gnss.pvt.PvtSolution or None (no channel usable)
    elevation: dict = field(default_factory=dict)   #: PRN -> (elevation, azimuth) deg


@dataclass
class GpsRun:
    """The back end's result: channels, epochs, time to first fix (s of recording)."""

    channels: list
    epochs: list
    fs_hz: float
    start: str                          #: "hot" or "cold"
    ttff_s: float | None
    time_set_s: float | None            #: when the receiver time was first set

    @property
    def fixes(self) -> list:
        return [e for e in self.epochs if e.solution is not None and e.solution.valid]


def _split(whole: int, frac: float) -> tuple[int, float]:
    w = math.floor(frac)
    return int(whole + w) % int(WEEK_S), frac - w


class ReceiverTime:
    """The receiver clock of the measurement epochs (module doc, *Receiver time*): unset
    until :meth:`set` at the first epoch with a usable channel, then ``t_rx(t) = T0 + t``
    for ``t`` seconds of the recording, ``T0`` held as whole seconds plus a fraction and
    moved by :meth:`steer` after each valid fix."""

    def __init__(self, initial_travel_s: float = 0.070):
        self.initial_travel_s = float(initial_travel_s)
        self.whole, self.frac = None, 0.0

    @property
    def is_set(self) -> bool:
        return self.whole is not None

    def set(self, latest_t_tx: float, t: float) -> None:
        """At recording time ``t`` put the latest transmit time ``initial_travel_s`` before
        the receiver time."""
        w = int(latest_t_tx // 1)
        self.whole, self.frac = _split(w, float(latest_t_tx) - w + self.initial_travel_s - t)

    def at(self, t: float) -> tuple[int, float]:
        """``(whole, fraction)`` of the receiver time at recording time ``t``."""
        return _split(self.whole, self.frac + t)

    def steer(self, bias_s: float) -> None:
        """Take a fix's clock bias (s) out of the receiver time."""
        self.whole, self.frac = _split(self.whole, self.frac - bias_s)


def fix_epoch(sample: int, t_rx: tuple, prns, counts, ephemerides, doppler_hz, cn0_dbhz,
              carrier_cycles, lli, *, reference_week: int, iono=None,
              config: GpsConfig = GpsConfig()) -> GpsEpoch:
    """One measurement epoch (module doc, *Observables* and *Navigation*): the channels'
    ``counts`` ``(tow_sf, n_bits, n_codes, chips)`` at the receiver time ``t_rx`` (a
    ``(whole, fraction)`` pair) -> pseudoranges, the satellites' states from
    ``ephemerides`` (one per row, None: unusable) at their transmit times, the solution
    (:func:`dsp.gnss.pvt.solve`) and the :class:`~dsp.gnss.observables.ObservationEpoch`.
    ``doppler_hz``, ``cn0_dbhz`` (NaN or infinite: unknown, reported NaN and weighted as
    45 dB-Hz), ``carrier_cycles``
    (RINEX sign) and ``lli`` are the rows' other observables."""
    tw, tf = t_rx
    t_rx_s = tw + tf
    pr, _ok = pseudoranges_from_channels((tw, tf), *counts)
    t_tx = transmit_time(*counts)
    n = len(prns)
    pos, vel = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    clk, drift = np.full(n, np.nan), np.full(n, np.nan)
    for j, e in enumerate(ephemerides):
        if e is None:
            continue
        st = satellite_states(e, system_time(e, t_tx[j]))
        pos[j], vel[j] = st.position, st.velocity
        clk[j], drift[j] = float(st.clock_bias), float(st.clock_drift)
    kw = {} if iono is None else dict(iono_alpha=iono.alpha, iono_beta=iono.beta)
    cn0 = np.asarray(cn0_dbhz, dtype=np.float64)
    cn0 = np.where(np.isfinite(cn0), cn0, np.nan)    # an estimator's -inf: no reading
    sol = solve(prns, pos, clk, pr, cn0_dbhz=np.where(np.isfinite(cn0), cn0, 45.0),
                sat_vel_mps=vel, sat_clock_drift=drift, doppler_hz=doppler_hz,
                gps_week=reference_week, gps_tow_s=t_rx_s, troposphere=config.troposphere,
                config=config.pvt, **kw)
    el = {int(p_): (float(e_), float(a_)) for p_, e_, a_ in
          zip(prns, sol.elevation_deg, sol.azimuth_deg)} \
        if len(sol.elevation_deg) == len(prns) else {}
    obs = ObservationEpoch(reference_week, t_rx_s, prns, pr, carrier_cycles, doppler_hz, cn0,
                           lli, clock_offset_s=sol.clock_bias_s if sol.valid else None)
    return GpsEpoch(int(sample), reference_week, t_rx_s, obs, sol, el)


def navigate(track, p, *, reference_week: int, inverted: bool, if_hz: float,
             ephemerides=None, iono=None, config: GpsConfig = GpsConfig(),
             progress=None) -> GpsRun:
    """Fixes from the multi-channel run ``track`` on array channel parameters ``p`` (module
    doc). ``ephemerides``: a sequence of :class:`dsp.gnss.ephemeris.Ephemeris` for a hot
    start (None: cold start, the decoded ones); ``iono``: Klobuchar parameters (None: the
    decoded ones if any); ``progress``: a callable ``(done, total)`` per epoch."""
    fs = float(track.fs_hz)
    n_ms = int(round(fs * 1e-3))
    step = int(round(fs / config.rate_hz))
    if step % n_ms:
        raise ValueError(f"--rate {config.rate_hz:g} Hz is not a whole number of ms samples "
                         f"at {fs:g} Hz")
    navs = [channel_navigation(a, track, p, reference_week=reference_week,
                               inverted=inverted, if_hz=if_hz) for a in track.assignments]
    usable = [c for c in navs if c.ok]
    if iono is None:
        iono = next((c.decode.iono for c in usable if c.decode.iono is not None), None)
    hot = ephemerides is not None
    ephs = tuple(ephemerides) if hot else ()
    samples = np.arange(step, track.n_samples, step, dtype=np.int64)
    clock = ReceiverTime(config.initial_travel_s)
    epochs, ttff, t_set = [], None, None
    seen: set = set()
    for i, n in enumerate(samples):
        rows = []
        for c in usable:
            if n < c.tow_sample or any(r[0] == c.prn for r in rows):
                continue
            tow_sf, n_bits, n_codes, chips, ok = c.counts(np.array([n]))
            if not ok[0]:
                continue
            if not hot and (c.eph_sample is None or n < c.eph_sample):
                continue
            rows.append((c.prn, c, float(tow_sf[0]), int(n_bits[0]), int(n_codes[0]),
                         float(chips[0])))
        if not clock.is_set:
            if not rows:
                epochs.append(GpsEpoch(int(n), reference_week, math.nan, None, None))
                continue
            clock.set(max(transmit_time(r[2], r[3], r[4], r[5]) for r in rows), n / fs)
            t_set = n / fs
        tw, tf = clock.at(n / fs)
        if not rows:
            epochs.append(GpsEpoch(int(n), reference_week, tw + tf, None, None))
            continue
        cnt = [np.array([r[j] for r in rows]) for j in range(2, 6)]
        cnt[1], cnt[2] = cnt[1].astype(np.int64), cnt[2].astype(np.int64)
        eph = [select_ephemeris(ephs, r[0], reference_week, tw + tf) if hot else
               r[1].ephemeris for r in rows]
        cs = [r[1] for r in rows]
        dop = np.array([c.doppler[c.record_at(np.array([n]))[0][0]] for c in cs])
        cn0 = np.array([float(c.cn0_at(np.array([n]))[0]) for c in cs])
        carr = np.array([-float(c.carrier_cycles(np.array([n]))[0]) for c in cs])
        lli = np.zeros(len(rows), dtype=np.int64)
        for j, c in enumerate(cs):
            key = (c.prn, c.channel, c.n_p[0])
            k = np.searchsorted(c.win_t, n / fs, side="right") - 1
            if key not in seen or (k >= 0 and not c.win_ok[k]):
                lli[j] = 1
            seen.add(key)
        ep = fix_epoch(int(n), (tw, tf), np.array([r[0] for r in rows], dtype=np.int64), cnt,
                       eph, dop, cn0, carr, lli, reference_week=reference_week, iono=iono,
                       config=config)
        epochs.append(ep)
        if ep.solution.valid:
            if ttff is None:
                ttff = n / fs
            clock.steer(ep.solution.clock_bias_s)
        if progress is not None:
            progress(i + 1, samples.size)
    return GpsRun(navs, epochs, fs, "hot" if hot else "cold", ttff, t_set)

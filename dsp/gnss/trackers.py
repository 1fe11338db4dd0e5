"""The carrier/code tracker interface of the GNSS channel, and the registry of trackers.

Every tracker the GNSS channel runs (the classic PLLs here; the adaptive UKF of the AUKF
patent, the INS-aided Kalman loop of the INS paper in their own modules) is built by a factory
``make(ctx, arith, **options) -> tracker`` registered under a name with
:func:`register_tracker`; the closed-loop runs (fast path, bit-exact channel, Verilator)
and the command line's ``--tracker`` look it up with :func:`make_tracker`, and nothing
else names a tracker.

A tracker is an object with

* ``step(ie, qe, ip, qp, il, ql) -> (carrier, code)``: one dump's six correlations (arrays
  of any common batch shape; the fixed-point form gets the integer accumulator values)
  in, the carrier and code NCO settings for the next epoch out -- in the float form the
  frequencies in Hz (carrier = ``if_hz + s * doppler``, ``s = -1`` for an inverted
  spectrum), in the fixed form the 32-bit NCO words (int64);
* ``frequencies_hz(out)``: the frequencies (Hz) a ``step`` output stands for (float:
  itself);
* ``doppler_hz()``: the current carrier Doppler estimate (Hz), a real value in both forms;
* ``report()`` (optional): a dict of the tracker's own figures for the run's JSON
  (``q_hat``, ``diverged``, ``pli``, ...), JSON-safe.

``arith`` is ``dsp.gnss.loops_fixed.FLOAT`` (golden, float64) or a
``dsp.gnss.loops_fixed.FixedArith`` (fixed point); a tracker with no fixed form raises
``ValueError`` naming itself when given a fixed arithmetic.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

__all__ = ["TrackerContext", "register_tracker", "make_tracker", "tracker_names", "needs_aiding",
           "tracker_options"]


@dataclass(frozen=True)
class TrackerContext:
    """What every tracker is told about the channel it closes.

    Attributes
    ----------
    fs_hz : float
        Sample rate the NCO words are scaled to.
    T_s : float
        Dump (loop update) period.
    if_hz : float
        Digital IF of the carrier NCO (0 on the fast path).
    inverted : bool
        Spectrum inverted (carrier = IF - Doppler).
    doppler0_hz, doppler_rate0_hz_s : float or array
        Initial Doppler and Doppler rate (from acquisition / the scenario), batch-shaped.
    doppler0_sigma_hz : float or None
        1-sigma error of ``doppler0_hz`` (a hand-over from acquisition), or None (the
        tracker starts on the truth, as on the fast path).
    cn0_dbhz : float or None
        Nominal C/N0 (for trackers that derive R from it; None: the tracker's default).
    spacing_chips : float
        Early-late half spacing of the correlator (chips).
    latency_epochs : int
        Epochs between a dump and the epoch its write takes effect in.
    aiding : callable or None
        ``aiding(k) -> Doppler rate (Hz/s)`` at epoch ``k`` from an external sensor (INS),
        or None.
    """

    fs_hz: float
    T_s: float = 1e-3
    if_hz: float = 0.0
    inverted: bool = False
    doppler0_hz: Any = 0.0
    doppler_rate0_hz_s: Any = 0.0
    doppler0_sigma_hz: float | None = None
    cn0_dbhz: float | None = None
    spacing_chips: float = 0.5
    latency_epochs: int = 0
    aiding: Callable[[int], Any] | None = field(default=None, compare=False)


TRACKERS: dict[str, tuple[Callable, str]] = {}
#: names of the trackers that need ``TrackerContext.aiding`` (an external sensor)
_NEEDS_AIDING: set[str] = set()
#: the options declared at registration (trackers whose factory takes ``**options``)
_OPTIONS: dict[str, dict] = {}


def register_tracker(name: str, factory: Callable, help: str = "", *,
                     needs_aiding: bool = False, options: dict | None = None) -> Callable:
    """Register ``factory(ctx, arith, **options)`` under ``name`` (unique);
    ``needs_aiding``: the tracker cannot run without ``TrackerContext.aiding``;
    ``options``: the keyword options it takes, with their defaults, for a factory that
    passes ``**options`` on (else its named keyword parameters are, :func:`tracker_options`)."""
    if name in TRACKERS and TRACKERS[name][0] is not factory:
        raise ValueError(f"tracker {name!r} is registered twice")
    TRACKERS[name] = (factory, help)
    if needs_aiding:
        _NEEDS_AIDING.add(name)
    if options is not None:
        _OPTIONS[name] = dict(options)
    return factory


def tracker_options(name: str) -> dict:
    """The keyword options the tracker ``name`` takes (``bn_hz``, ``dll_bn_hz``,
    ``r_mode``, ...) and their defaults: those declared at registration, else the factory's
    named keyword parameters after ``ctx`` and ``arith``. A run option not among them has
    no effect on that tracker (the run configurations refuse it)."""
    import inspect
    _load_builtin()
    if name not in TRACKERS:
        raise ValueError(f"unknown tracker {name!r}; choose from {', '.join(sorted(TRACKERS))}")
    if name in _OPTIONS:
        return dict(_OPTIONS[name])
    ps = list(inspect.signature(TRACKERS[name][0]).parameters.values())[2:]
    return {p.name: p.default for p in ps if p.default is not p.empty and
            p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}


def needs_aiding(name: str) -> bool:
    """True if the tracker ``name`` needs an external aiding source (INS Doppler rate)."""
    _load_builtin()
    return name in _NEEDS_AIDING


def _load_builtin():
    # modules that register trackers on import; a new tracker module is added to BUILTIN
    for mod in BUILTIN:
        __import__(mod)


BUILTIN: tuple[str, ...] = ("dsp.gnss.aukf", "dsp.ins.loops")


def tracker_names() -> tuple[str, ...]:
    _load_builtin()
    return tuple(sorted(TRACKERS))


def tracker_help(name: str) -> str:
    _load_builtin()
    return TRACKERS[name][1]


def make_tracker(name: str, ctx: TrackerContext, arith, **options):
    """Build the tracker ``name`` for ``ctx`` in arithmetic ``arith``."""
    _load_builtin()
    if name not in TRACKERS:
        raise ValueError(f"unknown tracker {name!r}; choose from {', '.join(sorted(TRACKERS))}")
    return TRACKERS[name][0](ctx, arith, **options)


def _pll_factory(order: int):
    def make(ctx: TrackerContext, arith, bn_hz: float = 15.0, dll_bn_hz: float = 1.0,
             costas: bool = True):
        from .loops_fixed import ChannelCore
        return ChannelCore(arith, ctx.fs_hz, ctx.T_s, order, bn_hz, dll_bn_hz,
                           ctx.spacing_chips, ctx.if_hz, ctx.inverted,
                           np.asarray(ctx.doppler0_hz, float),
                           np.asarray(ctx.doppler_rate0_hz_s, float), costas)
    return make


register_tracker("pll2", _pll_factory(2), "2nd-order Costas PLL + carrier-aided DLL")
register_tracker("pll3", _pll_factory(3),
                 "3rd-order Costas PLL (Kaplan a3 1.1, b3 2.4) + carrier-aided DLL")

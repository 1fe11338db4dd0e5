"""Carrier and code tracking loops, lock detectors and the tracking channel's DSP.

Loop filters (Kaplan & Hegarty, *Understanding GPS/GNSS*, 3rd ed., table 8.23 / 2nd ed.
table 5.6), all integrators Euler (``v += T u``), error ``e`` per epoch of ``T`` s::

    2nd order PLL:  w0 = Bn / 0.53,   v1 += T w0^2 e;            f = v1 + a2 w0 e,   a2 = 1.414
    3rd order PLL:  w0 = Bn / 0.7845, v2 += T w0^3 e;
                                      v1 += T (a3 w0^2 e + v2);   f = v1 + b3 w0 e,   a3 = 1.1, b3 = 2.4
    FLL assist (2nd order FLL, error ef Hz, w0f = Bnf / 0.53, into the 3rd order PLL):
                                      v2 += T (w0^3 e + w0f^2 ef); v1 += T (a3 w0^2 e + v2 + a2 w0f ef)
    carrier-aided 1st order DLL:      fc = f_chip + f_D / 1540 + 4 Bn_dll tau

``e`` in cycles gives ``f`` in Hz (the carrier Doppler of the replica), ``v2`` in Hz/s.
The NCO integrates the frequency: the replica phase advances ``f T`` over the next epoch.

Timing of the closed loop: the frequency computed from dump ``k`` applies to epoch
``k + 1 + latency`` (``latency = 0``: the golden correlator driven in Python, a write
before the next epoch starts; ``latency = 1``: the FPGA channel, where the dump arrives
during epoch ``k + 1`` and the double-buffered write takes effect at ``k + 2``).

Steady state: the loop is type 3 (three integrators: v2, v1, the NCO), and for a phase
input of constant third derivative ``J`` the Euler form is exact: the third difference of
the replica phase is ``T^3 w0^3 e``, hence ``e_ss = J / w0^3 = 0.4828 J / Bn^3`` (Kaplan's
``(1/w0^3) d^3R/dt^3``; ``J`` in deg/s^3 gives degrees) for any ``T``, with or without
latency. The digital loop's noise bandwidth differs from the nominal ``Bn`` by
``O(Bn T)``: :func:`noise_bandwidth` computes the actual one.
"""
from __future__ import annotations


import numpy as np

from .ca_code import CHIP_RATE_HZ, L1_HZ
from .discriminators import costas_atan, dll_nelp, fll_cross_dot, pll_atan2

A2, W2 = 1.414, 0.53
A3, B3, W3 = 1.1, 2.4, 0.7845


def pll_w0(order: int, bn_hz: float) -> float:
    if order == 2:
        return bn_hz / W2
    if order == 3:
        return bn_hz / W3
    raise ValueError(f"PLL order must be 2 or 3, not {order!r}")


def jerk_stress_deg(jerk_deg_s3, bn_hz: float) -> float:
    """Kaplan's 3rd-order steady-state error ``(1/w0^3) J = 0.4828 J / Bn^3`` (deg)."""
    return jerk_deg_s3 / pll_w0(3, bn_hz) ** 3


def kaplan_jitter_deg(cn0_dbhz, bn_hz: float, T_s: float):
    """Kaplan's PLL thermal jitter ``(360/2pi) sqrt(Bn/c (1 + 1/(2 T c)))`` (deg), c = C/N0."""
    c = 10.0 ** (np.asarray(cn0_dbhz, float) / 10)
    return 180.0 / np.pi * np.sqrt(bn_hz / c * (1 + 1 / (2 * T_s * c)))


class CarrierLoop:
    """A 2nd/3rd order PLL filter (optionally FLL-assisted), batched over any array shape.

    ``update(e_cycles, ef_hz=None) -> f_hz`` (replica Doppler for the next epoch)."""

    def __init__(self, order: int, bn_hz: float, T_s: float, f0_hz=0.0, fdot0_hz_s=0.0,
                 fll_bn_hz: float | None = None):
        self.order, self.bn, self.T = int(order), float(bn_hz), float(T_s)
        self.w0 = pll_w0(self.order, self.bn)
        self.w0f = None if fll_bn_hz is None else float(fll_bn_hz) / W2
        self.v1 = np.array(f0_hz, dtype=float)
        self.v2 = np.array(fdot0_hz_s, dtype=float) * np.ones_like(self.v1)

    def update(self, e, ef=None):
        T, w = self.T, self.w0
        e = np.asarray(e, float)
        ef = 0.0 if (ef is None or self.w0f is None) else np.asarray(ef, float)
        wf = 0.0 if self.w0f is None else self.w0f
        if self.order == 3:
            self.v2 = self.v2 + T * (w ** 3 * e + wf ** 2 * ef)
            self.v1 = self.v1 + T * (A3 * w ** 2 * e + self.v2 + A2 * wf * ef)
            return self.v1 + B3 * w * e
        self.v1 = self.v1 + T * (w ** 2 * e + wf ** 2 * ef)
        return self.v1 + A2 * w * e


def loop_impulse_response(step, T_s: float, latency: int = 0, n: int = 20000):
    """Impulse responses of a digital tracking loop to its discriminator noise, with this
    module's timing: epoch ``k``'s error is the input minus the replica's mid-epoch phase
    ``r_k``, the frequency computed from dump ``k`` is in force from epoch ``k + 1 + latency``
    and the NCO integrates it. ``step(e) -> (f, y)``: the loop filter on one error (phase
    units), returning the frequency (phase units per s) and any output ``y`` of interest.

    Returns ``(h_r, h_y)`` (``n`` samples each): the replica mid-epoch phase and ``y`` after
    dump ``k`` for a unit error impulse at epoch 0. A white discriminator noise of variance
    ``s2`` gives the replica phase variance ``s2 sum h_r^2`` and that of ``y`` ``s2 sum
    h_y^2``."""
    phi, f = 0.0, [0.0] * (int(latency) + 1)
    h_r, h_y = np.empty(n), np.empty(n)
    for k in range(n):
        r = phi + f[0] * T_s / 2          # replica mid-epoch phase
        h_r[k] = r
        e = (1.0 if k == 0 else 0.0) - r
        phi += f[0] * T_s
        fk, h_y[k] = step(e)
        f = f[1:] + [float(fk)]
    return h_r, h_y


def carrier_loop_response(order: int, bn_hz: float, T_s: float, latency: int = 0,
                          n: int | None = None):
    """:func:`loop_impulse_response` of the PLL filter (:class:`CarrierLoop`) with ``y`` its
    frequency state ``v1`` (Hz per cycle of error: the Doppler the trackers report); raises
    ``ValueError`` if the loop is unstable or has not settled in ``n`` epochs."""
    # The 3rd-order loop's complex poles decay at only ~0.149 w0 (damping ~0.2): ~20
    # time constants of 5.3 / Bn s.
    n = max(20000, int(150 / (bn_hz * T_s))) if n is None else int(n)
    loop = CarrierLoop(order, bn_hz, T_s)

    def step(e):
        f = float(loop.update(e))
        return f, float(loop.v1)
    h_r, h_v = loop_impulse_response(step, T_s, latency, n)
    if not (np.all(np.isfinite(h_r)) and np.all(np.isfinite(h_v))) or \
            abs(h_r[-50:]).max() > 1e-9:
        raise ValueError(f"the loop (order {order}, Bn {bn_hz} Hz, T {T_s} s, latency "
                         f"{latency}) is unstable or has not settled in {n} epochs")
    return h_r, h_v


def noise_bandwidth(order: int, bn_hz: float, T_s: float, latency: int = 0,
                    n: int | None = None) -> float:
    """The actual one-sided noise bandwidth of the digital loop (Hz), from its impulse
    response ``h`` (measurement noise to replica phase, :func:`carrier_loop_response`):
    ``Bn = sum h^2 / (2 T (sum h)^2)``."""
    h, _ = carrier_loop_response(order, bn_hz, T_s, latency, n)
    return float(np.sum(h ** 2) / (2 * T_s * np.sum(h) ** 2))


def pli(ip_sum, qp_sum):
    """Narrowband phase-lock indicator ``(I^2 - Q^2) / (I^2 + Q^2)`` of prompts summed over
    the detector's window (``cos 2 e``; 1 in lock)."""
    i2, q2 = np.asarray(ip_sum, float) ** 2, np.asarray(qp_sum, float) ** 2
    return (i2 - q2) / np.where(i2 + q2 > 0, i2 + q2, 1.0)


class LockDetector:
    """Phase-lock (narrowband PLI) and C/N0 lock detectors over windows of ``window``
    prompts (batched).

    * PLI: prompts summed coherently over blocks of ``m`` epochs, ``NBD = sum_b (I_b^2 -
      Q_b^2)``, ``NBP = sum_b (I_b^2 + Q_b^2)``, ``PLI = NBD / NBP`` (~ ``cos 2 e``). A block
      straddling a data-bit edge keeps the carrier phase (its sum is ``a e^{j e}`` times
      ``n1 - n2``), so only its weight drops: the detector works on data-modulated
      signals with a Costas loop. Phase lock if ``PLI >= pli_min`` (0.8: |e| <~ 18 deg).
    * C/N0: the data-insensitive M2M4 estimator (``dsp.gnss.cn0``) on the window; C/N0
      lock if the estimate ``>= cn0_min_dbhz``.

    ``update(prompt)`` returns ``True`` when a window closed (the fields then updated).
    """

    def __init__(self, T_s: float = 1e-3, window: int = 100, m: int = 10,
                 pli_min: float = 0.8, cn0_min_dbhz: float = 28.0):
        if window % m:
            raise ValueError(f"window ({window}) must be a whole number of PLI blocks m = {m}")
        self.T, self.window, self.m = float(T_s), int(window), int(m)
        self.pli_min, self.cn0_min = float(pli_min), float(cn0_min_dbhz)
        self._buf = []
        self.pli = self.cn0_dbhz = np.nan
        self.phase_lock = self.cn0_lock = False

    def update(self, prompt) -> bool:
        from .cn0 import cn0_m2m4
        self._buf.append(np.asarray(prompt, complex))
        if len(self._buf) < self.window:
            return False
        p = np.stack(self._buf, axis=-1)
        self._buf = []
        b = p.reshape(p.shape[:-1] + (-1, self.m)).sum(axis=-1)
        nbd = (b.real ** 2 - b.imag ** 2).sum(axis=-1)
        nbp = (b.real ** 2 + b.imag ** 2).sum(axis=-1)
        self.pli = nbd / np.where(nbp > 0, nbp, 1.0)
        self.cn0_dbhz = cn0_m2m4(p, self.T)
        self.phase_lock = self.pli >= self.pli_min
        self.cn0_lock = self.cn0_dbhz >= self.cn0_min
        return True


def hz_to_word(f_hz, fs_hz: float, bits: int = 32):
    """NCO frequency word ``round(f 2^bits / fs)`` (two's complement range) and the error
    ``word fs / 2^bits - f`` (Hz, ``|err| <= fs / 2^(bits+1)``). Pure."""
    f = np.asarray(f_hz, float)
    scale = 2.0 ** bits / fs_hz
    w = np.rint(f * scale).astype(np.int64)
    lim = 1 << (bits - 1)
    if np.any(w >= lim) or np.any(w < -lim):
        raise ValueError(f"frequency {f_hz!r} Hz outside the {bits}-bit NCO range +-fs/2")
    return w, w / scale - f


class TrackingChannel:
    """The tracking channel's DSP, batched: per dump (I/Q x E/P/L arrays of any common
    shape) returns the carrier and code NCO frequencies (Hz) to write back.

    Carrier: 2nd/3rd order PLL on a Costas (``costas=True``) or atan2 discriminator,
    optional FLL assist (cross/dot on successive prompts). Code: carrier-aided 1st order DLL
    on the normalised early-minus-late envelope. Lock detectors (PLI, C/N0) in ``lock``
    (:class:`LockDetector`). ``carrier_freq = if_hz + s f_D`` with
    ``s = -1`` for an inverted spectrum (the measured phase then has the opposite sign).
    """

    def __init__(self, T_s: float = 1e-3, order: int = 3, bn_hz: float = 15.0,
                 dll_bn_hz: float = 1.0, spacing_chips: float = 0.5, if_hz: float = 0.0,
                 inverted: bool = False, doppler0_hz=0.0, doppler_rate0_hz_s=0.0,
                 fll_bn_hz: float | None = None, costas: bool = True,
                 lock: "LockDetector | None" = None):
        self.T, self.s = float(T_s), (-1.0 if inverted else 1.0)
        self.if_hz, self.d, self.costas = float(if_hz), float(spacing_chips), bool(costas)
        self.pll = CarrierLoop(order, bn_hz, T_s, doppler0_hz, doppler_rate0_hz_s, fll_bn_hz)
        self.k_dll = 4.0 * float(dll_bn_hz)
        self.doppler = np.array(doppler0_hz, float)
        self.code_rate = CHIP_RATE_HZ * (1 + self.doppler / L1_HZ)
        self._prev = None
        self.lock = LockDetector(T_s) if lock is None else lock
        self.last_e = self.last_tau = None

    def update(self, ie, qe, ip, qp, il, ql):
        qp_s = self.s * np.asarray(qp, float)
        e = costas_atan(ip, qp_s) if self.costas else pll_atan2(ip, qp_s)
        ef = None
        if self.pll.w0f is not None and self._prev is not None:
            ef = fll_cross_dot(self._prev[0], self._prev[1], ip, qp_s, self.T,
                               four_quadrant=not self.costas)
        self._prev = (np.asarray(ip, float), qp_s)
        self.doppler = self.pll.update(e, ef)
        tau = dll_nelp(ie, qe, il, ql, self.d)
        self.code_rate = CHIP_RATE_HZ + self.doppler / (L1_HZ / CHIP_RATE_HZ) + self.k_dll * tau
        self.last_e, self.last_tau = e, tau
        self.lock.update(np.asarray(ip, float) + 1j * qp_s)
        return self.if_hz + self.s * self.doppler, self.code_rate

    def words(self, fs_hz: float, bits: int = 32):
        """The current frequencies as NCO words (carrier, code) and their errors (Hz)."""
        return hz_to_word(self.if_hz + self.s * self.doppler, fs_hz, bits), \
            hz_to_word(self.code_rate, fs_hz, bits)

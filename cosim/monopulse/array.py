"""Planar monopulse array: 4 subarrays of Mx x My elements, quantised element steering.

Geometry (docs/explanation/monopulse_signal.md), lengths in wavelengths
-----------------------------------------------------------------------
Subarray centres ``P1 = [0, 0]``, ``P2 = [0, Dy]``, ``P3 = [Dx, 0]``, ``P4 = [Dx, Dy]``;
``D = M d`` by default (8 x 8 at lambda/2: ``D = 4 lambda``). Direction cosines of a target
at azimuth ``phi`` (from the x axis) and ``theta`` (from the z axis)::

    u = sin(theta) cos(phi),   v = sin(theta) sin(phi),   u^2 + v^2 < 1 (visible region)

Sign convention (the monopulse paper's, kept so its equations hold as written): a plane wave from
``(u, v)`` reaches position ``p`` with phase ``-2 pi p.(u, v)`` relative to the origin, so
subarray ``i`` sees ``exp(-j phi_i)``, ``phi_i = 2 pi P_i.(u, v)``. (A wave from ``r`` reaches
``p`` early, ``+2 pi p.r`` at RF; the minus is what a spectrum-inverting, high-side-LO RF
down-conversion ahead of the IF delivers, and it is the paper's ``y_i = s exp(j dphi_i)``,
``dphi_i = phi_i0 - phi_i``.)

Steering (decision): each element's phase shifter applies ``+2 pi p_e.(u0, v0)`` with
``p_e`` the element position *relative to its subarray centre*, rounded to the nearest
multiple of ``2 pi / 2^phase_bits``; the four subarrays hold the same relative positions,
so they have the *same* quantised pattern and it cancels in Delta/Sigma (quantisation costs
gain, not bias). The inter-subarray steering phase ``phi_i0`` is applied digitally after the
DDC with the channel correction (``steering_correction``), exactly. The alternative,
``subarray_steering="elements"``, puts the full-array phase in the shifters (each subarray
then has its own quantised pattern, and the quantisation biases the angle).

Subarray pattern (normalised, 1 at the steering direction with ideal shifters)::

    AF(u, v; u0, v0) = (1/M) sum_e w_e exp(-j 2 pi p_e.(u, v)),   w_e = exp(j Q[2 pi p_e.(u0, v0)])

Channel ``i`` (subarray combiner output, before the ADC): ``g_i AF exp(-j phi_i)``, with
``g_i = 10^(gain_db_i / 20) exp(j phase_deg_i)`` the channel's gain/phase mismatch.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

N_CHANNELS = 4


def _pos_int(name, v, lo=1):
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, not {v!r}")
    return int(v)


def _pos_num(name, v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be a finite number > 0, not {v!r}")
    return float(v)


def check_visible(u, v, what="direction"):
    """Refuse direction cosines outside the visible region ``u^2 + v^2 < 1``."""
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    rho2 = u * u + v * v
    bad = ~(rho2 < 1.0)  # NaN is refused too
    if np.any(bad):
        k = np.flatnonzero(np.broadcast_to(bad, rho2.shape).ravel())[0]
        ub = float(np.broadcast_to(u, rho2.shape).ravel()[k])
        vb = float(np.broadcast_to(v, rho2.shape).ravel()[k])
        raise ValueError(f"{what} must lie in the visible region u^2 + v^2 < 1, not "
                         f"u = {ub!r}, v = {vb!r} (u^2 + v^2 = {ub * ub + vb * vb!r})")


def direction_cosines(az_rad, el_rad):
    """``(u, v) = (sin th cos ph, sin th sin ph)`` for azimuth ``ph`` and ``th`` from z."""
    az = np.asarray(az_rad, dtype=float)
    el = np.asarray(el_rad, dtype=float)
    return np.sin(el) * np.cos(az), np.sin(el) * np.sin(az)


def angles_from_uv(u, v):
    """``(az, el) = (atan2(v, u), arcsin(sqrt(u^2 + v^2)))``; refuses the invisible region."""
    check_visible(u, v)
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    return np.arctan2(v, u), np.arcsin(np.hypot(u, v))


def _cis(x):
    return np.cos(x) + 1j * np.sin(x)


def quantise_phase(phase_rad, bits):
    """Nearest multiple of ``2 pi / 2^bits`` (None: unquantised). Returns (phase, error)."""
    phase_rad = np.asarray(phase_rad, dtype=float)
    if bits is None:
        return phase_rad, np.zeros_like(phase_rad)
    step = 2 * np.pi / (1 << bits)
    q = np.round(phase_rad / step) * step
    return q, q - phase_rad


@dataclass(frozen=True)
class ArrayConfig:
    """The 2 x 2 monopulse array.

    Parameters
    ----------
    elements_x, elements_y : int
        Elements per subarray along x and y (8 x 8).
    element_spacing_wl : float
        Element spacing (wavelengths), > 0 (0.5).
    subarray_spacing_x_wl, subarray_spacing_y_wl : float or None
        ``Dx``, ``Dy`` (wavelengths), > 0; None = ``elements * element_spacing`` (4.0).
    phase_bits : int or None
        Phase-shifter word length, >= 1 (6); None = ideal (unquantised) shifters.
    gain_db, phase_deg : tuple of 4 floats
        Per-channel gain (dB) and phase (deg) mismatch of channels 1-4.
    subarray_steering : "digital" or "elements"
        Where the inter-subarray steering phase ``phi_i0`` is applied: "digital" (default,
        after the DDC, exact; the quantised pattern is common to the 4 subarrays) or
        "elements" (in the element phase shifters with the full-array phase
        ``2 pi (P_i + p_e).(u0, v0)`` quantised: each subarray gets its own pattern, the
        quantisation then biases Delta/Sigma; ``steering_correction`` is 1).
    """

    elements_x: int = 8
    elements_y: int = 8
    element_spacing_wl: float = 0.5
    subarray_spacing_x_wl: float | None = None
    subarray_spacing_y_wl: float | None = None
    phase_bits: int | None = 6
    gain_db: tuple = (0.0, 0.0, 0.0, 0.0)
    phase_deg: tuple = (0.0, 0.0, 0.0, 0.0)
    subarray_steering: str = "digital"

    def __post_init__(self):
        _pos_int("elements_x", self.elements_x)
        _pos_int("elements_y", self.elements_y)
        _pos_num("element_spacing_wl", self.element_spacing_wl)
        for name in ("subarray_spacing_x_wl", "subarray_spacing_y_wl"):
            v = getattr(self, name)
            if v is not None:
                _pos_num(name, v)
        if self.phase_bits is not None:
            b = self.phase_bits
            if isinstance(b, bool) or not isinstance(b, (int, np.integer)) or not 1 <= b <= 24:
                raise ValueError(f"phase_bits must be an integer in [1, 24] or None (ideal), "
                                 f"not {b!r}")
        for name in ("gain_db", "phase_deg"):
            v = getattr(self, name)
            if not isinstance(v, (tuple, list)) or len(v) != N_CHANNELS or not all(
                    isinstance(x, (int, float, np.integer, np.floating))
                    and not isinstance(x, bool) and math.isfinite(x) for x in v):
                raise ValueError(f"{name} must be 4 finite numbers (channels 1-4), not {v!r}")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if self.subarray_steering not in ("digital", "elements"):
            raise ValueError(f"subarray_steering must be 'digital' or 'elements', not "
                             f"{self.subarray_steering!r}")

    @property
    def dx_wl(self) -> float:
        """Subarray spacing ``Dx`` (wavelengths)."""
        s = self.subarray_spacing_x_wl
        return self.elements_x * self.element_spacing_wl if s is None else float(s)

    @property
    def dy_wl(self) -> float:
        """Subarray spacing ``Dy`` (wavelengths)."""
        s = self.subarray_spacing_y_wl
        return self.elements_y * self.element_spacing_wl if s is None else float(s)

    @property
    def unambiguous_offset(self) -> tuple[float, float]:
        """``lambda / (2 D)`` per axis: |u - u0|, |v - v0| must stay below (0.125, 0.125)."""
        return 0.5 / self.dx_wl, 0.5 / self.dy_wl

    @property
    def subarray_centres_wl(self) -> np.ndarray:
        """(4, 2) centres P1..P4 (wavelengths): [0,0], [0,Dy], [Dx,0], [Dx,Dy]."""
        dx, dy = self.dx_wl, self.dy_wl
        return np.array([[0.0, 0.0], [0.0, dy], [dx, 0.0], [dx, dy]])

    @property
    def element_offsets_wl(self) -> np.ndarray:
        """(M, 2) element positions relative to the subarray centre (wavelengths)."""
        d = self.element_spacing_wl
        ex = (np.arange(self.elements_x) - (self.elements_x - 1) / 2) * d
        ey = (np.arange(self.elements_y) - (self.elements_y - 1) / 2) * d
        gx, gy = np.meshgrid(ex, ey, indexing="ij")
        return np.stack([gx.ravel(), gy.ravel()], axis=1)

    @property
    def channel_gains(self) -> np.ndarray:
        """(4,) complex mismatch ``g_i``."""
        g = 10 ** (np.array(self.gain_db) / 20)
        return g * np.exp(1j * np.deg2rad(np.array(self.phase_deg)))

    def steering_weights(self, u0, v0) -> np.ndarray:
        """Quantised element weights (..., M) for the steering direction(s) ``(u0, v0)``."""
        check_visible(u0, v0, "steering direction")
        p = self.element_offsets_wl
        ph = 2 * np.pi * (np.multiply.outer(np.asarray(u0, float), p[:, 0])
                          + np.multiply.outer(np.asarray(v0, float), p[:, 1]))
        return np.exp(1j * quantise_phase(ph, self.phase_bits)[0])

    def subarray_pattern(self, u, v, u0, v0) -> np.ndarray:
        """Normalised subarray array factor ``AF(u, v; u0, v0)``, complex, shape of ``u``.

        ``(u0, v0)`` scalars (one steering); ``u``, ``v`` arrays of the same shape.
        """
        check_visible(u, v, "target direction")
        w = self.steering_weights(float(u0), float(v0)).reshape(self.elements_x,
                                                                 self.elements_y)
        d = self.element_spacing_wl
        ex = (np.arange(self.elements_x) - (self.elements_x - 1) / 2) * d
        ey = (np.arange(self.elements_y) - (self.elements_y - 1) / 2) * d
        u = np.asarray(u, float)
        v = np.asarray(v, float)
        # The grid is separable (exp(-j 2 pi (x u + y v)) = exp(-j 2 pi x u) exp(-j 2 pi y v))
        # even when the quantised weights are not: Mx + My exponentials per direction, not Mx My.
        ax = _cis(-2 * np.pi * np.multiply.outer(u, ex))
        ay = _cis(-2 * np.pi * np.multiply.outer(v, ey))
        return np.einsum("...x,xy,...y->...", ax, w, ay) / (self.elements_x * self.elements_y)

    def subarray_phases(self, u, v) -> np.ndarray:
        """``phi_i = 2 pi P_i.(u, v)``, shape (..., 4)."""
        P = self.subarray_centres_wl
        u = np.asarray(u, float)
        v = np.asarray(v, float)
        return 2 * np.pi * (np.multiply.outer(u, P[:, 0]) + np.multiply.outer(v, P[:, 1]))

    def channel_response(self, u, v, u0, v0) -> np.ndarray:
        """Channel outputs per unit target amplitude before the ADC, shape (..., 4):
        ``g_i AF exp(-j phi_i)`` ("digital"), or ``g_i AF_i`` with ``AF_i`` the pattern of
        subarray i's elements at their absolute positions under full-array quantised
        steering ("elements")."""
        if self.subarray_steering == "digital":
            af = self.subarray_pattern(u, v, u0, v0)
            return self.channel_gains * af[..., None] * np.exp(-1j * self.subarray_phases(u, v))
        check_visible(u0, v0, "steering direction")
        check_visible(u, v, "target direction")
        u = np.asarray(u, float)
        v = np.asarray(v, float)
        p = self.element_offsets_wl
        out = np.empty(u.shape + (N_CHANNELS,), complex)
        for i, c in enumerate(self.subarray_centres_wl):  # 4 subarrays
            x, y = p[:, 0] + c[0], p[:, 1] + c[1]
            w = np.exp(1j * quantise_phase(2 * np.pi * (x * u0 + y * v0), self.phase_bits)[0])
            ph = -2 * np.pi * (np.multiply.outer(u, x) + np.multiply.outer(v, y))
            out[..., i] = (_cis(ph) @ w) / p.shape[0]
        return self.channel_gains * out

    def steering_correction(self, u0, v0) -> np.ndarray:
        """Digital steering applied after the DDC, shape (..., 4): ``exp(j phi_i0)``
        ("digital") or 1 ("elements")."""
        check_visible(u0, v0, "steering direction")
        ph = self.subarray_phases(u0, v0)
        if self.subarray_steering == "elements":
            return np.ones_like(ph, dtype=complex)
        return np.exp(1j * ph)

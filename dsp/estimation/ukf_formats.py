"""Fixed-point formats of the unscented filter (:class:`UkfFormats`) and the weights of the
scaled unscented transform (:func:`sigma_weights`), with the rule that refuses weights a
``W`` format cannot hold accurately (:func:`weight_problem`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fixed import FixedFormat
from .formats import FormatTable, fmt, need_bits, need_shift, sum_bits


@dataclass(frozen=True)
class UkfFormats(FormatTable):
    """Fixed-point formats of the unscented filter, one per signal.

    The defaults suit states of order 1 (``x`` +-32) with covariances below 8 and
    measurements of order 1 (an I/Q pair); scale the model or change the table otherwise.

    ======  ==============================================================
    signal  what
    ======  ==============================================================
    z       measurement
    x       state; also the sigma points ``X`` are in ``X``
    P       covariance
    Pc      ``(L + lambda) P`` (and ``(L + lambda) Pp``), factored for the sigma points
    U       its Cholesky factor and the constant noise factors ``sqrt(c) Lq, sqrt(c) Lr``
    X       sigma points (state and noise parts) and the points propagated by ``f``
    W       weights ``Wm``, ``Wc`` and ``c = L + lambda``
    xm      predicted mean
    Pp      predicted covariance (incl. ``Q``, additive noise)
    Y       measurement sigma points ``h(X)`` and the predicted measurement
    D       deviations ``X - xm``, ``Y - zp`` and the weighted deviations ``Wc D``
    Pyy     innovation covariance (incl. ``R``, additive noise)
    Pxy     cross covariance
    Ls      Cholesky factor of ``Pyy``
    V       ``Ls^-1 Pxy^T`` (also gives ``P = Pp - V^T V``)
    K       gain
    e       innovation ``z - zp``
    prm     model parameters ``prm_f``, ``prm_h``
    ======  ==============================================================
    """

    z: FixedFormat = fmt(24, 20)
    x: FixedFormat = fmt(32, 26)
    P: FixedFormat = fmt(32, 28)
    Pc: FixedFormat = fmt(32, 26)
    U: FixedFormat = fmt(30, 24)
    X: FixedFormat = fmt(32, 26)
    W: FixedFormat = fmt(24, 18)
    xm: FixedFormat = fmt(32, 26)
    Pp: FixedFormat = fmt(32, 28)
    Y: FixedFormat = fmt(28, 24)
    D: FixedFormat = fmt(28, 24)
    Pyy: FixedFormat = fmt(32, 28)
    Pxy: FixedFormat = fmt(32, 28)
    Ls: FixedFormat = fmt(30, 24)
    V: FixedFormat = fmt(30, 24)
    K: FixedFormat = fmt(24, 20)
    e: FixedFormat = fmt(24, 20)
    prm: FixedFormat = fmt(24, 20)

    def __post_init__(self):
        self.validate()

    def check(self, n: int, m: int, L: int) -> None:
        """Every exact intermediate fits int64 and every alignment is a left shift."""
        w = {s: getattr(self, s).width for s in self.signals()}
        r = self.fracs()
        ns = 2 * L + 1
        need_shift("c P", r["W"] + r["P"] - r["Pc"], "Pc")
        need_shift("c Pp", r["W"] + r["Pp"] - r["Pc"], "Pc")
        need_bits("c P", w["W"] + max(w["P"], w["Pp"]) - 1)
        a = 2 * r["U"]
        need_bits("Cholesky of c P", max(sum_bits(w["U"], w["U"], n),
                                         w["Pc"] + need_shift("Cholesky of c P", a - r["Pc"], "Pc")) + 1)
        for what, f1, f2 in (("x + U", "x", "U"), ("xm + U", "xm", "U")):
            a = max(r[f1], r[f2])
            need_bits(what, max(w[f1] + a - r[f1], w[f2] + a - r[f2]) + 1)
            need_shift(what, a - r["X"], "X")
        need_bits("sum Wm X", sum_bits(w["W"], w["X"], ns))
        need_shift("sum Wm X", r["W"] + r["X"] - r["xm"], "xm")
        need_bits("sum Wm Y", sum_bits(w["W"], w["Y"], ns))
        a = max(r["X"], r["xm"])
        need_bits("X - xm", max(w["X"] + a - r["X"], w["xm"] + a - r["xm"]) + 1)
        need_shift("X - xm", a - r["D"], "D")
        need_shift("Y - zp", r["Y"] - r["D"], "D")
        need_bits("Wc D", w["W"] + w["D"] - 1)
        need_bits("sum (Wc D) D", sum_bits(w["D"], w["D"], ns) + 1)
        for sig, noise in (("Pp", "Q"), ("Pyy", "R"), ("Pxy", None)):
            need_shift("sum (Wc D) D", 2 * r["D"] - r[sig], sig)
            need_bits("sum (Wc D) D + noise", w[sig] + 2 * r["D"] - r[sig] + 1)
        a = 2 * r["Ls"]
        need_bits("Cholesky of Pyy", max(sum_bits(w["Ls"], w["Ls"], m),
                                         w["Pyy"] + need_shift("Cholesky of Pyy", a - r["Pyy"], "Pyy")) + 1)
        a = r["Ls"] + r["V"]
        need_bits("Ls^-1 Pxy^T", max(sum_bits(w["Ls"], w["V"], m),
                                     w["Pxy"] + need_shift("Ls^-1 Pxy^T", a - r["Pxy"], "Pxy")) + 1)
        a = r["Ls"] + r["K"]
        need_bits("Ls^-T V", max(sum_bits(w["Ls"], w["K"], m),
                                 w["V"] + need_shift("Ls^-T V", a - r["V"], "V")) + 1)
        a = max(r["z"], r["Y"])
        need_bits("z - zp", max(w["z"] + a - r["z"], w["Y"] + a - r["Y"]) + 1)
        need_shift("z - zp", a - r["e"], "e")
        a = r["K"] + r["e"]
        need_bits("xm + K e", max(sum_bits(w["K"], w["e"], m), w["xm"] + need_shift("xm + K e", a - r["xm"], "xm")) + 1)
        need_shift("xm + K e", a - r["x"], "x")
        a = 2 * r["V"]
        need_bits("Pp - V^T V", max(sum_bits(w["V"], w["V"], m), w["Pp"] + need_shift("Pp - V^T V", a - r["Pp"], "Pp")) + 1)
        need_shift("Pp - V^T V", a - r["P"], "P")
        a = max(r["P"], r["Pp"])
        need_bits("P = Pp (no update)", w["Pp"] + a - r["Pp"])

    def check_weights(self, L: int, alpha: float, beta: float, kappa: float) -> None:
        """Refuse UT parameters whose weights this table cannot hold (see
        :func:`weight_problem`), naming the smallest alpha that would do."""
        bad = weight_problem(self.W, L, alpha, beta, kappa)
        if bad is None:
            return
        need = None
        for a in np.geomspace(max(alpha, 1e-4), 10.0, 2000):
            if weight_problem(self.W, L, float(a), beta, kappa) is None:
                need = float(a)
                break
        hint = (f"alpha >= {need:.4g} would do (L = {L}, beta = {beta:g}, kappa = {kappa:g})"
                if need is not None else "no alpha in (0, 10] would do; widen the W format")
        raise ValueError(f"UT weights not representable in fixed point: {bad}; {hint}")


#: Largest ``sum |W|`` of a fixed-point UT: the rounding errors of the sigma points are
#: amplified by it in the mean and covariance (small alpha: a large negative centre weight
#: cancelling large positive ones).
WEIGHT_GAIN_MAX = 8.0
#: Largest relative quantisation error of a weight in the W format (2**-12).
WEIGHT_REL_ERR = 2.0 ** -12


def weight_problem(fw: FixedFormat, L: int, alpha: float, beta: float, kappa: float):
    """``None`` if the weights of ``(L, alpha, beta, kappa)`` suit the format ``fw``, else the
    rule broken, with the bad value: (1) every ``|Wm|``, ``|Wc|`` and ``c = L + lambda`` within
    the format's range; (2) ``sum |Wm|`` and ``sum |Wc|`` at most :data:`WEIGHT_GAIN_MAX`;
    (3) each weight quantised to a relative error of at most :data:`WEIGHT_REL_ERR` and
    ``|sum Wm_q - 1|`` at most that as well."""
    wm, wc, c = sigma_weights(L, alpha, beta, kappa)
    for name, v in (("Wm0", wm[0]), ("Wc0", wc[0]), ("Wi", wm[1]), ("c = L + lambda", c)):
        if not fw.min_value <= v <= fw.max_value:
            return (f"|{name}| = {abs(v):.6g} beyond the range of the W format {fw} "
                    f"([{fw.min_value:g}, {fw.max_value:g}])")
    for name, ws in (("Wm", wm), ("Wc", wc)):
        g = float(np.sum(np.abs(ws)))
        if g > WEIGHT_GAIN_MAX:
            return f"sum |{name}| = {g:.6g} > {WEIGHT_GAIN_MAX:g} (rounding errors amplified by it)"
    lsb = 2.0 ** -fw.frac
    for name, v in (("Wm0", wm[0]), ("Wc0", wc[0]), ("Wi", wm[1])):
        q = np.floor(v / lsb + 0.5) * lsb
        if v != 0 and abs(q - v) > WEIGHT_REL_ERR * abs(v):
            return (f"{name} = {v:.6g} quantised to {q:.6g} in {fw}: relative error "
                    f"{abs(q - v) / abs(v):.3g} > 2^-12")
    s = float(np.sum(np.floor(wm / lsb + 0.5))) * lsb
    if abs(s - 1.0) > WEIGHT_REL_ERR:
        return f"sum of the quantised Wm = {s:.9g}, off 1 by {abs(s - 1):.3g} > 2^-12"
    return None


def sigma_weights(L: int, alpha: float, beta: float, kappa: float):
    """``(Wm, Wc, c)`` of the scaled unscented transform, ``c = L + lambda``."""
    lam = alpha * alpha * (L + kappa) - L
    c = L + lam
    wm = np.full(2 * L + 1, 0.5 / c)
    wc = wm.copy()
    wm[0] = lam / c
    wc[0] = lam / c + (1.0 - alpha * alpha + beta)
    return wm, wc, c

"""Independent evaluations of the estimation kernels, for the bit-exact tests.

One plain-Python loop per filter, in the documented operation order, with the arithmetic
passed in: :class:`IntArith` (Python's unbounded integers: what the fixed-point core must
give bit for bit) or :class:`F32Arith` (numpy float32 scalars: what a float32 DSP gives).
Nothing here imports numba or the kernels.
"""
from __future__ import annotations

import math

import numpy as np


class IntArith:
    """Fixed point with unbounded integers (formats as ``(frac, lo, hi, half)``)."""

    def __init__(self, table):
        self.f = {s: (getattr(table, s).frac, getattr(table, s).min_int, getattr(table, s).max_int,
                      getattr(table, s).rounding == "half_up") for s in table.signals()}
        self.sat = {s: 0 for s in self.f}
        self.zero = 0

    def fr(self, s):
        return self.f[s][0]

    def align(self, v, s):
        assert s >= 0
        return v << s

    def store(self, acc, s, sig):
        _, lo, hi, half = self.f[sig]
        v = ((acc + (1 << (s - 1)) if half else acc) >> s) if s > 0 else acc << (-s)
        if v < lo or v > hi:
            self.sat[sig] += 1
            return lo if v < lo else hi
        return v

    def sqrt(self, v, sig):
        _, lo, hi, half = self.f[sig]
        r = math.isqrt(v)
        if half and v - r * r > r:
            r += 1
        if r > hi:
            self.sat[sig] += 1
            return hi
        return r

    def div(self, n, d, sig):
        _, lo, hi, half = self.f[sig]
        q = n // d
        if half and 2 * (n - q * d) >= d:
            q += 1
        if q < lo or q > hi:
            self.sat[sig] += 1
            return lo if q < lo else hi
        return q

    def one(self, frac):
        return 1 << frac


class F32Arith:
    """float32 scalars, every operation rounded to float32 in the order written."""

    zero = np.float32(0)

    def fr(self, s):
        return 0

    def align(self, v, s):
        return v

    def store(self, acc, s, sig):
        return acc

    def sqrt(self, v, sig):
        return np.sqrt(v)

    def div(self, n, d, sig):
        return n / d

    def one(self, frac):
        return np.float32(1)


def kf_step(ar, x, P, z, u, F, B, H, Q, R):
    """One predict + Joseph update of :mod:`dsp.estimation.kalman` (lists of scalars).
    ``z`` None: predict only. Returns ``(x, P)``."""
    n, m, p = len(x), len(H), (len(B[0]) if len(B) and len(B[0]) else 0)
    fr = ar.fr
    c = max(fr("F") + fr("x"), fr("B") + fr("u"))
    xp = []
    for i in range(n):
        acc = ar.zero
        for j in range(n):
            acc += F[i][j] * x[j]
        acc2 = ar.zero
        for l in range(p):
            acc2 += B[i][l] * u[l]
        acc = ar.align(acc, c - fr("F") - fr("x")) + ar.align(acc2, c - fr("B") - fr("u"))
        xp.append(ar.store(acc, c - fr("x"), "x"))
    M = [[None] * n for _ in range(n)]
    for i in range(n):
        for j in range(n):
            acc = ar.zero
            for l in range(n):
                acc += F[i][l] * P[l][j]
            M[i][j] = ar.store(acc, fr("F") + fr("P") - fr("M"), "M")
    a = fr("M") + fr("F")
    Pp = [[None] * n for _ in range(n)]
    for i in range(n):
        for j in range(i, n):
            acc = ar.zero
            for l in range(n):
                acc += M[i][l] * F[j][l]
            acc += ar.align(Q[i][j], a - fr("Q"))
            Pp[i][j] = Pp[j][i] = ar.store(acc, a - fr("P"), "P")
    if z is None:
        return xp, Pp
    a = fr("H") + fr("x")
    e = []
    for r in range(m):
        acc = ar.align(z[r], a - fr("z"))
        for j in range(n):
            acc -= H[r][j] * xp[j]
        e.append(ar.store(acc, a - fr("e"), "e"))
    PH = [[None] * m for _ in range(n)]
    for i in range(n):
        for r in range(m):
            acc = ar.zero
            for j in range(n):
                acc += Pp[i][j] * H[r][j]
            PH[i][r] = ar.store(acc, fr("P") + fr("H") - fr("PH"), "PH")
    a = fr("H") + fr("PH")
    S = [[None] * m for _ in range(m)]
    for r in range(m):
        for c2 in range(r, m):
            acc = ar.zero
            for j in range(n):
                acc += H[r][j] * PH[j][c2]
            acc += ar.align(R[r][c2], a - fr("R"))
            S[r][c2] = S[c2][r] = ar.store(acc, a - fr("S"), "S")
    L = [[ar.zero] * m for _ in range(m)]
    a = 2 * fr("L")
    for j in range(m):
        acc = ar.align(S[j][j], a - fr("S"))
        for l in range(j):
            acc -= L[j][l] * L[j][l]
        if not acc > 0:
            return xp, Pp
        L[j][j] = ar.sqrt(acc, "L")
        for i in range(j + 1, m):
            acc = ar.align(S[i][j], a - fr("S"))
            for l in range(j):
                acc -= L[i][l] * L[j][l]
            L[i][j] = ar.div(acc, L[j][j], "L")
    W = [[None] * n for _ in range(m)]
    a = fr("L") + fr("W")
    for r in range(m):
        for j in range(n):
            acc = ar.align(PH[j][r], a - fr("PH"))
            for l in range(r):
                acc -= L[r][l] * W[l][j]
            W[r][j] = ar.div(acc, L[r][r], "W")
    K = [[None] * m for _ in range(n)]
    a = fr("L") + fr("K")
    for r in range(m - 1, -1, -1):
        for j in range(n):
            acc = ar.align(W[r][j], a - fr("W"))
            for l in range(r + 1, m):
                acc -= L[l][r] * K[j][l]
            K[j][r] = ar.div(acc, L[r][r], "K")
    a = fr("K") + fr("e")
    xn = []
    for i in range(n):
        acc = ar.align(xp[i], a - fr("x"))
        for r in range(m):
            acc += K[i][r] * e[r]
        xn.append(ar.store(acc, a - fr("x"), "x"))
    a = fr("K") + fr("H")
    A = [[None] * n for _ in range(n)]
    for i in range(n):
        for j in range(n):
            acc = ar.one(a) if i == j else ar.zero
            for r in range(m):
                acc -= K[i][r] * H[r][j]
            A[i][j] = ar.store(acc, a - fr("A"), "A")
    for i in range(n):
        for j in range(n):
            acc = ar.zero
            for l in range(n):
                acc += A[i][l] * Pp[l][j]
            M[i][j] = ar.store(acc, fr("A") + fr("P") - fr("M"), "M")
    G = [[None] * m for _ in range(n)]
    for i in range(n):
        for c2 in range(m):
            acc = ar.zero
            for r in range(m):
                acc += K[i][r] * R[r][c2]
            G[i][c2] = ar.store(acc, fr("K") + fr("R") - fr("G"), "G")
    c = max(fr("M") + fr("A"), fr("G") + fr("K"))
    Pn = [[None] * n for _ in range(n)]
    for i in range(n):
        for j in range(i, n):
            acc = ar.zero
            for l in range(n):
                acc += M[i][l] * A[j][l]
            acc2 = ar.zero
            for r in range(m):
                acc2 += G[i][r] * K[j][r]
            acc = ar.align(acc, c - fr("M") - fr("A")) + ar.align(acc2, c - fr("G") - fr("K"))
            v = ar.store(acc, c - fr("P"), "P")
            if i == j and v < 0:
                v = ar.zero
            Pn[i][j] = Pn[j][i] = v
    return xn, Pn


class AlphaBetaRef:
    """The alpha-beta(-gamma) tracker of :mod:`dsp.estimation.alphabeta` step by step
    (per-sample units); ``ar`` an :class:`IntArith` or :class:`F32Arith`."""

    def __init__(self, ar, x, c, consts, window, adaptive, scale=False, relax=None, kd=0):
        self.ar, self.x, self.c = ar, list(x), list(c)
        self.floor, self.amin, self.amax, self.one, self.nw, self.svl, self.four = consts
        self.scale, self.relax, self.kd = scale, relax, kd     # floor / (1 - alpha); relax (c)
        self.ring, self.pos, self.cnt = [ar.zero] * window, 0, 0
        self.adaptive = adaptive

    def step(self, z):
        ar, x, n = self.ar, self.x, len(self.x)
        if n == 3:
            xp = [ar.store(x[0] + x[1] + x[2], 0, "x"), ar.store(x[1] + x[2] + x[2], 0, "x"), x[2]]
        else:
            xp = [ar.store(x[0] + x[1], 0, "x"), x[1]]
        if z is None:
            self.x = xp
            return
        fr = ar.fr
        e = ar.store(ar.align(z, fr("x") - fr("z")) - xp[0], fr("x") - fr("e"), "e")
        if self.adaptive:
            self.ring[self.pos] = ar.store(e * e, 2 * fr("e") - fr("s"), "s")
            self.pos = (self.pos + 1) % len(self.ring)
            self.cnt += 1
            if self.cnt >= len(self.ring):
                acc = ar.zero
                for v in self.ring:
                    acc += v
                Sm = ar.div(acc, self.nw, "s")
                fl = self.floor
                if self.scale:
                    if isinstance(fl, int):
                        den = (self.one - self.c[0]) >> self.kd
                        fl = ar.div(fl << (fr("c") - self.kd), den, "s")
                    else:
                        fl = ar.div(fl, self.one - self.c[0], "s")
                dm = Sm - fl
                if dm > 0:
                    if isinstance(dm, int):
                        g = ar.sqrt(dm << (2 * fr("l") - fr("s")), "l")
                        lam = ar.div(g << fr("l"), self.svl, "l")
                        sq = ar.sqrt(lam * lam + ((8 * lam) << fr("l")), "l")
                        rk = ar.div(self.four << fr("c"), self.four + lam + sq, "c")
                        al = ar.store((self.one << fr("c")) - rk * rk, fr("c"), "c")
                    else:
                        g = ar.sqrt(dm, "l")
                        lam = ar.div(g, self.svl, "l")
                        l8 = lam + lam
                        l8 = l8 + l8
                        l8 = l8 + l8
                        sq = ar.sqrt(lam * lam + l8, "l")
                        rk = ar.div(self.four, self.four + lam + sq, "c")
                        al = self.one - rk * rk
                else:
                    al = self.amin
                if self.relax is not None:
                    if isinstance(al, int):
                        lim = ar.store((self.one << fr("c")) - (self.one - self.c[0]) * self.relax,
                                       fr("c"), "c")
                    else:
                        lim = self.one - (self.one - self.c[0]) * self.relax
                    al = max(al, lim)
                al = min(max(al, self.amin), self.amax)
                v = self.one - al
                rr = ar.sqrt(v << fr("c") if isinstance(v, int) else v, "c")
                d = self.one - rr
                self.c[0] = al
                self.c[1] = ar.store(d * d + d * d, fr("c"), "c")
        a = fr("c") + fr("e")
        self.x = [ar.store(ar.align(xp[i], a - fr("x")) + self.c[i] * e, a - fr("x"), "x")
                  for i in range(n)]


def ukf_step_f32(x, P, z, F, H, Q, R, wm, wc, c):
    """One additive-noise UKF step (sigma points redrawn for h) on a linear model, numpy
    float32 scalars in the kernel's order (lists in, lists out)."""
    n, m = len(x), len(H)
    z0 = np.float32(0)

    def chol(A):
        k = len(A)
        L = [[z0] * k for _ in range(k)]
        for j in range(k):
            acc = A[j][j]
            for l in range(j):
                acc -= L[j][l] * L[j][l]
            L[j][j] = np.sqrt(acc)
            for i in range(j + 1, k):
                acc = A[i][j]
                for l in range(j):
                    acc -= L[i][l] * L[j][l]
                L[i][j] = acc / L[j][j]
        return L

    def points(mean, cov):
        L = chol([[c * cov[i][j] for j in range(n)] for i in range(n)])
        X = [list(mean)]
        X += [[mean[j] + L[j][i] for j in range(n)] for i in range(n)]
        X += [[mean[j] - L[j][i] for j in range(n)] for i in range(n)]
        return X

    def lin(M, v, noise):
        out = []
        for i in range(len(M)):
            acc = noise
            for j in range(len(v)):
                acc += M[i][j] * v[j]
            out.append(acc)
        return out

    ns = 2 * n + 1
    Xf = [lin(F, s, z0) for s in points(x, P)]
    xm = []
    for i in range(n):
        acc = z0
        for s in range(ns):
            acc += wm[s] * Xf[s][i]
        xm.append(acc)
    Pp = [[None] * n for _ in range(n)]
    for i in range(n):
        for j in range(i, n):
            acc = z0
            for s in range(ns):
                acc += wc[s] * (Xf[s][i] - xm[i]) * (Xf[s][j] - xm[j])
            Pp[i][j] = Pp[j][i] = acc + Q[i][j]
    Xf = points(xm, Pp)
    Zs = [lin(H, s, z0) for s in Xf]
    zp = []
    for r in range(m):
        acc = z0
        for s in range(ns):
            acc += wm[s] * Zs[s][r]
        zp.append(acc)
    S = [[None] * m for _ in range(m)]
    for r in range(m):
        for q in range(r, m):
            acc = z0
            for s in range(ns):
                acc += wc[s] * (Zs[s][r] - zp[r]) * (Zs[s][q] - zp[q])
            S[r][q] = S[q][r] = acc + R[r][q]
    Pxz = [[None] * m for _ in range(n)]
    for i in range(n):
        for r in range(m):
            acc = z0
            for s in range(ns):
                acc += wc[s] * (Xf[s][i] - xm[i]) * (Zs[s][r] - zp[r])
            Pxz[i][r] = acc
    Ls = chol(S)
    W = [[None] * n for _ in range(m)]
    for r in range(m):
        for j in range(n):
            acc = Pxz[j][r]
            for l in range(r):
                acc -= Ls[r][l] * W[l][j]
            W[r][j] = acc / Ls[r][r]
    K = [[None] * m for _ in range(n)]
    for r in range(m - 1, -1, -1):
        for j in range(n):
            acc = W[r][j]
            for l in range(r + 1, m):
                acc -= Ls[l][r] * K[j][l]
            K[j][r] = acc / Ls[r][r]
    xn = []
    for i in range(n):
        acc = xm[i]
        for r in range(m):
            acc += K[i][r] * (z[r] - zp[r])
        xn.append(acc)
    Pn = [[None] * n for _ in range(n)]
    for i in range(n):
        for j in range(i, n):
            acc = Pp[i][j]
            for r in range(m):
                acc -= W[r][i] * W[r][j]
            Pn[i][j] = Pn[j][i] = acc
    return xn, Pn


def ukf_step_int(A, x, P, z, model_f, model_h, Qq, Rq, Lq, Lr, wm, wc, c, pfloor, n, m, aug, redraw,
                 events):
    """One fixed-point UKF step with Python integers (:class:`IntArith` ``A`` of a
    ``UkfFormats`` table), in the kernel's order. ``model_f(x, w) / model_h(x, v)`` return
    lists of integers (in X / Y), ``z`` is the quantised measurement or None (predict only).
    Lists in, lists out; ``events`` counts chol_fail / s_not_pd."""
    fr = A.fr
    L = n + (n + m if aug else 0)
    ns = 2 * L + 1

    def chol(S_, fS, fL, sig):
        k = len(S_)
        Lm = [[0] * k for _ in range(k)]
        a = 2 * fr(fL) - fr(fS)
        for j in range(k):
            acc = S_[j][j] << a
            for l in range(j):
                acc -= Lm[j][l] * Lm[j][l]
            if not acc > 0:
                return None
            Lm[j][j] = A.sqrt(acc, sig)
            for i in range(j + 1, k):
                acc = S_[i][j] << a
                for l in range(j):
                    acc -= Lm[i][l] * Lm[j][l]
                Lm[i][j] = A.div(acc, Lm[j][j], sig)
        return Lm

    def factor(M, fM, floor):
        Pa = [[A.store(c * M[i][j], fr("W") + fr(fM) - fr("Pc"), "Pc") for j in range(n)] for i in range(n)]
        Ln = chol(Pa, "Pc", "U", "U")
        if Ln is None:
            events["chol_fail"] += 1
            d = [M[i][i] if M[i][i] > floor else floor for i in range(n)]
            if fM == "P":
                for i in range(n):
                    for j in range(n):
                        M[i][j] = 0
                    M[i][i] = d[i]
            Pa = [[A.store(c * (d[i] if i == j else 0), fr("W") + fr(fM) - fr("Pc"), "Pc") for j in range(n)]
                  for i in range(n)]
            Ln = chol(Pa, "Pc", "U", "U")
        return Ln

    def devs(pts, mean, fp, fmn):
        a = max(fr(fp), fr(fmn))
        D = [[A.store((pts[s][i] << (a - fr(fp))) - (mean[i] << (a - fr(fmn))), a - fr("D"), "D")
              for i in range(len(mean))] for s in range(ns)]
        Dw = [[A.store(wc[s] * D[s][i], fr("W"), "D") for i in range(len(mean))] for s in range(ns)]
        return D, Dw

    Ln = factor(P, "P", pfloor[0])
    La = [[0] * L for _ in range(L)]
    for i in range(n):
        for j in range(i + 1):
            La[i][j] = Ln[i][j]
    if aug:
        for i in range(n):
            for j in range(n):
                La[n + i][n + j] = Lq[i][j]
        for i in range(m):
            for j in range(m):
                La[2 * n + i][2 * n + j] = Lr[i][j]
    aX = max(fr("x"), fr("U"))
    X = [[x[j] if j < n else 0 for j in range(L)]] + [[0] * L for _ in range(2 * L)]
    for i in range(L):
        for j in range(L):
            if j < n:
                base, u = x[j] << (aX - fr("x")), La[j][i] << (aX - fr("U"))
                X[1 + i][j] = A.store(base + u, aX - fr("X"), "X")
                X[1 + L + i][j] = A.store(base - u, aX - fr("X"), "X")
            else:
                u = A.store(La[j][i] << (aX - fr("U")), aX - fr("X"), "X")
                X[1 + i][j], X[1 + L + i][j] = u, -u
    Xf = [[A.store(v, 0, "X") for v in model_f(X[s][:n], X[s][n:2 * n] if aug else [0] * n)] for s in range(ns)]
    xm = [A.store(sum(wm[s] * Xf[s][i] for s in range(ns)), fr("W") + fr("X") - fr("xm"), "xm") for i in range(n)]
    Dx, Dwx = devs(Xf, xm, "X", "xm")
    Pp = [[0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i, n):
            acc = 0
            for s in range(ns):
                acc += Dwx[s][i] * Dx[s][j]
            if not aug:
                acc += Qq[i][j] << (2 * fr("D") - fr("Pp"))
            Pp[i][j] = Pp[j][i] = A.store(acc, 2 * fr("D") - fr("Pp"), "Pp")
    if redraw and not aug:
        Ln = factor(Pp, "Pp", pfloor[1])
        aR = max(fr("xm"), fr("U"))
        Xf = [[A.store(xm[j] << (aR - fr("xm")), aR - fr("X"), "X") for j in range(n)]]
        Xf += [[A.store((xm[j] << (aR - fr("xm"))) + ((Ln[j][i] if i <= j else 0) << (aR - fr("U"))), aR - fr("X"), "X")
                for j in range(n)] for i in range(n)]
        Xf += [[A.store((xm[j] << (aR - fr("xm"))) - ((Ln[j][i] if i <= j else 0) << (aR - fr("U"))), aR - fr("X"), "X")
                for j in range(n)] for i in range(n)]
        Dx, Dwx = devs(Xf, xm, "X", "xm")
    aS = max(fr("x"), fr("xm"))
    if z is None:
        events["implausible"] += 1
        return ([A.store(v << (aS - fr("xm")), aS - fr("x"), "x") for v in xm],
                [[A.store(v << (max(fr("P"), fr("Pp")) - fr("Pp")), max(fr("P"), fr("Pp")) - fr("P"), "P") for v in row]
                 for row in Pp])
    Zs = [[A.store(v, 0, "Y") for v in model_h(Xf[s], X[s][2 * n:] if aug else [0] * m)] for s in range(ns)]
    zp = [A.store(sum(wm[s] * Zs[s][r] for s in range(ns)), fr("W"), "Y") for r in range(m)]
    Dz = [[A.store(Zs[s][r] - zp[r], fr("Y") - fr("D"), "D") for r in range(m)] for s in range(ns)]
    Dwz = [[A.store(wc[s] * Dz[s][r], fr("W"), "D") for r in range(m)] for s in range(ns)]
    S = [[0] * m for _ in range(m)]
    for r in range(m):
        for q in range(r, m):
            acc = 0
            for s in range(ns):
                acc += Dwz[s][r] * Dz[s][q]
            if not aug:
                acc += Rq[r][q] << (2 * fr("D") - fr("Pyy"))
            S[r][q] = S[q][r] = A.store(acc, 2 * fr("D") - fr("Pyy"), "Pyy")
    Pxz = [[0] * m for _ in range(n)]
    for i in range(n):
        for r in range(m):
            acc = 0
            for s in range(ns):
                acc += Dwx[s][i] * Dz[s][r]
            Pxz[i][r] = A.store(acc, 2 * fr("D") - fr("Pxy"), "Pxy")
    Ls = chol(S, "Pyy", "Ls", "Ls")
    if Ls is None:
        events["s_not_pd"] += 1
        return ([A.store(v << (aS - fr("xm")), aS - fr("x"), "x") for v in xm],
                [[A.store(v << (max(fr("P"), fr("Pp")) - fr("Pp")), max(fr("P"), fr("Pp")) - fr("P"), "P") for v in row]
                 for row in Pp])
    W = [[0] * n for _ in range(m)]
    a = fr("Ls") + fr("V") - fr("Pxy")
    for r in range(m):
        for j in range(n):
            acc = Pxz[j][r] << a
            for l in range(r):
                acc -= Ls[r][l] * W[l][j]
            W[r][j] = A.div(acc, Ls[r][r], "V")
    K = [[0] * m for _ in range(n)]
    a = fr("Ls") + fr("K") - fr("V")
    for r in range(m - 1, -1, -1):
        for j in range(n):
            acc = W[r][j] << a
            for l in range(r + 1, m):
                acc -= Ls[l][r] * K[j][l]
            K[j][r] = A.div(acc, Ls[r][r], "K")
    aZ = max(fr("Y"), fr("z"))
    e = [A.store((z[r] << (aZ - fr("z"))) - (zp[r] << (aZ - fr("Y"))), aZ - fr("e"), "e") for r in range(m)]
    a = fr("K") + fr("e")
    xn = [A.store((xm[i] << (a - fr("xm"))) + sum(K[i][r] * e[r] for r in range(m)), a - fr("x"), "x")
          for i in range(n)]
    a = 2 * fr("V")
    Pn = [[0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i, n):
            acc = Pp[i][j] << (a - fr("Pp"))
            for r in range(m):
                acc -= W[r][i] * W[r][j]
            Pn[i][j] = Pn[j][i] = A.store(acc, a - fr("P"), "P")
    return xn, Pn


def rnd_int(acc, s, half):
    """The model operator ``rs`` on Python integers."""
    if s > 0:
        return (acc + (1 << (s - 1))) >> s if half else acc >> s
    return acc << (-s)


def trig_int(fn, v, fin, fout, half):
    """``sin_q`` / ``cos_q`` on Python integers (one rounding of the float64 libm value)."""
    t = fn(float(v) * 2.0 ** -fin) * 2.0 ** fout
    return math.floor(t + 0.5) if half else math.floor(t)

"""Helpers shared by the pulse-peak search tests (``test_peak_*.py``; imported as
``_peak_util``, this folder being on ``sys.path``, see ``conftest.py``): stimulus envelopes,
the per-sample reference loops, running the Amaranth simulation against the model, and the
parameter sets several files use."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from cosim.backends.pysim import run_stream, unpack_fields
from dsp.tacan.peak_params import PeakParams
from hdl.tacan.peak_model import peak_search
from hdl.tacan.peak import PeakSearch


def realistic_envelope(rng, n, *, noise=200.0, width=10.0, min_gap=21, max_gap=150,
                       amp_range=(2.0, 20.0), amp_width=19, pair_offset=0, single=0.0):
    """Rayleigh noise (mean ``noise``) plus Gaussian pulses (FWHM ``width`` samples) at
    random spacing > 20 samples with amplitudes 2..20 times the noise mean.

    ``pair_offset = D``: each pulse gets a partner ``D`` samples later (its own random
    amplitude, so either pulse of a pair may be the larger), except a fraction ``single``
    of them, left alone."""
    mean_to_sigma = 1.0 / np.sqrt(np.pi / 2)
    e = rng.rayleigh(noise * mean_to_sigma, n)
    centres = np.cumsum(rng.integers(min_gap, max_gap, n // min_gap + 1))
    centres = centres[centres < n]
    amps = rng.uniform(*amp_range, centres.size) * noise
    if pair_offset:
        paired = rng.random(centres.size) >= single
        second = centres[paired] + pair_offset
        centres = np.concatenate((centres, second))
        amps = np.concatenate((amps, rng.uniform(*amp_range, second.size) * noise))
    sigma = width / (2 * np.sqrt(2 * np.log(2)))
    k = np.arange(-4 * int(sigma + 1), 4 * int(sigma + 1) + 1)
    shape = np.exp(-0.5 * (k / sigma) ** 2)
    for c, a in zip(centres, amps):
        idx = c + k
        ok = (idx >= 0) & (idx < n)
        e[idx[ok]] += a * shape[ok]
    return np.minimum(np.round(e), (1 << amp_width) - 1).astype(np.int64)


def reference_loop(e, p, *, is_float=False, thr_min=None):
    """Straight per-sample transcription of the algorithm (independent of the model)."""
    L = p.block_len
    out = []
    nu, bsum = 0, 0
    F = 0                 # floor_frac: the floor with smooth_log2 fraction bits
    is_open, pmax, nmax, below, length = False, 0, 0, 0, 0
    tm = p.thr_min if thr_min is None else thr_min
    for n, x in enumerate(e):
        x = float(x) if is_float else int(x)
        b = n // L
        if b == 0:
            T = float("inf")
            bsum += x
        elif is_float:
            T = max(tm, nu * p.thr_mult / 2 ** p.thr_frac)
            clip = nu * 2 ** p.clip_log2
            bsum += x if x <= clip else (nu if p.clip_to_floor else clip)
        else:
            T = max(p.thr_min, (nu * p.thr_mult) >> p.thr_frac)
            clip = nu << p.clip_log2
            bsum += x if x <= clip else (nu if p.clip_to_floor else clip)
        if (n + 1) % L == 0:
            if is_float:
                m = bsum / L
                nu = m if b == 0 else nu + (m - nu) / 2 ** p.smooth_log2
            else:
                m = bsum >> p.block_log2
                if p.floor_frac:
                    F = m * 2 ** p.smooth_log2 if b == 0 else F - F // 2 ** p.smooth_log2 + m
                    nu = F // 2 ** p.smooth_log2
                else:
                    nu = m if b == 0 else nu + ((m - nu) >> p.smooth_log2)
            bsum = 0
        if not is_open:
            if x >= T:
                is_open, pmax, nmax, below, length = True, x, n, 0, 1
        else:
            if x > pmax:
                pmax, nmax = x, n
            below = 0 if x >= T else below + 1
            length += 1
            if below == p.hold or length == p.max_len:
                out.append((pmax, nmax, n))
                is_open = False
    return out


def as_tuples(r):
    return list(zip(r.amplitude.tolist(), r.index.tolist(), r.end_index.tolist()))


def run_sim(p, e, in_valid=None, dut=None, **kw):
    res = run_stream(dut if dut is not None else PeakSearch(p), e, in_valid=in_valid,
                     flush_cycles=p.latency + 2, **kw)
    f = unpack_fields(res.words, p.out_layout)
    return res, f["amplitude"], f["timestamp"]


def check_sim(p, e, in_valid=None, idle_payload=None):
    """Simulation == model (:func:`peak_search`), the output cycles included. ``idle_payload``:
    the input payload on the cycles of ``in_valid`` that offer nothing (default: the last
    word offered stays)."""
    dut = PeakSearch(p)
    writes = None
    if idle_payload is not None:
        writes = [(int(c), dut.i.payload, idle_payload)
                  for c in np.flatnonzero(~np.asarray(in_valid, bool))]
    res = run_stream(dut, e, in_valid=in_valid, flush_cycles=p.latency + 2, writes=writes)
    f = unpack_fields(res.words, p.out_layout)
    ref, _ = peak_search(e, p)
    np.testing.assert_array_equal(f["amplitude"], ref.amplitude)
    np.testing.assert_array_equal(f["timestamp"], ref.timestamp)
    if p.partner_offset:
        np.testing.assert_array_equal(f["partner"], ref.partner)
        np.testing.assert_array_equal(f["partner_late"], ref.partner_late)
    # Emitted params.latency cycles after the input transfer of the closing sample (of the
    # sample emit_delay later with the pair-partner readout or the pair detection).
    in_cycles = np.arange(e.size) if in_valid is None else np.flatnonzero(in_valid)[:e.size]
    np.testing.assert_array_equal(res.cycles,
                                  in_cycles[ref.end_index + p.emit_delay] + p.latency)
    return ref


SMALL = PeakParams(block_log2=5, hold=3, max_len=24)


def pair_sum(e, D):
    """``s[n] = e[n] + e[n - D]`` (``e`` = 0 before the first sample)."""
    e = np.asarray(e)
    return e + np.concatenate((np.zeros(D, e.dtype), e))[:e.size]


def pair_envelope(rng, n, D, **kw):
    """:func:`realistic_envelope` with pulse pairs ``D`` apart (a quarter of them single
    pulses), spaced so that most pairs stand apart and some overlap; a carrier (max_len
    cuts) and a stretch at the top of the input range."""
    aw = kw.pop("amp_width", 19)
    e = realistic_envelope(rng, n, pair_offset=D, single=0.25, min_gap=21 + D,
                           max_gap=150 + 2 * D, amp_width=aw, **kw)
    e[n // 3:n // 3 + 500] = min(4000, (1 << aw) - 1)
    e[n // 2:n // 2 + 50] = (1 << aw) - 1
    return e


#: TACAN X mode at 5 MHz envelope samples (12 us = 60 samples), the censored floor.
TACAN_X_PAIR = PeakParams(pair_offset=60, clip_to_floor=True, smooth_log2=10, thr_mult=46)


#: D = 60 (12 us at 5 MHz), the pair checks on; a noise-free floor of 100.
PAIR_CHECKED = PeakParams(block_log2=8, hold=5, max_len=128, clip_to_floor=True, pair_offset=60,
                          pair_balance=4, pair_spread=8)


def checked_envelope(rng, n, D, other=None, width=10.0, **kw):
    """:func:`pair_envelope` (pairs ``D`` apart, a quarter single pulses) with, at the
    sample-wise max, a sparser stream of pairs ``other`` apart (default ``1.25 D``: the 15-us
    pairs of the other TACAN mode at ``D`` = 12 us), a third of them single pulses; pulses
    ``width`` samples at half amplitude (TACAN at 5 MHz: 19)."""
    other = other or int(round(1.25 * D))
    e = pair_envelope(rng, n, D, width=width, **kw)
    e2 = realistic_envelope(rng, n, pair_offset=other, single=0.33, min_gap=60 + other,
                            max_gap=300 + 3 * other, amp_width=kw.get("amp_width", 19),
                            width=width)
    return np.maximum(e, e2)


def assert_checks_bite(p, e):
    """Each check on in ``p`` drops some of the peaks the side-lobe rule keeps and keeps
    others (so the tests below can fail)."""
    plain, _ = peak_search(e, replace(p, pair_balance=0, pair_spread=0))
    got, _ = peak_search(e, p)
    for name in ("pair_balance", "pair_spread"):
        if getattr(p, name):
            only = replace(p, **{"pair_balance": 0, "pair_spread": 0, name: getattr(p, name)})
            r, _ = peak_search(e, only)
            assert 5 <= r.index.size <= plain.index.size - 2, (name, r.index.size,
                                                                plain.index.size)
    assert got.index.size >= 5
    return got

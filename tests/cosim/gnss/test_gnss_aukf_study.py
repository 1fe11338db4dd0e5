"""AUKF patent acceptance A2/A4 on the fast path (cosim.gnss.study_aukf): >= 100 Monte Carlo
runs slow-marked, plus a short unmarked form."""
import functools

import numpy as np
import pytest

from cosim.gnss.study_aukf import Q0, run_point


def test_q_hat_moves_towards_q_true_short():
    """Short form: 16 runs x 3 s at 32 dB-Hz: the median q_hat leaves q0 towards the truth
    (below 0.7 q0 for 0.1 q0 -- measured 2.79 --, above 2 q0 for 10 q0); no divergence."""
    lo = run_point(0.1 * Q0, 32.0, trackers=("aukf",), n_runs=16, duration_s=3.0, seed=3)["aukf"]
    hi = run_point(10 * Q0, 32.0, trackers=("aukf",), n_runs=16, duration_s=3.0, seed=3)["aukf"]
    assert lo["q_hat_median_final"] < 0.7 * Q0, lo["q_hat_median_final"]
    assert hi["q_hat_median_final"] > 2 * Q0, hi["q_hat_median_final"]
    assert lo["diverged"] == 0 and hi["diverged"] == 0


@functools.lru_cache(maxsize=None)
def _point(factor, duration_s=10.0):
    """100 runs at 32 dB-Hz, seed 1, aukf and ukf on the same truths; A4 is judged on 60 s
    runs (docs/explanation/gnss_aukf.md, results/aukf_convergence.md), A2/A3 on 10 s and 60 s."""
    return run_point(factor * Q0, 32.0, trackers=("aukf", "ukf"), n_runs=100,
                     duration_s=duration_s, seed=1)


@pytest.mark.slow
@pytest.mark.parametrize("factor", [10.0, 0.1])
def test_a2_100_runs(factor):
    """A2: AUKF Doppler RMSE < fixed-q UKF's (100 runs x 10 s, 32 dB-Hz, seed 1).
    Measured (results/aukf.md): 10 q0 0.0742 vs 0.0960 Hz; 0.1 q0 0.0333 vs 0.0372 Hz."""
    p = _point(factor)
    a, u = p["aukf"], p["ukf"]
    assert a["doppler_rmse_hz"] < u["doppler_rmse_hz"], (a["doppler_rmse_hz"], u["doppler_rmse_hz"])
    assert a["diverged"] == 0 and u["diverged"] == 0


@pytest.mark.slow
@pytest.mark.parametrize("factor", [0.1, 1.0, 10.0])
def test_a4_100_runs(factor):
    """A4: median final q_hat within x2 of q_true at the end of a 60 s run (100 runs,
    32 dB-Hz); A2/A3 hold on the same runs. Measured: 0.1 q0 0.500 (truth 0.5), q0 4.51,
    10 q0 47.6. After 10 s the 0.1 q0 median is still 1.55 (x3.1: the slave's information
    on ln q accrues at ~0.065 nats^2 per block against the prior's 1)."""
    p = _point(factor, 60.0)
    q = p["aukf"]["q_hat_median_final"]
    assert factor * Q0 / 2 <= q <= 2 * factor * Q0, q
    a, u = p["aukf"]["doppler_rmse_hz"], p["ukf"]["doppler_rmse_hz"]
    assert (a <= 1.1 * u) if factor == 1.0 else (a < u), (a, u)
    assert p["aukf"]["diverged"] == 0 and p["aukf"]["cycle_slips"] == 0


@pytest.mark.slow
def test_a3_100_runs():
    """A3: q_true = q0: AUKF Doppler RMSE <= 1.1 x the UKF's (measured 0.0466 vs 0.0456 Hz)."""
    p = _point(1.0)
    a, u = p["aukf"]["doppler_rmse_hz"], p["ukf"]["doppler_rmse_hz"]
    assert a <= 1.1 * u, (a, u)

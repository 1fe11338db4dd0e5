"""The default frequency plan has one home (hdl.gnss.params.DEFAULT_FS_HZ) and no code-loop
dead zone; a rate commensurate with the chip rate is warned about in one line."""
from fractions import Fraction

import numpy as np
import pytest

from cosim.gnss.config import CODE_DEAD_ZONE_WARN_M, frequency_plan_warning
from cosim.gnss.signal import GnssSignalConfig
from hdl.gnss.params import DEFAULT_FS_HZ, DEFAULT_IF_HZ, GnssChannelParams, code_phase_step_chips


def test_defaults_come_from_one_home():
    assert GnssSignalConfig().fs_hz == GnssChannelParams().fs_hz == DEFAULT_FS_HZ == 16.384e6
    assert GnssSignalConfig().if_hz == GnssChannelParams().if_hz == DEFAULT_IF_HZ
    p = GnssChannelParams()
    # 16384 samples per code period; the nominal chip rate's code NCO word is exact
    assert DEFAULT_FS_HZ * 1e-3 == 16384
    assert Fraction(p.code_word()) * Fraction(DEFAULT_FS_HZ) / 2 ** 32 == 1_023_000


@pytest.mark.parametrize("fs_hz, p", [(16.368e6, 16), (8.184e6, 8), (40.92e6, 40),
                                      (38.192e6, 112), (16.384e6, 16384), (20e6, 20000),
                                      (12e6, 4000), (5e6, 5000)])
def test_code_phase_step_is_one_over_the_reduced_numerator(fs_hz, p):
    assert code_phase_step_chips(fs_hz) == 1 / p


def test_commensurate_rate_is_warned_in_one_line():
    msg = frequency_plan_warning(16.368e6)
    assert msg == ("--fs-hz 16.368 MS/s = 16 x 1.023 MHz puts the samples at only 16 offsets "
                   "within a chip: without code Doppler the code loop has a dead zone of 1/16 "
                   "chip (18.3 m); a rate incommensurate with the chip rate, such as the "
                   "default 16.384 MS/s (1/16384 chip), has none")
    assert "\n" not in msg
    assert "112/3 x 1.023 MHz" in frequency_plan_warning(38.192e6)     # 2.6 m
    for fs in (DEFAULT_FS_HZ, 5e6, 12e6, 20e6, 26e6):
        assert frequency_plan_warning(fs) is None
    assert code_phase_step_chips(38.192e6) * 299_792_458 / 1.023e6 > CODE_DEAD_ZONE_WARN_M


def test_gnss_command_warns_before_work(capsys):
    import argparse
    from cosim.core.receivers import add_options
    from cosim.gnss.receiver import OPTIONS, build_configs
    p = argparse.ArgumentParser()
    add_options(p, OPTIONS)
    sig, _ = build_configs(p.parse_args(["--fs-hz", "16.368e6"]))
    assert sig.fs_hz == 16.368e6
    err = capsys.readouterr().err
    assert err.startswith("warning: --fs-hz 16.368 MS/s = 16 x 1.023 MHz") and err.count("\n") == 1
    build_configs(p.parse_args([]))
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_static_code_tracking_dead_zone_only_at_the_commensurate_rate():
    """The whole chain (acquisition, hand-over, golden correlators, fixed-point pll3 with its
    1 Hz DLL) on a static signal 0.37 chip into a chip: at 16.368 MS/s the code loop keeps
    the acquisition's sample-grid error (more than a quarter of the 1/16-chip step) and the
    dead-zone rule fails; at the default rate it settles on the true phase and the rule
    passes. The benchmark's verdict and section follow the figures."""
    import copy
    from cosim.gnss.bench import _dead_zone_markdown, code_dead_zone, dead_zone_verdict
    dz = code_dead_zone(offsets_chips=(0.37,), runs_per_offset=1, duration_s=4.5,
                        settle_s=0.5, backend="golden")
    d, c = dz["rates"]
    assert (d["fs_hz"], c["fs_hz"]) == (DEFAULT_FS_HZ, 16.368e6)
    assert d["max_abs_bias_chips"] < d["dll_sigma_chips"] < c["step_chips"] / 4 \
        < c["max_abs_bias_chips"]
    assert d["passes"] and not c["passes"]
    assert dead_zone_verdict(dz) == {"code_bias_default_rate_within_se": True,
                                     "code_bias_commensurate_rate_caught": True}
    bad = copy.deepcopy(dz)
    bad["rates"][0]["pooled_bias_chips"] = 3.01 * d["se_pooled_chips"]
    assert dead_zone_verdict(bad)["code_bias_default_rate_within_se"] is False
    md = "\n".join(_dead_zone_markdown(dz))
    assert "| 16.384 | 16.0156 | 1/16384 |" in md and "| 16.368 | 16.0000 | 1/16 |" in md
    assert "| passes |" in md and "| fails |" in md


def _ar1(a: float, m: int, s: int, seed: int):
    """(m, s) series of the AR(1) ``x_k = a x_(k-1) + w_k``, started in steady state."""
    from scipy.signal import lfilter
    rng = np.random.default_rng(seed)
    w = rng.standard_normal((m, s))
    w[0] /= np.sqrt(1 - a * a)
    return lfilter([1.0], [1.0, -a], w, axis=0)


def test_a_loop_errors_standard_error_accounts_for_its_correlation():
    """A first-order loop's error (AR(1), correlation ~0.3 s at 1 ms epochs like the 1 Hz
    DLL's): the standard error of a 6 s window's mean, estimated from the series without
    trusting their means to be 0, is the spread of the means (400 windows), the correlation
    time and independent epochs are the AR(1)'s; the naive sigma / sqrt(M) is 4x too small.
    A random walk (no restoring force) does not average out: no standard error."""
    from cosim.gnss.bench import loop_mean_standard_error
    a, m = 1 - 1 / 300, 6000
    x = _ar1(a, m, 2400, seed=7)
    means = x.mean(axis=0)
    est = [loop_mean_standard_error(x[:, k:k + 6], 1e-3) for k in range(0, 2400, 6)]
    se = np.mean([e["se_run_chips"] for e in est])
    assert abs(se / means.std() - 1) < 0.1
    assert abs(np.mean([e["n_eff"] for e in est]) / (m * (1 - a) / (1 + a)) - 1) < 0.15
    assert abs(np.mean([e["correlation_time_s"] for e in est]) / 0.2995 - 1) < 0.15
    assert means.std() > 4 * x.std() / np.sqrt(m)
    # the pooled mean of 6 runs within 3 of its standard errors: as often as a normal's
    z = np.array([abs(x[:, k:k + 6].mean()) / e["se_pooled_chips"]
                  for k, e in zip(range(0, 2400, 6), est)])
    assert np.mean(z > 3) < 0.02
    walk = np.cumsum(np.random.default_rng(1).standard_normal((4000, 2)), axis=0)
    assert loop_mean_standard_error(walk, 1e-3)["se_run_chips"] is None


def _rate(fs, biases, se_run):
    return {"fs_hz": fs, "pooled_bias_chips": float(np.mean(biases)),
            "max_abs_bias_chips": float(np.max(np.abs(biases))), "se_run_chips": se_run,
            "se_pooled_chips": None if se_run is None else se_run / np.sqrt(len(biases))}


@pytest.mark.parametrize("biases, se_run, passes", [
    ([0.001, -0.001, 0.0005, 0.0, 0.0002, -0.0003], 0.001, True),
    ([0.0012] * 6, 0.001, True),            # 2.94 pooled SE: within 3
    ([0.00125] * 6, 0.001, False),          # 3.06 pooled SE: a bias common to the runs
    ([0.0039, -0.0039, 0.0, 0.0, 0.0, 0.0], 0.001, True),
    ([0.0041, -0.0041, 0.0, 0.0, 0.0, 0.0], 0.001, False),  # one run beyond 4 of its SE
    ([0.0, 0.0], None, False),              # no standard error: does not average out
])
def test_the_dead_zone_rule(biases, se_run, passes):
    from cosim.gnss.bench import COMMENSURATE_FS_HZ, dead_zone_rule, dead_zone_verdict
    r = _rate(DEFAULT_FS_HZ, biases, se_run)
    assert dead_zone_rule(r) is passes
    caught = _rate(COMMENSURATE_FS_HZ, [0.038, 0.021, 0.016, 0.016, 0.006, 0.008], 0.001)
    missed = _rate(COMMENSURATE_FS_HZ, [0.0] * 6, 0.001)
    assert dead_zone_verdict({"rates": [r, caught]}) == {
        "code_bias_default_rate_within_se": passes, "code_bias_commensurate_rate_caught": True}
    assert dead_zone_verdict({"rates": [r, missed]})["code_bias_commensurate_rate_caught"] \
        is False
    assert dead_zone_verdict({"rates": []}) == {"code_bias_default_rate_within_se": False,
                                                "code_bias_commensurate_rate_caught": False}

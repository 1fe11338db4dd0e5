"""The default frequency plan has one home (hdl.gnss.params.DEFAULT_FS_HZ) and no code-loop
dead zone; a rate commensurate with the chip rate is warned about in one line."""
from fractions import Fraction

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
    the acquisition's sample-grid error (more than a quarter of the 1/16-chip step); at the
    default rate it settles on the true phase (its mean error within the DLL's thermal
    noise). The benchmark's verdict and section follow the figures."""
    import copy
    from cosim.gnss.bench import _dead_zone_markdown, code_dead_zone, dead_zone_verdict
    dz = code_dead_zone(offsets_chips=(0.37,), seeds=(1,), duration_s=0.8, settle_s=0.5,
                        backend="golden")
    d, c = dz["rates"]
    assert (d["fs_hz"], c["fs_hz"]) == (DEFAULT_FS_HZ, 16.368e6)
    assert d["max_abs_bias_chips"] < d["dll_sigma_chips"] < c["step_chips"] / 4 \
        < c["max_abs_bias_chips"]
    assert d["max_chips"] < 2 * d["dll_sigma_chips"] < c["max_chips"]
    assert dead_zone_verdict(dz) == {"code_bias_default_rate_within_dll_noise": True}
    bad = copy.deepcopy(dz)
    bad["rates"][0]["max_abs_bias_chips"] = 1.01 * d["dll_sigma_chips"]
    assert dead_zone_verdict(bad) == {"code_bias_default_rate_within_dll_noise": False}
    md = "\n".join(_dead_zone_markdown(dz))
    assert "| 16.384 | 16.0156 | 1/16384 |" in md and "| 16.368 | 16.0000 | 1/16 |" in md

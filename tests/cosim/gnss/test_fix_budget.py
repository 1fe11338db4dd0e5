"""A generated static run against its thermal-noise error budget (cosim.gnss.fix_budget,
the gps-fix benchmark): the refusals (fast) and a short hot start through the bit-exact
array whose pseudorange and range-rate noise must be the budget's within 20 % and its
position and velocity RMS within their statistical spread of it (slow)."""
import argparse
import json

import pytest

from cosim.gnss.fix_bench import gps_fix
from cosim.gnss.fix_budget import fix_budget, loops_of
from cosim.gnss.gps_receiver import GpsRun
from dsp.gnss.budget import TrackingLoops
from hdl.gnss.params import GnssChannelParams


def test_the_budget_needs_fixes_and_a_pll_tracker():
    with pytest.raises(ValueError, match="0 fixes"):
        fix_budget(GpsRun([], [], 5e6, "cold", None, None), {}, TrackingLoops())
    p = GnssChannelParams(fs_hz=5e6, if_hz=1.25e6, el_spacing_samples=2)
    with pytest.raises(ValueError, match="--tracker aukf"):
        loops_of(argparse.Namespace(tracker="aukf", bn_hz=15.0), p)
    lo = loops_of(argparse.Namespace(tracker="pll3", bn_hz=15.0), p)
    assert (lo.order, lo.bn_hz, lo.dll_bn_hz, lo.latency) == (3, 15.0, 1.0, 1)
    assert lo.spacing_chips == pytest.approx(2 * 1.023e6 / 5e6)


@pytest.mark.slow
def test_short_hot_start_meets_its_budget(tmp_path):
    """20 s hot start (fixes from ~8 s on) at 45 dB-Hz through the bit-exact array model with
    the fixed-point pll3 trackers. The pooled per-satellite pseudorange and range-rate noise
    (~90 samples, ~7 % spread) within 20 % of the loops' formulas; the 3-D position and
    velocity RMS of ~12 fixes (~15 % spread) within three of their own spreads of the
    budget."""
    r = gps_fix(tmp_path, quick=True, work=tmp_path / "run")
    assert len(r["scenario"]["acquired"]) >= 8 and len(r["satellites_used"]) >= 8
    assert r["fixes"] >= 10
    assert json.loads((tmp_path / "gps_fix_quick.json").read_text())["fixes"] == r["fixes"]
    assert r["pooled_ratio_sigma"] < 0.08
    assert abs(r["pseudorange_ratio_pooled"] - 1) < 0.2, r["satellites"]
    assert abs(r["range_rate_ratio_pooled"] - 1) < 0.2, r["satellites"]
    for k in ("position", "velocity"):
        assert abs(r[k]["ratio"] - 1) < 3 * r[k]["ratio_sigma"], r[k]

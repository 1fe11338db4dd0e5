"""``python -m cosim bench gnss-tracking``: the quick form writes its figures and verdicts;
the verdicts come from the figures (they turn False when a figure leaves its tolerance)."""
import copy
import json

import pytest

from cosim.tools.bench import benchmarks
from cosim.gnss.bench import gnss_tracking, tracking_verdicts


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("gnss_tracking")
    return out, gnss_tracking(out, quick=True, dead_zone=False)   # its own test: slow


def test_gnss_tracking_is_registered():
    assert "gnss-tracking" in benchmarks()


def test_gnss_tracking_quick_writes_figures(quick):
    out, r = quick
    assert {"machine", "loop", "config", "jitter", "jerk", "threshold",
            "kaplan_threshold_dbhz", "verdict"} <= r.keys()
    assert {"date", "command", "commit", "cpu"} <= r["machine"].keys()
    assert json.loads((out / "gnss_tracking.json").read_text())["verdict"] == r["verdict"]
    assert (out / "gnss_tracking.md").read_text().startswith("# GNSS carrier tracking")
    assert [j["latency"] for j in r["jitter"]] == [0, 1]
    for j in r["jitter"]:
        assert len(j["ratio_to_actual"]) == len(j["cn0_dbhz"]) == len(j["slipped_trials"])
    for t in r["threshold"]:
        assert t["cn0_dbhz"][0] <= t["threshold_dbhz"] <= t["cn0_dbhz"][-1]
        assert t["hold_fraction"][-1] == 1.0
    assert r["kaplan_threshold_dbhz"] == pytest.approx(28.7, abs=0.05)
    assert r["verdict"] == tracking_verdicts(r["jitter"], r["jerk"])


def test_gnss_tracking_verdicts_follow_the_figures(quick):
    _, r = quick
    jit, jerk = copy.deepcopy(r["jitter"]), copy.deepcopy(r["jerk"])
    base = tracking_verdicts(jit, jerk)
    i = jit[0]["cn0_dbhz"].index(35.0)
    jit[0]["ratio_to_actual"][i] = 1.11                      # 11 % above Kaplan
    jerk[1]["ratio"] = 0.94                                  # 6 % below the theory
    v = tracking_verdicts(jit, jerk)
    assert v == {"jitter_within_10pct_above_35dbhz": False, "jerk_stress_within_5pct": False}
    jit = copy.deepcopy(r["jitter"])
    jit[1]["slipped_trials"][i] = 1                          # a slip fails the jitter run
    assert not tracking_verdicts(jit, r["jerk"])["jitter_within_10pct_above_35dbhz"]
    jit = copy.deepcopy(r["jitter"])
    jit[0]["cn0_dbhz"][i] = 34.0                             # below 35 dB-Hz: not judged
    jit[0]["ratio_to_actual"][i] = 2.0
    assert tracking_verdicts(jit, r["jerk"]) == base

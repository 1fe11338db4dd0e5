"""The tacan-accuracy judge's grid, pooling and checks (cosim.tacan.bench_accuracy), on
records made up here (the records themselves are the benchmark's)."""
import numpy as np
import pytest

from cosim.tacan.bench_accuracy import FULL, AccuracyGrid, checks, pool


def _rec(mode, snr, b, seed, both, pulse, slip=False, misleading=0, locked=True):
    def sc(rmse, mean):
        if not locked:
            return {"locked": False}
        return {"locked": True, "rmse_deg": rmse, "mean_error_deg": mean,
                "max_abs_error_deg": 40.0 if slip else 3 * rmse, "slip": slip, "valid": 10,
                "misleading": misleading, "measured_on": "pairs", "paired_fraction": 0.3}
    return {"mode": mode, "snr_db": snr, "bearing_deg": b, "seed": seed,
            "both": sc(*both), "pulse": sc(*pulse)}


def test_the_full_grid_is_the_issue_s():
    assert FULL.bearings.size == 36 and FULL.snrs_db == (0.0, 3.0, 6.0, 10.0, 20.0)
    assert FULL.modes == ("X", "Y") and FULL.records >= 4 and FULL.variants[0] == "both"
    assert len(FULL.items()) == 36 * 2 * 5 * FULL.records


@pytest.mark.parametrize("bad", [dict(bearing_step_deg=0), dict(modes=("Z",)),
                                 dict(records=0), dict(duration_s=2.0),
                                 dict(variants=("pulse", "both")), dict(snrs_db=())])
def test_a_bad_grid_is_refused(bad):
    with pytest.raises(ValueError):
        AccuracyGrid(**bad)


def test_pooling_and_the_checks():
    g = AccuracyGrid(bearing_step_deg=180, snrs_db=(0.0, 6.0), modes=("X",), records=2,
                     variants=("both", "pulse"))
    recs = [_rec("X", 0.0, b, k, (0.3, 0.1), (1.0, 0.5)) for b in (0.0, 180.0) for k in (0, 1)]
    # at 6 dB the default is worse than the single pulses at 180 deg
    recs += [_rec("X", 6.0, 0.0, k, (0.11, 0.0), (0.11, 0.0)) for k in (0, 1)]
    recs += [_rec("X", 6.0, 180.0, k, (0.3, 0.2), (0.11, 0.0)) for k in (0, 1)]
    rows = pool(recs, g)
    assert [(r["snr_db"], r["detector"]) for r in rows] == [
        (0.0, "both"), (0.0, "pulse"), (6.0, "both"), (6.0, "pulse")]
    r = rows[2]
    assert r["records"] == r["locked"] == 4
    assert r["rmse_deg"] == pytest.approx(np.sqrt((2 * 0.11 ** 2 + 2 * 0.3 ** 2) / 4))
    assert r["rmse_over_crb"] == pytest.approx(r["rmse_deg"] / r["crb_deg"])
    assert r["ci95"][0] <= r["rmse_over_crb"] <= r["ci95"][1]
    assert r["worst_bearing_deg"] == 180.0 and r["max_abs_mean_error_deg"] == pytest.approx(0.2)
    assert r["measured_on"] == {"pairs": 4} and r["paired_fraction"] == [0.3, 0.3, 0.3]
    c = checks(rows, recs, g)
    assert c["default_worse_than_pulse_at"] == [["X", 6.0]]
    assert not c["from_3db_within_1_3"]
    assert c["at_0db_ok"] and c["at_0db"] == {"records": 4, "with_bearing": 4,
                                             "sector_slips": 0, "misleading": 0}
    assert c["passed"] is False
    good = recs[:4] + [_rec("X", 6.0, b, k, (0.11, 0.0), (0.11, 0.0)) for b in (0.0, 180.0)
                       for k in (0, 1)]
    assert checks(pool(good, g), good, g)["passed"] is True
    # a slip, a misleading bearing or a record without a bearing at 0 dB fails the check
    for bad in (dict(slip=True), dict(misleading=1), dict(locked=False)):
        worse = recs[1:] + [_rec("X", 0.0, 0.0, 0, (0.3, 0.1), (1.0, 0.5), **bad)]
        assert not checks(pool(worse, g), worse, g)["at_0db_ok"]


def test_every_record_of_the_grid_has_its_own_noise():
    from cosim.tacan.bench_accuracy import AccuracyGrid
    g = AccuracyGrid(bearing_step_deg=60.0, snrs_db=(3.0,), modes=("X",), records=2)
    seeds = [it["seed"] for it in g.items()]
    assert seeds == list(range(100, 112))


def test_a_failing_judge_exits_non_zero(monkeypatch, tmp_path, capsys):
    """``bench`` exits 1 when a judge's summary says its checks failed (its results are
    written all the same), 0 when they passed."""
    import cosim.tools.bench as bench
    from cosim.cli import main
    for passed, rc in ((False, 1), (True, 0)):
        monkeypatch.setattr(bench, "run", lambda *a, passed=passed, **k: {"passed": passed})
        assert main(["bench", "tacan-accuracy", "--out", str(tmp_path)]) == rc
    assert "tacan-accuracy: its checks failed" in capsys.readouterr().err

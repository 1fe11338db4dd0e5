"""What a user sees (cosim.studies.shown) and how the studies judge by it: accuracy of the
estimates shown valid, availability, integrity -- on synthetic estimate arrays, no runs."""
import numpy as np
import pytest

from cosim.studies.faults import _shown_table
from cosim.studies.proposal import aggregate, confirms, failing, passes, propose
from cosim.studies.shown import paired, pool, wilson_ci
from dsp.shown import shown_figures
from cosim.studies.spec import SweepConfig

T = np.arange(1, 100) * 0.01            # an estimate every 10 ms, 0.01 .. 0.99 s
WIN = dict(settle_s=0.5, end_s=1.0, epoch_s=0.1, bound=20.0)


def _errors(seed, sigma=0.1):
    return np.random.default_rng(seed).normal(0.0, sigma, T.size)


def _fig(seed, sigma=0.1, valid=None, spike=None):
    e = _errors(seed, sigma)
    if spike is not None:
        e[spike] = 40.0                 # a sector error
    return shown_figures(T, e, np.ones(T.size, bool) if valid is None else valid, **WIN)


def test_an_all_flagged_record_is_unavailable_not_accurate():
    f = _fig(1, valid=np.zeros(T.size, bool))
    assert f["n_valid"] == 0 and f["rmse"] is None and f["mean_error"] is None
    assert f["availability"] == 0.0 and f["first_valid_s"] is None
    assert f["n_estimates"] == 50 and f["n_epochs"] == 5 and f["misleading"] == 0
    # pooled with records that show valid bearings: it adds nothing to the accuracy, and
    # takes its share of the availability
    good = [_fig(s) for s in (2, 3, 4)]
    p = pool(good + [f])
    assert p["rmse"] == pytest.approx(pool(good)["rmse"])
    assert p["availability"] == pytest.approx(0.75) and p["never_valid"] == 1


def test_availability_is_the_last_estimate_of_each_epoch():
    v = np.ones(T.size, bool)
    v[(T > 0.59) & (T < 0.695)] = False     # epoch 0.6-0.7 ends flagged (0.69 flagged)
    v[(T > 0.705) & (T < 0.785)] = False    # epoch 0.7-0.8 flagged in the middle, ends valid
    f = shown_figures(T, _errors(5), v, **WIN)
    assert f["available_epochs"] == 4 and f["availability"] == pytest.approx(0.8)
    # an epoch without any estimate is not available
    keep = (T < 0.8) | (T > 0.9)
    f = shown_figures(T[keep], _errors(5)[keep], np.ones(keep.sum(), bool), **WIN)
    assert f["availability"] == pytest.approx(0.8)
    # the time to the first valid estimate counts from the record's start, before settling
    v = np.zeros(T.size, bool)
    v[T >= 0.3] = True
    assert shown_figures(T, _errors(5), v, **WIN)["first_valid_s"] == pytest.approx(0.3)


def test_misleading_counts_only_estimates_shown_valid_after_settling():
    e = _errors(6)
    e[10] = 40.0                             # before settling: not scored
    e[70] = -25.0                            # after settling, shown valid: misleading
    e[80] = 30.0
    v = np.ones(T.size, bool)
    v[80] = False                            # flagged: not misleading
    f = shown_figures(T, e, v, **WIN)
    assert f["misleading"] == 1 and f["misleading_rate"] == pytest.approx(1 / 49)
    slip = np.zeros(T.size, bool)
    slip[90:] = True                         # the receiver's own test (e.g. a cycle slip)
    assert shown_figures(T, e, v, **WIN, misleading=slip)["misleading"] == 1 + 9
    assert wilson_ci(0, 100)[0] == 0.0 and 0.03 < wilson_ci(0, 100)[1] < 0.04
    assert wilson_ci(0, 0) is None


def test_misleading_estimates_are_paired_per_record_not_netted():
    p = [_fig(7, spike=60), _fig(8)]
    g = [_fig(7), _fig(8, spike=60)]
    assert paired(p, g, "k")["excess_misleading"] == 1
    assert paired(g, g, "k")["excess_misleading"] == 0


def _results(cfg, table):
    """Synthetic sweep results: ``table[adc_bits](trial)`` -> that point's shown figures;
    the golden chain's are _fig(trial)."""
    out = [{"kind": "golden", "combo": [["golden", 1]], "snr_db": 10.0, "trial": t,
            "shown": _fig(t)} for t in range(cfg.trials)]
    for b, fn in table.items():
        out += [{"kind": "point", "combo": [["adc_bits", b]], "snr_db": 10.0, "trial": t,
                 "shown": fn(t)} for t in range(cfg.trials)]
    return out


CFG = SweepConfig(params=(("adc_bits", (4, 5, 6)),), snr_db=(10.0,), trials=5, recheck=0)


def test_one_misleading_estimate_fails_integrity_even_when_the_rmse_passes():
    res = _results(CFG, {6: _fig, 5: lambda t: _fig(t, spike=70 if t == 2 else None),
                         4: _fig})
    rows = {r["adc_bits"]: r for r in aggregate(CFG, res)}
    r5 = rows[5]
    # the sector error is shown valid: it is no accurate estimate, but the RMSE of the
    # point is dominated by it only in one trial; the point's ratio is what it is -- the
    # verdict must come from integrity
    assert r5["misleading"] == 1 and r5["golden_misleading"] == 0
    assert r5["excess_misleading"] == 1 and "integrity" in failing(r5, 0.05)
    ok = {**r5, "ratio_to_golden": 1.0, "ratio_ci95": [0.99, 1.01]}   # RMSE that passes
    assert failing(ok, 0.05) == ["integrity"]
    assert not passes(ok, 0.05) and not confirms(ok, 0.05)
    assert passes(rows[6], 0.05) and rows[6]["ratio_to_golden"] == pytest.approx(1.0)
    # a misleading estimate refuses the width even where accuracy is not judged
    assert failing({**ok, "golden_locked": 0}, 0.05) == ["integrity"]
    assert propose(CFG, list(rows.values())) == {"adc_bits": 6}


def test_a_proposal_that_would_lower_availability_is_refused():
    flag_last = np.ones(T.size, bool)
    flag_last[T > 0.895] = False          # the last epoch of every trial flagged: -0.2
    res = _results(CFG, {6: _fig, 5: _fig,
                         4: lambda t: shown_figures(T, _errors(t), flag_last, **WIN)})
    rows = {r["adc_bits"]: r for r in aggregate(CFG, res)}
    r4 = rows[4]
    assert r4["availability"] == pytest.approx(0.8) and r4["golden_availability"] == 1.0
    assert r4["availability_diff"] == pytest.approx(-0.2)
    assert r4["ratio_to_golden"] == pytest.approx(1.0, abs=0.05)    # accurate when shown
    assert failing(r4, 0.05) == ["availability"]
    assert propose(CFG, list(rows.values())) == {"adc_bits": 5}
    # within the stated margin it passes
    assert passes(r4, 0.05, margin=0.25)


def test_an_all_flagged_point_is_unavailable_in_the_sweep():
    res = _results(CFG, {6: _fig, 5: _fig,
                         4: lambda t: _fig(t, valid=np.zeros(T.size, bool))})
    r4 = {r["adc_bits"]: r for r in aggregate(CFG, res)}[4]
    assert r4["locked"] == 0 and r4["rmse_deg"] is None and r4["ratio_to_golden"] is None
    assert r4["availability"] == 0.0
    assert "availability" in failing(r4, 0.05) and "accuracy" in failing(r4, 0.05)


def test_fault_report_shows_the_three_figures():
    rows = [{"ber": 0.0, "shown": pool([_fig(1)]), "availability_diff": 0.0,
             "excess_misleading": 0},
            {"ber": 1e-3, "shown": pool([_fig(1, spike=80)]), "availability_diff": 0.0,
             "excess_misleading": 1}, {"ber": 1e-2, "shown": None}]
    lines = _shown_table(rows, "bearing")
    assert lines[-2].split("|")[-2].strip() == "1" and lines[-2].split("|")[8].strip() == "1"
    assert lines[-1].startswith("| 0.01 | -")


def test_the_published_proposal_record_keeps_the_three_figures():
    from cosim.studies.report import proposal_record
    res = _results(CFG, {6: _fig, 5: _fig, 4: lambda t: _fig(t, spike=70)})
    rows = aggregate(CFG, res)
    s = {"config": {"receiver": "tacan", "params": [["adc_bits", [4, 5, 6]]],
                    "target_rel": 0.05, "availability_margin": 0.02},
         "machine": {"command": "x", "commit": "c", "date": "d"}, "elapsed_s": 1.0, "rows": rows,
         "proposal": propose(CFG, rows),
         "confirmation": {"confirmed": True, "params": {"adc_bits": 5}, "attempts": [{}],
                          "rows": [r for r in rows if r["adc_bits"] == 5]}}
    p = proposal_record(s)
    assert p["proposal"] == {"adc_bits": 5} and p["confirmation"]["params"] == {"adc_bits": 5}
    r4 = next(r for r in p["rows"] if r["adc_bits"] == 4)
    assert r4["misleading"] == 5 and r4["excess_misleading"] == 5 and r4["availability"] == 1.0
    assert p["confirmation"]["rows"][0]["accuracy"] == pytest.approx(
        p["confirmation"]["rows"][0]["golden_accuracy"])

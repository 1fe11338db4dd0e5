"""Quantisation sweeps: parameters, one small sweep end to end, resume, Dask, the proposal."""
import json

import numpy as np
import pytest

import cosim.studies.sweep as sw
import cosim.tacan.run
from cosim.cli import main
from cosim.studies.proposal import confirms, passes, propose, ratio_ci
from cosim.studies.report import plot
from cosim.studies.spec import SweepConfig, parse_param, parse_values
from cosim.studies.sweep import study
from cosim.backends.verilator_harness import verilator_available

SMALL = dict(params=(("adc_bits", (4, 10)),), snr_db=(15.0,), trials=2, duration_s=0.7,
             memory_s=0.15, recheck=0)


def test_parse_values_and_params():
    assert parse_values("4:8") == (4, 5, 6, 7, 8)
    assert parse_values("0:20:5") == (0, 5, 10, 15, 20)
    assert parse_values("8,12,16") == (8, 12, 16)
    assert parse_values("floor,half_up") == ("floor", "half_up")
    assert parse_values("0.5:1.5:0.5") == (0.5, 1.0, 1.5)
    assert parse_param("dsp.P=30:46:8") == ("dsp.P", (30, 38, 46))
    assert parse_param("nco_amp_bits=8,12") == ("nco_amp_bits", (8, 12))
    for bad, msg in (("adc_bits", "NAME=VALUES"), ("nope=1", "unknown parameter"),
                     ("dsp.Z=3", "unknown parameter"), ("adc_bits=8:4", "a <= b"),
                     ("adc_bits=", "empty value list"), ("adc_bits=1:2:3:4", "a:b or a:b:step")):
        with pytest.raises(ValueError, match=msg):
            parse_param(bad)


@pytest.mark.parametrize("kw, msg", [
    (dict(trials=0), "trials must be an integer >= 1"),
    (dict(snr_db=()), "snr_db must be finite numbers"),
    (dict(duration_s=0.4, memory_s=0.25), "--duration-s must exceed"),
    (dict(params=(("adc_bits", (4,)), ("adc_bits", (5,)))), "parameter given twice"),
    (dict(params=(("adc_bits", ()),)), "has no values"),
    (dict(recheck_backend="iverilog"), "recheck_backend must be"),
    (dict(recheck_samples=10), "recheck_samples must be an integer >= 1000"),
    (dict(target_rel=0), "target_rel must be in"),
])
def test_sweep_config_errors(kw, msg):
    with pytest.raises(ValueError, match=msg):
        SweepConfig(**kw)


def _rows(table):
    """Synthetic aggregate rows: {bits: ratio} at one SNR where the golden chain locks."""
    return [{"adc_bits": b, "snr_db": 10.0, "trials": 10, "invalid": None, "locked": 10,
             "golden_locked": 10, "ratio_to_golden": r, "availability_diff": 0.0,
             "excess_misleading": 0} for b, r in table.items()]


def test_proposal_is_the_smallest_width_from_which_every_larger_one_passes():
    cfg = SweepConfig(params=(("adc_bits", (4, 5, 6, 7, 8)),), recheck=0)
    assert propose(cfg, _rows({4: 1.5, 5: 1.2, 6: 1.04, 7: 1.01, 8: 1.0})) == {"adc_bits": 6}
    # passing at 5 by chance but failing at 6 does not make 5 the proposal
    assert propose(cfg, _rows({4: 1.5, 5: 1.03, 6: 1.06, 7: 1.01, 8: 1.0})) == {"adc_bits": 7}
    assert propose(cfg, _rows({4: 1.5, 5: 1.3, 6: 1.2, 7: 1.1, 8: 1.07})) == {"adc_bits": None}
    # less availability than the golden chain fails even with a good RMSE
    rows = _rows({4: 1.0, 5: 1.0, 6: 1.0, 7: 1.0, 8: 1.0})
    rows[0]["availability_diff"] = -0.3
    assert propose(cfg, rows) == {"adc_bits": 5}


def test_proposal_does_not_refuse_a_width_for_unresolved_noise():
    cfg = SweepConfig(params=(("adc_bits", (4, 5, 6)),), recheck=0)
    rows = _rows({4: 1.30, 5: 1.07, 6: 1.04})
    rows[1]["ratio_ci95"] = [1.02, 1.12]          # 7 % measured, 2 % is as likely: passes
    rows[0]["ratio_ci95"] = [1.20, 1.40]          # significantly worse: fails
    assert propose(cfg, rows) == {"adc_bits": 5}
    rows[1]["ratio_ci95"] = [1.06, 1.08]          # resolved, and above the target
    assert propose(cfg, rows) == {"adc_bits": 6}


def test_ratio_interval_is_paired_and_deterministic():
    pairs = [({"rmse_deg": 0.2 * (1 + 0.1 * k)}, {"rmse_deg": 0.2 * (1 + 0.1 * k) / 1.05})
             for k in range(10)]
    ci = ratio_ci(pairs, "x")
    assert ci == ratio_ci(pairs, "x")
    assert ci[0] == pytest.approx(1.05) and ci[1] == pytest.approx(1.05)  # exact pairing
    assert ratio_ci(pairs[:2], "x") is None


@pytest.fixture(scope="module")
def small_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    cfg = SweepConfig(**{**SMALL, "recheck": 1, "recheck_samples": 200_000})
    s = study(cfg, out, jobs=1, progress=False)
    return cfg, out, s


def test_small_sweep_writes_every_output(small_sweep):
    cfg, out, s = small_sweep
    for f in ("summary.json", "points.csv", "summary.csv", "report.md", "rmse_vs_adc_bits.png",
              "sweep.json", "proposal.json"):
        assert (out / f).stat().st_size > 0, f
    assert s["n_points"] == 4 and len(list((out / "points").glob("*.json"))) == 4 + 2  # + golden
    rows = {r["adc_bits"]: r for r in s["rows"]}
    assert set(rows) == {4, 10}
    for r in rows.values():
        assert r["locked"] == r["golden_locked"] == 2
        assert 0 < r["rmse_deg"] < 0.5 and r["golden_rmse_deg"] > 0
    # 10 bits is indistinguishable from the golden chain, 4 bits is measurably worse
    assert abs(rows[10]["ratio_to_golden"] - 1) < 0.1
    # the range log covers the front end and the DSP core
    assert {"fe.adc", "fe.mixer", "fe.cic", "fe.fir", "fe.envelope", "dsp.x", "dsp.P",
            "dsp.K"} <= set(s["ranges"])
    assert s["ranges"]["fe.adc"]["max"] <= s["ranges"]["fe.adc"]["hi"]
    report = (out / "report.md").read_text()
    assert "## Ranges and overflows" in report and "## Word-length proposal" in report
    assert "Confirmation re-run" in report
    c = s["confirmation"]
    if s["proposal"]["adc_bits"] is not None:
        assert c["params"]["adc_bits"] >= s["proposal"]["adc_bits"]
        assert c["attempts"][0]["params"] == s["proposal"]


@pytest.mark.skipif(not verilator_available(), reason="Verilator not installed")
def test_small_sweep_rechecks_a_point_cycle_accurately(small_sweep):
    _, _, s = small_sweep
    (rc,) = s["rechecks"]
    assert rc["backend"] == "verilator" and rc["samples"] == 200_000
    assert rc["words"] > 0 and rc["same_bits"] is True and "error" not in rc
    cr = s["confirmation"].get("recheck")       # the combination to build, on the RTL too
    assert cr is None or (cr["same_bits"] is True and cr["words"] > 0)


def test_interrupted_sweep_resumes_from_its_cache(small_sweep, monkeypatch):
    cfg, out, s = small_sweep
    pts = sorted((out / "points").glob("*.json"))
    victim = next(p for p in pts if json.loads(p.read_text())["kind"] == "point")
    victim.unlink()                          # as if interrupted before this point finished
    calls = []
    real = cosim.tacan.run.run_tacan
    monkeypatch.setattr(cosim.tacan.run, "run_tacan", lambda *a, **k: calls.append(1) or real(*a, **k))
    s2 = sw.run_sweep(replace_recheck(cfg), out, jobs=1, progress=False)
    assert len(calls) == 1                   # only the missing point was run again
    assert s2["rows"] == s["rows"]           # and it gave the same bits


def replace_recheck(cfg):
    from dataclasses import replace
    return replace(cfg, recheck=0)


def test_same_sweep_on_a_local_dask_cluster_gives_the_same_rows(small_sweep, tmp_path):
    """Through the CLI in a subprocess (a Dask cluster leaves threads and C-extension state
    behind; the test process stays clean of them)."""
    pytest.importorskip("distributed")
    import subprocess
    import sys
    cfg, _, s = small_sweep
    p = subprocess.run([sys.executable, "-m", "cosim", "sweep", "tacan", "--param",
                        "adc_bits=4,10", "--snr-db", "15", "--trials", "2", "--duration-s",
                        "0.7", "--memory-s", "0.15", "--recheck", "0", "--no-confirm",
                        "--scheduler", "dask", "--jobs", "2", "--out", str(tmp_path), "--json"],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    d = json.loads((tmp_path / "summary.json").read_text())
    assert d["rows"] == json.loads(json.dumps(s["rows"]))


def test_dsp_format_and_rounding_parameters_run(tmp_path):
    cfg = SweepConfig(params=(("dsp.P", (30, 46)), ("dsp.K.rounding", ("floor", "half_up"))),
                      snr_db=(15.0,), trials=1, duration_s=0.7, memory_s=0.15, recheck=0)
    s = sw.run_sweep(cfg, tmp_path, jobs=1, progress=False)
    assert len(s["rows"]) == 4 and all(r["invalid"] is None for r in s["rows"])
    # the widths reach the DSP: a 30-bit P (16 integer bits, 14 fraction bits) moves the
    # estimates away from the golden chain's (on one 0.7 s record in either direction:
    # 0.96 here), a 46-bit P keeps them within 1e-3
    for r in s["rows"]:
        off = abs(r["ratio_to_golden"] - 1.0)
        assert off > 0.01 if r["dsp.P"] == 30 else off < 1e-3, r


def test_cli_sweep_json(tmp_path, capsys):
    rc = main(["sweep", "tacan", "--param", "adc_bits=6,12", "--snr-db", "15", "--trials", "1",
               "--duration-s", "0.7", "--memory-s", "0.15", "--recheck", "0", "--no-confirm",
               "--jobs", "1", "--out", str(tmp_path), "--json"])
    assert rc == 0
    r = json.loads(capsys.readouterr().out)
    assert r["n_points"] == 2 and "adc_bits" in r["proposal"]
    assert (tmp_path / "report.md").exists()


def test_one_at_a_time_design():
    cfg = SweepConfig(params=(("adc_bits", (6, 8, 12)), ("dsp.P", (38, 46)),
                              ("mixer_rounding", ("half_even", "floor"))), design="oat",
                      recheck=0)
    assert cfg.reference == {"adc_bits": 12, "dsp.P": 46, "mixer_rounding": "half_even"}
    c = cfg.combos
    assert len(c) == 3 + 2 + 2 - 2 and len(set(c)) == len(c)
    assert (("adc_bits", 6), ("dsp.P", 46), ("mixer_rounding", "half_even")) in c
    assert (("adc_bits", 12), ("dsp.P", 46), ("mixer_rounding", "floor")) in c
    assert len(SweepConfig(params=cfg.params, recheck=0).combos) == 12
    with pytest.raises(ValueError, match="design must be"):
        SweepConfig(design="random")


def _fake_confirmation(monkeypatch, reinits):
    """run_sweep replaced by one row per run: ``reinits(params)`` filter re-initialisations
    (0: confirms); returns the list of the params tried."""
    tried = []

    def fake_run_sweep(ccfg, out, **kw):
        p = {n: v[0] for n, v in ccfg.params}
        tried.append(p)
        k = reinits(p)
        row = {"snr_db": 10.0, "trials": 10, "invalid": None, "locked": 10,
               "golden_locked": 10, "golden_reinit": 0, "dsp_events": {"reinit": k},
               "ratio_to_golden": 1.01 if k == 0 else 1.04, "ratio_ci95": [0.9, 1.1],
               "availability_diff": 0.0, "excess_misleading": 0}
        return {"rows": [row]}
    monkeypatch.setattr(sw, "run_sweep", fake_run_sweep)
    return tried


def test_confirmation_widens_only_the_parameter_that_fails(monkeypatch, tmp_path):
    """Widths that pass one at a time can fail together: the confirmation widens each
    parameter alone one swept step and keeps the one that confirms -- not every parameter."""
    cfg = SweepConfig(params=(("adc_bits", (4, 6, 8)), ("dsp.P", (34, 38, 46))), recheck=0,
                      design="oat")
    tried = _fake_confirmation(monkeypatch, lambda p: 0 if p["dsp.P"] >= 38 else 3)
    c = sw.confirm(cfg, {"adc_bits": 4, "dsp.P": 34}, tmp_path, progress=False)
    assert tried == [{"adc_bits": 4, "dsp.P": 34}, {"adc_bits": 6, "dsp.P": 34},
                     {"adc_bits": 4, "dsp.P": 38}]
    assert c["confirmed"] and c["params"] == {"adc_bits": 4, "dsp.P": 38}
    assert [a["widened"] for a in c["attempts"]] == [None, "adc_bits", "dsp.P"]
    assert [a["confirmed"] for a in c["attempts"]] == [False, False, True]


def test_confirmation_keeps_the_nearest_and_widens_again(monkeypatch, tmp_path):
    """When no single widening confirms, the nearest (fewest re-initialisations) is kept and
    the next round widens from it; when no round confirms, the widest values are tried."""
    cfg = SweepConfig(params=(("adc_bits", (4, 6, 8)), ("dsp.P", (34, 38, 46))), recheck=0,
                      design="oat")
    tried = _fake_confirmation(monkeypatch, lambda p: (p["adc_bits"] < 6) + 2 * (p["dsp.P"] < 38))
    c = sw.confirm(cfg, {"adc_bits": 4, "dsp.P": 34}, tmp_path, progress=False)
    assert tried == [{"adc_bits": 4, "dsp.P": 34}, {"adc_bits": 6, "dsp.P": 34},
                     {"adc_bits": 4, "dsp.P": 38}, {"adc_bits": 6, "dsp.P": 38},
                     {"adc_bits": 4, "dsp.P": 46}]
    assert c["confirmed"] and c["params"] == {"adc_bits": 6, "dsp.P": 38}
    tried = _fake_confirmation(monkeypatch, lambda p: 0 if p == {"adc_bits": 8, "dsp.P": 46}
                               else 1 + (p["dsp.P"] < 46))
    c = sw.confirm(cfg, {"adc_bits": 4, "dsp.P": 34}, tmp_path, progress=False, max_backoff=1)
    assert tried[-1] == {"adc_bits": 8, "dsp.P": 46} and c["attempts"][-1]["widened"] == "all"
    assert c["confirmed"] and c["params"] == {"adc_bits": 8, "dsp.P": 46}
    tried = _fake_confirmation(monkeypatch, lambda p: 1)
    c = sw.confirm(cfg, {"adc_bits": 4, "dsp.P": 34}, tmp_path, progress=False, max_backoff=1)
    assert not c["confirmed"] and c["params"] == {"adc_bits": 8, "dsp.P": 46}


def test_confirmation_is_stricter_than_the_proposal():
    row = {"snr_db": 10.0, "trials": 10, "invalid": None, "locked": 10, "golden_locked": 10,
           "golden_reinit": 0, "dsp_events": {}, "ratio_to_golden": 1.07,
           "ratio_ci95": [1.0, 1.1], "availability_diff": 0.0, "excess_misleading": 0}
    assert passes(row, 0.05) and not confirms(row, 0.05)


def test_trial_signal_seeds_are_deterministic_and_distinct_for_negative_snr():
    """A negative SNR (below the noise floor) gets its own seed instead of a SeedSequence
    error; an SNR >= 0 keeps the seed of the published studies."""
    from types import SimpleNamespace

    from cosim.tacan.study import trial_signal
    cfg = SimpleNamespace(seed=1, duration_s=1.0)
    seeds = {snr: trial_signal(cfg, snr, 0).seed for snr in (-3.0, -0.5, 0.0, 0.5, 3.0)}
    assert len(set(seeds.values())) == 5
    assert trial_signal(cfg, -3.0, 0).seed == seeds[-3.0]
    assert seeds[3.0] == int(np.random.default_rng([1, 0, 3000]).integers(1 << 31))


def test_a_cached_point_does_not_outlive_the_code(monkeypatch):
    """The point cache is keyed by the project's sources: after a code change (a new default
    detector, a new lock rule) a study recomputes its points instead of reusing old ones."""
    import dsp.jit
    cfg = SweepConfig(params=(("adc_bits", (6, 8)),), recheck=0)
    combo = (("adc_bits", 6),)
    k = sw.point_key(cfg, combo, 10.0, 0)
    assert k == sw.point_key(cfg, combo, 10.0, 0) != sw.point_key(cfg, combo, 10.0, 1)
    monkeypatch.setattr(dsp.jit, "source_hash", lambda dirs: "another version of the code")
    assert sw.point_key(cfg, combo, 10.0, 0) != k


def test_a_width_that_makes_the_filter_diverge_is_not_proposed():
    """A re-initialisation is the fixed-point filter diverging, not trial noise: a width
    with more of them than the golden filter is refused even when the ratio's interval
    reaches the target (one divergent trial in ten widens it down to ~0.9)."""
    row = {"snr_db": 10.0, "trials": 10, "invalid": None, "locked": 10, "golden_locked": 10,
           "golden_reinit": 0, "dsp_events": {"reinit": 1}, "ratio_to_golden": 37.4,
           "ratio_ci95": [0.94, 75.2], "availability_diff": 0.0, "excess_misleading": 0}
    assert not passes(row, 0.05)
    assert passes({**row, "dsp_events": {"reinit": 0}}, 0.05)
    assert passes({**row, "golden_reinit": 1}, 0.05)


def test_of_several_confirming_widenings_the_smallest_is_kept(monkeypatch, tmp_path):
    """When widening either of two parameters confirms, the one that adds fewer bits wins
    (ADC 4 -> 5 before P 34 -> 38), even though the other's ratio is better."""
    cfg = SweepConfig(params=(("adc_bits", (4, 5, 6)), ("dsp.P", (34, 38, 46))), recheck=0,
                      design="oat")
    _fake_confirmation(monkeypatch, lambda p: 0 if p["adc_bits"] >= 5 or p["dsp.P"] >= 38 else 2)
    ratio = {5: 1.04, 4: 1.0}

    real = sw.run_sweep

    def with_ratios(ccfg, out, **kw):
        s = real(ccfg, out, **kw)
        p = {n: v[0] for n, v in ccfg.params}
        if s["rows"][0]["dsp_events"]["reinit"] == 0:
            s["rows"][0]["ratio_to_golden"] = ratio[p["adc_bits"]]
        return s
    monkeypatch.setattr(sw, "run_sweep", with_ratios)
    c = sw.confirm(cfg, {"adc_bits": 4, "dsp.P": 34}, tmp_path, progress=False)
    assert [a["confirmed"] for a in c["attempts"]] == [False, True, True]
    assert c["confirmed"] and c["params"] == {"adc_bits": 5, "dsp.P": 34}


def test_a_parameter_held_at_one_value_gets_no_plot(tmp_path):
    cfg = SweepConfig(params=(("adc_bits", (6, 8)), ("detector", ("pulse",))), recheck=0)
    rows = [{"adc_bits": b, "detector": "pulse", "snr_db": float(s), "rmse_deg": 0.1,
             "golden_rmse_deg": 0.1, "crb_deg": 0.09, "availability": 1.0,
             "golden_availability": 1.0, "misleading": 0, "golden_misleading": 0}
            for b in (6, 8) for s in cfg.snr_db]
    assert plot(cfg, rows, tmp_path) == ["rmse_vs_adc_bits.png"]
    assert not (tmp_path / "rmse_vs_detector.png").exists()

"""``python -m cosim synth --all`` (cosim.tools.synth.synth_all / run_all) and its page.

The fast tests check the argument handling, the report parsing, the JSON and its page
without running the tools; the slow one synthesises and places every top at three seeds
(about an hour of one core) and fails when a top misses 100 MHz at its median seed."""
import json

import pytest

import cosim.tools.synth as synth_mod
from cosim.cli import main
from cosim.core.receivers import receivers
from cosim.tools import pages
from cosim.tools.synth import critical_path
from cosim.tools.synth_record import all_tops, merge

TOPS = {"tacan_frontend", "gnss_channel", "gnss_channel_array12", "gnss_channel_iq",
        "gnss_channel_array12_iq", "monopulse_frontend"}


def test_all_tops_are_every_registered_top():
    tops = all_tops(receivers())
    assert TOPS <= set(tops)
    assert set(tops) == {n for r in receivers() for n in (r.tops or {})}


@pytest.mark.parametrize("argv, msg", [
    (["--all", "--seed", "2"], "--all builds every top at every --seeds: drop --seed"),
    (["--all", "--top", "gnss"], "--all builds every top at every --seeds: drop --top"),
    (["--all", "--channels", "12"], "--all builds every top at every --seeds: drop --channels"),
    (["--all", "--seeds", "1,1"], "--seeds takes distinct seeds >= 0, not '1,1'"),
    (["--all", "--seeds", "1,x"], "--seeds takes comma-separated integers, not '1,x'"),
    (["--all", "--jobs", "0"], "--jobs must be an integer in [1,"),
    (["--jobs", "2"], "--jobs goes with --all (one top: --top, --seed)"),
    (["--tops", "gnss_channel"], "--tops goes with --all"),
    (["--seeds", "4,5"], "--seeds goes with --all"),
])
def test_bad_arguments_refused_before_work(argv, msg, capsys, monkeypatch, tmp_path):
    def never(*a, **k):
        raise AssertionError("synthesis started")
    monkeypatch.setattr(synth_mod, "synth_all", never)
    monkeypatch.setattr(synth_mod, "synth", never)
    assert main(["synth", "--out", str(tmp_path), *argv]) == 2
    assert capsys.readouterr().err.strip().startswith(f"error: {msg}")


def _hop(kind, cell, port, delay):
    at = {"cell": cell, "port": port, "loc": [1, 1]}
    return {"type": kind, "from": at, "to": at, "delay": delay}


REPORT = {"fmax": {"clk": {"achieved": 101.0, "constraint": 100}}, "critical_paths": [
    {"from": "<async>", "to": "posedge clk", "path": [_hop("routing", "pin", "O", 4.0)]},
    {"from": "posedge clk", "to": "posedge clk", "path": [
        _hop("clk-to-q", "core.cnt_TRELLIS_FF_Q_3", "Q", 0.5),
        _hop("routing", "x_LUT4_Z", "A", 2.0), _hop("logic", "x_LUT4_Z", "Z", 0.25),
        _hop("routing", "fifo.mem_TRELLIS_FF_Q", "M", 1.5),
        _hop("setup", "fifo.mem_TRELLIS_FF_Q", "M", 0.0)]}]}


def test_critical_path_is_the_register_to_register_one():
    cp = critical_path(REPORT)
    assert (cp["from"], cp["to"], cp["to_port"]) == ("core.cnt", "fifo.mem", "M")
    assert cp["from_cell"] == "core.cnt_TRELLIS_FF_Q_3"
    assert (cp["ns"], cp["routing_ns"], cp["logic_ns"], cp["cells"]) == (4.25, 3.5, 0.75, 1)
    assert critical_path({"critical_paths": REPORT["critical_paths"][:1]}) is None


def _fake_run(tops, *, seeds, fmax):
    rows = [{"top": n, "lut4": 10, "ff": 5, "mult18": 1, "bram": 0,
             "fmax_mhz": list(fmax), "fmax_min": min(fmax), "fmax_median": sorted(fmax)[1],
             "met_all_seeds": min(fmax) >= 100, "met_at_median": sorted(fmax)[1] >= 100,
             "critical_from": "a", "critical_to": "b", "yosys_s": 1.0} for n in tops]
    runs = [{"top": n, "seed": s, "fmax_mhz": f, "timing_met": f >= 100, "lut4": 10, "ff": 5,
             "critical_from": "a", "critical_to": "b", "critical_ns": 9.9, "logic_ns": 3.0,
             "routing_ns": 6.9, "logic_cells": 4, "nextpnr_s": 2.0}
            for n in tops for s, f in zip(seeds, fmax)]
    return {"tops": rows, "runs": runs, "failures": {}, "seeds": list(seeds), "jobs": 2,
            "wall_s": 3.0, "tool_cpu_s": 5.0, "complete": True}


@pytest.mark.parametrize("fmax, rc", [((101.0, 100.5, 104.0), 0), ((99.0, 100.5, 104.0), 1)])
def test_one_json_and_its_page(fmax, rc, monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(synth_mod, "tool_versions", lambda: {"yosys": "y", "nextpnr-ecp5": "n"})
    monkeypatch.setattr(synth_mod, "synth_all",
                        lambda tops, *, seeds, **kw: _fake_run(tops, seeds=seeds, fmax=fmax))
    assert main(["synth", "--all", "--jobs", "1", "--out", str(tmp_path / "b"),
                 "--results", str(tmp_path / "results")]) == rc
    rec = json.loads((tmp_path / "results" / "synth.json").read_text())
    assert rec == json.loads((tmp_path / "b" / "synth.json").read_text())
    assert {t["top"] for t in rec["tops"]} == set(all_tops(receivers()))
    assert rec["seeds"] == [1, 2, 3] and rec["all_met_all_seeds"] is (rc == 0)
    assert rec["all_met_at_median"] and rec["tools"]["yosys"] == "y"
    assert {"command", "commit", "date", "cpu", "cores"} <= set(rec["machine"])
    page = pages.render_page("synth", rec)
    rows = [ln for ln in page.splitlines() if ln.startswith("| gnss_channel_array12 |")]
    assert rows[0].split(" | ")[5:10] == [f"{f:.1f}" for f in fmax] + \
        [f"{min(fmax):.1f}", f"{sorted(fmax)[1]:.1f}"]
    assert len(rows) == 4        # one in the tops' table, one per seed
    lines = [w for w, *_ in pages.headline({"synth": rec})]
    assert len(lines) == len(rec["tops"]) and "monopulse_frontend" in lines[-1]
    assert "wall" in capsys.readouterr().out


@pytest.mark.synth
@pytest.mark.slow
@pytest.mark.skipif(not synth_mod.yowasp_available(),
                    reason="YoWASP yosys / nextpnr not installed")
def test_every_top_meets_100mhz_at_its_median_seed(tmp_path, capsys):
    """A fresh ``synth --all`` (every top, seeds 1-3): every top placed at every seed and
    >= 100 MHz at its median seed."""
    rc = main(["synth", "--all", "--timeout-min", "120", "--out", str(tmp_path), "--json"])
    rec = json.loads((tmp_path / "synth.json").read_text())
    assert not rec["failures"], rec["failures"]
    assert {t["top"] for t in rec["tops"]} == set(all_tops(receivers()))
    missed = {t["top"]: t["fmax_mhz"] for t in rec["tops"] if not t["fmax_median"] >= 100}
    assert not missed, f"below 100 MHz at the median seed: {missed}"
    assert rc in (0, 1)         # 1: a top misses 100 MHz at one seed (not its median)


def _fake_placed(tops, *, seeds, fmax, netlist):
    """synth_all's answer with every top placed at ``seeds`` with ``fmax`` (one per seed)
    from a netlist with id ``netlist``."""
    runs = [{"top": n, "seed": s, "netlist": netlist, "fmax_mhz": f, "timing_met": f >= 100,
             "lut4": 10, "ff": 5, "critical_from": f"a{s}", "critical_to": "b",
             "critical_ns": 9.9, "logic_ns": 3.0, "routing_ns": 6.9, "logic_cells": 4,
             "nextpnr_s": 2.0} for n in tops for s, f in zip(seeds, fmax)]
    rows = [synth_mod.top_row(n, list(seeds), [r for r in runs if r["top"] == n], 100.0,
                              {"netlist": netlist, "lut4": 10, "ff": 5, "mult18": 1, "bram": 0,
                               "yosys_s": 1.0}) for n in tops]
    return {"tops": rows, "runs": runs, "failures": {}, "seeds": list(seeds), "jobs": 1,
            "netlists": {n: netlist for n in tops}, "wall_s": 3.0, "tool_cpu_s": 5.0,
            "complete": True}


def test_tops_merges_into_the_existing_json_seed_by_seed(monkeypatch, tmp_path):
    """``--tops`` (with any ``--seeds``) merges into ``--results``' synth.json run by run:
    a top not built keeps its rows, a re-placed seed replaces the old one, the other seeds
    of a top are kept only when they placed the same netlist; each row names its commit,
    the file lists its invocations, and runs made with other settings are refused."""
    monkeypatch.setattr(synth_mod, "tool_versions", lambda: {"yosys": "y", "nextpnr-ecp5": "n"})
    run = {"fmax": (99.0, 100.5, 104.0), "netlist": "n1"}
    monkeypatch.setattr(synth_mod, "synth_all",
                        lambda tops, *, seeds, **kw: _fake_placed(tops, seeds=seeds, **run))
    base = ["synth", "--all", "--jobs", "1", "--out", str(tmp_path / "b"),
            "--results", str(tmp_path / "r")]

    def rec():
        return json.loads((tmp_path / "r" / "synth.json").read_text())

    assert main(base) == 1
    run.update(fmax=(101.0, 102.0, 103.0), netlist="n2")
    assert main(base + ["--tops", "gnss_channel,monopulse_frontend"]) == 1
    got = {t["top"]: t for t in rec()["tops"]}
    assert list(got) == list(all_tops(receivers()))
    assert got["gnss_channel"]["fmax_min"] == got["monopulse_frontend"]["fmax_min"] == 101.0
    assert got["tacan_frontend"]["fmax_mhz"] == [99.0, 100.5, 104.0]
    assert "tacan_frontend" in rec()["merged"] and "gnss_channel" not in rec()["merged"]
    assert len(rec()["runs"]) == 3 * len(got) and all(t["commit"] for t in rec()["tops"])
    assert "earlier" in pages.render_page("synth", rec())
    # seed 1 of the same tacan netlist placed again: replaces that seed only
    run.update(fmax=(100.7,), netlist="n1")
    assert main(base + ["--tops", "tacan_frontend", "--seeds", "1"]) == 1
    r = rec()
    tacan = next(t for t in r["tops"] if t["top"] == "tacan_frontend")
    assert tacan["fmax_mhz"] == [100.7, 100.5, 104.0] and tacan["met_all_seeds"]
    assert r["seeds"] == [1, 2, 3] and r["complete"] and len(r["runs"]) == 3 * len(got)
    assert [i["seeds"] for i in r["invocations"]] == [[1, 2, 3], [1, 2, 3], [1]]
    assert r["wall_s"] == 3 * 3.0 and r["tool_cpu_s"] == 3 * 5.0
    # another netlist of gnss_channel at a new seed: its old seeds go, the file is incomplete
    run.update(fmax=(105.0,), netlist="n3")
    assert main(base + ["--tops", "gnss_channel", "--seeds", "4"]) == 1
    r = rec()
    gnss = next(t for t in r["tops"] if t["top"] == "gnss_channel")
    assert r["seeds"] == [1, 2, 3, 4] and gnss["fmax_mhz"] == [None, None, None, 105.0]
    assert not gnss["met_all_seeds"] and not r["complete"] and not r["all_met_all_seeds"]
    assert [x["seed"] for x in r["runs"] if x["top"] == "gnss_channel"] == [4]
    assert main(base + ["--tops", "gnss_channel", "--target-mhz", "90"]) == 2
    assert main(base + ["--tops", "nope"]) == 2


def test_an_invocation_whose_rows_are_all_replaced_is_no_longer_listed():
    """merge keeps an invocation (and its wall time) while a row of it is left."""
    def placed(tops, seeds, commit):
        r = _fake_placed(tops, seeds=seeds, fmax=[101.0] * len(seeds), netlist=commit)
        for x in r["runs"]:
            x["commit"] = commit
        return dict(r, device="d", target_mhz=100.0, router="router2", tmg_ripup=True,
                    machine={"commit": commit, "command": f"synth {commit}"})
    order = ["a", "b"]
    first = merge(placed(["a", "b"], [1, 2], "c1"), placed(["a"], [1, 2], "c2"), order)
    assert [i["commit"] for i in first["invocations"]] == ["c1", "c2"]     # b's rows are c1's
    both = merge(first, placed(["b"], [1, 2], "c3"), order)
    assert [i["commit"] for i in both["invocations"]] == ["c2", "c3"]
    assert both["wall_s"] == 2 * 3.0 and both["complete"]


def test_scheduler_seed_by_seed_with_checkpoints_and_failures(monkeypatch, tmp_path):
    """synth_all with the tools replaced: one yosys run per top, then the seeds in order
    (largest netlist first within a seed); a failed run is reported and the rest go on;
    every finished run is checkpointed."""
    order, lock = [], __import__("threading").Lock()
    sizes = {"small": 10, "big": 99, "broken": 50}

    def synthesise(component, *, name, out_dir, timeout_s, verilog):
        work = tmp_path / name
        work.mkdir()
        (work / "yosys_stat.json").write_text(json.dumps(
            {"design": {"num_cells_by_type": {"LUT4": sizes[name]}}}))
        return work

    def place(work, *, name, seed, run_dir, **kw):
        with lock:
            order.append((name, seed))
        if name == "broken" and seed == 2:
            raise RuntimeError("nextpnr failed (exit 1)")
        f = 90.0 + sizes[name] / 10 + seed
        return {"lut4": sizes[name], "ff": 1, "mult18": 0, "bram": 0, "fmax_mhz": f,
                "timing_met": f >= 100, "critical_path": {"from": "a", "to": "b", "ns": 1.0}}

    monkeypatch.setattr(synth_mod, "synthesise", synthesise)
    monkeypatch.setattr(synth_mod, "place", place)
    monkeypatch.setattr(synth_mod, "_check", lambda *a: ("y", "n"))
    monkeypatch.setattr(synth_mod, "verilog_text", lambda c, name, emit_src: name)
    seen = []
    r = synth_mod.synth_all({n: object for n in sizes}, seeds=(1, 2, 3), jobs=1,
                            out_dir=tmp_path, checkpoint=seen.append)
    assert order == [(n, s) for s in (1, 2, 3) for n in ("big", "broken", "small")]
    assert list(r["failures"]) == ["broken seed 2"] and r["complete"]
    assert len(seen) == 3 + 9 and not seen[-1]["complete"]
    rows = {t["top"]: t for t in r["tops"]}
    assert rows["broken"]["fmax_mhz"] == [96.0, None, 98.0]
    assert not rows["broken"]["met_all_seeds"] and rows["big"]["met_all_seeds"]
    assert rows["big"]["fmax_median"] == 101.9 and rows["small"]["fmax_min"] == 92.0
    assert len(r["runs"]) == 8


def test_netlist_reused_for_the_same_verilog(monkeypatch, tmp_path):
    calls = []
    monkeypatch.setattr(synth_mod, "_check", lambda *a: ("yosys", "nextpnr"))

    def run(cmd, log, cwd, timeout):
        calls.append(cmd[0])
        (cwd / "t.json").write_text("{}")
    monkeypatch.setattr(synth_mod, "_run", run)
    for text in ("module t; endmodule", "module t; endmodule", "module t(); endmodule"):
        synth_mod.synthesise(None, name="t", out_dir=tmp_path, verilog=text)
    assert calls == ["yosys", "yosys"]
    assert (tmp_path / "t" / "t.v").read_text() == "module t(); endmodule"

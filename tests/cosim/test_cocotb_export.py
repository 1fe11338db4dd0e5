"""``python -m cosim verilog --cocotb DIR``: the standalone cocotb testbench of an exported
design runs outside the toolkit (copied to a directory of its own, started there with
``python run.py`` without the toolkit's environment variables; it imports only cocotb) with
cocotb's runner on Icarus Verilog, passes on the model's words and fails on a wrong one; bad
options are refused before any work. The slow TACAN test runs the bench with the Python
named by ``KFNAV_CLEAN_PYTHON`` when set (a virtual environment with only cocotb installed).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys

import pytest

from cosim.backends.icarus import icarus_available, icarus_missing_message
from cosim.cli import main
from hdl.gnss.params import DEFAULT_FS_HZ

needs_icarus = pytest.mark.skipif(not icarus_available(), reason=icarus_missing_message())


def _clean_env() -> dict:
    """The environment without the project on the Python path."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "COCOTB"))}
    env.pop("PYTEST_CURRENT_TEST", None)
    return env


def _run(bench, python=sys.executable):
    return subprocess.run([python, "run.py"], cwd=bench, env=_clean_env(),
                          capture_output=True, text=True, timeout=900)


def _export(tmp_path, capsys, designs, *extra):
    rc = main(["verilog", "--out", str(tmp_path / "v"), "--designs", designs, "--no-lint",
               "--cocotb", str(tmp_path / "tb"), "--json", *extra])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    return out


@pytest.mark.icarus
@needs_icarus
def test_nco_bench_runs_standalone_and_fails_on_a_wrong_word(tmp_path, capsys):
    """The NCO's bench (run-time frequency writes, gaps in valid), moved to a directory of
    its own: run.py passes; one expected word changed: it fails naming the word."""
    out = _export(tmp_path, capsys, "nco")
    assert [f["name"] for f in out["files"]] == ["nco"]
    (b,) = out["cocotb"]
    assert b["name"] == "nco" and b["words"] == 1000
    bench = tmp_path / "elsewhere"
    shutil.copytree(b["path"], bench)
    assert sorted(p.name for p in bench.iterdir()) == [
        "case.json", "kfnav_stream_driver.py", "nco.v", "run.py", "test_nco.py"]
    case = json.loads((bench / "case.json").read_text())
    assert len(case["writes"]) == 7 and set(case["in_valid"]) == {"0", "1"}
    r = _run(bench)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "1000 output words equal the model's" in r.stdout + r.stderr
    case["words"][321] ^= 1
    (bench / "case.json").write_text(json.dumps(case))
    r = _run(bench)
    assert r.returncode == 1
    assert "output word 321: " in r.stdout + r.stderr


@pytest.mark.parametrize("argv, match", [
    (["--designs", "nco,bogus", "--cocotb", "X"], r"--designs takes names among"),
    (["--cocotb-size", "100"], r"--cocotb-seed and --cocotb-size need --cocotb DIR"),
    (["--cocotb", "X", "--cocotb-size", "0"], r"--cocotb-size must be >= 1"),
    (["--cocotb", "X", "--cocotb-seed", "-1"], r"--cocotb-seed must be >= 0"),
])
def test_bad_options_are_refused_before_work(tmp_path, capsys, argv, match):
    argv = [str(tmp_path / a) if a == "X" else a for a in argv]
    assert main(["verilog", "--out", str(tmp_path / "v"), "--no-lint", *argv]) == 2
    assert re.search("error: " + match, capsys.readouterr().err)
    assert not (tmp_path / "v").exists() and not (tmp_path / "X").exists()


@pytest.mark.slow
@pytest.mark.icarus
@needs_icarus
def test_tacan_bench_runs_from_a_clean_directory(tmp_path, capsys):
    """The TACAN top's bench (noise bursts, long stalls), copied to a clean directory and
    run there; with KFNAV_CLEAN_PYTHON naming a Python that has only cocotb installed, by
    that Python."""
    out = _export(tmp_path, capsys, "tacan_frontend")
    (b,) = out["cocotb"]
    assert b["words"] > 0
    bench = tmp_path / "clean"
    shutil.copytree(b["path"], bench)
    r = _run(bench, os.environ.get("KFNAV_CLEAN_PYTHON", sys.executable))
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert f"{b['words']} output words equal the model's" in r.stdout + r.stderr


@pytest.mark.slow
@pytest.mark.icarus
@needs_icarus
def test_gnss_benches_with_register_writes(tmp_path, capsys):
    """The GNSS I/Q channel's and the two 12-channel arrays' benches (the registered tops,
    three code periods): every channel handed over and rewritten on the bus mid-run, the
    model's records of every channel expected; the I/Q channel's bench runs from a directory
    of its own."""
    out = _export(tmp_path, capsys,
                  "gnss_channel_iq,gnss_channel_array12,gnss_channel_array12_iq")
    benches = {b["name"]: b for b in out["cocotb"]}
    assert sorted(benches) == ["gnss_channel_array12", "gnss_channel_array12_iq",
                               "gnss_channel_iq"]
    for name, b in benches.items():
        case = json.loads((tmp_path / "tb" / name / "case.json").read_text())
        addr = {v for c, p, v in case["writes"] if p == "reg_addr"}
        channels = 12 if "array" in name else 1
        assert len(addr) == 4 * channels, (name, sorted(addr))     # every register of each
        period = round(DEFAULT_FS_HZ * 1e-3)                        # samples per code period
        late = [c for c, p, v in case["writes"] if p == "reg_we" and v and c > period]
        assert late and b["words"] > 0 and b["cycles"] == 3 * period + 700
    bench = tmp_path / "clean"
    shutil.copytree(benches["gnss_channel_iq"]["path"], bench)
    r = _run(bench, os.environ.get("KFNAV_CLEAN_PYTHON", sys.executable))
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    words = benches["gnss_channel_iq"]["words"]
    assert f"{words} output words equal the model's" in r.stdout + r.stderr

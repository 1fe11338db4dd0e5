"""Smoke test of ``python -m cosim bench estimation --quick``: it writes build/bench_quick
(relative to the working directory), never the published results/, and its rows include the
fixed-point UKF. Slow: the first run in a cache directory compiles ~12 kernels (minutes on
the shared host; ~20 s warm)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from cosim.cli import main

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_bench_estimation_quick_writes_build_not_results(tmp_path, monkeypatch):
    published = REPO / "results" / "estimation_speed.json"
    before = published.stat().st_mtime_ns if published.exists() else None
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "estimation", "--quick"]) == 0
    out = tmp_path / "build" / "bench_quick"
    summary = json.loads((out / "estimation_speed.json").read_text())
    assert summary["quick"] is True
    assert (out / "estimation_speed.md").exists()
    rows = {(r["filter"], r["arithmetic"]) for r in summary["rows"]}
    assert ("UKF n=4 aug", "fixed") in rows and ("alpha-beta adaptive", "fixed") in rows
    assert all(r["updates_per_s"] > 0 for r in summary["rows"])
    assert (published.stat().st_mtime_ns if published.exists() else None) == before

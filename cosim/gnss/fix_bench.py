"""``python -m cosim bench gps-fix``: a cold start on the generated static scenario through
``python -m cosim gps`` (the bit-exact channel-array model, fixed-point pll3 trackers), set
against its thermal-noise error budget (:func:`cosim.gnss.fix_budget.fix_budget`).

Written to ``results/gps_fix.json`` / ``.md`` with the machine, date, command and commit.
"""
from __future__ import annotations

import json
import pickle
from pathlib import Path

from ..core.provenance import machine_info

__all__ = ["gps_fix", "DEFAULT_DURATION_S"]

#: The cold start's first fix of the default scenario comes 31 s in; 35 fixes follow at 1 Hz.
DEFAULT_DURATION_S = 66.0


def _args(duration_s: float, cn0_dbhz: float, seed: int, out: Path, hot: bool):
    """The parsed options of the ``gps`` command for the benchmark's run."""
    import argparse
    from .gps_cli import add_parser
    parser = argparse.ArgumentParser(prog="gps-fix")
    add_parser(parser.add_subparsers(dest="command"),
               lambda sub, name, **kw: sub.add_parser(name, **kw))
    argv = ["gps", "--duration-s", f"{duration_s:g}", "--cn0-dbhz", f"{cn0_dbhz:g}",
            "--seed", str(seed), "--out", str(out), "--no-plots", "--json",
            "--tracker", "pll3", "--dsp", "fixed", "--backend", "model", "--rate", "1"]
    return parser.parse_args(argv + (["--hot-start"] if hot else []))


def gps_fix(out: Path, quick: bool = False, duration_s: float | None = None,
            cn0_dbhz: float = 45.0, seed: int = 1, hot_start: bool | None = None,
            work: Path | None = None) -> dict:
    """``python -m cosim bench gps-fix``: the generated static scenario (nominal
    constellation, ``cn0_dbhz`` on every satellite, ``seed``) through ``python -m cosim
    gps`` on the bit-exact channel-array model with the fixed-point pll3 trackers, a cold
    start of ``duration_s`` (default 66 s: the first fix 31 s in, then 35 fixes at 1 Hz),
    and its error budget (:func:`fix_budget`); ``quick``: a 20 s hot start. Writes
    ``gps_fix.json`` / ``.md`` under ``out`` (``gps_fix_quick`` with ``quick``), the run's
    own outputs under ``work`` (default ``build/gps_fix``) with the run itself
    (``run.pkl``: the GpsRun, the options, the scenario without its signal object)."""
    from .fix_budget import fix_budget, loops_of, markdown
    from .gps_cli import process
    from .multichannel import channel_params_for
    from .acquire_cli import open_file
    hot = quick if hot_start is None else bool(hot_start)
    dur = (20.0 if quick else DEFAULT_DURATION_S) if duration_s is None else float(duration_s)
    work = Path("build/gps_fix" + ("_quick" if quick else "")) if work is None else Path(work)
    a = _args(dur, cn0_dbhz, seed, work, hot)
    run, summary, scenario = process(a)
    with open(work / "run.pkl", "wb") as fh:         # the run, kept for a re-analysis
        pickle.dump({"run": run, "options": vars(a),
                     "scenario": {k: v for k, v in scenario.items() if k != "signal"}}, fh)
    loops = loops_of(a, channel_params_for(open_file(a)))
    res = {"benchmark": "gps-fix", "machine": machine_info(), "quick": quick,
           "scenario": {"duration_s": dur, "cn0_dbhz": cn0_dbhz, "seed": seed,
                        "start": "hot" if hot else "cold", "constellation": "nominal",
                        "receiver": "static, 52 N 4.4 E 30 m",
                        "channel": "bit-exact array model, 12 channels, fixed-point pll3 "
                                   f"(Bn {loops.bn_hz:g} Hz) + carrier-aided DLL",
                        "acquired": summary["acquired"]},
           "wall_s": summary["wall_s"], **fix_budget(run, scenario, loops)}
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    name = "gps_fix_quick" if quick else "gps_fix"
    (out / f"{name}.json").write_text(json.dumps(res, indent=1) + "\n")
    (out / f"{name}.md").write_text(markdown(res))
    return res

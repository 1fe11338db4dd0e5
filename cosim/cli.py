"""Command line: ``python -m cosim <command> ...`` (see ``--help``)."""
from __future__ import annotations

import argparse
import sys

from .core.receivers import GIVEN_ATTR, add_options, get, parse_finite, parse_int, receivers
from .core.validate import check_jobs, check_out_dir, dumps

#: Errors a user can cause (bad input, a full disk, a run too big): one line on stderr and
#: exit 2; the traceback only with --debug.
EXPECTED_ERRORS = (ValueError, RuntimeError, OSError, OverflowError, MemoryError)


class _Help(argparse.ArgumentDefaultsHelpFormatter):
    """--help shows every option's default (units are in each help text); an option that
    is unset by default (None, a flag, an empty list) says what unset means in its help."""

    def _get_help_string(self, action):
        text = action.help or ""
        d = action.default
        if "default" in text or d is None or d is False or d == [] or d == argparse.SUPPRESS:
            return text
        return super()._get_help_string(action)


#: Namespace attribute naming the innermost (sub)command's parser of a parse
#: (:meth:`OneLineParser.parse_known_args`).
_PROG_ATTR = "_prog"
_MARKING: dict = {}


def _marking(cls):
    """``cls`` (an argparse action class) that also records its ``dest`` in the namespace's
    :data:`~cosim.core.receivers.GIVEN_ATTR` set when its option is on the command line
    (argparse calls an action only for what was given)."""
    if cls not in _MARKING:
        def __call__(self, parser, namespace, values, option_string=None):
            vars(namespace).setdefault(GIVEN_ATTR, set()).add(self.dest)
            return cls.__call__(self, parser, namespace, values, option_string)
        _MARKING[cls] = type(cls.__name__, (cls,), {"__call__": __call__})
    return _MARKING[cls]


class OneLineParser(argparse.ArgumentParser):
    """argparse's own errors (a bad type, an unknown choice, a missing argument, an
    unrecognised argument) as one line on stderr and exit 2, like every other error of the
    command line, instead of the usage block, pointing at the help of the (sub)command that
    was parsed. Subcommands inherit it (``add_subparsers`` makes parsers of the parent's
    class). Every option records, when given on the command line, its ``dest`` in the
    namespace (:func:`cosim.core.receivers.given_options`): an option given at its default
    value is told from one left out."""

    def add_argument(self, *args, **kwargs):
        action = super().add_argument(*args, **kwargs)
        if action.option_strings and not isinstance(action, argparse._HelpAction):
            action.__class__ = _marking(type(action))
        return action

    def parse_known_args(self, args=None, namespace=None):
        ns, extras = super().parse_known_args(args, namespace)
        vars(ns).setdefault(_PROG_ATTR, self.prog)      # a subcommand's parser sets it first
        return ns, extras

    def parse_args(self, args=None, namespace=None):
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            self.exit(2, f"error: unrecognized arguments: {' '.join(extras)} "
                         f"(see {getattr(ns, _PROG_ATTR, self.prog)} --help)\n")
        return ns

    def error(self, message):
        text = " ".join(str(message).split())
        self.exit(2, f"error: {text} (see {self.prog} --help)\n")


def _parser(sub, name, **kw):
    p = sub.add_parser(name, formatter_class=_Help, **kw)
    p.add_argument("--debug", action="store_true",
                   help="show the traceback of an error instead of one line")
    return p


def _add_receivers(sub):
    """``python -m cosim <receiver>``, ``sweep <receiver>`` and ``faults <receiver>``: one
    subcommand per registered receiver (:mod:`cosim.core.receivers`), its options derived from
    its configuration dataclasses."""
    rx = receivers()
    for r in rx:
        p = _parser(sub, r.name, help=r.help)
        add_options(p, r.options)
        p.set_defaults(func=r.run)
    for study, help in (("sweep", "quantisation sweep of a receiver: word lengths/modes x SNR "
                                  "x trials, report, word-length proposal and its "
                                  "confirmation"),
                        ("faults", "bit-error study of a receiver: flip bits in its samples, "
                                   "FIFO words, registers or DSP state")):
        have = [r for r in rx if getattr(r, study) is not None]
        p = sub.add_parser(study, formatter_class=_Help, help=help,
                           description=f"{help}. Options and their defaults: "
                                       f"`python -m cosim {study} <receiver> --help`.")
        per = p.add_subparsers(dest="receiver", required=True, metavar="receiver",
                               help=f"receiver ({', '.join(r.name for r in have)})")
        for r in have:
            s = getattr(r, study)
            q = _parser(per, r.name, help=s.help)
            add_options(q, s.options)
            q.set_defaults(func=s.run)


def _add_adc_loss(sub):
    # Listed for --help; main() hands the arguments to cosim.studies.adc_loss.main.
    sub.add_parser("adc-loss", help="ADC quantisation loss on a noise-dominated tone: Monte "
                                    "Carlo against theory (1.96 dB at 1 bit, ...); see "
                                    "`python -m cosim adc-loss --help`", add_help=False)


def _add_bench(sub):
    p = _parser(sub, "bench", help="run a benchmark and write its results under results/")
    from .tools.bench import benchmarks
    known = benchmarks()
    p.add_argument("name", type=str.lower, choices=sorted(known), help="benchmark")
    p.add_argument("--quick", action="store_true",
                   help="reduced sweep (smoke test); written to build/bench_quick unless "
                        "--out is given, never to results/")
    p.add_argument("--out", default=None,
                   help="output directory (default results, or build/bench_quick with --quick)")
    p.add_argument("--jobs", type=parse_int, default=None,
                   help=f"worker processes, 1 .. the cores ({', '.join(_jobs_benchmarks())}; "
                        f"default: all cores)")
    p.add_argument("--scheduler", default=None,
                   help=f"where the tasks run ({', '.join(_scheduler_benchmarks())}): 'local' "
                        f"(process pool, the default), 'dask' (local Dask cluster) or a Dask "
                        f"scheduler address (tcp://HOST:PORT; its workers need this checkout)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=_cmd_bench)


def _scheduler_benchmarks() -> list[str]:
    """Benchmarks whose tasks run on the studies' engine (--scheduler)."""
    from .tools.bench import benchmarks
    return [name for name, b in benchmarks().items() if b.scheduler]


def _jobs_benchmarks() -> list[str]:
    """Benchmarks that spread over worker processes (--jobs); the others measure one core
    or size their own pool."""
    from .tools.bench import benchmarks
    return [name for name, b in benchmarks().items() if b.jobs]


def _cmd_bench(a) -> int:
    from pathlib import Path
    from .core.provenance import REPO_ROOT
    from .tools.bench import run
    out = a.out if a.out is not None else ("build/bench_quick" if a.quick else "results")
    if a.quick and Path(out).resolve() == (REPO_ROOT / "results").resolve():
        raise ValueError("--quick results are a smoke test: they must not overwrite the "
                         "published results/ (use another --out)")
    jobs_benchmarks = _jobs_benchmarks()
    if a.jobs is not None and a.name not in jobs_benchmarks:
        raise ValueError(f"--jobs has no effect on bench {a.name} (only on "
                         f"{', '.join(jobs_benchmarks)})")
    jobs = check_jobs(a.jobs) if a.jobs is not None else None
    if a.scheduler is not None:
        from .studies.engine import check_scheduler
        sched = _scheduler_benchmarks()
        if a.name not in sched:
            raise ValueError(f"--scheduler has no effect on bench {a.name} (only on "
                             f"{', '.join(sched)})")
        check_scheduler(a.scheduler, a.jobs, flag="--scheduler", reach=True)
    check_out_dir(out, "--out")
    summary = run(a.name, out=out, quick=a.quick, jobs=jobs, scheduler=a.scheduler)
    if a.json:
        print(dumps(summary))
    if summary.get("passed") is False:        # a judge whose checks failed (results written)
        print(f"error: bench {a.name}: its checks failed (results written under {out})",
              file=sys.stderr)
        return 1
    return 0


def _add_hdl(sub):
    p = _parser(sub, "check-equivalence",
                help="run the bit-exact model, Amaranth sim, Verilator and Icarus Verilog on "
                     "one record and count mismatching FIFO words (exit 1 on any, or when "
                     "fewer than two backends compared a non-empty record)")
    tops = [r.name for r in receivers() if r.equivalence is not None]
    p.add_argument("--top", type=str.lower, default=None, choices=tops,
                   help=f"design (default {tops[0]}; with --scenario the first top that has "
                        f"it)")
    p.add_argument("--samples", type=parse_int, default=None,
                   help="ADC samples (default 20000; pysim and icarus run up to 40000); with "
                        "--scenario the window (default 500000: 100 ms at 5 MS/s)")
    p.add_argument("--backends", default=None,
                   help="comma-separated subset of model,pysim,verilator,icarus (at least two; "
                        "each one named must run on the record); default all four, a backend "
                        "that cannot run (not installed, record too long) skipped with a note")
    p.add_argument("--seed", type=int, default=1, help="signal seed (>= 0)")
    p.add_argument("--stall", action="store_true",
                   help="DSP ready pattern with long stalls and a 4-word FIFO (drops, markers)")
    p.add_argument("--scenario", type=str.lower, default=None,
                   help="instead of the top's record: a window of a generated scenario, "
                        "acquired once and tracked closed loop on the top's channel array by "
                        "every backend; FIFO words, bus writes and tracker outputs compared "
                        "(gnss: gps, the 8-satellite scenario of the gps command)")
    p.add_argument("--channels", type=parse_int, default=None,
                   help="with --scenario: channels of the array (default 8)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_check_equivalence)

    p = _parser(sub, "verilog", help="export every HDL block and the receivers' tops to "
                                     "Verilog and lint them with Verilator")
    p.add_argument("--out", default="build/verilog", help="output directory")
    p.add_argument("--no-lint", action="store_true", help="do not lint")
    p.add_argument("--designs", default=None,
                   help="comma-separated Verilog module names to export (default: all)")
    p.add_argument("--cocotb", default=None, metavar="DIR",
                   help="also write a standalone cocotb testbench per design with a stimulus "
                        "case into DIR/<name>/ (Verilog, stimulus and the model's words, "
                        "the test, run.py; see docs/howto/cocotb_testbench.md)")
    p.add_argument("--cocotb-seed", type=int, default=1, help="stimulus seed of --cocotb")
    p.add_argument("--cocotb-size", type=parse_int, default=None,
                   help="input words (FIFO: cycles; tops: ADC samples) of each --cocotb "
                        "case (default: each design's own)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_verilog)

    p = _parser(sub, "synth", help="synthesise and place-and-route a top for ECP5 (YoWASP)")
    tops = [r.name for r in receivers() if r.tops]
    p.add_argument("--top", type=str.lower, default=None, choices=tops,
                   help=f"design (default {tops[0]})")
    p.add_argument("--all", action="store_true",
                   help="every registered top (each receiver's tops: channel counts and input "
                        "kinds) at every --seeds, --jobs runs at a time; --results DIR writes "
                        "DIR/synth.json")
    p.add_argument("--tops", default=None,
                   help="with --all: only these tops (comma-separated Verilog names); "
                        "--results merges them into DIR/synth.json, the other tops' rows kept")
    p.add_argument("--seeds", default="1,2,3",
                   help="nextpnr seeds of --all (comma-separated)")
    p.add_argument("--jobs", type=parse_int, default=None,
                   help="tool runs at a time with --all (default: the cores)")
    p.add_argument("--device", default="LFE5U-85F", help="ECP5 part")
    p.add_argument("--target-mhz", type=parse_finite, default=100.0, help="clock target (MHz)")
    p.add_argument("--out", default="build/synth", help="output directory")
    p.add_argument("--seed", type=int, default=None, help="nextpnr seed (default 1)")
    p.add_argument("--router", default="router2", choices=("router2", "router1"),
                   help="nextpnr router (router1: nextpnr-ecp5's default, slow when congested)")
    p.add_argument("--no-tmg-ripup", action="store_true",
                   help="without nextpnr's timing-driven rip-up in the router (--tmg-ripup)")
    p.add_argument("--channels", type=parse_int, default=None,
                   help="channels on one input stream (receivers with an array top: gnss)")
    p.add_argument("--timeout-min", type=parse_finite, default=30.0,
                   help="limit for each tool run (yosys, nextpnr) in minutes")
    p.add_argument("--variant", default=None,
                   help="another build of the top (receivers with variants: gnss iq, the "
                        "complex I/Q input)")
    p.add_argument("--results", default=None,
                   help="also write the figures with machine/date/command to "
                        "DIR/synth_<top>[_<variant>].json (..._<N>ch.json for --channels N > 1)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_synth)


#: ``check-equivalence``'s record without ``--samples`` (the tops' and the scenarios').
EQUIVALENCE_SAMPLES, SCENARIO_SAMPLES = 20_000, 500_000


def _cmd_check_equivalence(a) -> int:
    from .tools.equivalence import BACKENDS, check_record_size, skip_reason
    named = a.backends is not None
    text = a.backends if named else ",".join(BACKENDS)
    backends = tuple(b.strip().lower() for b in text.split(",") if b.strip())
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"--backends takes a subset of {','.join(BACKENDS)}, not {unknown}")
    if len(set(backends)) < 2:
        raise ValueError(f"--backends must name at least two backends to compare, not "
                         f"{text!r}")
    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, not {a.seed}")
    kw = {}
    if a.samples is not None:
        kw["samples"] = check_record_size(a.samples)
    if a.top is None:
        have = [r.name for r in receivers() if r.equivalence is not None
                and (a.scenario is None or a.scenario in r.equivalence_scenarios)]
        if not have:
            raise ValueError(f"--scenario: no top has the scenario {a.scenario!r}")
        a.top = have[0]
    rx = get(a.top)
    if a.scenario is not None:
        if a.scenario not in rx.equivalence_scenarios:
            have = ", ".join(rx.equivalence_scenarios) or "none"
            raise ValueError(f"--scenario: the {a.top} top has scenarios {have}, not "
                             f"{a.scenario!r}")
        kw.update(scenario=a.scenario, channels=a.channels)
    elif a.channels is not None:
        raise ValueError("--channels needs --scenario (the channel array's closed loop)")
    if named:       # a backend asked for by name runs, or the check is refused before work
        n = a.samples if a.samples is not None else \
            (SCENARIO_SAMPLES if a.scenario is not None else EQUIVALENCE_SAMPLES)
        for name in backends:
            why = skip_reason(name, n) if name != "model" else None
            if why is not None:
                raise ValueError(f"--backends names {name}, which cannot run this check: {why} "
                                 f"(--samples {n:,}; lower --samples or leave {name} out)")
    r = rx.equivalence(backends=backends, seed=a.seed, stall=a.stall, progress=not a.json,
                       **kw)
    if a.json:
        print(dumps(r))
    else:
        print(f"{r['top']}: {r['samples']} samples, {r['words']} FIFO words "
              f"({r['peaks']} peaks, {r['markers']} markers, {r['dropped']} dropped), "
              f"backends {', '.join(r['backends'])}: {r['mismatches']} mismatches")
        for c in r["compared"]:
            print(f"  compared {c}")
        for name, why in r["skipped"].items():
            print(f"  skipped {name}: {why}")
        print(f"  simulators: {r['simulators']}")
        sc = r.get("scenario")
        if sc is not None:
            print(f"  scenario {sc['name']}: {sc['window_ms']:g} ms window, PRNs {sc['prns']}; "
                  f"acquired {[c['prn'] for c in sc['acquired']]}; on {sc['channels']} "
                  f"channels: " + ", ".join(f"PRN {x['prn']} {x['status']} ({x['records']} "
                                            f"records)" for x in sc["assignments"]))
    if not r["equivalent"] or r["mismatches"]:
        print(f"error: {r['verdict'] if not r['equivalent'] else str(r['mismatches']) + ' mismatches'}",
              file=sys.stderr)
        return 1
    return 0


def hdl_blocks() -> dict:
    """Every HDL block (the TACAN front end's parameters) and every receiver's top (its
    registry entry's ``tops``), by Verilog module name
    (:func:`cosim.tools.stream_cases.exported_designs`)."""
    from .tools.stream_cases import exported_designs
    return exported_designs()


def _cmd_verilog(a) -> int:
    from .core.executables import find_executable
    from .tools.verilog import export_verilog, lint
    check_out_dir(a.out, "--out")
    designs = hdl_blocks()
    names = list(designs)
    if a.designs is not None:
        names = [n.strip() for n in a.designs.split(",") if n.strip()]
        unknown = [n for n in names if n not in designs]
        if unknown or not names:
            raise ValueError(f"--designs takes names among {', '.join(designs)}, not "
                             f"{a.designs!r}")
    if a.cocotb is not None:
        # every exported design has a stimulus case (test_every_exported_design_has_a_case)
        check_out_dir(a.cocotb, "--cocotb")
        if a.cocotb_seed < 0:
            raise ValueError(f"--cocotb-seed must be >= 0, not {a.cocotb_seed}")
        if a.cocotb_size is not None and a.cocotb_size < 1:
            raise ValueError(f"--cocotb-size must be >= 1, not {a.cocotb_size}")
    elif a.cocotb_size is not None or a.cocotb_seed != 1:
        raise ValueError("--cocotb-seed and --cocotb-size need --cocotb DIR")
    out, bad = [], 0
    do_lint = not a.no_lint and find_executable("verilator") is not None
    for name in names:
        path = export_verilog(designs[name](), name=name, out_dir=a.out)
        findings = lint(path) if do_lint else None
        bad += len(findings or [])
        out.append({"name": name, "path": str(path), "lint": findings})
    benches = []
    if a.cocotb is not None:
        from .tools.cocotb_export import export_cocotb
        from .tools.stream_cases import stream_case
        for name in names:
            case = stream_case(name, seed=a.cocotb_seed, size=a.cocotb_size)
            benches.append({"name": name, "path": str(export_cocotb(case, a.cocotb)),
                            "cycles": case.n_cycles, "words": int(len(case.words))})
    if a.json:
        print(dumps({"files": out, "linted": do_lint, "findings": bad, "cocotb": benches}))
    else:
        for f in out:
            state = "not linted" if f["lint"] is None else \
                ("lint clean" if not f["lint"] else f"{len(f['lint'])} lint findings")
            print(f"{f['path']}  ({state})")
            for line in f["lint"] or []:
                print(f"    {line}")
        if not do_lint and not a.no_lint:
            print("verilator not on PATH: files written, not linted")
        for b in benches:
            print(f"{b['path']}/  (cocotb testbench: {b['cycles']:,} cycles, {b['words']:,} "
                  f"expected words; run: python {b['path']}/run.py)")
    return 0 if bad == 0 else 1


def _cmd_synth(a) -> int:
    import time
    from .tools.synth import synth, tool_versions
    check_out_dir(a.out, "--out")
    if a.results is not None:
        check_out_dir(a.results, "--results")
    if not 0 < a.target_mhz <= 1000:
        raise ValueError(f"--target-mhz must be in (0, 1000] MHz, not {a.target_mhz:g}")
    if not 0 < a.timeout_min <= 24 * 60:
        raise ValueError(f"--timeout-min must be in (0, 1440] minutes, not {a.timeout_min:g}")
    if a.all:
        return _cmd_synth_all(a)
    for flag, given in (("--jobs", a.jobs is not None), ("--tops", a.tops is not None),
                        ("--seeds", a.seeds != "1,2,3")):
        if given:
            raise ValueError(f"{flag} goes with --all (one top: --top, --seed)")
    a.top = a.top or [r.name for r in receivers() if r.tops][0]
    a.seed = 1 if a.seed is None else a.seed
    a.channels = 1 if a.channels is None else a.channels
    rx = get(a.top)
    name, make = next(iter(rx.tops.items()))
    if a.variant is not None:
        if a.variant not in rx.variants:
            have = ", ".join(rx.variants) or "none"
            raise ValueError(f"--variant: the {a.top} top has variants {have}, not "
                             f"{a.variant!r}")
        build = rx.variants[a.variant]
        top = build(a.channels)             # refuses a count it cannot build, before work
        name = f"{name}_{a.variant}" + (f"_array{a.channels}" if a.channels != 1 else "")
    elif a.channels != 1:
        if rx.array_top is None:
            raise ValueError(f"--channels: the {a.top} top has no multi-channel array "
                             f"(only --channels 1), not {a.channels}")
        top = rx.array_top(a.channels)      # refuses a count it cannot build, before work
        name = f"{name}_array{a.channels}"
    else:
        top = make()
    t0 = time.time()
    r = synth(top, name=name, device=a.device, target_mhz=a.target_mhz, out_dir=a.out,
              seed=a.seed, timeout_s=60 * a.timeout_min, router=a.router,
              tmg_ripup=not a.no_tmg_ripup)
    wall_s = time.time() - t0
    short = {"top": a.top, "channels": a.channels,
             **{k: r[k] for k in ("lut4", "ff", "mult18", "bram", "fmax_mhz")}}
    if a.results:
        from pathlib import Path
        from .core.provenance import machine_info
        Path(a.results).mkdir(parents=True, exist_ok=True)
        rec = {**short, "device": r["device"], "target_mhz": r["target_mhz"],
               "timing_met": r["timing_met"], "seed": a.seed, "router": a.router,
               "tmg_ripup": not a.no_tmg_ripup, "wall_s": round(wall_s, 1),
               "tools": tool_versions(), "machine": machine_info()}
        if a.variant is not None:
            rec = {"variant": a.variant, **rec}
        suffix = (f"_{a.variant}" if a.variant is not None else "") + \
            (f"_{a.channels}ch" if a.channels != 1 else "")
        (Path(a.results) / f"synth_{a.top}{suffix}.json").write_text(dumps(rec, indent=1) + "\n")
    if a.json:
        print(dumps(short))
    else:
        chans = (f" ({a.variant})" if a.variant is not None else "") + \
            (f" x{a.channels}" if a.channels != 1 else "")
        print(f"{a.top}{chans} on {r['device']}: {r['lut4']} LUT4, {r['ff']} FF, {r['mult18']} MULT18, "
              f"{r['bram']} DP16KD, Fmax {r['fmax_mhz']:.1f} MHz "
              f"(target {r['target_mhz']:g}: {'met' if r['timing_met'] else 'MISSED'})")
    return 0


def _cmd_synth_all(a) -> int:
    from .tools.synth_record import run_all
    return run_all(a, receivers())


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="python -m cosim", formatter_class=_Help,
                                description="FPGA+DSP co-simulation of Kalman-filter navigation "
                                            "receivers. Bad input exits 2 with one line on "
                                            "stderr (--debug: the traceback).")
    sub = p.add_subparsers(dest="command", required=True)
    _add_receivers(sub)
    _add_adc_loss(sub)
    _add_bench(sub)
    _add_hdl(sub)
    from .gnss.acquire_cli import add_parser as _add_gnss_acquire
    _add_gnss_acquire(sub, _parser)
    from .gnss.track_cli import add_parser as _add_gnss_track
    _add_gnss_track(sub, _parser)
    from .gnss.gps_cli import add_parser as _add_gps
    _add_gps(sub, _parser)
    return p


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    from .core.provenance import source_commit
    source_commit()         # results name the code this run started with
    if argv[:1] == ["adc-loss"]:        # its own parser (python -m cosim.studies.adc_loss)
        from .studies.adc_loss import main as adc_loss_main
        return adc_loss_main(argv[1:], parser_class=OneLineParser)
    parser = build_parser()
    a = parser.parse_args(argv)
    try:
        return a.func(a)
    except EXPECTED_ERRORS as e:
        if a.debug:
            raise
        print(f"error: {_one_line(e)}", file=sys.stderr)
        return 2


def _one_line(e: BaseException) -> str:
    """An expected error as one line (a MemoryError or OverflowError may have no text)."""
    text = " ".join(str(e).split())
    if isinstance(e, MemoryError):
        return "out of memory" + (f": {text}" if text else "") + \
            " (reduce the run: --duration-s, --samples, --trials, ...)"
    if isinstance(e, OSError) and not isinstance(e, FileNotFoundError) and e.filename:
        return f"{e.strerror or type(e).__name__}: {e.filename}"
    return text or type(e).__name__

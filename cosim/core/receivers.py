"""The receiver registry: what ``python -m cosim`` knows about each receiver.

A receiver is one package (its front end in ``hdl/<name>/``, its DSP in ``dsp/<name>/``,
its signal generator and run in ``cosim/<name>/``) plus one :class:`Receiver` entry,
handed to :func:`register` when its entry module is imported. The command line is built
from the entries: the subcommand ``python -m cosim <name>``, the tops of ``verilog``,
``check-equivalence --top`` and ``synth --top``, and ``sweep <name>`` / ``faults <name>``.
How to add one: ``docs/howto/add_a_receiver.md``.

Options are derived from the receiver's configuration dataclasses (:class:`Option`): the
field name gives the flag (``duration_s`` -> ``--duration-s``), its annotation the type
(``float``: a finite number; ``int``: a whole number, ``1e6`` allowed; ``bool``: a flag;
``str`` with ``choices``), its default the default (written once, in the dataclass), and
its help comes from the field's ``metadata["help"]``, else the :class:`Option`'s ``help``,
else the class docstring's numpydoc entry for the field. ``metadata`` may also give ``choices``,
``case`` (``"upper"``/``"lower"``: choices are case-insensitive), ``none`` (words read as
None, e.g. ``("none", "inf")``) and ``metavar``. The parsed value lands in ``args.<dest>``
(the field name with the prefix); :func:`config_kwargs` collects them back into keyword
arguments of the dataclass.
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib
import math
import re
import typing
from dataclasses import dataclass, field
from typing import Any, Callable

__all__ = ["Receiver", "Study", "Figure", "Frontend", "SweepModel", "FaultModel",
           "Option", "Arg", "register", "unregister",
           "get", "receivers", "frontend_for", "add_options", "config_kwargs", "given_options",
           "given_fields", "GIVEN_ATTR", "BUILTIN"]

#: Entry modules of the receivers shipped with the toolkit (importing one registers it).
BUILTIN = ("cosim.tacan.receiver", "cosim.gnss.receiver", "cosim.monopulse.receiver",
           "cosim.ins.receiver")

_REGISTRY: dict[str, "Receiver"] = {}
_MISSING = dataclasses.MISSING
#: Attribute of a parsed namespace: the set of the ``dest`` of every option given on the
#: command line (``cosim.cli.OneLineParser`` records it; :func:`given_options`).
GIVEN_ATTR = "_given"
#: Option.default when the dataclass's default is the option's default.
FROM_FIELD = type("FromField", (), {"__repr__": lambda self: "FROM_FIELD"})()


# -- argument types ------------------------------------------------------------------------
def parse_int(s: str) -> int:
    """An integer; also 1e6-style literals that are whole numbers (not 4.5)."""
    try:
        return int(s)
    except ValueError:
        pass
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {s!r}") from None
    if not (math.isfinite(v) and v.is_integer()):
        raise argparse.ArgumentTypeError(f"must be a whole number, not {s}")
    return int(v)


def parse_finite(s: str) -> float:
    """A finite float."""
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {s!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be a finite number, not {s}")
    return v


def _or_none(parse, words):
    words = tuple(w.lower() for w in words)

    def f(s: str):
        return None if s.lower() in words else parse(s)
    f.__name__ = parse.__name__     # argparse names the type in its "invalid ..." message
    return f


# -- what a receiver declares ---------------------------------------------------------------
@dataclass(frozen=True)
class Option:
    """A command-line option derived from one field of a configuration dataclass.

    Parameters
    ----------
    config : type
        The dataclass (e.g. ``TacanSignalConfig``).
    name : str
        The field (e.g. ``"duration_s"``).
    prefix : str
        Put before the field name in the flag and ``args`` (``"dsp_"``: ``period_cycles``
        -> ``--dsp-period-cycles``, ``args.dsp_period_cycles``).
    flag : str, optional
        The flag, when it is not the field's kebab-case name (``target_rel`` -> ``--target``).
    default : optional
        Only to say "unset" (None: e.g. "taken from a preset"); the real default is the
        dataclass's, never written here.
    help : str, optional
        Used when the field has no ``metadata["help"]`` (before its docstring entry).
    choices, case, metavar :
        As in the field metadata (these win).
    """

    config: type
    name: str
    prefix: str = ""
    flag: str | None = None
    default: Any = FROM_FIELD
    help: str | None = None
    choices: tuple | None = None
    case: str | None = None
    metavar: str | None = None

    @property
    def dest(self) -> str:
        return self.prefix + self.name

    def argparse_kwargs(self) -> tuple[list[str], dict]:
        """The flags and keyword arguments of ``parser.add_argument``."""
        f = _field(self.config, self.name)
        md = dict(f.metadata)
        for k in ("choices", "case", "metavar"):
            if getattr(self, k) is not None:
                md[k] = getattr(self, k)
        default = self.default if self.default is not FROM_FIELD else _field_default(f)
        helptext = md.get("help") or self.help or _doc_entry(self.config, self.name)
        if not helptext:
            raise ValueError(f"option {self.config.__name__}.{self.name} has no help: give "
                             f"metadata['help'], Option(help=...) or a docstring entry")
        kw: dict = {"dest": self.dest, "default": default, "help": helptext}
        typ = _resolve(self.config, self.name)
        if typ is bool:
            kw["action"] = "store_true"
        else:
            parse = {float: parse_finite, int: parse_int, str: str}.get(typ)
            if parse is None:
                raise TypeError(f"{self.config.__name__}.{self.name}: no command-line type for "
                                f"{typ!r} (use Arg for it)")
            case = md.get("case")
            if case is not None:
                parse = {"upper": str.upper, "lower": str.lower}[case]
            if md.get("none"):
                parse = _or_none(parse, md["none"])
            kw["type"] = parse
            if md.get("choices") is not None:
                kw["choices"] = list(md["choices"])
            if md.get("metavar") is not None:
                kw["metavar"] = md["metavar"]
        flag = self.flag or "--" + self.dest.replace("_", "-")
        if self.flag and "metavar" not in kw and "action" not in kw:
            kw["metavar"] = self.flag.lstrip("-").replace("-", "_").upper()
        return [flag], kw


@dataclass(frozen=True)
class Arg:
    """An option that is not a configuration field (``--json``, ``--dsp-stall START:STOP``):
    ``parser.add_argument(*flags, **kwargs)``."""

    flags: tuple
    kwargs: dict = field(default_factory=dict)

    def __init__(self, *flags, **kwargs):
        object.__setattr__(self, "flags", flags)
        object.__setattr__(self, "kwargs", kwargs)

    def argparse_kwargs(self):
        return list(self.flags), dict(self.kwargs)


@dataclass(frozen=True)
class Figure:
    """A receiver's primary figure of merit: ``key`` in its run's JSON, e.g. ``rmse_deg``."""

    key: str
    label: str
    unit: str


@dataclass(frozen=True)
class Frontend:
    """A receiver's front end, as :func:`cosim.backends.factory.open_frontend` opens it.

    Parameters
    ----------
    params : type
        The front end's parameter dataclass: ``open_frontend(backend, params)`` finds this
        entry by ``isinstance(params, Frontend.params)``.
    component : callable
        ``component(params)`` -> the Amaranth top (a stream ``wiring.Component``; ``pysim``
        and ``verilator`` sessions run it).
    model : callable
        ``model(params, log_ranges=False)`` -> the bit-exact model as a
        :class:`cosim.core.session.FrontendSession` (the ``model`` backend).
    verilog_name : str
        The Verilog module name of the top (Verilator sessions).
    inputs : callable, optional
        ``inputs(params)`` -> ``{port: value}`` set at reset (e.g. an NCO word); default none.
    """

    params: type
    component: Callable[[Any], Any]
    model: Callable[..., Any]
    verilog_name: str
    inputs: Callable[[Any], dict] | None = None

    def reset_inputs(self, params) -> dict:
        return {} if self.inputs is None else dict(self.inputs(params))


@dataclass(frozen=True)
class SweepModel:
    """The receiver's side of the generic sweep engine (:mod:`cosim.studies.sweep`): the
    engine designs the points (grid / one at a time), caches and resumes them, pairs each
    with the golden run of the same record, bootstraps, proposes, confirms and reports; the
    receiver says what a parameter is and runs one record.

    Parameters
    ----------
    check_param : callable
        ``check_param(name)``: raise ValueError for a parameter name the receiver does not
        know (the up-front validation of ``--param``).
    check_point : callable
        ``check_point(cfg, combo)``: build the point's configuration from the swept values
        ``combo`` (``((name, value), ...)``) and raise ValueError if it is refused; called for
        every point before the first runs.
    record : callable
        ``record(cfg, snr_db, trial, combos)`` -> an object for one Monte Carlo record
        (the signal of that SNR and trial seed made once, a front-end cache shared by its
        points) with ``base`` (a dict every row of the record carries), ``golden()`` and
        ``point(combo, recheck=False)``; each returns the metrics dict: ``shown``, the
        three figures of what a user sees (:func:`dsp.shown.shown_figures`:
        the receiver's estimates, valid flags and error bound), optionally ``dsp_events``,
        ``ranges``, ``recheck``, ``crb_deg`` and any other metric. A point is paired with
        the golden run of its own record.
    confirm_recheck : callable, optional
        ``confirm_recheck(cfg, combo) -> dict``: re-check the confirmed combination on a
        cycle-accurate backend (``same_bits``, ...).
    default_params : tuple
        The swept parameters when none is given.
    cpu_s_per_record_s : float
        CPU seconds a point costs per second of record (the up-front size check).
    title : str
        The report's title.
    description : str
        The report's sentence on what a point runs and what its golden pairing is.
    shown_note : str
        The report's sentence on what the receiver's estimates, display epoch, valid flag
        and misleading bound are.
    """

    check_param: Callable[[str], None]
    check_point: Callable[..., None]
    record: Callable[..., Any]
    confirm_recheck: Callable[..., dict] | None = None
    default_params: tuple = ()
    cpu_s_per_record_s: float = 1.5
    title: str = "quantisation sweep"
    description: str = ""
    shown_note: str = ""


@dataclass(frozen=True)
class FaultModel:
    """The receiver's side of the generic fault study (:mod:`cosim.studies.faults`): the
    engine runs BER 0 and every BER x trial, aggregates and reports; the receiver says
    where bits can flip and runs one (BER, trial).

    Parameters
    ----------
    targets : tuple of str
        Where the bits flip (``--target``).
    check : callable
        ``check(fc)``: the receiver's rules on a ``FaultConfig`` (ValueError).
    check_size : callable
        ``check_size(fc)``: build the first record, validate it, refuse one too big.
    word_width : callable
        ``word_width(fc)``: width of the target's words (``--bits`` positions).
    record : callable
        ``record(fc, ber, trial, cache) -> dict``: one run (``flips``, ``exception``,
        the scores); never raises. ``cache`` is shared by the runs of one trial.
    cpu_s_per_record_s : float
        CPU seconds a run costs per second of record (the up-front size check).
    quantity : str
        What the scores measure, in the report's words (``"bearing"``; its NaN column).
    plot_title : str
        The plot's subject (``"TACAN bearing"``: "<plot_title> vs bit errors in <target>").
    scores_note : str
        The report's paragraph saying what the columns are for this receiver.
    """

    targets: tuple
    check: Callable[[Any], None]
    check_size: Callable[[Any], None]
    word_width: Callable[[Any], int]
    record: Callable[..., dict]
    cpu_s_per_record_s: float = 1.5
    quantity: str = "bearing"
    plot_title: str = "TACAN bearing"
    scores_note: str = (
        "Every bearing after settling: RMSE, worst error, disturbed (error > {disturbed_deg:g} "
        "deg) and the longest disturbance. Integrity: flagged (the receiver's warning flag: "
        "filter warming up, latest inputs rejected, ambiguous fine sector or implausible noise "
        "estimate), misleading (disturbed and *not* flagged) and the errors of the unflagged "
        "bearings. State faults: the DSP's continuity check saw its Kalman state or covariance "
        "change between two references by more than the filter can (a corrupted word) and put "
        "the previous reference's back, predicted to now; twice in a row it re-initialises.")


@dataclass(frozen=True)
class Study:
    """A study subcommand of a receiver (``sweep <name>``, ``faults <name>``); ``model``
    (a :class:`SweepModel` for a sweep, a :class:`FaultModel` for faults) lets the generic
    engine run the receiver's points."""

    help: str
    options: tuple
    run: Callable[[argparse.Namespace], int]
    model: Any = None


@dataclass(frozen=True)
class Benchmark:
    """One benchmark, ``python -m cosim bench <name>`` (a receiver's ``benchmarks`` maps the
    name to this; :mod:`cosim.tools.bench` dispatches).

    Parameters
    ----------
    run : callable
        ``run(out, quick=False, jobs=None) -> dict``: writes its results under the directory
        ``out`` (a :class:`pathlib.Path`) and returns the summary. A judge (a benchmark with
        pass/fail checks) puts ``"passed": bool`` in it; ``bench`` exits 1 when it is False.
    jobs : bool
        True when the benchmark spreads over ``--jobs`` worker processes (the others
        measure one core or size their own pool).
    scheduler : bool
        True when it runs its tasks on :func:`cosim.studies.engine.run_tasks` and takes
        ``--scheduler`` (``run(..., scheduler=...)``: local, dask or a Dask scheduler's
        address).
    """

    run: Callable[..., dict]
    jobs: bool = False
    scheduler: bool = False


@dataclass(frozen=True)
class Receiver:
    """Everything the command line needs to know about one receiver.

    Parameters
    ----------
    name : str
        The subcommand (``python -m cosim <name>``) and the ``--top`` of its front end.
    help : str
        One line for ``python -m cosim --help``.
    config : type
        The run's configuration dataclass (e.g. ``TacanRunConfig``).
    options : tuple of Option or Arg
        Options of ``python -m cosim <name>``.
    run : callable
        ``run(args) -> exit code``: the subcommand.
    frontend : Frontend, optional
        The front end: its parameter class, Amaranth top, bit-exact model session and
        Verilog name (:func:`cosim.backends.factory.open_frontend` opens it on every backend).
    tops : dict, optional
        Verilog module name -> a function building the top with default parameters
        (``verilog`` exports and lints each; ``synth --top <name>`` synthesises the first).
    array_top : callable, optional
        ``array_top(channels)`` -> a top of ``channels`` channels on one input stream
        (``synth --top <name> --channels N``, Verilog name ``<first top>_array<N>``); it
        refuses a channel count it cannot build (ValueError).
    variants : dict, optional
        Variant name -> ``make(channels)``, a top of another build of the front end (e.g.
        GNSS ``iq``: complex input) of ``channels`` channels (``synth --top <name> --variant
        V [--channels N]``, Verilog name ``<first top>_<V>`` and ``..._array<N>``); like
        ``array_top`` it refuses a channel count it cannot build.
    equivalence : callable, optional
        ``equivalence(samples=, backends=, seed=, stall=, progress=) -> dict`` for
        ``check-equivalence --top <name>`` (the keys of
        :func:`cosim.tools.equivalence.compare_backends`).
    equivalence_scenarios : tuple of str
        Scenarios ``equivalence`` also takes as ``scenario=`` (with ``channels=``):
        ``check-equivalence --top <name> --scenario S [--channels N]``, a closed-loop run
        on a window of a generated scenario (GNSS ``gps``: the channel array).
    metrics : tuple of str
        Keys of the run's JSON result that score it.
    primary : Figure
        The figure that says how good the receiver is.
    sweep, faults : Study, optional
        ``sweep <name>`` and ``faults <name>``.
    benchmarks : dict, optional
        Benchmark name -> :class:`Benchmark` (``python -m cosim bench <name>``).
    stream_cases : dict, optional
        Top name (a key of ``tops``) -> ``case(make_top, seed, size, short) -> dict``: the
        top's seeded stimulus, register writes and the bit-exact model's output words and
        cycles (:func:`cosim.tools.top_cases.top_case`; the cocotb checks on Icarus and
        ``verilog --cocotb``).
    """

    name: str
    help: str
    config: type
    options: tuple
    run: Callable[[argparse.Namespace], int]
    metrics: tuple
    primary: Figure
    frontend: Frontend | None = None
    tops: dict = field(default_factory=dict)
    array_top: Callable[[int], Any] | None = None
    variants: dict = field(default_factory=dict)
    equivalence: Callable[..., dict] | None = None
    equivalence_scenarios: tuple = ()
    sweep: Study | None = None
    faults: Study | None = None
    benchmarks: dict = field(default_factory=dict)
    stream_cases: dict = field(default_factory=dict)

    def __post_init__(self):
        if not re.fullmatch(r"[a-z][a-z0-9-]*", self.name):
            raise ValueError(f"receiver name must be lower-case letters, digits and '-', "
                             f"not {self.name!r}")
        if self.frontend is not None and not isinstance(self.frontend, Frontend):
            raise TypeError(f"Receiver.frontend must be a Frontend, not "
                            f"{type(self.frontend).__name__}")
        for name, b in self.benchmarks.items():
            if not re.fullmatch(r"[a-z][a-z0-9-]*", name) or not isinstance(b, Benchmark):
                raise ValueError(f"Receiver.benchmarks maps lower-case names to Benchmark, not "
                                 f"{name!r}: {type(b).__name__}")
        stray = sorted(set(self.stream_cases) - set(self.tops))
        if stray:
            raise ValueError(f"Receiver.stream_cases of tops it does not have: {stray} (tops: "
                             f"{sorted(self.tops)})")
        if self.primary.key not in self.metrics:
            raise ValueError(f"the primary figure {self.primary.key!r} must be one of the "
                             f"metrics {list(self.metrics)}")


def register(receiver: Receiver) -> Receiver:
    """Add a receiver (its entry module calls this at import). A name is registered once."""
    old = _REGISTRY.get(receiver.name)
    if old is not None and old is not receiver:
        raise ValueError(f"a receiver named {receiver.name!r} is already registered")
    _REGISTRY[receiver.name] = receiver
    return receiver


def unregister(name: str) -> None:
    """Remove a receiver (tests that register their own)."""
    _REGISTRY.pop(name, None)


def _load_builtin():
    for mod in BUILTIN:
        importlib.import_module(mod)


def receivers() -> tuple[Receiver, ...]:
    """Every registered receiver, the built-in ones first."""
    _load_builtin()
    return tuple(_REGISTRY.values())


def get(name: str) -> Receiver:
    _load_builtin()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(f"no receiver named {name!r} (known: "
                         f"{', '.join(_REGISTRY)})") from None


def frontend_for(params) -> Frontend:
    """The registered :class:`Frontend` whose parameter class ``params`` is an instance of."""
    rs = receivers()
    for r in rs:
        if r.frontend is not None and isinstance(params, r.frontend.params):
            return r.frontend
    known = [r.frontend.params.__name__ for r in rs if r.frontend is not None]
    raise TypeError(f"no front end registered for parameters of type "
                    f"{type(params).__name__} (known: {', '.join(known)})")


# -- options <-> dataclasses ----------------------------------------------------------------
def add_options(parser: argparse.ArgumentParser, options) -> None:
    for o in options:
        flags, kw = o.argparse_kwargs()
        parser.add_argument(*flags, **kw)


def config_kwargs(args: argparse.Namespace, options, config: type) -> dict:
    """Keyword arguments of ``config`` from the parsed options derived from its fields
    (an option left unset, None where the field's default is not, is left out)."""
    out = {}
    for o in options:
        if isinstance(o, Option) and o.config is config:
            v = getattr(args, o.dest)
            if v is None and o.default is None:
                continue
            out[o.name] = v
    return out


def given_options(args: argparse.Namespace) -> frozenset:
    """The ``dest`` of every option given on the command line (at its default value too);
    empty for a namespace not parsed by ``cosim.cli.OneLineParser``."""
    return frozenset(getattr(args, GIVEN_ATTR, ()))


def given_fields(args: argparse.Namespace, options, config: type) -> frozenset:
    """The fields of ``config`` whose option (of ``options``) was given on the command line:
    what a configuration's "ignored option" rules check, so that an option given at its
    default value is refused like any other where it changes nothing."""
    given = given_options(args)
    return frozenset(o.name for o in options
                     if isinstance(o, Option) and o.config is config and o.dest in given)


def _field(cls, name):
    for f in dataclasses.fields(cls):
        if f.name == name:
            return f
    raise ValueError(f"{cls.__name__} has no field {name!r}")


def _field_default(f):
    if f.default is not _MISSING:
        return f.default
    if f.default_factory is not _MISSING:
        return f.default_factory()
    raise ValueError(f"field {f.name!r} has no default: a command-line option needs one")


def _resolve(cls, name):
    """The field's type, ``X | None`` as ``X``."""
    t = typing.get_type_hints(cls)[name]
    args = [a for a in typing.get_args(t) if a is not type(None)]
    if typing.get_origin(t) in (typing.Union, getattr(__import__("types"), "UnionType", None)) \
            and len(args) == 1:
        t = args[0]
    return t


def _doc_entry(cls, name) -> str | None:
    """The numpydoc ``Parameters`` text of ``name`` in ``cls``'s docstring (first sentence
    block, one line), or None."""
    doc = cls.__doc__ or ""
    lines = doc.splitlines()
    for i, line in enumerate(lines):
        head = line.strip().split(" : ")[0]
        if name in [h.strip() for h in head.split(",")] and " : " in line:
            indent = len(line) - len(line.lstrip())
            body = []
            for nxt in lines[i + 1:]:
                if not nxt.strip() or len(nxt) - len(nxt.lstrip()) <= indent:
                    break
                body.append(nxt.strip())
            return " ".join(body) or None
    return None

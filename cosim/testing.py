"""Check your own Amaranth stream block against your numpy model, on every simulator.

One call from a pytest test runs a component on the Amaranth simulator
(:func:`cosim.backends.pysim.run_stream`), on Verilator
(:class:`cosim.backends.verilator.VerilatorStreamSim`) and on Icarus Verilog under cocotb
(:class:`cosim.backends.icarus.IcarusStreamSim`, four-state and event-driven: an X or Z on
an output fails the check) with the same stimulus and the same back-pressure, and asserts
that each gives the words your model predicts -- and the same words on the same cycles as
the others::

    from cosim.testing import check_stream

    def test_my_fir():
        x = rng.integers(-2**11, 2**11, 2000)
        check_stream(MyFir(taps), lambda x: my_model(taps, x), x,
                     ready=rng.random(3000) < 0.7)

The component follows the convention of :mod:`cosim.backends.pysim`: a ``sync``-domain
``wiring.Component`` with an input stream ``i`` (optional) and an output stream ``o``
(``amaranth.lib.stream``), payloads as packed integers (the bits of
``Value.cast(payload)``; a signed payload as signed integers; wider than 63 bits as Python
ints). :func:`cosim.backends.pysim.pack_fields` / :func:`~cosim.backends.pysim.unpack_fields`
convert struct payloads.

On a mismatch it raises :class:`StreamMismatch` (an ``AssertionError``, so pytest shows it
as a failure) saying which backend, the first differing output index, the cycle it came
out on, the expected and actual values and the words around it; and it re-runs the
failing backends with waveforms written under ``build/check_stream/<test>/`` (named in the
message; pysim and Verilator write them, Icarus does not). Verilator or Icarus/cocotb
missing: the backends that can run are still checked, then the test is skipped with the
reason (pass ``backends=("pysim",)`` to not ask for the others).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .backends.pysim import StreamResult, resolve_port, run_stream
from .core.provenance import REPO_ROOT

__all__ = ["check_stream", "StreamCheck", "StreamMismatch", "BACKENDS"]

#: Backends :func:`check_stream` knows.
BACKENDS = ("pysim", "verilator", "icarus")


class StreamMismatch(AssertionError):
    """A backend disagreed with the model or with another backend (the message says where)."""


@dataclass
class StreamCheck:
    """What :func:`check_stream` ran and compared (all equal when it returns).

    Attributes
    ----------
    results : dict of str to StreamResult
        Per backend: output words, their cycles, probes.
    expected_words : ndarray
        The model's words.
    expected_cycles : ndarray or None
        The model's cycles, if it gave them.
    skipped : dict of str to str
        Backends asked for but not run, with the reason.
    """

    results: dict = field(default_factory=dict)
    expected_words: np.ndarray | None = None
    expected_cycles: np.ndarray | None = None
    skipped: dict = field(default_factory=dict)

    @property
    def words(self) -> np.ndarray:
        return next(iter(self.results.values())).words

    @property
    def cycles(self) -> np.ndarray:
        return next(iter(self.results.values())).cycles


def _as_expected(out):
    """Model output -> (words, cycles or None, probes dict)."""
    if isinstance(out, dict):
        return out["words"], out.get("cycles"), dict(out.get("probes") or {})
    if hasattr(out, "words"):
        probes = getattr(out, "probes", None) or {}
        return out.words, getattr(out, "cycles", None), dict(probes)
    if isinstance(out, tuple) and len(out) == 2:
        return out[0], out[1], {}
    return out, None, {}


def _ints(a) -> list[int]:
    return [int(v) for v in np.asarray(a).ravel()]


def _fmt(v: int) -> str:
    return f"{v}" if v < 0 else f"{v} (0x{v:x})"


def _same(a, b) -> bool:
    """Equal as integers (fast for numeric arrays; object arrays of wide ints too)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        return False
    if a.dtype == object or b.dtype == object:
        return _ints(a) == _ints(b)
    return bool(np.array_equal(a, b))


def _first_diff(got: list[int], want: list[int]) -> int | None:
    for k, (g, w) in enumerate(zip(got, want)):
        if g != w:
            return k
    return None if len(got) == len(want) else min(len(got), len(want))


def _compare(what: str, got: StreamResult, want_words, want_cycles, want_probes,
             context: int = 3) -> str | None:
    """None if equal, else a report of the first difference."""
    if _same(got.words, want_words) and (want_cycles is None or _same(got.cycles, want_cycles)) \
            and all(k in got.probes and _same(got.probes[k], v) for k, v in want_probes.items()):
        return None
    gw, ww = _ints(got.words), _ints(want_words)
    gc = _ints(got.cycles)
    lines = []
    k = _first_diff(gw, ww)
    if k is not None:
        lines.append(f"{what}: words differ at index {k} of {len(ww)} expected "
                     f"({len(gw)} produced)")
        if k < len(gw):
            lines.append(f"  cycle  : {gc[k]}")
        lines.append(f"  expected: {_fmt(ww[k]) if k < len(ww) else '(no more words)'}")
        lines.append(f"  actual  : {_fmt(gw[k]) if k < len(gw) else '(no more words)'}")
        lo = max(0, k - context)
        lines.append(f"  expected[{lo}:{k + context + 1}] = {ww[lo:k + context + 1]}")
        lines.append(f"  actual  [{lo}:{k + context + 1}] = {gw[lo:k + context + 1]}")
    elif want_cycles is not None:
        wc = _ints(want_cycles)
        j = _first_diff(gc, wc)
        if j is not None:
            lines.append(f"{what}: words equal, output cycles differ at index {j} (word "
                         f"{_fmt(gw[j]) if j < len(gw) else '-'})")
            lines.append(f"  expected cycle: {wc[j] if j < len(wc) else '-'}")
            lines.append(f"  actual cycle  : {gc[j] if j < len(gc) else '-'}")
    for name, want in want_probes.items():
        if name not in got.probes:
            lines.append(f"{what}: probe {name!r} not recorded")
            continue
        pg, pw = _ints(got.probes[name]), _ints(want)
        j = _first_diff(pg, pw)
        if j is not None:
            lines.append(f"{what}: probe {name!r} differs at cycle {j}: expected "
                         f"{pw[j] if j < len(pw) else '-'}, actual {pg[j] if j < len(pg) else '-'}")
    return "\n".join(lines) or None


def _test_dir() -> str:
    nodeid = os.environ.get("PYTEST_CURRENT_TEST", "check_stream").split(" (")[0]
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", nodeid.split("/")[-1])[:120]


def _verilog_name(component, name: str | None) -> str:
    n = name or re.sub(r"(?<!^)(?=[A-Z])", "_", type(component).__name__).lower()
    n = re.sub(r"[^A-Za-z0-9_]", "_", n)
    return n if re.match(r"[A-Za-z_]", n) else "dut_" + n


def check_stream(component, model, stimulus=None, *, valid=None, ready=None,
                 n_cycles: int | None = None, flush_cycles: int = 64,
                 inputs: dict | None = None, writes=None, probe: dict | None = None,
                 backends=BACKENDS, check_cycles: bool = True, name: str | None = None,
                 vcd: str = "on_failure", build_dir: str | Path | None = None) -> StreamCheck:
    """Run ``component`` on each backend and assert its output equals ``model``.

    Parameters
    ----------
    component : wiring.Component
        The block: output stream ``o``, optional input stream ``i``, ``sync`` domain.
    model : callable or array
        ``model(stimulus)`` (or the expected output itself), returning the expected output
        words (array), or ``(words, cycles)``, or a dict / object with ``words`` and
        optionally ``cycles`` and ``probes`` (e.g. a
        :class:`~cosim.backends.pysim.StreamResult` or a block model's result). Cycles, when given, are compared too; the backends are always
        compared with each other on words *and* cycles.
    stimulus : array of int, optional
        Packed input payloads, offered in order on ``i``.
    valid : array of bool, optional
        Per cycle, offer the next input word (default every cycle).
    ready : array of bool or hdl.model.fifo.ReadySchedule, optional
        Per-cycle ``o.ready``: the back-pressure (default always ready). A schedule needs
        ``n_cycles``.
    n_cycles : int, optional
        Cycles to run (default: until every input is taken, then ``flush_cycles``).
    inputs : dict of port name -> int, optional
        Constant values of other input ports (Verilog names, e.g. ``"gain"``).
    writes : list of (cycle, port name, value), optional
        Input ports set before the edge of a cycle (run-time register writes), in cycle
        order.
    probe : dict of name -> port name, optional
        Ports recorded every cycle; compared between backends and with the model's
        ``probes`` of the same names.
    backends : tuple of str
        Any of ``"pysim"``, ``"verilator"``, ``"icarus"`` (default all three; the first
        one's result is the reference the others are compared with, after each is compared
        with the model).
    check_cycles : bool
        Compare output cycles between backends (default True).
    name : str, optional
        Verilog module name (default from the class name).
    vcd : {"on_failure", "always", "never"}
        Waveforms: re-run a failing backend with a VCD (default), always write them, or never.
    build_dir : path, optional
        Where waveforms go (default ``<repo>/build/check_stream/<test name>/``).

    Returns
    -------
    StreamCheck

    Raises
    ------
    StreamMismatch
        On any difference (message: backend, first differing index, cycle, expected and
        actual values, VCD paths).
    """
    def reject(msg):
        # The caller's mistake, not the component's: no "created but never used" warning.
        component._MustUse__silence = True
        raise ValueError(msg)
    backends = tuple(backends)
    for b in backends:
        if b not in BACKENDS:
            reject(f"backend must be one of {BACKENDS}, not {b!r}")
    if not backends:
        reject("check_stream needs at least one backend")
    if vcd not in ("on_failure", "always", "never"):
        reject(f"vcd must be 'on_failure', 'always' or 'never', not {vcd!r}")
    from hdl.model.fifo import ReadySchedule
    if isinstance(ready, ReadySchedule):
        if n_cycles is None:
            reject("a ReadySchedule needs n_cycles")
        ready = ready.mask(n_cycles)
    expected = model(stimulus) if callable(model) else model
    want_words, want_cycles, want_probes = _as_expected(expected)
    if not check_cycles:
        want_cycles = None
    vname = _verilog_name(component, name)
    out_dir = Path(build_dir) if build_dir is not None else \
        REPO_ROOT / "build" / "check_stream" / _test_dir()
    writes = [(int(c), p, int(v)) for c, p, v in writes or ()]
    if any(not isinstance(p, str) for _, p, _ in writes) or \
            [c for c, _, _ in writes] != sorted(c for c, _, _ in writes):
        reject("writes must be (cycle, port name, value) in cycle order")
    kw = dict(in_valid=valid, out_ready=ready, n_cycles=n_cycles, flush_cycles=flush_cycles,
              inputs=inputs, probe=probe)
    check = StreamCheck(expected_words=np.asarray(want_words),
                        expected_cycles=None if want_cycles is None else np.asarray(want_cycles))
    sims = {}

    def run(backend, wave: Path | None):
        if backend == "pysim":
            # run_stream samples Values; names are resolved as the Verilog export spells them
            pkw = dict(kw, probe={k: resolve_port(component, v) for k, v in (probe or {}).items()},
                       writes=[(c, resolve_port(component, p), v) for c, p, v in writes])
            return run_stream(component, stimulus, vcd=wave, **pkw)
        if backend not in sims:
            if backend == "verilator":
                from .backends.verilator import VerilatorStreamSim
                sims[backend] = VerilatorStreamSim(component, vname)
            else:
                from .backends.icarus import IcarusStreamSim
                sims[backend] = IcarusStreamSim(component, vname)
        if backend == "verilator":
            return sims[backend].run(stimulus, trace=wave, writes=writes, **kw)
        if wave is not None:
            raise NotImplementedError("Icarus runs write no waveform (pysim's and "
                                      "Verilator's do)")
        return sims[backend].run(stimulus, writes=writes, **kw)

    def wave_path(backend):
        return out_dir / f"{vname}.{backend}.vcd"

    failures: list[str] = []
    failed: list[str] = []
    for b in backends:
        if b == "verilator":
            from .backends.verilator_harness import verilator_available
            if not verilator_available():
                check.skipped[b] = "Verilator, make or a C++ compiler not found on PATH"
                continue
        if b == "icarus":
            from .backends.icarus import icarus_available, icarus_missing_message
            if not icarus_available():
                check.skipped[b] = icarus_missing_message()
                continue
        try:
            res = run(b, wave_path(b) if vcd == "always" and b != "icarus" else None)
        except AssertionError as e:   # an X or Z on an output (icarus)
            failures.append(f"{b}: {e}")
            failed.append(b)
            continue
        check.results[b] = res
        report = _compare(f"{b} vs model", res, want_words, want_cycles, want_probes)
        if report is None and len(check.results) > 1:
            ref_name = next(iter(check.results))
            ref = check.results[ref_name]
            report = _compare(f"{b} vs {ref_name}", res, ref.words,
                              ref.cycles if check_cycles else None,
                              ref.probes)
        if report is not None:
            failures.append(report)
            failed.append(b)
    if failures:
        msg = "\n".join(failures)
        if vcd == "on_failure":
            paths = []
            for b in failed:
                try:
                    run(b, wave_path(b))
                    paths.append(str(wave_path(b)))
                except Exception as e:      # the report matters more than the waveform
                    paths.append(f"({b}: no waveform: {e})")
            msg += "\nwaveforms: " + ", ".join(paths)
        elif vcd == "always":
            msg += "\nwaveforms: " + ", ".join(str(wave_path(b)) for b in check.results
                                               if b != "icarus")
        raise StreamMismatch(msg)
    if check.skipped:
        try:
            import pytest
        except ImportError:     # not under pytest: the result says what was skipped
            return check
        pytest.skip("; ".join(f"{b} not run: {r}" for b, r in check.skipped.items()) +
                    f" (checked on {', '.join(check.results) or 'nothing'})")
    return check

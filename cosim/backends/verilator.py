"""Compiled cycle-accurate simulation of a stream component with Verilator.

Same convention and the same results as :func:`cosim.backends.pysim.run_stream` (words *and* cycles,
bit for bit), but the clock loop runs in C++: the component is exported to Verilog
(:mod:`cosim.backends.verilog`), Verilated, compiled with a generated harness into a shared library
and driven through ``ctypes`` with numpy buffers. Python only runs between chunks: at the
cycles of register writes, when the output buffer is full, and every ``_CHUNK_CYCLES``
cycles so that Ctrl-C works.

Builds are cached under ``build/verilator/<sha256>/`` keyed on the Verilog text, the
harness (this file and :mod:`cosim.backends.verilator_harness`, which generates the C++), the
Verilator version and the trace kind; constructing a simulator
for a design that has been built before only loads the library.

Per cycle the harness does what ``run_stream``'s testbench does before its ``tick()``: set
``i.valid``/``i.payload`` (the payload only when offering, so it holds its last value
otherwise, as in ``run_stream``) and ``o.ready``, evaluate with ``clk`` low, sample
``o.valid``, ``o.payload``, ``o.ready`` and ``i.ready`` (the values the clock edge sees),
then raise ``clk`` and evaluate the edge. ``rst`` is held low, as ``amaranth.sim`` does.

Speed (what is compiled is equivalent to the exported Verilog, bit for bit; see
:func:`cosim.backends.verilator_harness.verilator_source`):

- ``rst``, and any other top-level input the harness never drives, is tied to 0 in a thin
  wrapper module instead of being an input held at 0. Every register's next-state logic
  reads ``rst``, so with ``rst`` an input Verilator evaluates nearly the whole design in its
  input-combinational region, twice per cycle (once per ``eval``); tied, it folds the reset
  away and only the logic fed by the driven inputs stays there (~3x on the TACAN front end).
- yosys writes arithmetic shifts and sign extensions as concatenations of single bits
  (``{ x[24], x[24], x[24:2] }``), which Verilator turns into one shift-and-mask per bit;
  they are respelled as replications and ``>>>`` (~20 % fewer instructions on the TACAN
  front end, ~4x on the CORDIC envelope).
- The hot loop calls the model's evaluation function directly (``Vdut___024root___eval``,
  when the Verilated model has it) rather than ``eval()``, skipping ``eval_step``'s
  per-call thread-local and message-queue bookkeeping, which a model built without
  ``--threads`` does not use.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
from amaranth.hdl import Value

from ..core.executables import tool_env
from ..core.provenance import REPO_ROOT
from ..core.session import FrontendSession, ready_window
from . import verilator_harness as _harness
from .build_cache import cached_build, publish, temp_dir_beside
from .pysim import StreamResult, input_items
from .verilog import PortInfo, stream_ports, verilator_missing_message, verilog_text
from .verilator_harness import (CFLAGS, HARNESS_TEMPLATE, MAKE_OPTS, HARNESS_VERSION, as_value,
                                limbs, parse_header_ports, payload_get_code, payload_set_code,
                                RunArgs, verilator_source, verilator_version)

__all__ = ["VerilatorStreamSim", "VerilatorSession"]

#: Longest stretch of cycles one call into C runs, so Python can react to Ctrl-C (~1 s).
_CHUNK_CYCLES = 1 << 24
#: Initial output buffer (words); grown in further chunks as needed.
_OUT_CHUNK = 1 << 20
#: Cycles per call when per-cycle probes are recorded (bounds the probe buffer).
_PROBE_CHUNK = 1 << 18

_STATUS_DONE, _STATUS_PAUSED, _STATUS_FULL = 0, 1, 2

class VerilatorStreamSim:
    """A component compiled with Verilator, run like :func:`cosim.backends.pysim.run_stream`.

    Parameters
    ----------
    component : wiring.Component
        A ``sync``-domain component with an output stream ``o`` and optionally an input
        stream ``i`` (``amaranth.lib.stream``), payloads of any width (wider than 63 bits:
        object arrays of Python ints, as ``run_stream`` returns them); other ports up to 64
        bits can be set (``inputs``, ``writes``) or read (``probe``).
    name : str
        Verilog top module name.
    build_dir : path, optional
        Cache directory (default ``<repo>/build/verilator``).
    jobs : int, optional
        Parallel compile jobs (default: number of CPUs).

    Attributes
    ----------
    built : bool
        True if this construction compiled the design, False if it loaded a cached build.
    lib_path : Path
        The shared library in use.
    verilog : str
        The Verilog text that was compiled.
    ports : list of PortInfo
        Ports of the component and their Verilog names.

    Raises
    ------
    RuntimeError
        Verilator (or make / a C++ compiler) is missing, or the build fails (the message
        includes the tail of the build log).
    """

    def __init__(self, component, name: str = "dut", *, build_dir: str | Path | None = None,
                 jobs: int | None = None):
        self.component = component
        self.name = name
        self.ports: list[PortInfo] = stream_ports(component)
        self._by_name = {p.name: i for i, p in enumerate(self.ports)}
        self._by_id = {id(p.value): i for i, p in enumerate(self.ports)}
        self.verilog = verilog_text(component, name=name, emit_src=False)
        # Checked after the export so that the component is elaborated either way (no
        # UnusedElaboratable warning when the tool is missing).
        if not _harness.verilator_available():   # looked up at call time (tests patch it)
            raise RuntimeError(verilator_missing_message())
        self._build_dir = Path(build_dir) if build_dir is not None else REPO_ROOT / "build" / "verilator"
        self._jobs = jobs or os.cpu_count() or 1
        self._libs: dict[str, ctypes.CDLL] = {}
        self.built = False
        self.lib_path = self._ensure_lib(None)

    # -- building -------------------------------------------------------------------------

    def _cache_key(self, trace_kind: str | None) -> str:
        h = hashlib.sha256()
        for part in (self.verilog, HARNESS_VERSION, verilator_version(), trace_kind or "notrace",
                     Path(__file__).read_text(), Path(_harness.__file__).read_text()):
            h.update(part.encode())
            h.update(b"\0")
        return h.hexdigest()

    def _ensure_lib(self, trace_kind: str | None) -> Path:
        key = trace_kind or ""
        if key in self._libs:
            return Path(self._libs[key]._name)
        # One build per key at a time (pytest-xdist workers, parallel sweeps): the others wait
        # on the lock and then load the finished library instead of compiling it too.
        out, built = cached_build(self._build_dir, self._cache_key(trace_kind), "libsim.so",
                                  lambda tmp: self._compile(tmp, trace_kind))
        if built and trace_kind is None:
            self.built = True
        lib_path = out / "libsim.so"
        lib = ctypes.CDLL(str(lib_path))
        lib.sim_args_size.restype = ctypes.c_int64
        lib.sim_traced.restype = ctypes.c_int64
        lib.sim_new.restype = ctypes.c_void_p
        lib.sim_new.argtypes = [ctypes.c_char_p]
        lib.sim_free.argtypes = [ctypes.c_void_p]
        lib.sim_set.argtypes = [ctypes.c_void_p, ctypes.c_int32, ctypes.c_uint64]
        lib.sim_get.restype = ctypes.c_uint64
        lib.sim_get.argtypes = [ctypes.c_void_p, ctypes.c_int32]
        lib.sim_run.restype = ctypes.c_int32
        lib.sim_run.argtypes = [ctypes.c_void_p, ctypes.POINTER(RunArgs)]
        if lib.sim_args_size() != ctypes.sizeof(RunArgs):
            raise RuntimeError(f"harness ABI mismatch in {lib_path}: delete {self._build_dir}")
        self._libs[key] = lib
        return lib_path

    def _compile(self, tmp: Path, trace_kind: str | None) -> None:
        """Verilate and compile into the empty directory ``tmp`` (:func:`cached_build` moves
        it into the cache)."""
        (tmp / f"{self.name}.v").write_text(self.verilog)
        source, top = verilator_source(self.verilog, self.name, {p.name for p in self.ports})
        (tmp / "vlsim.v").write_text(source)
        harness = tmp / "harness.cpp"
        harness.write_text("// placeholder, written after Verilating\n")
        trace_args, ldflags = [], []
        if trace_kind == "vcd":
            trace_args = ["--trace"]
        elif trace_kind == "fst":
            trace_args = ["--trace-fst"]
            ldflags = ["-lz"]
        cmd = ["verilator", "--cc", "--exe", str(harness), "-O3", "--x-assign", "fast",
               "-Wno-fatal", "-Wno-lint", "-Wno-style", "--top-module", top,
               "--prefix", "Vdut", "-Mdir", str(tmp / "obj"), *trace_args,
               "-CFLAGS", CFLAGS, "-LDFLAGS", " ".join(["-shared", *ldflags]),
               "-o", "libsim.so", str(tmp / "vlsim.v")]
        log = [" ".join(cmd)]
        self._run_logged(cmd, log, tmp)
        header = (tmp / "obj" / "Vdut.h").read_text()
        direct_eval = any("void Vdut___024root___eval(Vdut___024root* vlSelf)" in f.read_text()
                          for f in (tmp / "obj").glob("Vdut___024root__DepSet_*.cpp"))
        harness.write_text(self._harness_source(parse_header_ports(header), trace_kind,
                                                direct_eval))
        # The C++ optimisation level (verilated.mk defaults to -Os) matters for speed.
        make = ["make", "-C", str(tmp / "obj"), "-f", "Vdut.mk", f"-j{self._jobs}",
                *MAKE_OPTS]
        # The Verilator runtime (verilated.cpp, ...) takes most of the compile time and
        # does not depend on the design: reuse its objects from an earlier build with the
        # same Verilator, flags and trace kind (make skips them when they are newer).
        runtime = self._build_dir / "_runtime" / hashlib.sha256("\0".join(
            [verilator_version(), CFLAGS, *MAKE_OPTS, trace_kind or "notrace"]
        ).encode()).hexdigest()[:16]
        if runtime.is_dir():
            for f in sorted(runtime.iterdir(), key=lambda f: f.suffix != ".d"):
                shutil.copy(f, tmp / "obj" / f.name)  # .d first, then newer .o
        log.append(" ".join(make))
        self._run_logged(make, log, tmp)
        if not runtime.is_dir():
            rt_tmp = temp_dir_beside(runtime, "rt.tmp-")
            for f in (tmp / "obj").glob("verilated*.[od]"):
                shutil.copy(f, rt_tmp / f.name)
            publish(rt_tmp, runtime)
        shutil.copy2(tmp / "obj" / "libsim.so", tmp / "libsim.so")
        shutil.copy2(tmp / "obj" / "Vdut.h", tmp / "Vdut.h")
        shutil.rmtree(tmp / "obj")
        (tmp / "build.log").write_text("\n".join(log))

    @staticmethod
    def _run_logged(cmd, log: list[str], tmp: Path) -> None:
        proc = subprocess.run(cmd, capture_output=True, text=True, env=tool_env())
        log.append(proc.stdout + proc.stderr)
        if proc.returncode != 0:
            tail = "\n".join((proc.stdout + proc.stderr).splitlines()[-40:])
            raise RuntimeError(f"Verilator build failed ({cmd[0]} exited {proc.returncode}):\n{tail}")

    def _harness_source(self, cxx: dict[str, tuple[str, str, int]], trace_kind: str | None,
                        direct_eval: bool = False) -> str:
        for p in self.ports:
            if p.name not in cxx:
                raise RuntimeError(f"port {p.name!r} not found in the Verilated model")

        def c(name):
            return cxx[name][0]

        get_cases, set_cases = [], []
        for i, p in enumerate(self.ports):
            if p.width > 64:
                continue
            get_cases.append(f"    case {i}: return (uint64_t)top->{c(p.name)};")
            if p.direction == "in":
                mask = (1 << p.width) - 1
                set_cases.append(f"    case {i}: top->{c(p.name)} = v & {mask}ULL; break;")
        # A zero-width input payload (a bare strobe stream) is not a port: only valid is driven.
        has_in = "i__valid" in cxx
        has_i_payload = has_in and "i__payload" in cxx
        i_set = payload_set_code(c("i__payload"), cxx["i__payload"][2]) if has_i_payload else ""
        o_get = payload_get_code(c("o__payload"), cxx["o__payload"][2])
        subs = {
            "@VERSION@": HARNESS_VERSION,
            "@TRACED@": "1" if trace_kind else "0",
            "@DIRECT_EVAL@": "1" if direct_eval else "0",
            "@TRACE_INCLUDE@": {None: "", "vcd": '#include "verilated_vcd_c.h"',
                                "fst": '#include "verilated_fst_c.h"'}[trace_kind],
            "@TRACE_CLASS@": {None: "void", "vcd": "VerilatedVcdC", "fst": "VerilatedFstC"}[trace_kind],
            "@GET_CASES@": "\n".join(get_cases),
            "@SET_CASES@": "\n".join(set_cases),
            "@HAS_IN@": "1" if has_in else "0",
            "@HAS_I_PAYLOAD@": "1" if has_i_payload else "0",
            "@HAS_I_READY@": "1" if "i__ready" in cxx else "0",
            "@HAS_O_READY@": "1" if "o__ready" in cxx else "0",
            "@I_VALID@": c("i__valid") if has_in else "",
            "@I_PAYLOAD@": c("i__payload") if has_i_payload else "",
            "@I_PAYLOAD_SET@": i_set,
            "@O_PAYLOAD_GET@": o_get,
            "@I_READY@": c("i__ready") if "i__ready" in cxx else "",
            "@O_VALID@": c("o__valid"),
            "@O_PAYLOAD@": c("o__payload"),
            "@O_READY@": c("o__ready") if "o__ready" in cxx else "",
        }
        src = HARNESS_TEMPLATE
        for k, v in subs.items():
            src = src.replace(k, v)
        return src

    # -- running --------------------------------------------------------------------------

    def port_index(self, port) -> int:
        """Index of ``port`` (a ``Value`` of the component, or its Verilog name) in :attr:`ports`."""
        if isinstance(port, str):
            if port not in self._by_name:
                raise KeyError(f"no port named {port!r}; ports: {sorted(self._by_name)}")
            idx = self._by_name[port]
        else:
            value = as_value(port)
            if id(value) not in self._by_id:
                raise KeyError(f"{port!r} is not a port of the component (ports are its "
                               f"signature members: {sorted(self._by_name)})")
            idx = self._by_id[id(value)]
        if self.ports[idx].width > 64:
            raise NotImplementedError(f"port {self.ports[idx].name} is wider than 64 bits")
        return idx

    def _input_index(self, port) -> int:
        idx = self.port_index(port)
        p = self.ports[idx]
        if p.direction != "in":
            raise ValueError(f"port {p.name} is an output; only inputs can be set")
        if p.name in ("i__valid", "i__payload", "o__ready"):
            raise ValueError(f"port {p.name} is driven by the stream runner, not by inputs/writes")
        return idx

    @staticmethod
    def _to_u64(words, width: int) -> np.ndarray:
        # The harness masks to the port width, so int64/uint64 arrays are passed as they are
        # (two's complement bits, as amaranth.sim truncates negative values).
        words = np.asarray(words)
        if width > 64:   # limbs(width) uint64 entries per word, LSB first
            nl, m64 = limbs(width), (1 << 64) - 1
            mask = (1 << width) - 1
            return np.array([(int(w) & mask) >> (64 * j) & m64 for w in words.ravel()
                             for j in range(nl)], dtype=np.uint64)
        if words.dtype == object:
            mask = (1 << width) - 1
            return np.array([int(w) & mask for w in words], dtype=np.uint64)
        if words.dtype.kind == "u":
            return np.ascontiguousarray(words, dtype=np.uint64)
        if words.dtype.kind in "ib":
            return np.ascontiguousarray(words, dtype=np.int64).view(np.uint64)
        raise TypeError(f"input words must be integers, not {words.dtype}")

    @staticmethod
    def _from_u64(raw: np.ndarray, width: int, signed: bool) -> np.ndarray:
        if width > 64:
            nl = limbs(width)
            ints = [sum(int(v) << (64 * j) for j, v in enumerate(row))
                    for row in raw.reshape(-1, nl)]
            if signed:
                ints = [v - (1 << width) if v >> (width - 1) else v for v in ints]
            return np.array(ints, dtype=object)
        if width <= 63:
            vals = raw.view(np.int64)
            if signed:
                sign = np.int64(1 << (width - 1))
                vals = (vals ^ sign) - sign
            return vals
        ints = [int(v) for v in raw]
        if signed:
            ints = [v - (1 << 64) if v >> 63 else v for v in ints]
        return np.array(ints, dtype=object)

    def run(self, in_words=None, *, in_valid=None, out_ready=None, n_cycles=None,
            flush_cycles: int = 64, inputs: dict | None = None, writes: list | None = None,
            probe: dict | None = None, final: dict | None = None,
            trace: str | Path | None = None,
            trace_window: tuple[int, int] | None = None) -> StreamResult:
        """Run from reset; same arguments and result as :func:`cosim.backends.pysim.run_stream`.

        Parameters
        ----------
        in_words, in_valid, out_ready, n_cycles, flush_cycles
            As in :func:`cosim.backends.pysim.run_stream`.
        inputs : dict of port name -> int, or list of (port, int)
            Constant values of other input ports: Verilog names such as ``"freq"`` as dict
            keys, or ``Value`` objects of the component in pairs (Amaranth values are
            unhashable); masked to the port width.
        writes : list of (cycle, port, value)
            ``port`` takes ``value`` from ``cycle`` on (applied before that cycle's edge).
        probe : dict of name -> port
            Record top-level ports (not internal signals) every cycle, sampled where the
            clock edge sees them, as ``run_stream`` does.
        final : dict of name -> port
            Top-level ports read once, after the last clock edge (``StreamResult.final``).
        trace : path, optional
            Write a waveform, FST if the suffix is ``.fst``, else VCD (opt-in; builds a
            separate traced library; put the file under ``build/``). Time unit: half a
            clock cycle (cycle ``n`` is at times ``2n`` and ``2n+1``).
        trace_window : (start, stop), optional
            Only dump cycles ``start <= cycle < stop`` (default: all).
        """
        trace_kind = None
        if trace is not None:
            trace_kind = "fst" if str(trace).endswith(".fst") else "vcd"
            self._ensure_lib(trace_kind)
        lib = self._libs[trace_kind or ""]

        has_in = in_words is not None
        if has_in and "i__valid" not in self._by_name:
            raise ValueError("in_words given but the component has no input stream `i`")
        if has_in and "i__payload" not in self._by_name:
            # Zero-width payload (a strobe stream): only the number of words matters.
            words_u64 = np.zeros(len(np.asarray(in_words)), dtype=np.uint64)
        elif has_in:
            pin = self.ports[self._by_name["i__payload"]]
            words_u64 = self._to_u64(in_words, pin.width)
        else:
            words_u64 = np.zeros(0, dtype=np.uint64)
        n_in = len(words_u64) // (limbs(self.ports[self._by_name["i__payload"]].width)
                                  if has_in and "i__payload" in self._by_name else 1)
        valid_u8 = np.zeros(0, np.uint8) if in_valid is None else \
            np.ascontiguousarray(np.asarray(in_valid, dtype=bool).astype(np.uint8))
        ready_u8 = np.zeros(0, np.uint8) if out_ready is None else \
            np.ascontiguousarray(np.asarray(out_ready, dtype=bool).astype(np.uint8))
        const_inputs = [(self._input_index(p), int(v)) for p, v in input_items(inputs)]
        write_list = sorted(((int(c), self._input_index(p), int(v)) for c, p, v in (writes or [])),
                            key=lambda w: w[0])
        probe = dict(probe or {})
        probe_idx = np.array([self.port_index(p) for p in probe.values()], dtype=np.int32)
        n_probe = len(probe_idx)
        final = {k: self.port_index(v) for k, v in (final or {}).items()}
        final_vals: dict[str, int] = {}
        if n_cycles is not None and n_cycles < 0:
            raise ValueError(f"n_cycles must be >= 0, not {n_cycles}")

        a = RunArgs()
        a.in_words, a.n_in, a.has_in = words_u64.ctypes.data, n_in, int(has_in)
        a.in_valid, a.n_valid = valid_u8.ctypes.data, len(valid_u8)
        a.out_ready, a.n_ready = ready_u8.ctypes.data, len(ready_u8)
        a.n_cycles = -1 if n_cycles is None else int(n_cycles)
        a.cyc, a.accepted, a.flush_left = 0, 0, int(flush_cycles)
        a.trace_start, a.trace_stop = (0, 1 << 62) if trace_window is None else map(int, trace_window)
        a.probe_idx, a.n_probe = probe_idx.ctypes.data, n_probe

        out_cap = _OUT_CHUNK if n_cycles is None else max(1, min(_OUT_CHUNK, int(n_cycles)))
        out_chunks: list[tuple[np.ndarray, np.ndarray]] = []
        probe_chunks: list[np.ndarray] = []
        chunk_max = _PROBE_CHUNK if n_probe else _CHUNK_CYCLES
        probe_buf = np.zeros((chunk_max, max(n_probe, 1)), dtype=np.uint64)
        a.probe_buf = probe_buf.ctypes.data

        o_nl = limbs(self.ports[self._by_name["o__payload"]].width)

        def new_out_buffer():
            ow = np.empty(out_cap * o_nl, dtype=np.uint64)
            oc = np.empty(out_cap, dtype=np.int64)
            out_chunks.append((ow, oc))
            a.out_words, a.out_cycles, a.out_cap, a.n_out = ow.ctypes.data, oc.ctypes.data, out_cap, 0

        if trace is not None:
            Path(trace).parent.mkdir(parents=True, exist_ok=True)
        handle = lib.sim_new(str(trace).encode() if trace is not None else None)
        try:
            for idx, v in const_inputs:
                lib.sim_set(handle, idx, v & 0xFFFF_FFFF_FFFF_FFFF)
            new_out_buffer()
            w = 0
            while True:
                while w < len(write_list) and write_list[w][0] <= a.cyc:
                    lib.sim_set(handle, write_list[w][1], write_list[w][2] & 0xFFFF_FFFF_FFFF_FFFF)
                    w += 1
                start = a.cyc
                a.stop_cycle = start + chunk_max
                if w < len(write_list):
                    a.stop_cycle = min(a.stop_cycle, write_list[w][0])
                status = lib.sim_run(handle, ctypes.byref(a))
                if n_probe and a.cyc > start:
                    probe_chunks.append(probe_buf[:a.cyc - start, :n_probe].copy())
                if status == _STATUS_DONE:
                    break
                if status == _STATUS_FULL:
                    out_chunks[-1] = (out_chunks[-1][0][:a.n_out * o_nl],
                                      out_chunks[-1][1][:a.n_out])
                    new_out_buffer()
            for fname, idx in final.items():
                p = self.ports[idx]
                final_vals[fname] = int(self._from_u64(
                    np.array([lib.sim_get(handle, idx)], dtype=np.uint64), p.width, p.signed)[0])
        finally:
            lib.sim_free(handle)
        out_chunks[-1] = (out_chunks[-1][0][:a.n_out * o_nl], out_chunks[-1][1][:a.n_out])

        pout = self.ports[self._by_name["o__payload"]]
        raw = np.concatenate([ow for ow, _ in out_chunks])
        cycles = np.concatenate([oc for _, oc in out_chunks])
        words = self._from_u64(raw, pout.width, pout.signed)
        probes = {}
        if n_probe:
            allp = np.concatenate(probe_chunks) if probe_chunks else np.zeros((0, n_probe), np.uint64)
            for j, pname in enumerate(probe):
                p = self.ports[probe_idx[j]]
                probes[pname] = self._from_u64(np.ascontiguousarray(allp[:, j]), p.width,
                                               p.signed).astype(np.int64)
        return StreamResult(words=words, cycles=cycles, n_cycles=int(a.cyc),
                            in_accepted=int(a.accepted), probes=probes, final=final_vals)

    def open(self, inputs: dict | None = None) -> VerilatorSession:
        """A :class:`VerilatorSession` of this build: the Verilated model created once, reset,
        ``inputs`` set (as in :meth:`run`), and kept alive between steps."""
        return VerilatorSession(self, inputs=inputs)


# -- persistent sessions ---------------------------------------------------------------------


class VerilatorSession(FrontendSession):
    """The compiled model of a :class:`VerilatorStreamSim` kept alive across steps.

    The harness's ``sim_run`` is called once per step (and at each write inside it) with the
    step's words and ``ready`` pattern, counting that call's cycles from 0; the model, its
    registers and the payload it was last offered persist between calls, so N steps give the
    bits of one :meth:`VerilatorStreamSim.run` (same per-cycle protocol). Implements
    :class:`cosim.core.session.FrontendSession`. No waveform (a trace's time base is per call:
    use :meth:`VerilatorStreamSim.run` with ``trace=``).
    """

    backend = "verilator"

    def __init__(self, sim: VerilatorStreamSim, inputs: dict | None = None):
        super().__init__()
        self.sim = sim
        self._lib = sim._libs[""]
        self._handle = None
        self._has_in = "i__valid" in sim._by_name
        self._pin = sim.ports[sim._by_name["i__payload"]] if "i__payload" in sim._by_name \
            else None
        self._pout = sim.ports[sim._by_name["o__payload"]]
        const = [(sim._input_index(p), int(v)) for p, v in input_items(inputs)]
        self._handle = self._lib.sim_new(None)
        for idx, v in const:
            self._lib.sim_set(self._handle, idx, v & 0xFFFF_FFFF_FFFF_FFFF)

    def _check_port(self, port) -> None:
        self.sim._input_index(port)

    def _read(self, port):
        idx = self.sim.port_index(port)
        p = self.sim.ports[idx]
        raw = np.array([self._lib.sim_get(self._handle, idx)], dtype=np.uint64)
        return int(self.sim._from_u64(raw, p.width, p.signed)[0])

    def _step(self, queue, ready, n, writes):
        sim, lib = self.sim, self._lib
        start = self.cycle
        if not self._has_in:
            words_u64 = np.zeros(0, dtype=np.uint64)
        elif self._pin is not None:
            words_u64 = sim._to_u64(queue, self._pin.width)
        else:       # zero-width payload: only the number of words matters
            words_u64 = np.zeros(len(queue), dtype=np.uint64)
        r = ready_window(ready, start, n)
        ready_u8 = np.zeros(0, np.uint8) if r is None else np.ascontiguousarray(r.astype(np.uint8))
        valid_u8 = np.zeros(0, np.uint8)
        wl = [(c - start, sim._input_index(p), v) for c, p, v in writes]
        a = RunArgs()
        a.in_words, a.n_in, a.has_in = words_u64.ctypes.data, len(words_u64), int(self._has_in)
        a.in_valid, a.n_valid = valid_u8.ctypes.data, 0
        a.out_ready, a.n_ready = ready_u8.ctypes.data, len(ready_u8)
        a.n_cycles = n
        a.cyc, a.accepted, a.flush_left = 0, 0, 0
        a.trace_start, a.trace_stop = 0, 0
        probe_idx = np.zeros(1, np.int32)
        probe_buf = np.zeros((1, 1), np.uint64)
        a.probe_idx, a.n_probe, a.probe_buf = probe_idx.ctypes.data, 0, probe_buf.ctypes.data
        cap = max(1, min(_OUT_CHUNK, n))
        chunks: list[tuple[np.ndarray, np.ndarray]] = []

        def new_out():
            ow, oc = np.empty(cap, np.uint64), np.empty(cap, np.int64)
            chunks.append((ow, oc))
            a.out_words, a.out_cycles, a.out_cap, a.n_out = ow.ctypes.data, oc.ctypes.data, cap, 0
        new_out()
        w = 0
        while True:
            while w < len(wl) and wl[w][0] <= a.cyc:
                lib.sim_set(self._handle, wl[w][1], wl[w][2] & 0xFFFF_FFFF_FFFF_FFFF)
                w += 1
            a.stop_cycle = a.cyc + _CHUNK_CYCLES
            if w < len(wl):
                a.stop_cycle = min(a.stop_cycle, wl[w][0])
            status = lib.sim_run(self._handle, ctypes.byref(a))
            if status == _STATUS_DONE:
                break
            if status == _STATUS_FULL:
                chunks[-1] = (chunks[-1][0][:a.n_out], chunks[-1][1][:a.n_out])
                new_out()
        chunks[-1] = (chunks[-1][0][:a.n_out], chunks[-1][1][:a.n_out])
        raw = np.concatenate([ow for ow, _ in chunks])
        cycles = np.concatenate([oc for _, oc in chunks]) + np.int64(start)
        words = sim._from_u64(raw, self._pout.width, self._pout.signed)
        return words, cycles, int(a.accepted) if self._has_in else 0

    def _close(self):
        if self._handle is not None:
            self._lib.sim_free(self._handle)
            self._handle = None

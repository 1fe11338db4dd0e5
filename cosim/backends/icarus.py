"""Event-driven simulation of a stream component with Icarus Verilog, driven by cocotb.

The third simulator of the exported Verilog, independent of the other two: Amaranth's own
simulator runs the design before export (:mod:`cosim.backends.pysim`), Verilator compiles a
respelled copy of the export into C++ (:mod:`cosim.backends.verilator`), and Icarus
interprets the exported text itself (:func:`cosim.backends.verilog.verilog_text`, the same
text that is linted and synthesised), unmodified, as its top module.

- Build: ``cocotb_tools.runner.get_runner("icarus").build`` compiles the Verilog as
  Verilog-2005 (``iverilog -g2005``, :data:`ICARUS_FLAGS`: the language yosys writes) into
  ``build/icarus/<sha256>/sim.vvp``, the key hashing the Verilog text, the flags, the Icarus
  and cocotb versions and the testbench (:mod:`cosim.backends.icarus_tb`); a design built
  before is not compiled again. Not ``-g2012`` (the runner's default): under SystemVerilog
  rules a variable's declaration initializer is applied before any process starts, so the
  initializer yosys gives every combinational ``always @*`` block to run it at time 0 makes no
  event, and a block whose inputs are all initialised registers keeps X until one of them
  changes -- an X select that four-state ``if`` reads as false (a channel's first FIFO record
  lost its last three words that way, while the model, Amaranth and Verilator agreed).
- Run: :class:`IcarusSession` (a :class:`cosim.core.session.FrontendSession`) starts
  ``vvp`` through the runner's ``test`` in a thread, with :mod:`cosim.backends.icarus_tb` as
  cocotb's test module; the simulator stays alive between steps, each step one message over a
  Unix socket with its stimulus as whole arrays (input words, ``valid``, ``ready``, writes)
  and one answer with the output words and their cycles, so Python's per-cycle work is the
  cocotb coroutine's and nothing else. Per cycle the coroutine does what the Verilator harness
  does (module doc of :mod:`cosim.backends.icarus_tb`); ``rst`` and every input nobody
  writes are held at 0, as Verilator's wrapper ties them and ``amaranth.sim`` leaves them.
- Four states: Icarus keeps X (unknown) and Z (undriven) bits, which the two-state
  simulators cannot represent (Verilator makes them 0 or 1). An X or Z on ``o.valid``, on
  ``i.ready`` when a word is offered, on ``o.payload`` when a word is taken, or on any output
  at a step's last edge (or a port read) fails the run with :class:`UnknownValueError`
  naming the port, its bits and the cycle.
- :class:`IcarusStreamSim` builds once and runs records like
  :func:`cosim.backends.pysim.run_stream` (:meth:`IcarusStreamSim.run`, one session from
  reset) or opens sessions (:meth:`IcarusStreamSim.open`).

Speed: ~0.3-2e3 cycles per second for a whole top (Icarus' event scheduling of the design
and one cocotb edge trigger per cycle); short windows only. :func:`icarus_available` says whether
``iverilog``/``vvp`` and cocotb are installed (``make setup`` installs both).
"""
from __future__ import annotations

import hashlib
import logging
import os
import shutil
import socket
import subprocess
import tempfile
import threading
import time
from multiprocessing.connection import Connection
from pathlib import Path

import numpy as np

from ..core.provenance import REPO_ROOT
from ..core.session import FrontendSession, ready_window
from .build_cache import cached_build
from .pysim import StreamResult, input_items
from .verilator_harness import as_value
from .verilog import PortInfo, stream_ports, verilog_text

__all__ = ["IcarusStreamSim", "IcarusSession", "UnknownValueError", "icarus_available",
           "icarus_missing_message", "icarus_version"]

#: Compiler flags after the runner's own (``-g2012``, overridden: module doc).
ICARUS_FLAGS = ("-g2005",)

#: The cocotb test module run inside ``vvp`` (imported there, not here: it needs cocotb).
TB_MODULE = "cosim.backends.icarus_tb"
#: Its source (part of the build key).
TB_PATH = Path(__file__).with_name("icarus_tb.py")
#: The environment variable naming a session's socket (``icarus_tb.SOCKET_ENV``).
SOCKET_ENV = "KFNAV_ICARUS_SOCKET"
#: Seconds to wait for ``vvp`` to start and connect to a session's socket.
CONNECT_TIMEOUT_S = 120.0
#: The ports the stream protocol drives (not settable through ``inputs``/``writes``).
STREAM_PORTS = ("i__valid", "i__payload", "o__ready")


def icarus_available() -> bool:
    """True if ``iverilog`` and ``vvp`` are on PATH and cocotb is installed."""
    if shutil.which("iverilog") is None or shutil.which("vvp") is None:
        return False
    try:
        import cocotb_tools.runner  # noqa: F401
    except ImportError:
        return False
    return True


def icarus_missing_message() -> str:
    return ("Icarus Verilog (iverilog, vvp) or cocotb not found: install them with `make "
            "setup` (apt-get install iverilog; pip install -e '.[test]') or use the "
            "model/pysim/verilator backends")


def icarus_version() -> str:
    """``iverilog -V``'s first line and the cocotb version (both part of the build key)."""
    import cocotb
    exe = shutil.which("iverilog")
    if exe is None:
        raise RuntimeError(icarus_missing_message())
    out = subprocess.run([exe, "-V"], capture_output=True, text=True, check=False).stdout
    return f"{out.splitlines()[0] if out else 'iverilog'}; cocotb {cocotb.__version__}"


def signed_words(values, width: int, signed: bool) -> np.ndarray:
    """Unsigned port values as :func:`cosim.backends.pysim.run_stream` returns them: int64
    up to 63 bits, Python ints in an object array wider; two's complement if ``signed``."""
    ints = [int(v) for v in values]
    if signed:
        ints = [v - (1 << width) if v >> (width - 1) else v for v in ints]
    if width <= 63 or (not ints and width <= 64):
        return np.array(ints, dtype=np.int64)
    return np.array(ints, dtype=object)


class UnknownValueError(AssertionError):
    """An output of the design was X or Z where a simulator of two-state values would have
    read 0 or 1 (an :class:`AssertionError`: a check that sees one fails, saying which port,
    its bits and the cycle)."""


class IcarusStreamSim:
    """A component compiled with Icarus Verilog (``iverilog``), run by cocotb in ``vvp``.

    Parameters
    ----------
    component : wiring.Component
        A ``sync``-domain component with an output stream ``o`` and optionally an input
        stream ``i``; other input ports can be set (``inputs``, ``writes``), any port read.
    name : str
        Verilog top module name.
    build_dir : path, optional
        Cache directory (default ``<repo>/build/icarus``).

    Attributes
    ----------
    built : bool
        True if this construction compiled the design, False if it found a cached build.
    build_path : Path
        The build directory in use (``sim.vvp``, the Verilog, ``build.log``).
    verilog : str
        The Verilog text simulated (the export, unmodified).
    ports : list of PortInfo
        Ports of the component and their Verilog names.
    """

    def __init__(self, component, name: str = "dut", *, build_dir: str | Path | None = None):
        self.component = component
        self.name = name
        self.ports: list[PortInfo] = stream_ports(component)
        self._by_name = {p.name: p for p in self.ports}
        self._by_id = {id(p.value): p for p in self.ports}
        self.verilog = verilog_text(component, name=name, emit_src=False)
        if not icarus_available():   # after the export: the component is elaborated either way
            raise RuntimeError(icarus_missing_message())
        root = Path(build_dir) if build_dir is not None else REPO_ROOT / "build" / "icarus"
        self.built = False
        self.build_path = self._ensure_build(root)

    # -- building -------------------------------------------------------------------------
    def _cache_key(self) -> str:
        h = hashlib.sha256()
        for part in (self.verilog, self.name, " ".join(ICARUS_FLAGS), icarus_version(),
                     TB_PATH.read_text()):
            h.update(part.encode())
            h.update(b"\0")
        return h.hexdigest()

    def _ensure_build(self, root: Path) -> Path:
        out, self.built = cached_build(root, self._cache_key(), "sim.vvp", self._compile)
        return out

    def _compile(self, tmp: Path) -> None:
        """Compile into the empty directory ``tmp`` (:func:`cached_build` moves it)."""
        from cocotb_tools.runner import get_runner
        src = tmp / f"{self.name}.v"
        src.write_text(self.verilog)
        runner = get_runner("icarus")
        try:
            runner.build(sources=[src], hdl_toplevel=self.name, build_dir=tmp,
                         timescale=("1ns", "1ps"), log_file=tmp / "build.log", always=True,
                         build_args=list(ICARUS_FLAGS))
        except (RuntimeError, SystemExit) as e:
            log = (tmp / "build.log").read_text() if (tmp / "build.log").exists() else ""
            tail = "\n".join(log.splitlines()[-40:])
            raise RuntimeError(f"Icarus build of {self.name} failed ({e}):\n{tail}") from None

    # -- ports ----------------------------------------------------------------------------
    def port(self, port) -> PortInfo:
        """The :class:`PortInfo` of ``port`` (a Verilog port name or an Amaranth value)."""
        if isinstance(port, str):
            if port not in self._by_name:
                raise KeyError(f"no port named {port!r}; ports: {sorted(self._by_name)}")
            return self._by_name[port]
        value = as_value(port)
        if id(value) not in self._by_id:
            raise KeyError(f"{port!r} is not a port of the component (ports are its "
                           f"signature members: {sorted(self._by_name)})")
        return self._by_id[id(value)]

    def input_port(self, port) -> PortInfo:
        """The input port ``port`` that ``inputs``/``writes`` may set (not a stream port)."""
        p = self.port(port)
        if p.direction != "in":
            raise ValueError(f"port {p.name} is an output; only inputs can be set")
        if p.name in STREAM_PORTS:
            raise ValueError(f"port {p.name} is driven by the stream runner, not by inputs/writes")
        return p

    # -- running --------------------------------------------------------------------------
    def open(self, inputs: dict | None = None) -> IcarusSession:
        """An :class:`IcarusSession` of this build: ``vvp`` started, every input at 0 but
        ``inputs`` (as in :meth:`run`), kept alive between steps."""
        return IcarusSession(self, inputs=inputs)

    def run(self, in_words=None, *, in_valid=None, out_ready=None,
            n_cycles: int | None = None, flush_cycles: int = 64, inputs: dict | None = None,
            writes: list | None = None, probe: dict | None = None,
            final: dict | None = None) -> StreamResult:
        """Run from reset; the arguments and the result of
        :func:`cosim.backends.pysim.run_stream`: ``n_cycles`` cycles, or (None) until every
        input word is taken and then ``flush_cycles`` more; ``writes``: ``(cycle, port,
        value)``, ``port`` a name or an Amaranth value of the component; ``probe``: name ->
        port recorded at every edge; ``final``: ports read after the last edge."""
        if n_cycles is not None and (isinstance(n_cycles, bool) or
                                     not isinstance(n_cycles, (int, np.integer)) or n_cycles < 0):
            raise ValueError(f"n_cycles must be an integer >= 0, not {n_cycles!r}")
        if isinstance(flush_cycles, bool) or not isinstance(flush_cycles, (int, np.integer)) \
                or flush_cycles < 0:
            raise ValueError(f"flush_cycles must be an integer >= 0, not {flush_cycles!r}")
        if in_words is not None and "i__valid" not in self._by_name:
            raise ValueError("in_words given but the component has no input stream `i`")
        probe = {k: self.port(v) for k, v in (probe or {}).items()}
        if out_ready is not None:   # as run_stream: entries past n_cycles are not used
            out_ready = np.asarray(out_ready, dtype=bool).ravel()
        if in_valid is not None:
            in_valid = np.asarray(in_valid, dtype=bool).ravel()
        n_in = 0 if in_words is None else np.asarray(in_words).size
        with self.open(inputs) as s:
            s._probes = probe
            for c, p, v in writes or []:
                s.write(self.input_port(p).name, int(v), cycle=int(c))
            if n_cycles is not None:
                steps = [self._step_from(s, in_words, in_valid, out_ready, int(n_cycles))]
            else:
                # Steps of as many cycles as words are left (one word per cycle at most), so
                # the last word is taken on a step's last cycle; then the flush.
                steps, left = [], n_in
                queued = in_words
                while left:
                    steps.append(self._step_from(s, queued, in_valid, out_ready, left))
                    queued, left = None, n_in - sum(r.in_accepted for r in steps)
                steps.append(self._step_from(s, None, None, out_ready, int(flush_cycles)))
            fin = {k: s.read(self.port(p).name) for k, p in (final or {}).items()}
            probes = {k: np.concatenate(s.probes[k]) if s.probes.get(k) else
                      np.zeros(0, np.int64) for k in probe}
        words = [r.words for r in steps]
        return StreamResult(words=np.concatenate(words) if len(words) > 1 else words[0],
                            cycles=np.concatenate([r.cycles for r in steps]),
                            n_cycles=sum(r.n_cycles for r in steps),
                            in_accepted=sum(r.in_accepted for r in steps),
                            probes=probes, final=fin)


    @staticmethod
    def _step_from(s, words, in_valid, out_ready, n):
        """``s.step`` of ``n`` cycles from the session's cycle, ``in_valid``/``out_ready``
        (per cycle from reset) cut to them."""
        a = s.cycle
        v = None if in_valid is None else in_valid[a:a + n]
        r = None if out_ready is None else out_ready[a:a + n]
        return s.step(words, r, n_cycles=n, valid=v)


class _QuietSkip(logging.Filter):
    """Drops the runner's "Skipping compilation" warning of a session's set-up build."""

    def filter(self, record):
        return not record.getMessage().startswith("Skipping compilation")


class IcarusSession(FrontendSession):
    """``vvp`` running :mod:`cosim.backends.icarus_tb`, kept alive across steps (module doc).

    Implements :class:`cosim.core.session.FrontendSession`; :meth:`step` also takes
    ``valid`` (the input's ``valid`` per cycle of the step, shorter: valid after its end).
    The session's log (cocotb's and vvp's output) is ``log_path``, removed on a clean close.
    """

    backend = "icarus"

    def __init__(self, sim: IcarusStreamSim, inputs: dict | None = None):
        super().__init__()
        from cocotb_tools.runner import get_runner
        self.sim = sim
        self._conn: Connection | None = None
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._sock_dir: str | None = None
        self._valid = None
        self._unknown: str | None = None
        #: Per probe name, the values of each step (:meth:`probe`).
        self.probes: dict[str, list] = {}
        self._probes: dict[str, PortInfo] = {}   # name -> port recorded at every edge
        self._pin = sim.port("i__payload") if "i__payload" in sim._by_name else None
        self._pout = sim.port("o__payload")
        init = {"rst": 0}   # clk: the testbench's clock
        init.update({p.name: 0 for p in sim.ports if p.direction == "in"})
        for p, v in input_items(inputs):
            info = sim.input_port(p)
            init[info.name] = int(v) & ((1 << info.width) - 1)
        self.run_dir = Path(tempfile.mkdtemp(prefix="run-", dir=sim.build_path))
        self.log_path = self.run_dir / "sim.log"
        # The socket lives in a short /tmp path (Unix socket paths are limited to ~100 bytes).
        self._sock_dir = tempfile.mkdtemp(prefix="kfnav-icarus-")
        sock_path = os.path.join(self._sock_dir, "s")
        server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        server.bind(sock_path)
        server.listen(1)
        # The runner's test() needs its build() called first; the design is built (sim.vvp is
        # newer than its source), so this only sets the runner up and compiles nothing.
        runner = get_runner("icarus")
        quiet = _QuietSkip()
        runner.log.addFilter(quiet)
        try:
            runner.build(sources=[sim.build_path / f"{sim.name}.v"], hdl_toplevel=sim.name,
                         build_dir=sim.build_path, log_file=self.run_dir / "build.log",
                         build_args=list(ICARUS_FLAGS))
        finally:
            runner.log.removeFilter(quiet)

        def serve():
            try:
                runner.test(test_module=TB_MODULE, hdl_toplevel=sim.name,
                            build_dir=sim.build_path, test_dir=self.run_dir,
                            results_xml=str(self.run_dir / "results.xml"),
                            extra_env={SOCKET_ENV: sock_path},
                            log_file=self.log_path)
            except BaseException as e:   # SystemExit from the runner included
                self._error = e
        self._thread = threading.Thread(target=serve, name=f"icarus-{sim.name}", daemon=True)
        self._thread.start()
        try:   # on failure, __del__ -> close() stops vvp and removes the socket's directory
            server.settimeout(0.2)
            t0 = time.monotonic()
            while True:
                try:
                    conn, _ = server.accept()
                    break
                except socket.timeout:
                    if not self._thread.is_alive() or time.monotonic() - t0 > CONNECT_TIMEOUT_S:
                        raise RuntimeError(self._failure("vvp did not connect")) from None
            conn.settimeout(None)
            self._conn = Connection(conn.detach())
        finally:
            server.close()
        self._call(("init", init, [p.name for p in sim.ports if p.direction == "out"]))

    # -- the link to vvp ------------------------------------------------------------------
    def _failure(self, what: str) -> str:
        log = self.log_path.read_text(errors="replace") if self.log_path.exists() else ""
        tail = "\n".join(log.splitlines()[-30:])
        why = f" ({self._error!r})" if self._error is not None else ""
        return f"Icarus session of {self.sim.name}: {what}{why}; log {self.log_path}:\n{tail}"

    def _call(self, msg):
        try:
            self._conn.send(msg)
            return self._conn.recv()
        except (EOFError, OSError):
            self._thread.join(timeout=30)
            raise RuntimeError(self._failure("the simulator stopped")) from None

    # -- FrontendSession ------------------------------------------------------------------
    def step(self, in_words=None, ready=None, *, n_cycles: int | None = None, valid=None):
        self._valid = None if valid is None else np.asarray(valid, dtype=bool).ravel()
        try:
            return super().step(in_words, ready, n_cycles=n_cycles)
        finally:
            self._valid = None

    def _check_port(self, port) -> None:
        self.sim.input_port(port)

    def _read(self, port):
        p = self.sim.port(port)
        v = self._call(("read", p.name))
        if isinstance(v, str):
            raise UnknownValueError(f"Icarus: port {p.name} of {self.sim.name} is {v} (X or Z "
                                    f"bits) after cycle {self.cycle}")
        return int(signed_words([v], p.width, p.signed)[0])

    def _step(self, queue, ready, n, writes):
        start = self.cycle
        if self._pin is None:
            words = [0] * len(queue)
        else:
            mask = (1 << self._pin.width) - 1
            q = np.asarray(queue)
            words = ((q.astype(np.int64).view(np.uint64) & np.uint64(mask)).tolist()
                     if q.dtype != object and self._pin.width <= 64
                     else [int(w) & mask for w in q])
        r = ready_window(ready, start, n)
        rdy = [] if r is None else r.tolist()
        vld = [] if self._valid is None else self._valid.tolist()
        wl = []
        for c, port, v in writes:
            p = self.sim.input_port(port)
            wl.append((int(c) - start, p.name, int(v) & ((1 << p.width) - 1)))
        if self._unknown is not None:
            raise UnknownValueError(self._unknown)
        probes = [q.name for q in self._probes.values()]
        out_w, out_c, accepted, unknown, pv = self._call(("step", words, vld, rdy, int(n), wl,
                                                          probes))
        if unknown is not None:
            c, port, bits = unknown
            self._unknown = (f"Icarus: output {port} of {self.sim.name} is {bits} (X or Z "
                             f"bits) at the edge of cycle {start + c}, after {len(out_w)} "
                             f"output words of this step; the session stops there")
            raise UnknownValueError(self._unknown)
        words_out = signed_words(out_w, self._pout.width, self._pout.signed)
        for (k, q), vals in zip(self._probes.items(), pv):
            self.probes.setdefault(k, []).append(signed_words(vals, q.width, q.signed))
        return words_out, np.asarray(out_c, np.int64) + np.int64(start), int(accepted)

    def _close(self):
        ok = False
        if self._conn is not None:
            try:
                ok = self._call(("close",)) == "ok"
            except RuntimeError:
                ok = False
            self._conn.close()
            self._conn = None
        if self._thread is not None:
            self._thread.join(timeout=60)
        if self._sock_dir is not None:
            shutil.rmtree(self._sock_dir, ignore_errors=True)
        if ok and self._error is None and not self._thread.is_alive():
            shutil.rmtree(self.run_dir, ignore_errors=True)

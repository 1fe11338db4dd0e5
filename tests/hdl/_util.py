"""Helpers shared by the HDL block tests (imported as ``_util``; see ``conftest.py``).

- :class:`WithClear`: a block with a synchronous ``clear`` input (reset mid-run).
- :func:`assert_lints_clean`: export with :mod:`cosim.tools.verilog` and lint with Verilator.
- :data:`needs_verilator`, :func:`verilator_sim`, :func:`assert_same_stream`: the
  "exported Verilog simulates identically" checks against :func:`cosim.backends.pysim.run_stream`.
- :func:`accepted_cycles`: when ``run_stream`` transfers each input word.
"""
from __future__ import annotations


import numpy as np
import pytest
from amaranth.hdl import Module, ResetInserter
from amaranth.lib import wiring
from amaranth.lib.wiring import In

from cosim.backends.pysim import StreamResult
from cosim.backends.verilator import VerilatorStreamSim
from cosim.backends.verilator_harness import verilator_available
from cosim.tools.verilog import export_verilog, lint
from cosim.backends.verilog import verilator_missing_message
from cosim.core.executables import find_executable

__all__ = ["WithClear", "accepted_cycles", "assert_lints_clean", "needs_verilator",
           "verilator_sim", "assert_same_stream"]


class WithClear(wiring.Component):
    """``dut`` with an extra synchronous ``clear`` input that resets all of it.

    Every member of ``dut``'s signature is passed through under the same name (streams are
    connected, plain ports assigned), so stimulus written for the bare block works as is.
    """

    def __init__(self, dut: wiring.Component):
        self.dut = dut
        super().__init__({**dict(dut.signature.members), "clear": In(1)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = ResetInserter(self.clear)(self.dut)
        for name, member in self.dut.signature.members.items():
            outer, inner = getattr(self, name), getattr(self.dut, name)
            if member.is_signature:
                if member.flow == In:
                    wiring.connect(m, wiring.flipped(outer), inner)
                else:
                    wiring.connect(m, inner, wiring.flipped(outer))
            elif member.flow == In:
                m.d.comb += inner.eq(outer)
            else:
                m.d.comb += outer.eq(inner)
        return m


def accepted_cycles(n: int, in_valid) -> np.ndarray:
    """Cycle of each of ``n`` input transfers under ``run_stream``'s offer rule for an
    always-ready input (offered every cycle once the ``in_valid`` pattern runs out)."""
    if in_valid is None:
        return np.arange(n)
    cyc = np.flatnonzero(np.asarray(in_valid, dtype=bool))[:n]
    return np.r_[cyc, len(in_valid) + np.arange(n - len(cyc))]


def assert_lints_clean(component: wiring.Component, name: str, *, check_width: bool = False):
    """Export ``component`` to ``build/verilog/<name>.v`` and assert Verilator ``-Wall``
    finds nothing beyond :data:`cosim.tools.verilog.LINT_WAIVERS`.

    ``check_width=True`` turns the ``WIDTH`` warning back on, for blocks whose Verilog is
    clean of it (their tests never waived it).
    """
    if find_executable("verilator") is None:
        pytest.skip(verilator_missing_message())
    path = export_verilog(component, name=name)
    findings = lint(path, extra_args=("-Wwarn-WIDTH",) if check_width else ())
    assert findings == [], "\n".join(findings)


def needs_verilator(f):
    """Decorator for tests that compile a block with Verilator: marked ``verilator`` and
    skipped, with the reason, when the tool chain is missing."""
    f = pytest.mark.skipif(not verilator_available(),
                           reason="Verilator, make or a C++ compiler not found on PATH "
                                  "(install with `make setup`: apt-get install verilator)")(f)
    return pytest.mark.verilator(f)


def verilator_sim(component: wiring.Component, name: str) -> VerilatorStreamSim:
    """``component`` compiled with Verilator (cached under ``build/verilator``)."""
    return VerilatorStreamSim(component, name)


def assert_same_stream(got: StreamResult, want: StreamResult, what: str = ""):
    """Zero mismatches between two stream runs: every output word and its cycle, the run
    length and the number of inputs taken."""
    assert len(got.words) == len(want.words), f"{what}: {len(got.words)} vs {len(want.words)} words"
    np.testing.assert_array_equal(got.words, want.words, err_msg=f"{what}: words")
    np.testing.assert_array_equal(got.cycles, want.cycles, err_msg=f"{what}: output cycles")
    assert (got.n_cycles, got.in_accepted) == (want.n_cycles, want.in_accepted), what
    assert set(got.probes) == set(want.probes), what
    for k in want.probes:
        np.testing.assert_array_equal(got.probes[k], want.probes[k], err_msg=f"{what}: {k}")


# -- real/complex sample streams (CIC, FIR) ---------------------------------------------------
def channel_layout(width: int, channels: int):
    """``unpack_fields`` layout of a real (1) or complex {"i","q"} (2) sample of ``width``."""
    return [("i", width, True), ("q", width, True)][:channels]


def pack_channels(x: np.ndarray, width: int, channels: int) -> np.ndarray:
    """Samples (n,) or (n, 2) -> packed payload words."""
    from cosim.backends.pysim import pack_fields
    if channels == 1:
        return pack_fields({"i": x}, channel_layout(width, 1))
    return pack_fields({"i": x[:, 0], "q": x[:, 1]}, channel_layout(width, 2))


def unpack_channels(words: np.ndarray, width: int, channels: int) -> np.ndarray:
    """Packed payload words -> samples (n,) or (n, 2)."""
    from cosim.backends.pysim import unpack_fields
    f = unpack_fields(words, channel_layout(width, channels))
    return f["i"] if channels == 1 else np.stack([f["i"], f["q"]], axis=1)


def random_samples(rng, width: int, n: int, sample_shape) -> np.ndarray:
    """Uniform random signed ``width``-bit samples of shape (n, *sample_shape)."""
    lo, hi = -(1 << (width - 1)), 1 << (width - 1)
    return rng.integers(lo, hi, size=(n, *sample_shape), dtype=np.int64)


def gnss_stimulus(p, n, seed, writes_at=(), n_writes=0, ready_p=0.7, ch=1, pairs=None):
    """A GNSS channel/array test's stimulus on ``p`` (:class:`hdl.gnss.params.
    GnssChannelParams`): ``n`` random ADC words (``(n, 2)`` I/Q pairs with complex input),
    register writes -- ``n_writes`` per channel at random cycles, every register in turn on
    a random one of ``ch`` channels, or one per cycle of ``writes_at`` -- and a random DSP
    ``ready`` (probability ``ready_p``). ``pairs=True`` draws ``(n, 2)`` words whatever the
    input (a real-input test then takes a column)."""
    from hdl.gnss.params import REG_CARR_FREQ, REG_CODE_FREQ, REG_PRN
    rng = np.random.default_rng(seed)
    lo = -(1 << (p.adc_bits - 1))
    pairs = p.complex_input if pairs is None else pairs
    x = rng.integers(lo, -lo, (n, 2) if pairs else n)
    writes = []
    cyc = sorted(rng.choice(np.arange(10, n - 10), n_writes * ch, replace=False)) \
        if n_writes else list(writes_at)
    for k, c in enumerate(cyc):
        reg = k % 4
        chn = int(rng.integers(0, ch))
        if reg == REG_CARR_FREQ:
            v = p.carr_word(p.if_hz + float(rng.uniform(-5e3, 5e3)))
        elif reg == REG_CODE_FREQ:
            v = p.code_word(1.023e6 + float(rng.uniform(-50, 50)))
        elif reg == REG_PRN:
            v = int(rng.integers(1, 33))
        else:
            v = int(rng.integers(0, 1 << p.slew_bits))
        writes.append((int(c), 4 * chn + reg, v))
    ready = rng.random(n + 400) < ready_p
    return x, writes, ready

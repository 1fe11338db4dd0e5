"""Stream payloads wider than 64 bits on both simulation backends (a 144-bit correlator dump
needs them): pack/unpack, amaranth.sim and Verilator agree word for word and cycle for
cycle, signed and unsigned, across the 64-bit and 32-bit limb boundaries."""
from __future__ import annotations

import numpy as np
import pytest
from amaranth.hdl import Module, Value, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from cosim.backends.pysim import pack_fields, unpack_fields
from cosim.testing import check_stream


class _AddOne(wiring.Component):
    """Registered ``o = i + 1`` (wraps) with back-pressure, payload ``shape``."""

    def __init__(self, shape):
        super().__init__({"i": In(stream.Signature(shape)), "o": Out(stream.Signature(shape))})

    def elaborate(self, platform):
        m = Module()
        m.d.comb += self.i.ready.eq(~self.o.valid | self.o.ready)
        with m.If(self.i.ready):
            m.d.sync += [self.o.valid.eq(self.i.valid),
                         self.o.payload.eq(Value.cast(self.i.payload) + 1)]
        return m


def _wide_ints(rng, width, n):
    v = [int.from_bytes(rng.bytes((width + 7) // 8), "little") % (1 << width) for _ in range(n)]
    v[:4] = [0, (1 << width) - 1, 1 << (width - 1), (1 << 64) - 1 if width > 64 else 1]
    return np.array(v, dtype=object)


@pytest.mark.verilator
@pytest.mark.parametrize("width", [64, 128, 150])   # 1, 2 and 2.3 uint64 limbs
def test_unsigned_wide_payload_both_backends(width):
    rng = np.random.default_rng(width)
    x = _wide_ints(rng, width, 300)
    want = np.array([(int(v) + 1) % (1 << width) for v in x], dtype=object)
    ready = rng.random(500) < 0.7
    res = check_stream(_AddOne(unsigned(width)), want, x, ready=ready, name=f"add_one_u{width}")
    assert res.words.dtype == (object if width > 63 else np.int64)


@pytest.mark.verilator
def test_signed_wide_payload_both_backends():
    width = 100
    rng = np.random.default_rng(7)
    u = _wide_ints(rng, width, 200)
    x = np.array([v - (1 << width) if v >> (width - 1) else v for v in map(int, u)],
                 dtype=object)
    want = np.array([((v + 1 + (1 << (width - 1))) % (1 << width)) - (1 << (width - 1))
                     for v in map(int, x)], dtype=object)
    check_stream(_AddOne(signed(width)), want, x, name="add_one_s100")


def test_pack_unpack_struct_wider_than_63_bits():
    layout = [(f"{a}{b}", 24, True) for a in "epl" for b in "iq"]    # I/Q x E/P/L
    rng = np.random.default_rng(8)
    f = {name: rng.integers(-(1 << 23), 1 << 23, 50) for name, _, _ in layout}
    words = pack_fields(f, layout)
    assert words.dtype == object and max(map(int, words)) < 1 << 144
    back = unpack_fields(words, layout)
    for name in f:
        np.testing.assert_array_equal(back[name], f[name])


@pytest.mark.verilator
def test_struct_payload_144_bits_both_backends():
    """A correlator-dump struct (6 x signed 24) through both backends."""
    layout = data.StructLayout({f"{a}_{b}": signed(24)
                                for a in ("early", "prompt", "late") for b in "iq"})
    rng = np.random.default_rng(9)
    x = _wide_ints(rng, 144, 200)
    want = np.array([(int(v) + 1) % (1 << 144) for v in x], dtype=object)

    check_stream(_AddOne(layout), want, x, ready=rng.random(400) < 0.5, name="pass_struct144")

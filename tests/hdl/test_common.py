"""hdl.common: the shared rounding and saturation (every mode == dsp.fixed, in the
Amaranth simulator), and the constructor-error policy of every block."""
from __future__ import annotations

import numpy as np
import pytest
from amaranth.hdl import Module, Signal, signed
from amaranth.sim import Simulator

from dsp.fixed import OVERFLOWS, ROUNDINGS, FixedFormat, shift_right
from hdl.cic import Cic
from hdl.common import (NARROW_MUL_BITS, check_bool, check_params, const_mul, fit_width,
                        narrow_mul, round_shift)
from hdl.ddc import Ddc
from hdl.envelope import Envelope
from hdl.fir import Fir
from hdl.mixer import Mixer
from hdl.nco import Nco
from hdl.tacan.peak import PeakSearch
from hdl.tacan.frontend import TacanFrontEnd


def _comb_eval(width: int, build, values) -> list[int]:
    """Values of the combinational expression ``build(v)`` for each input value."""
    v = Signal(signed(width))
    out = build(v)
    o = Signal(out.shape())
    m = Module()
    m.d.comb += o.eq(out)
    sim = Simulator(m)
    got = []

    async def bench(ctx):
        for x in values:
            ctx.set(v, int(x))
            got.append(ctx.get(o))

    sim.add_testbench(bench)
    sim.run()
    return got


@pytest.mark.parametrize("rounding", ROUNDINGS)
@pytest.mark.parametrize("drop", [-2, 0, 1, 3])
def test_round_shift_equals_dsp_fixed(rounding, drop):
    """Every 8-bit input: the HDL rounding == dsp.fixed.shift_right (the models' rule)."""
    xs = np.arange(-128, 128)
    got = _comb_eval(8, lambda v: round_shift(v, drop, rounding), xs)
    np.testing.assert_array_equal(got, shift_right(xs, drop, rounding))


@pytest.mark.parametrize("c", list(range(0, 12)) + [15, 52, 255])
def test_const_mul(c):
    """Every 8-bit unsigned input: shifts and adds give x * c; up to 10 (the peak search's
    pair_keep and pair_balance) at most two terms, one adder."""
    xs = np.arange(256)
    got = _comb_eval(9, lambda v: const_mul(v.as_unsigned(), c), xs)
    np.testing.assert_array_equal(got, xs * c)
    if 0 < c <= 10:
        assert len(list(const_mul(Signal(8), c)._rhs_signals())) == 1    # x only
        assert str(const_mul(Signal(8), c)).count("(+") + str(
            const_mul(Signal(8), c)).count("(-") <= 1, c
    with pytest.raises(ValueError, match="integer constant >= 0"):
        const_mul(Signal(8), -1)


@pytest.mark.parametrize("wb", range(1, NARROW_MUL_BITS + 2))
@pytest.mark.parametrize("wa", [1, 3, 6])
def test_narrow_mul(wa, wb):
    """Every pair of signed inputs: the signed product, taken apart into shifted copies
    (no multiplier: no `*` in the expression) up to NARROW_MUL_BITS bits, a `*` above."""
    a, b = Signal(signed(wa)), Signal(signed(wb))
    out = narrow_mul(a, b)
    o = Signal(signed(wa + wb))
    m = Module()
    m.d.comb += o.eq(out)
    sim = Simulator(m)
    xs = range(-(1 << (wa - 1)), 1 << (wa - 1))
    ys = range(-(1 << (wb - 1)), 1 << (wb - 1))
    got = []

    async def bench(ctx):
        for x in xs:
            for y in ys:
                ctx.set(a, x)
                ctx.set(b, y)
                got.append(ctx.get(o))

    sim.add_testbench(bench)
    sim.run()
    assert got == [x * y for x in xs for y in ys]
    assert ("(*" in str(out)) == (min(wa, wb) > NARROW_MUL_BITS)


@pytest.mark.parametrize("overflow", OVERFLOWS)
def test_fit_width_equals_dsp_fixed(overflow):
    xs = np.arange(-128, 128)
    got = _comb_eval(8, lambda v: fit_width(v, 5, overflow), xs)
    want = FixedFormat(width=5, overflow=overflow).fit(xs)[0]
    np.testing.assert_array_equal(got, want)


def test_bad_modes():
    v = Signal(signed(8))
    with pytest.raises(ValueError, match=r"rounding must be one of .*, not 'nearest'"):
        round_shift(v, 2, "nearest")
    with pytest.raises(ValueError, match=r"overflow must be one of .*, not 'clip'"):
        fit_width(v, 4, "clip")


@pytest.mark.parametrize("block,article,cls", [
    (Cic, "a", "CicParams"), (Fir, "a", "FirParams"), (Mixer, "a", "MixerParams"),
    (Nco, "an", "NcoParams"), (Ddc, "a", "DdcParams"), (Envelope, "an", "EnvelopeParams"),
    (PeakSearch, "a", "PeakParams"), (TacanFrontEnd, "a", "TacanFrontendParams"),
])
def test_every_block_refuses_wrong_params_with_value_error(block, article, cls):
    """One policy: ValueError naming the rule and repeating the bad value."""
    with pytest.raises(ValueError, match=rf"^{block.__name__} needs {article} {cls}, not \{{'width': 3\}}$"):
        block({"width": 3})


def test_check_helpers():
    class Dummy:
        pass
    assert check_params(Dummy(), 3, int) == 3
    with pytest.raises(ValueError, match=r"Dummy flag must be True or False, not 1"):
        check_bool(Dummy(), "flag", 1)

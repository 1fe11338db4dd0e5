"""Complex mixer: Amaranth simulation == bit-exact model, corners, scaling, errors, lint;
the exported Verilog (Verilator) == Amaranth simulation == model."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from cosim.backends.pysim import pack_fields, run_stream, unpack_fields
from cosim.testing import check_stream
from hdl.mixer import Mixer
from hdl.model.mixer import MixerModel, MixerParams

from _util import accepted_cycles, assert_lints_clean, needs_verilator

ROUNDINGS = ("floor", "half_up", "half_even", "zero")


def _in_layout(p: MixerParams):
    a, b = p.in_width, p.lo_width
    x = [("xi", a, True), ("xq", a, True)] if p.complex_input else [("x", a, True)]
    return x + [("cos", b, True), ("sin", b, True)]


def _random_inputs(p: MixerParams, n: int, rng) -> dict:
    """Uniform words with 10 % of each operand forced to full scale (either sign)."""
    def draw(w):
        v = rng.integers(-(1 << (w - 1)), 1 << (w - 1), n)
        fs = rng.random(n) < 0.1
        v[fs] = rng.choice([-(1 << (w - 1)), (1 << (w - 1)) - 1], np.count_nonzero(fs))
        return v
    f = {"cos": draw(p.lo_width), "sin": draw(p.lo_width)}
    if p.complex_input:
        f["xi"], f["xq"] = draw(p.in_width), draw(p.in_width)
    else:
        f["x"] = draw(p.in_width)
    return f


def _model(p: MixerParams, f: dict):
    x = (f["xi"], f["xq"]) if p.complex_input else f["x"]
    return MixerModel(p).run(x, f["cos"], f["sin"])


def _out_layout(p: MixerParams):
    return [("i", p.out_width, True), ("q", p.out_width, True)]


def _sim(p: MixerParams, f: dict, in_valid=None):
    dut = Mixer(p)
    res = run_stream(dut, pack_fields(f, _in_layout(p)), in_valid=in_valid,
                     flush_cycles=p.latency + 4)
    o = unpack_fields(res.words, _out_layout(p))
    return o["i"], o["q"], res


def _check(p: MixerParams, n: int, seed: int, gaps: bool = True, backends=("pysim",),
           name=None):
    """Random operands (seeded) through ``backends``: the model's words, each on the cycle
    its input was taken plus the latency (cosim.testing.check_stream)."""
    rng = np.random.default_rng(seed)
    f = _random_inputs(p, n, rng)
    in_valid = rng.random(n + n // 4) < 0.8 if gaps else None
    mi, mq = _model(p, f)
    want = pack_fields({"i": mi, "q": mq}, _out_layout(p)), \
        accepted_cycles(n, in_valid) + p.latency
    check_stream(Mixer(p), want, pack_fields(f, _in_layout(p)), valid=in_valid,
                 flush_cycles=p.latency + 4, backends=backends, name=name)


@pytest.mark.parametrize("rounding,overflow", list(itertools.product(ROUNDINGS, ("wrap", "saturate"))))
def test_real_random(rounding, overflow):
    p = MixerParams(rounding=rounding, overflow=overflow)
    _check(p, 2500, seed=100 + ROUNDINGS.index(rounding) * 2 + (overflow == "wrap"))


@pytest.mark.parametrize("rounding", ROUNDINGS)
def test_complex_random(rounding):
    p = MixerParams(complex_input=True, in_width=14, lo_width=16, out_width=20,
                    rounding=rounding, overflow="saturate")
    _check(p, 2500, seed=200 + ROUNDINGS.index(rounding))


@pytest.mark.parametrize("p", [
    MixerParams(in_width=4, lo_width=4, out_width=10),               # drop_bits < 0: exact
    MixerParams(in_width=8, lo_width=6, out_width=13),               # drop_bits = 0
    MixerParams(in_width=8, lo_width=6, out_width=12, rounding="half_even"),  # drop_bits = 1
    MixerParams(headroom_bits=1, rounding="zero", overflow="wrap"),
    MixerParams(complex_input=True, in_width=5, lo_width=7, out_width=6, rounding="half_even",
                overflow="wrap"),
    MixerParams(input_stages=2),                                      # latency 5
    MixerParams(complex_input=True, input_stages=4, rounding="floor"),  # latency 8
])
def test_widths_and_headroom(p):
    _check(p, 1500, seed=300)


@pytest.mark.slow
@pytest.mark.parametrize("p", [MixerParams(), MixerParams(complex_input=True, rounding="half_even")])
def test_random_1e5(p):
    """1e5 random samples through the Amaranth simulation (about a minute each)."""
    _check(p, 100_000, seed=400 + p.complex_input)


@pytest.mark.parametrize("p", [
    MixerParams(rounding="floor", overflow="wrap"),
    MixerParams(rounding="half_up", overflow="saturate"),
    MixerParams(complex_input=True, rounding="half_even", overflow="saturate"),
    MixerParams(complex_input=True, rounding="zero", overflow="wrap"),
])
def test_full_scale_corners(p):
    """Every combination of {min, min+1, -1, 0, 1, max} for each operand."""
    def vals(w):
        return [-(1 << (w - 1)), -(1 << (w - 1)) + 1, -1, 0, 1, (1 << (w - 1)) - 1]
    xs, ls = vals(p.in_width), vals(p.lo_width)
    if p.complex_input:
        rows = list(itertools.product(xs, xs, ls, ls))
        names = ["xi", "xq", "cos", "sin"]
    else:
        rows = list(itertools.product(xs, ls, ls))
        names = ["x", "cos", "sin"]
    f = {k: np.array(col, dtype=np.int64) for k, col in zip(names, zip(*rows))}
    i, q, _ = _sim(p, f)
    mi, mq = _model(p, f)
    np.testing.assert_array_equal(i, mi)
    np.testing.assert_array_equal(q, mq)
    # The most negative x times the most negative LO is +1.0: one LSB over full scale.
    mn_x, mn_l = -(1 << (p.in_width - 1)), -(1 << (p.lo_width - 1))
    top = (1 << (p.out_width - 1)) - 1
    k = [j for j, r in enumerate(rows) if all(v == (mn_x if n[0] == "x" else mn_l) for v, n in zip(r, names))]
    assert len(k) == 1
    if p.complex_input:   # i = 2.0 (overflow), q = 0
        assert i[k[0]] == (top if p.overflow == "saturate" else 0) and q[k[0]] == 0
    else:                 # i = +1.0, q = -(x*sin) = -1.0 (fits)
        assert i[k[0]] == (top if p.overflow == "saturate" else -(top + 1))
        assert q[k[0]] == -(top + 1)


def test_model_rounding_against_float():
    """The model's rounding equals an independent float formulation (products < 2**53)."""
    rng = np.random.default_rng(7)
    x = rng.integers(-2048, 2048, 20000)
    c = rng.integers(-32768, 32768, 20000)
    s = rng.integers(-32768, 32768, 20000)
    prod = x * c / 2.0 ** 9
    ref = {"floor": np.floor(prod), "half_up": np.floor(prod + 0.5),
           "half_even": np.rint(prod), "zero": np.trunc(prod)}
    for r in ROUNDINGS:
        p = MixerParams(rounding=r, overflow="saturate")
        assert p.drop_bits == 9
        i, _ = MixerModel(p).run(x, c, s)
        np.testing.assert_array_equal(i, np.clip(ref[r], -(1 << 17), (1 << 17) - 1), err_msg=r)


def test_scaling_properties():
    p = MixerParams()
    assert (p.product_width, p.sum_width, p.frac_bits, p.drop_bits, p.latency) == (28, 28, 26, 9, 4)
    pc = MixerParams(complex_input=True, headroom_bits=1)
    assert (pc.sum_width, pc.drop_bits, pc.latency) == (29, 10, 5)
    # Unity gain in full-scale units: 0.5 * 0.5 -> 0.25.
    i, q = MixerModel(p).run(np.array([1024]), np.array([16384]), np.array([-16384]))
    assert i[0] == q[0] == 1 << 15


@pytest.mark.parametrize("kwargs,match", [
    (dict(in_width=1), r"mixer in_width must be an integer in \[2, 32\], not 1"),
    (dict(lo_width=33), r"mixer lo_width must be an integer in \[2, 32\], not 33"),
    (dict(out_width=0), r"mixer out_width must be an integer in \[2, 48\], not 0"),
    (dict(headroom_bits=9), r"mixer headroom_bits must be an integer in \[0, 8\], not 9"),
    (dict(rounding="nearest"), r"mixer rounding must be one of .*'half_even'.*, not 'nearest'"),
    (dict(overflow="clip"), r"mixer overflow must be one of \('wrap', 'saturate'\), not 'clip'"),
    (dict(complex_input="yes"), r"mixer complex_input must be a bool, not 'yes'"),
    (dict(input_stages=0), r"mixer input_stages must be an integer in \[1, 4\], not 0"),
])
def test_bad_params(kwargs, match):
    with pytest.raises(ValueError, match=match):
        MixerParams(**kwargs)


def test_model_refuses_out_of_range():
    m = MixerModel(MixerParams())
    with pytest.raises(ValueError, match=r"mixer LO sin must be signed 16-bit integers in \[-32768, 32767\], found 32768"):
        m.run(np.array([1]), np.array([1]), np.array([32768]))
    with pytest.raises(ValueError, match=r"mixer input x must be signed 12-bit"):
        m.run(np.array([-2049]), np.array([1]), np.array([1]))


def test_bad_component_argument():
    with pytest.raises(ValueError, match=r"Mixer needs a MixerParams, not 12"):
        Mixer(12)


@pytest.mark.verilator
@pytest.mark.parametrize("name,p", [
    ("mixer_real", MixerParams()),
    ("mixer_real_floor_wrap", MixerParams(rounding="floor", overflow="wrap")),
    ("mixer_cplx_even", MixerParams(complex_input=True, rounding="half_even")),
    ("mixer_cplx_zero", MixerParams(complex_input=True, rounding="zero", overflow="wrap")),
])
def test_verilog_lint(name, p):
    # Waived: only cosim.tools.verilog.LINT_WAIVERS less WIDTH (the mixer is clean of it).
    assert_lints_clean(Mixer(p), name, check_width=True)


#: Compiled with Verilator: the real mixer of the DDC and a complex one (the other datapath),
#: with rounding modes that differ on ties.
VL_PARAMS = {"real": MixerParams(rounding="half_up", overflow="saturate"),
             "complex": MixerParams(complex_input=True, in_width=14, lo_width=16, out_width=20,
                                    rounding="half_even", overflow="saturate")}


@needs_verilator
@pytest.mark.parametrize("kind", sorted(VL_PARAMS))
def test_verilator_matches_pysim_and_model(kind):
    """Same stimulus as the random sim tests (10 % full-scale operands, gaps in valid):
    model == pysim == Verilator, words and cycles."""
    p = VL_PARAMS[kind]
    _check(p, 2500, seed=500 + p.complex_input, backends=("pysim", "verilator"),
           name=f"mixer_{kind}_vl")


@needs_verilator
@pytest.mark.parametrize("kind", sorted(VL_PARAMS))
def test_verilator_matches_model_long(kind):
    p = VL_PARAMS[kind]
    _check(p, 1_000_000, seed=510 + p.complex_input, backends=("verilator",),
           name=f"mixer_{kind}_vl")


@pytest.mark.parametrize("p, kept", [
    (MixerParams(), 0), (MixerParams(input_stages=2), 3), (MixerParams(input_stages=3), 3),
    (MixerParams(complex_input=True, input_stages=2), 4),
])
def test_last_input_stage_is_marked_keep(p, kept):
    """With two or more input stages the copies beside the multipliers (the last stage:
    x, cos, -sin; complex: xi, xq, cos, sin) carry ``keep``, so synthesis does not merge
    the copies of mixers fed the same LO or samples; earlier stages do not."""
    import re
    from cosim.backends.verilog import verilog_text
    text = verilog_text(Mixer(p), name="mixer_keep", emit_src=False)
    got = re.findall(r"\(\* keep = 32'd1 \*\)\s+reg (?:\[\d+:0\] )?\\?(\S+?) ", text)
    assert len(got) == kept
    assert all(re.search(rf"_p{p.input_stages - 1}(\$\d+)?$", g) for g in got), got


@pytest.mark.synth
@pytest.mark.slow
def test_synthesis_keeps_each_mixers_input_copies(tmp_path):
    """Two mixers fed the same LO and sample: yosys keeps each one's last input stage (17 +
    16 + 12 flip-flops each); identical registers without ``keep`` would be merged into one
    set (the monopulse DDCs' LO copies were, before the mixer marked them)."""
    import json
    import re
    from amaranth.hdl import Module
    from amaranth.lib import wiring as w
    from amaranth.lib.wiring import In, Out
    from amaranth.lib import stream
    from cosim.tools.synth import synthesise, yowasp_available
    if not yowasp_available():
        pytest.skip("YoWASP yosys not installed")
    p = MixerParams(input_stages=2)
    from hdl.mixer import mixer_in_layout
    from hdl.common import iq_layout

    class Two(w.Component):
        def __init__(self):
            out = Out(stream.Signature(iq_layout(p.out_width), always_ready=True))
            super().__init__({"i": In(stream.Signature(mixer_in_layout(p), always_ready=True)),
                              "a": out, "b": out})

        def elaborate(self, platform):
            m = Module()
            for name, port in (("m0", self.a), ("m1", self.b)):
                mix = m.submodules[name] = Mixer(p)
                m.d.comb += [mix.i.valid.eq(self.i.valid), mix.i.payload.eq(self.i.payload),
                             port.valid.eq(mix.o.valid), port.payload.eq(mix.o.payload)]
            return m

    from cosim.backends.verilog import verilog_text
    work = synthesise(None, name="two_mixers", out_dir=tmp_path,
                      verilog=verilog_text(Two(), name="two_mixers", emit_src=False))
    cells = json.loads((work / "two_mixers.json").read_text())["modules"]["two_mixers"]["cells"]
    ffs = {}
    for n, c in cells.items():
        hit = re.match(r"\\?(m\d)\.(\S+_p1)_TRELLIS_FF", n)
        if c["type"] == "TRELLIS_FF" and hit:
            ffs[hit.groups()] = ffs.get(hit.groups(), 0) + 1
    assert ffs == {(m, r): k for m in ("m0", "m1")
                   for r, k in (("$signal_p1", 12), ("c_p1", 16), ("sn_p1", 17))}

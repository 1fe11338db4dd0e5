"""GNSS tracking channel: model == Amaranth simulation == Verilator, parameter errors."""
import numpy as np
import pytest

from cosim.pysim import run_stream
from dsp.gnss.ca_code import ca_code_levels
from hdl.gnss.channel import GnssChannel, GnssChannelArray, array_params
from hdl.gnss.model import (REG_CARR_FREQ, REG_CODE_FREQ, REG_PRN, REG_SLEW, GnssArrayModel,
                            GnssChannelModel, GnssChannelParams, bus_writes, dump_epochs_for,
                            unpack_record)

#: Reduced rate for the Amaranth simulation: 2 samples per chip, 2046 samples per epoch.
SMALL = GnssChannelParams(fs_hz=2.046e6, if_hz=0.3e6, el_spacing_samples=2, slew_bits=6,
                          carr_table_bits=6, lo_bits=3, fifo_depth=64)


def stimulus(p, n, seed, writes_at=(), n_writes=0, ready_p=0.7, ch=1):
    rng = np.random.default_rng(seed)
    lo = -(1 << (p.adc_bits - 1))
    x = rng.integers(lo, -lo, n)
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


def run_pysim(dut, x, writes, ready, n_cycles, data_width):
    return run_stream(dut, x, out_ready=ready, n_cycles=n_cycles,
                      writes=bus_writes(writes, data_width=data_width))


def test_pysim_matches_model_with_writes_and_backpressure():
    p = SMALL
    n = 3 * 2046 + 300
    x, writes, ready = stimulus(p, n, seed=1, n_writes=2)
    # A write right at the start, one in every register, so every boundary sees one.
    writes += [(5, REG_PRN, 7), (7, REG_SLEW, 9)]
    n_cycles = n + 60
    want = GnssArrayModel(p).run(x, writes, n_cycles=n_cycles, out_ready=ready)
    assert len(want.records) >= 3
    got = run_pysim(GnssChannel(p), x, writes, ready, n_cycles, p.reg_data_width)
    np.testing.assert_array_equal(got.words, want.words)
    np.testing.assert_array_equal(got.cycles, want.cycles)

"""The receiver tops' stream cases: stimulus with register writes mid-run, and the bit-exact
model's answer (:func:`cosim.tools.stream_cases.stream_case` of a top).

Every exported top (:func:`cosim.tools.stream_cases.exported_designs`) has a case here
(:data:`TOP_CASES`), on the stimulus of its equivalence check and with the register writes
the closed loop makes, set at cycles chosen by a seed, through the whole record:

- ``tacan_frontend``: seeded noise bursts over a noise floor (:func:`_bursts`: a peak report
  every few hundred samples; the equivalence check's TACAN record has a pulse pair every
  ~5,600) with writes of the NCO word ``freq`` (the IF retuned by up to +-40 kHz and back),
  under seeded stalls (:func:`cosim.tools.equivalence.stall_pattern`); the model is the
  front end's session.
- ``gnss_channel``, ``gnss_channel_iq`` and the 12-channel arrays ``gnss_channel_array12``,
  ``gnss_channel_array12_iq``: the GPS L1 C/A record of ``check-equivalence --top gnss``
  (:func:`cosim.gnss.equivalence.gnss_equivalence_stimulus`: PRN 7 at 45 dB-Hz, real IF or
  zero-IF I/Q; the real-input short cases seeded ADC words, :data:`GNSS_SHORT`) with its
  hand-over to channel 0 (PRN, carrier and code words, slew) and seeded writes of every
  register (carrier and code words near the truth, slews, a PRN switched away and back)
  from a quarter code period on, a third of a code period apart on average, so each dump
  boundary takes new words (a write becomes active at the next one); an array's other
  channels are handed over to other PRNs at random Doppler and code phase, and each seeded
  write goes to a random channel. Writes that fall on one cycle go out on consecutive
  cycles (one bus write a cycle). Stalls of a quarter code period on average. The model is
  :class:`hdl.gnss.model.GnssArrayModel` (the arbiter and FIFO included).
- ``monopulse_frontend``: the record of ``check-equivalence --top monopulse``
  (:func:`cosim.monopulse.equivalence.stimulus`: random ADC codes and replica bits, seeded
  writes of the channel coefficients and the steering words); the model is the front end's
  session.

Two sizes. ``short=False`` (``python -m cosim verilog --cocotb``): the registered top with
its own parameters (the exported Verilog), a record long enough for its closed-loop
behaviour (TACAN 10,000 samples; GNSS three code periods of 16,368 samples; monopulse one
record of 81,920 samples). ``short=True`` (the Icarus check in ``make test``): the same
top's HDL at reduced parameters (:data:`GNSS_SHORT`: the GNSS channels at 2.046 MS/s; the
12-snapshot monopulse block of its equivalence check; a TACAN FIFO of 4 words and
noise-floor blocks of 1,024 cycles, :data:`TACAN_SHORT_BLOCK_LOG2`) on a record of 1,500 to
8,500 samples (:data:`GNSS_PERIODS`), and a FIFO that holds one record and a marker (an
array: half its channels' records), so records are dropped and counted.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

__all__ = ["TOP_CASES", "top_case", "GNSS_SHORT"]

#: Cycles run after the last ADC sample (the last record leaves the pipeline and the FIFO).
FLUSH_CYCLES = 400
#: The reduced GNSS channel of the short cases, by input: 2.046 MS/s (2 samples per chip,
#: 2,046 per code period), a small carrier table; complex at zero IF, real at 0.3 MHz -- a
#: rate at which no real IF keeps the C/A main lobe in the first Nyquist zone, so the real
#: input's record is seeded uniform ADC words (the same hand-over and writes); the satellite's
#: real-IF signal runs in ``check-equivalence --top gnss`` at 5.115 MS/s.
GNSS_SHORT = {"real": dict(fs_hz=2.046e6, if_hz=0.3e6, el_spacing_samples=2, slew_bits=12,
                           carr_table_bits=6, lo_bits=3),
              "complex": dict(fs_hz=2.046e6, if_hz=0.0, el_spacing_samples=2, slew_bits=12,
                              carr_table_bits=6, lo_bits=3, input="complex")}
#: Code periods in a GNSS case's record: the hand-over's slew holds the first dump back by up
#: to a period, so a channel gives ``periods - 1`` or ``periods`` records (short case: one
#: channel, the arrays; the registered tops).
GNSS_PERIODS = {"channel": 4, "array": 3, "registered": 3}
#: ``block_log2`` of the TACAN short case's peak searches (noise-floor blocks of 256 envelope
#: samples; the registered front end's 1,024 hold its first report back ~4,300 cycles).
TACAN_SHORT_BLOCK_LOG2 = 8


def _elaborated(comp):
    """``comp``, elaborated (only asked for its parameters and ports here)."""
    from amaranth.hdl import Fragment
    Fragment.get(comp, None)
    return comp


def _width(comp, port: str) -> int:
    return next(len(v) for path, _, v in comp.signature.flatten(comp)
                if "__".join(map(str, path)) == port)


def _session_run(fe, params, x, ready, n_cycles, writes):
    """The front end's bit-exact model session from reset: port writes, then one step."""
    with fe.model(params) as s:
        for c, port, v in writes:
            s.write(port, int(v), int(c))
        r = s.step(x, ready, n_cycles=n_cycles)
    return np.asarray(r.words), np.asarray(r.cycles, np.int64)


def _frontend(verilog_name: str):
    from ..core.receivers import receivers
    return next(r.frontend for r in receivers()
                if r.frontend is not None and r.frontend.verilog_name == verilog_name)


# -- TACAN -------------------------------------------------------------------------------------
def _bursts(rng, width: int, n: int) -> np.ndarray:
    """Signed ``width``-bit ADC codes: a noise floor (2 % of full scale rms) with bursts of
    strong noise (30 % rms, clipped at full scale), 70 samples long, 100..400 samples apart:
    broadband energy in any pass band, switched on and off (a peak report every few hundred
    samples, where the TACAN record has a pulse pair every ~5,600)."""
    x = rng.normal(0.0, 0.02, n)
    t = int(rng.integers(0, 100))
    while t < n:
        x[t:t + 70] += rng.normal(0.0, 0.3, len(x[t:t + 70]))
        t += int(rng.integers(100, 400))
    full = 1 << (width - 1)
    return np.clip(np.round(x * full), -full, full - 1).astype(np.int64)


def _tacan(make_top, seed, size, short):
    from hdl.model.nco import nco_freq_word
    from .equivalence import stall_pattern
    fe = _frontend("tacan_frontend")
    comp = _elaborated(make_top())
    p = comp.params
    if short:           # noise-floor blocks of 256 samples (1,024 cycles), not 4,096 cycles
        cfg = p.config
        blocks = {k: replace(getattr(cfg, k), block_log2=TACAN_SHORT_BLOCK_LOG2)
                  for k in ("peak", "pair_peak") if getattr(cfg, k) is not None}
        p = replace(p, fifo_depth=4, config=replace(cfg, **blocks))
    n = int(size or (3000 if short else 10_000))
    rng = np.random.default_rng([seed, 1])
    x = _bursts(rng, _width(comp, "i__payload"), n)
    n_cycles = n + FLUSH_CYCLES
    ready = stall_pattern(n_cycles, seed, burst=max(n_cycles // 8, 1))
    # the NCO retuned by up to +-40 kHz at seeded cycles, the last write back on the IF
    cyc = np.sort(rng.choice(np.arange(1, n), min(4, n - 1), replace=False))
    writes = [(int(c), "freq", nco_freq_word(p.config.if_hz + float(rng.uniform(-4e4, 4e4)),
                                             f_clk_hz=p.config.fs_hz,
                                             phase_bits=p.nco_phase_bits).word)
              for c in cyc[:-1]] + [(int(cyc[-1]), "freq", p.nco_freq_word)]
    inputs = fe.reset_inputs(p)
    words, cycles = _session_run(fe, p, x, ready, n_cycles, writes)
    return dict(make=lambda: fe.component(p), in_words=x, out_ready=ready, n_cycles=n_cycles,
                words=words, cycles=cycles, inputs=inputs, writes=writes)


# -- GNSS --------------------------------------------------------------------------------------
def _serial(writes):
    """Register writes ``(cycle, address, value)``, in order, one bus write a cycle: a write
    on a busy cycle goes out on the next free one."""
    out, last = [], -1
    for c, a, v in sorted(writes, key=lambda w: w[0]):
        last = max(int(c), last + 1)
        out.append((last, int(a), int(v)))
    return out


def _gnss(make_top, seed, size, short, *, channels: int, iq: bool):
    from hdl.gnss.channel import gnss_top
    from hdl.gnss.model import GnssArrayModel
    from hdl.gnss.params import GnssChannelParams
    from hdl.model.bus import bus_writes
    from ..gnss.equivalence import gnss_equivalence_stimulus
    from ..gnss.handover import array_handover_writes
    from .equivalence import stall_pattern
    if short:
        comp = _elaborated(gnss_top(channels,
                                    GnssChannelParams(**GNSS_SHORT["complex" if iq else "real"])))
    else:
        comp = _elaborated(make_top())
    p = comp.params
    if short:           # one record (a channel) or half the channels' records, and a marker
        p = replace(p, fifo_depth=max(channels // 2, 1) * p.fifo.record_words + 2)
    period = round(p.fs_hz * 1e-3)
    periods = GNSS_PERIODS["registered" if not short else "array" if channels > 1 else
                           "channel"]
    n = int(size or periods * period + 300)
    rng = np.random.default_rng([seed, channels, 2 + iq])
    x, named = gnss_equivalence_stimulus(replace(p, channel_bits=0), n, seed,
                                         write_spacing=max(period // 3, 1), first=period // 4,
                                         signal=not (short and not iq))
    regs = p.registers
    handed = named[:4]                                  # PRN 7's hand-over, to channel 0
    later = named[4:]
    writes = [(c, regs[r].address, v) for c, r, v in handed]
    if channels > 1:
        others = [int(k) for k in rng.choice([k for k in range(1, 33) if k != 7],
                                             channels - 1, replace=False)]
        sats = [(prn, float(rng.uniform(-4e3, 4e3)), float(rng.uniform(0, 1023)))
                for prn in others]
        ho = array_handover_writes(p, [(7, 0.0, 0.0)] + sats, start_cycle=len(writes))
        writes += [w for w in ho if w[1] >= 4]          # channels 1.. (0 has its own)
    for c, r, v in later:
        ch = int(rng.integers(0, channels))
        writes.append((c, 4 * ch + regs[r].address, v))
    writes = _serial(writes)
    n_cycles = n + FLUSH_CYCLES
    ready = stall_pattern(n_cycles, seed, burst=max(period // 4, 1))   # records get out
    model = GnssArrayModel(p, channels)
    want = model.run(x, writes, n_cycles=n_cycles, out_ready=ready)
    make = (lambda: gnss_top(channels, p)) if short else make_top
    return dict(make=make, in_words=p.pack_samples(x), out_ready=ready, n_cycles=n_cycles,
                words=want.words, cycles=want.cycles,
                writes=bus_writes(writes, data_width=p.reg_data_width))


# -- monopulse ---------------------------------------------------------------------------------
def _monopulse(make_top, seed, size, short):
    from hdl.model.bus import bus_writes
    from ..monopulse.equivalence import EQUIV_PARAMS, stimulus
    from .equivalence import stall_pattern
    fe = _frontend("monopulse_frontend")
    p = EQUIV_PARAMS if short else _elaborated(make_top()).params
    p = replace(p, fifo_depth=p.record_words + 2)
    n = int(size or (1500 if short else p.snapshots * p.snapshot_decimation + 2000))
    x, regs = stimulus(p, n, seed)
    n_cycles = n + p.latency + FLUSH_CYCLES
    ready = stall_pattern(n_cycles, seed, burst=max(n_cycles // 8, 1))
    writes = bus_writes(regs, data_width=_width(_elaborated(fe.component(p)), "reg_data"))
    words, cycles = _session_run(fe, p, x, ready, n_cycles, writes)
    return dict(make=lambda: fe.component(p), in_words=x, out_ready=ready, n_cycles=n_cycles,
                words=words, cycles=cycles, writes=writes)


#: Each exported top's case: ``case(make_top, seed, size, short) -> dict`` (module doc).
TOP_CASES: dict[str, Callable] = {
    "tacan_frontend": _tacan,
    "gnss_channel": lambda *a: _gnss(*a, channels=1, iq=False),
    "gnss_channel_iq": lambda *a: _gnss(*a, channels=1, iq=True),
    "gnss_channel_array12": lambda *a: _gnss(*a, channels=12, iq=False),
    "gnss_channel_array12_iq": lambda *a: _gnss(*a, channels=12, iq=True),
    "monopulse_frontend": _monopulse,
}


def top_case(name: str, make_top, seed: int, size: int | None, short: bool) -> dict:
    """The case of top ``name`` (module doc): ``make`` (the component), ``in_words``,
    ``out_ready``, ``n_cycles``, the model's ``words`` and ``cycles``, ``inputs``,
    ``writes`` (port-level ``(cycle, port, value)``)."""
    return TOP_CASES[name](make_top, int(seed), size, bool(short))


"""The GNSS tops' stream cases (:mod:`cosim.tools.top_cases`): ``gnss_channel``,
``gnss_channel_iq`` and the 12-channel arrays ``gnss_channel_array12``,
``gnss_channel_array12_iq``.

The GPS L1 C/A record of ``check-equivalence --top gnss``
(:func:`cosim.gnss.equivalence.gnss_equivalence_stimulus`: PRN 7 at 45 dB-Hz, real IF or
zero-IF I/Q; the real-input short cases seeded ADC words, :data:`GNSS_SHORT`) with its
hand-over to channel 0 (PRN, carrier and code words, slew) and seeded writes of every
register (carrier and code words near the truth, slews, a PRN switched away and back) from a
quarter code period on, a third of a code period apart on average, so each dump boundary
takes new words (a write becomes active at the next one); an array's other channels are
handed over to other PRNs at random Doppler and code phase, and each seeded write goes to a
random channel. Writes that fall on one cycle go out on consecutive cycles (one bus write a
cycle). Stalls of a quarter code period on average. The model is
:class:`hdl.gnss.model.GnssArrayModel` (the arbiter and FIFO included). Registered tops:
three code periods (49,804 cycles). Short: 2.046 MS/s (:data:`GNSS_SHORT`), four code
periods for a channel and three for an array (:data:`GNSS_PERIODS`), a FIFO of one record
(an array: half its channels' records) and a marker.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

__all__ = ["gnss_case", "GNSS_SHORT", "GNSS_PERIODS"]

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


def gnss_case(make_top, seed: int, size: int | None, short: bool, *, channels: int,
              iq: bool) -> dict:
    """The case of the GNSS top of ``channels`` channels, I/Q input if ``iq`` (module doc;
    the keys of :func:`cosim.tools.top_cases.top_case`)."""
    from hdl.gnss.channel import gnss_top
    from hdl.gnss.model import GnssArrayModel
    from hdl.gnss.params import GnssChannelParams
    from hdl.model.bus import bus_writes
    from ..tools.equivalence import stall_pattern
    from ..tools.top_cases import FLUSH_CYCLES, elaborated, one_write_a_cycle
    from .equivalence import gnss_equivalence_stimulus
    from .handover import array_handover_writes
    if short:
        comp = elaborated(gnss_top(channels,
                                    GnssChannelParams(**GNSS_SHORT["complex" if iq else "real"])))
    else:
        comp = elaborated(make_top())
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
    writes = one_write_a_cycle(writes)
    n_cycles = n + FLUSH_CYCLES
    ready = stall_pattern(n_cycles, seed, burst=max(period // 4, 1))   # records get out
    model = GnssArrayModel(p, channels)
    want = model.run(x, writes, n_cycles=n_cycles, out_ready=ready)
    make = (lambda: gnss_top(channels, p)) if short else make_top
    return dict(make=make, in_words=p.pack_samples(x), out_ready=ready, n_cycles=n_cycles,
                words=want.words, cycles=want.cycles,
                writes=bus_writes(writes, data_width=p.reg_data_width))

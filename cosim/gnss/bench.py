"""``python -m cosim bench gnss-speed``: closed-loop simulation speed of one GNSS channel.

The same record (default scenario: PRN 7, 45 dB-Hz, seed-002 dynamics, 16.368 MS/s, 2-bit
ADC) is tracked closed loop (:func:`cosim.gnss.run.closed_loop`: pipeline, FIFO service
every 0.5 ms, fixed-point 3rd-order PLL writing the NCO words back) on the bit-exact model
and on Verilator, after an untimed warm-up (numba compilation, the Verilator build). The
ADC words are generated before the clock starts: the figure is the closed loop's (channel,
FIFO, record reassembly, tracker, writes), not the signal generator's. The two runs must
give the same digest (words, cycles, writes, DSP outputs). Written to
``results/gnss_speed.json`` / ``.md`` with the machine, date and command; the ratio of the two
is what to compare on a shared machine (measured in one run).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..bench import machine_info

#: Real-time sample rate of the default front end (S/s).
REAL_TIME_SPS = 16.368e6


def gnss_speed(out: Path, quick: bool = False, duration_s: float | None = None) -> dict:
    from ..verilator import verilator_available
    from .run import DynamicsChoice, GnssRunConfig, _acquire, adc_words, closed_loop
    from .signal import GnssSignalConfig, GnssSignalGenerator
    dur = duration_s if duration_s is not None else (0.1 if quick else 1.0)
    sig = DynamicsChoice("seed002").apply(GnssSignalConfig(prn=7, cn0_dbhz=45.0,
                                                           duration_s=dur + 0.05))
    run = GnssRunConfig(dsp="fixed", tracker="pll3", bn_hz=15.0)
    gen = GnssSignalGenerator(sig)
    _, hand = _acquire(gen, run)
    p = run.hdl_params(sig)
    n = int(round(dur * sig.fs_hz))
    x = adc_words(gen.samples(0, n)[0])
    blk = run.block_samples

    def loop(backend, m):
        return closed_loop(backend, p, run, (x[k:min(k + blk, m)] for k in range(0, m, blk)),
                           hand["doppler_hz"], hand["code_phase_chips"],
                           cn0_dbhz=sig.cn0_dbhz)

    backends = ["model"] + (["verilator"] if verilator_available() else [])
    rows, digests = [], {}
    for be in backends:
        loop(be, 20 * 16368)                     # warm-up: compile / build, not timed
        t0 = time.perf_counter()
        cl = loop(be, n)
        wall = time.perf_counter() - t0
        digests[be] = {**cl.pipeline.digest, "dsp": cl.track.digest()}
        rows.append({"backend": be, "samples": n, "records": cl.track.n_seen,
                     "writes": len(cl.pipeline.writes), "wall_s": wall,
                     "samples_per_s": n / wall, "x_real_time": n / wall / REAL_TIME_SPS})
    same = len(set(json.dumps(d, sort_keys=True) for d in digests.values())) == 1
    res = {"machine": machine_info(), "benchmark": "gnss-speed", "duration_s": dur,
           "scenario": "PRN 7, 45 dB-Hz, seed002 (1000 m/s, 1 g), 16.368 MS/s, 2-bit ADC, "
                       "pll3 fixed, Bn 15 Hz, DSP service 0.5 ms",
           "rows": rows, "same_bits": same, "digests": digests}
    if len(rows) == 2:
        res["model_over_verilator"] = rows[0]["samples_per_s"] / rows[1]["samples_per_s"]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "gnss_speed.json").write_text(json.dumps(res, indent=1) + "\n")
    (out / "gnss_speed.md").write_text(_markdown(res))
    if not same:
        raise RuntimeError(f"gnss-speed: the backends disagree: {digests}")
    return res


def _markdown(r: dict) -> str:
    m = r["machine"]
    lines = ["# GNSS closed-loop simulation speed (one channel)", "",
             f"Measured {m['date']} on {m['host']} ({m['cpu']}, {m['cores']} cores, shared), "
             f"commit {m['commit']}, command `{m['command']}`.", "",
             f"Scenario: {r['scenario']}; {r['duration_s']:g} s of record, closed loop "
             f"(channel + FIFO + record reassembly + tracker + NCO writes), signal generated "
             f"before timing. Same bits on every backend: {r['same_bits']}.", "",
             "| backend | samples | records | writes | wall (s) | samples/s | x real time "
             "(16.368 MS/s) |", "|---|---|---|---|---|---|---|"]
    for row in r["rows"]:
        lines.append(f"| {row['backend']} | {row['samples']:,} | {row['records']} | "
                     f"{row['writes']} | {row['wall_s']:.2f} | {row['samples_per_s'] / 1e6:.2f} M | "
                     f"{row['x_real_time']:.3f} |")
    if "model_over_verilator" in r:
        lines += ["", f"Model / Verilator speed ratio (same run): "
                      f"{r['model_over_verilator']:.2f}."]
    return "\n".join(lines) + "\n"

"""``python -m cosim bench gnss-throughput``: speed of the multi-channel closed loop.

A synthetic 12 MS/s real-IF recording (int8, 2-bit, IF 3 MHz, like the PocketSDR front end)
of 12 satellites (40-48 dB-Hz, seed 1; :mod:`cosim.gnss.synthetic_file`) is written under
``build/``; then 1, 4, 8 and 12 of them are tracked at once
(:func:`cosim.gnss.multichannel.track_file`: the bit-exact array model, one fixed-point
``pll3`` per channel, the DSP service every 0.5 ms), handed over from the truth (the
acquisition is not timed), after an untimed warm-up. Per channel count (best of
:data:`REPEATS` runs, the machine being shared): channel x samples per second and the
multiple of real time, per wall second and per CPU second of the process
(:func:`time.process_time`: what the run costs whatever else the cores carry), and the
pipeline's digest. The 12 channels run once more with ``parallel=True``
(:class:`~cosim.gnss.multichannel.TrackConfig`: the channels on numba's threads; the same
digest). The 12-channel run is profiled (:mod:`cProfile`) once more to say where the time
goes: the array's numba kernel (:mod:`hdl.gnss.kernel`), the trackers, the rest (pipeline,
FIFO model, record packing and reassembly in Python). Written with
:func:`cosim.core.provenance.write_result` to ``results/gnss_throughput.json`` / ``.md``.
"""
from __future__ import annotations

import cProfile
import os
import pstats
import time
from pathlib import Path

from ..core.provenance import machine_info, write_result

FS_HZ, IF_HZ = 12e6, 3e6
COUNTS = (1, 4, 8, 12)
#: Timed runs per channel count (the best is kept).
REPEATS = 3
#: The array model's compiled kernels (what the profile counts as the kernel).
KERNELS = ("array_kernel", "array_kernel_parallel", "channel_kernel")


def _recording(path: Path, duration_s: float):
    from .synthetic_file import SatelliteSpec, write_synthetic
    sats = [SatelliteSpec(prn, -4000.0 + 700.0 * k, (97.3 * (k + 1)) % 1023,
                          40.0 + 8.0 * k / 11, 0.1 * k)
            for k, prn in enumerate((1, 3, 6, 8, 11, 14, 17, 19, 22, 25, 28, 31))]
    write_synthetic(path, "int8", FS_HZ, IF_HZ, duration_s, sats, seed=1)
    return sats


def _profile_split(prof: cProfile.Profile) -> dict:
    st = pstats.Stats(prof).stats
    total = max(v[3] for v in st.values())
    kern = sum(v[3] for k, v in st.items() if k[2] in KERNELS and "kernel" in k[0])
    trk = sum(v[3] for k, v in st.items() if k[2] == "step" and "loops_fixed" in k[0])
    return {"total_s": total, "array_kernel_s": kern, "trackers_s": trk,
            "rest_s": total - kern - trk}


def gnss_throughput(out: Path, quick: bool = False) -> dict:
    from .config import GnssRunConfig
    from .files import SampleFile
    from .multichannel import Candidate, TrackConfig, track_file
    dur = 0.05 if quick else 0.3
    path = Path("build") / "bench" / f"gnss_throughput_{int(dur * 1e3)}ms.bin"
    sats = _recording(path, dur)
    f = SampleFile(path, "int8", FS_HZ, IF_HZ)
    cands = [Candidate(s.prn, s.doppler_hz, s.code_phase_chips, s.cn0_dbhz) for s in sats]
    run = GnssRunConfig(tracker="pll3", dsp="fixed", backend="model")
    load = os.getloadavg()[0]
    track_file(f, cands[:2], run, TrackConfig(channels=2), n_samples=24_000)     # warm-up
    rows = []
    for n in COUNTS:
        wall = cpu = float("inf")
        for _ in range(1 if quick else REPEATS):
            t0, c0 = time.perf_counter(), time.process_time()
            m = track_file(f, cands[:n], run, TrackConfig(channels=n))
            wall = min(wall, time.perf_counter() - t0)
            cpu = min(cpu, time.process_time() - c0)
        locked = sum(a.status == "tracked" for a in m.assignments)
        rows.append({"channels": n, "samples": m.n_samples, "wall_s": wall, "cpu_s": cpu,
                     "channel_samples_per_s": n * m.n_samples / wall,
                     "x_real_time": m.n_samples / FS_HZ / wall,
                     "x_real_time_cpu": m.n_samples / FS_HZ / cpu, "tracked": locked,
                     "fifo_dropped": int(m.pipeline.overflow_count or 0),
                     "digest": m.pipeline.digest["all"]})
    # the 12 channels on numba's threads (--parallel): the same bits, its wall time
    track_file(f, cands[:2], run, TrackConfig(channels=2, parallel=True), n_samples=24_000)
    t0, c0 = time.perf_counter(), time.process_time()
    m = track_file(f, cands, run, TrackConfig(channels=12, parallel=True))
    par = {"wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
           "digest": m.pipeline.digest["all"]}
    par["x_real_time"] = m.n_samples / FS_HZ / par["wall_s"]
    prof = cProfile.Profile()
    prof.enable()
    track_file(f, cands, run, TrackConfig(channels=12))
    prof.disable()
    split = _profile_split(prof)
    res = {"machine": machine_info(), "benchmark": "gnss-throughput", "duration_s": dur,
           "scenario": f"synthetic int8 2-bit real IF {IF_HZ / 1e6:g} MHz at "
                       f"{FS_HZ / 1e6:g} MS/s, 12 satellites 40-48 dB-Hz, bit-exact array "
                       f"model, pll3 fixed per channel, DSP service 0.5 ms",
           "load_average_1min": load, "rows": rows, "parallel_12_channels": par,
           "profile_12_channels": split}
    write_result(Path(out), "gnss_throughput", res, _markdown(res))
    return res


def _markdown(r: dict) -> str:
    m = r["machine"]
    p = r["profile_12_channels"]
    lines = ["# GNSS multi-channel closed-loop throughput", "",
             f"Measured {m['date']} on {m['host']} ({m['cpu']}, {m['cores']} cores, shared), "
             f"commit {m['commit']}, command `{m['command']}`; load average "
             f"{r['load_average_1min']:.1f} at the start (wall times grow with it, CPU times "
             f"much less).", "",
             f"Scenario: {r['scenario']}; {r['duration_s']:g} s of recording.", "",
             "| channels | wall (s) | CPU (s) | channel x samples/s | x real time (wall) | "
             "x real time (CPU) | tracked | pipeline digest |",
             "|---|---|---|---|---|---|---|---|"]
    for x in r["rows"]:
        lines.append(f"| {x['channels']} | {x['wall_s']:.2f} | {x['cpu_s']:.2f} | "
                     f"{x['channel_samples_per_s']:.3g} | {x['x_real_time']:.3g} | "
                     f"{x['x_real_time_cpu']:.3g} | {x['tracked']} | `{x['digest']}` |")
    q = r["parallel_12_channels"]
    lines += ["", f"12 channels with `--parallel` (the channels on numba's threads): wall "
              f"{q['wall_s']:.2f} s ({q['x_real_time']:.3g} x real time), CPU {q['cpu_s']:.2f} s, "
              f"digest `{q['digest']}` (the serial run's: the same bits). It gains only where "
              f"a core is idle."]
    lines += ["", f"Where the 12-channel run's {p['total_s']:.2f} s go (cProfile, so slower "
              f"than the timed run): array kernel (numba) {p['array_kernel_s']:.2f} s, "
              f"fixed-point trackers (Python) {p['trackers_s']:.2f} s, the rest (pipeline, "
              f"FIFO model, record packing and reassembly, lock detectors) "
              f"{p['rest_s']:.2f} s.", ""]
    return "\n".join(lines)

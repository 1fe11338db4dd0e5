"""The rules a monopulse run is checked against before any work
(:class:`cosim.monopulse.run.MonopulseRunConfig` applies them; the messages name the
command line's options, ``python -m cosim monopulse``).

* :func:`check_run_size`: the run's memory and wall time, estimated from its configuration
  for its backend (:func:`run_cost`), through the one size rule of
  :func:`cosim.core.validate.check_budget`.
* :func:`check_values`: values that have no meaning in this receiver -- an SNR above what the
  ADC resolves in the snapshot band or too low for the sum beam of a whole block ever to
  reach the detection threshold, a threshold at or below the noise power, a negative
  mismatch spread.
* :func:`check_record`: a record shorter than one block, a target that leaves the visible
  region during it (the message names the time and ``--duration-s``), a record too short to
  score anything (``--settle-s``, ``--latency-blocks``), a manoeuvre after the record.
* :func:`check_ignored`: options that would change nothing in the run asked for are
  refused (as TACAN refuses its FIFO options on the golden backend), not ignored.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..core.validate import check_budget
from .fastpath import snapshot_snr

__all__ = ["check_run", "run_cost", "check_run_size", "check_values", "check_record", "check_ignored",
           "max_snr_db", "block_sum_snr_db", "first_scored_block"]

#: Wall time of the fast path (Python loop over blocks and trials): s per block plus s per
#: block and trial (measured on the shared 2-core machine under load: 2.7 ms + 1.5 ms per
#: trial; the estimate errs long on an idle machine).
FAST_S_PER_BLOCK, FAST_S_PER_TRIAL_BLOCK = 2.7e-3, 1.5e-3
#: The golden IF chain: s per block plus s per ADC sample of the 4 channels (measured: 15 ms
#: and 1.1 us).
GOLDEN_S_PER_BLOCK, GOLDEN_S_PER_SAMPLE = 15e-3, 1.2e-6
#: Memory: the process (interpreter, numpy, numba; ~0.24 GB resident measured), the loop's
#: per block and trial arrays (steering, measurements, estimates, modes, the scoring's
#: temporaries: 250-370 B measured by tracemalloc), and per ADC sample of one block (the IF
#: record of 4 channels and the chain's temporaries: 170 B measured on the golden chain,
#: 700 B on the model front end).
PROCESS_BYTES = 300 * 2 ** 20
BYTES_PER_TRIAL_BLOCK = 400
BYTES_PER_BLOCK_SAMPLE = {"golden": 200, "model": 1024, "pysim": 1024, "verilator": 1024,
                          "icarus": 1024}


def _blocks(run, sig) -> int:
    return max(1, int(round(run.duration_s / sig.block_s)))


def run_cost(run, sig) -> tuple[float, float, str, str]:
    """``(memory_bytes, seconds, what, options)`` of :func:`cosim.monopulse.run.run_monopulse`
    on ``run`` (the constants above; the HDL backends at their simulated cycles a second,
    :data:`cosim.monopulse.hdl_loop.CYCLES_PER_S`)."""
    K, B = _blocks(run, sig), run.trials
    spb = sig.samples_per_block
    mem = PROCESS_BYTES + BYTES_PER_TRIAL_BLOCK * K * B
    what = (f"{K:,} blocks x {B:,} trial{'s' if B > 1 else ''} on the {run.backend} backend "
            f"(--duration-s {run.duration_s:g} in blocks of {sig.block_s * 1e3:.3g} ms, "
            f"--snapshots {sig.snapshots})")
    if run.backend == "fast":
        return (mem, K * (FAST_S_PER_BLOCK + FAST_S_PER_TRIAL_BLOCK * B), what,
                "--duration-s or --trials, or raise --snapshots (fewer, longer blocks)")
    mem += BYTES_PER_BLOCK_SAMPLE[run.backend] * spb
    if run.backend == "golden":
        return mem, K * (GOLDEN_S_PER_BLOCK + GOLDEN_S_PER_SAMPLE * spb), what, "--duration-s"
    from .hdl_loop import CYCLES_PER_S
    n = (K + 1) * spb
    rate = CYCLES_PER_S[run.backend]
    what = (f"{n:,} cycles on the {run.backend} backend (about {rate:.0e} cycles/s; "
            f"--duration-s {run.duration_s:g})")
    opt = "--duration-s" + ("; long records run on --backend model"
                            if run.backend in ("pysim", "icarus") else "")
    return mem, n / rate, what, opt


def check_run_size(run, sig=None, note: bool = False) -> None:
    """Refuse a run this machine cannot hold or finish (:func:`run_cost` against
    :func:`cosim.core.validate.check_budget`); ``note``: say how long a long one takes."""
    sig = run.signal_config() if sig is None else sig
    mem, seconds, what, options = run_cost(run, sig)
    check_budget(what, options, memory_bytes=mem, seconds=seconds, note=note)


def block_sum_snr_db(sig) -> float:
    """SNR (dB) of the sum beam of one block with the beam on the target: 4 channels
    coherently over N snapshots, the ADC's quantisation noise included."""
    snr = snapshot_snr(sig)
    return math.inf if not math.isfinite(snr) else 10 * math.log10(4 * sig.snapshots * snr)


def max_snr_db(sig) -> float:
    """Highest per-subarray SNR (dB) the ``adc_bits`` ADC resolves: the noise must span at
    least one ADC step (the fast path takes the quantisation as additive uniform noise,
    valid while the noise spans steps; above it the ADC, not ``snr_db``, sets the noise)."""
    # sigma_w^2 = D / (4 SNR) >= step^2, step = fs_sigma sqrt(0.5 + sigma_w^2) / 2^(b-1):
    # with r = (2^(b-1) / fs_sigma)^2, SNR <= D (r - 1) / 2.
    r = (2.0 ** (sig.adc_bits - 1) / sig.adc_full_scale_sigma) ** 2
    return 10 * math.log10(sig.decimation * (r - 1) / 2)


def check_values(run, sig) -> None:
    if run.detect_db <= 0:
        raise ValueError(f"--detect-db must be > 0 dB (the threshold over the sum beam's noise "
                         f"power; at 0 dB noise alone passes 37 % of the blocks, below it "
                         f"nearly all), not {run.detect_db:g}")
    for name, flag in (("gain_spread_db", "--gain-spread-db"),
                       ("phase_spread_deg", "--phase-spread-deg")):
        v = getattr(run, name)
        if v < 0:
            raise ValueError(f"{flag} must be >= 0 (channels 2-4 are drawn in +- it), not {v:g}")
    if run.phase_spread_deg > 180:
        raise ValueError(f"--phase-spread-deg must be <= 180, not {run.phase_spread_deg:g}")
    if sig.adc_bits is not None:
        top = max_snr_db(sig)
        for flag, v in (("--snr-db", run.snr_db), ("--cal-snr-db", run.cal_snr_db)):
            if v is not None and v > top:
                raise ValueError(f"{flag} {v:g} is above what the {sig.adc_bits}-bit ADC "
                                 f"resolves ({top:.1f} dB: the noise must span at least one "
                                 f"ADC step; above it the ADC sets the noise): lower {flag} "
                                 f"or raise --adc-bits")
    snr = block_sum_snr_db(sig)
    if snr < run.detect_db:
        raise ValueError(f"--snr-db {run.snr_db:g} gives the sum beam of a block {snr:.1f} dB "
                         f"over its noise (4 channels x {sig.snapshots} snapshots), below the "
                         f"{run.detect_db:g} dB detection threshold: the target could never "
                         f"be detected; raise --snr-db")


def first_scored_block(run, sig) -> int:
    """The earliest block that can be scored: tracking starts at block ``2 +
    latency_blocks`` at the earliest (a detection in block 0, its confirmation in the block
    the steering reaches, ``1 + latency_blocks`` later), scoring at ``settle_s``."""
    lead = 1 + run.latency_blocks
    settle = int(math.ceil(run.settle_s / sig.block_s - 0.5))   # first centre >= settle_s
    return max(lead + 1, settle)


def check_run(run, sig) -> None:
    """Every rule of this module, in the order that keeps each check cheap: the options,
    the values, one block at least, the size, then the record block by block."""
    check_ignored(run)
    check_values(run, sig)
    if run.duration_s < sig.block_s:
        raise ValueError(f"--duration-s {run.duration_s:g} is shorter than one measurement "
                         f"block ({sig.snapshots:,} snapshots at {sig.chip_rate_hz / 1e6:g} "
                         f"Msnapshot/s = {sig.block_s:.3g} s): lengthen --duration-s or "
                         f"reduce --snapshots")
    check_run_size(run, sig)
    check_record(run, sig)


def check_record(run, sig) -> None:
    """The record (at least one block long, :func:`check_run`): the target visible all
    along, a manoeuvre inside it, something to score (unless ``run.require_score`` is
    False)."""
    T = sig.block_s
    K = _blocks(run, sig)
    if run.accel_u or run.accel_v:
        if run.manoeuvre_start_s >= K * T:
            raise ValueError(f"the manoeuvre starts at --manoeuvre-start-s "
                             f"{run.manoeuvre_start_s:g}, after the end of the run "
                             f"(--duration-s {run.duration_s:g}): it would change nothing")
    traj = sig.trajectory
    t = sig.block_centre_s(np.arange(K))
    u, v = traj.unchecked(t) if hasattr(traj, "unchecked") else traj(t)
    out = ~(np.asarray(u) ** 2 + np.asarray(v) ** 2 < 1.0)
    if np.any(out):
        k = int(np.flatnonzero(out)[0])
        raise ValueError(f"the target leaves the visible region u^2 + v^2 < 1 at t = "
                         f"{t[k]:.4g} s (u = {float(u[k]):.4g}, v = {float(v[k]):.4g}): "
                         f"shorten --duration-s {run.duration_s:g} to below that, or change "
                         f"--u0, --v0, --du-dt, --dv-dt, --accel-u, --accel-v")
    if not run.require_score:
        return
    if not 0 <= run.settle_s < run.duration_s:
        raise ValueError(f"--settle-s must be >= 0 and shorter than the record (--duration-s "
                         f"{run.duration_s:g}: nothing would be scored), not {run.settle_s:g}")
    first = first_scored_block(run, sig)
    if first >= K:
        raise ValueError(
            f"the record is too short to score anything: {K:,} blocks of {T * 1e3:.3g} ms "
            f"(--duration-s {run.duration_s:g}), the first tracked block is 2 + "
            f"--latency-blocks {run.latency_blocks} at the earliest and scoring starts at "
            f"--settle-s {run.settle_s:g} (block {first:,}): lengthen --duration-s, or reduce "
            f"--latency-blocks or --settle-s")


#: Options that only act in some runs: (fields, flags, when they act, why not otherwise).
_ONLY_WITH = (
    (("cal_snapshots", "cal_snr_db"), lambda r: not r.skip_calibration,
     "set the calibration, but --skip-calibration skips it"),
    (("service_period_cycles", "service_latency_cycles", "service_batch_words",
      "compute_cycles", "control_latency_cycles"),
     lambda r: r.backend not in ("fast", "golden"),
     "set how the DSP reads the FPGA FIFO, but --backend {backend} has no FIFO: use "
     "--backend model, pysim, verilator or icarus"),
    (("eq36", "floor_scaling", "noise_floor", "alpha_relax"), lambda r: r.tracker == "adaptive",
     "set the adaptive tracking index, but --tracker fixed has fixed gains (--sigma-a)"),
    (("manoeuvre_start_s", "manoeuvre_end_s"), lambda r: bool(r.accel_u or r.accel_v),
     "set the manoeuvre window, but there is no manoeuvre (--accel-u and --accel-v are 0)"),
)


def check_ignored(run, given=frozenset()) -> None:
    """Refuse an option where it changes nothing: set to a value other than its default, or
    named in ``given`` (the fields given on the command line,
    :func:`cosim.core.receivers.given_fields`: at their default value too)."""
    default = {f.name: f.default for f in dataclasses.fields(run)}
    for names, acts, why in _ONLY_WITH:
        given_ = [n for n in names if n in given or getattr(run, n) != default[n]]
        if given_ and not acts(run):
            flags = ", ".join("--" + n.replace("_", "-") for n in given_)
            why = why.format(backend=run.backend)
            raise ValueError(f"{flags} {why if len(given_) > 1 else why.replace('set ', 'sets ', 1)}")

"""The monopulse closed beam-steering loop through the HDL front end (``--backend model``,
``pysim``, ``verilator``): the scenario of the golden path, measured by
:mod:`hdl.monopulse` instead of the float chain.

::

    generate(block k, steering in force) -> ADC words -> front-end session -> FIFO records
        ^                                                                      |
        |   analog phase shifters                                               v
    steering (u0, v0) + 4 coefficients  <--  ControlPath  <--  DSP: tracker / search (run._Loop)

One front-end session (:func:`cosim.backends.factory.open_frontend` on the backend, register writes
by :class:`cosim.core.session.RegisterSession`) in the streaming pipeline
(:class:`cosim.core.pipeline.Pipeline`): every DSP service reads the FIFO words, reassembles the
records (:func:`dsp.records.receive_records`) and, per record, runs the same loop step as the
fast and golden paths (:class:`cosim.monopulse.run._Loop`); its steering command goes back as
register writes (``u0``, ``v0`` and the four channel coefficients ``exp(j phi_i0) c_i`` of
the steering times the calibration, scaled by one common factor so that ``|k_i| <= 1``),
issued ``compute_cycles`` after the service's read window and holding ``control_latency_cycles``
later.

Timing. The front end's registers are double buffered: a write lands in the shadow and
becomes active at the next block boundary. Block 0 always runs on the reset registers, so
the HDL run starts with one *preamble* block (zeros, its record ignored): HDL block ``j + 1``
carries scenario block ``j`` (the generator's block ``j``: the same samples, truth and
steering as the golden path). The steering of scenario blocks 0 and 1 is the search's first
two positions, written before the run; the record of scenario block ``k`` arrives during
block ``k + 1`` and its command lands before that block's boundary, so it steers block
``k + 2``: the loop's ``lead = 1 + latency_blocks`` with ``latency_blocks = 1`` (the only
latency the hardware has; other values are refused). Each record's ``u0`` (recovered as
``u - du(ang_a)``, bit-exact) is checked against the command meant for its block: a DSP too
slow to turn a record around within one block is an error, not a silent mismatch.

Units. The record's beams are ``G N`` times the golden chain's (:func:`record_gain`), so the
sum-beam detection uses the golden noise variance times ``(G N)^2`` and the same threshold.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from dsp.fixed import shift_right

from .fastpath import noise_variance

__all__ = ["hdl_params", "record_gain", "hdl_closed_loop", "check_hdl_timing", "check_hdl_run",
           "FaultHooks"]

#: Cycles per FIFO word the DSP's service reads (as the GNSS loop).
CYCLES_PER_WORD = 4


def hdl_params(run, sig):
    """The front end for the scenario: its rates, ADC, block length, spacings, plus
    ``run.hdl_changes``."""
    from hdl.monopulse.params import MonopulseFrontendParams
    arr = sig.array
    return MonopulseFrontendParams(fs_hz=sig.fs_hz, if_hz=sig.if_hz,
                                   snapshot_decimation=sig.decimation, cic_rate=sig.decimation,
                                   adc_bits=sig.adc_bits, snapshots=sig.snapshots,
                                   spacing_x_wl=arr.dx_wl, spacing_y_wl=arr.dy_wl,
                                   **dict(run.hdl_changes))


def record_gain(p, adc_step: float) -> float:
    """``G``: a record's accumulated beam (LSBs) is ``G N`` times the golden chain's beam
    (:func:`dsp.monopulse.golden.golden_chain` with the same coefficients ``k``, each part
    ``<= 1``, ``coef_word(k)``): the ADC (``1 / adc_step`` per volt), the DDC mixer (the
    NCO's peak, ``2**-drop_bits``; the golden DDC has a factor 2), the CIC (and FIR) DC gain
    (the golden integrate-and-dump averages), the correction (``coef_max``,
    ``2**-drop_bits``)."""
    g = p.nco.peak / (2.0 * adc_step * 2.0 ** p.ddc.mixer.drop_bits)
    g *= p.cic.float_gain
    if p.fir is not None:
        g *= p.fir.dc_gain
    return g * p.coef_max / 2.0 ** p.corr.drop_bits


def _service(run):
    from ..core.link import DspServiceConfig
    return DspServiceConfig(period_cycles=run.service_period_cycles,
                            latency_cycles=run.service_latency_cycles,
                            batch_words=run.service_batch_words, cycles_per_word=CYCLES_PER_WORD)


def check_hdl_timing(run, p) -> None:
    """Refuse (before work) a DSP service that cannot turn a record around within one block:
    worst case from the record's FIFO write to its last register write landing =
    FIFO (2) + a service period + the read of one record + compute + control + the 6 bus
    writes, against the block's ``N D`` cycles."""
    svc = _service(run)
    worst = (2 + svc.period_cycles + svc.latency_cycles + p.record_words * CYCLES_PER_WORD
             + run.compute_cycles + run.control_latency_cycles + 6 + 1)
    block = p.snapshots * p.snapshot_decimation
    if worst >= block:
        raise ValueError(
            f"the DSP service cannot turn a record around within one block on the HDL front "
            f"end: worst case {worst} cycles (service_period_cycles {svc.period_cycles} + "
            f"service_latency_cycles {svc.latency_cycles} + {p.record_words} words x "
            f"{CYCLES_PER_WORD} + compute_cycles {run.compute_cycles} + "
            f"control_latency_cycles {run.control_latency_cycles} + bus) >= {block} cycles "
            f"per block (snapshots {p.snapshots} x {p.snapshot_decimation}): shorten the "
            f"service or use more snapshots")
    if svc.batch_words < p.record_words:
        raise ValueError(f"service_batch_words must hold one record ({p.record_words} words), "
                         f"not {svc.batch_words}")


@dataclass
class FaultHooks:
    """Bit errors injected into the HDL closed loop (the fault study): ``adc(k, codes)``
    returns scenario block ``k``'s ADC codes (4, N D) with flips; ``fifo(words)`` the FIFO
    words a DSP service read, with flips. With hooks the DSP does not raise on a bad record
    (block counter or steering words not those expected): it counts it and treats the block
    as undetected; it re-synchronises on a record whose block counter and steering words
    both match a later block (records lost: the blocks between count as missing)."""

    adc: object = None
    fifo: object = None


class _HdlDsp:
    """The pipeline's DSP callback: records -> the loop -> register writes."""

    def __init__(self, run, sig, p, loop, cal_n, ut, vt, thr, gain, faults=None):
        from dsp.records import RecordRxState
        self.run, self.sig, self.p, self.loop = run, sig, p, loop
        self.cal_n, self.ut, self.vt, self.thr = cal_n, ut, vt, thr
        self.gn2 = (gain * p.snapshots) ** 2
        self.nv = noise_variance(sig)
        self.rx = RecordRxState()
        self.faults = faults
        self.n_records = 0           # records received (preamble included)
        self.next_block = 0          # the scenario block the next record should carry
        self.bad_records = 0
        self.missing_blocks = 0
        self.K = loop.K

    def writes_for(self, st):
        """Register writes steering a block at ``st`` = (u0, v0)."""
        from hdl.monopulse.params import coef_word, dc_word
        arr = self.sig.array
        k = arr.steering_correction(st[0], st[1]) * self.cal_n
        out = [(f"coef{i + 1}", coef_word(k[i], self.p)) for i in range(4)]
        return out + [("u0", dc_word(st[0], self.p)), ("v0", dc_word(st[1], self.p))]

    def _steering_words(self, f):
        """The (u0, v0) words a record's block ran on: ``u - du(ang_a)`` (bit-exact)."""
        p = self.p
        (kx, sx), (ky, sy) = p.dc_coefs
        u0 = int(f["u"] - shift_right(np.int64(f["ang_a"]) * np.int64(kx), sx, "half_up"))
        v0 = int(f["v"] - shift_right(np.int64(f["ang_e"]) * np.int64(ky), sy, "half_up"))
        return [x & ((1 << p.dc_bits) - 1) for x in (u0, v0)]

    def _want(self, k):
        from hdl.monopulse.params import dc_word
        return [dc_word(x, self.p) for x in self.loop.steer[k, 0]]

    def _block(self, k, f):
        """Scenario block ``k`` measured by record fields ``f`` (None: undetected)."""
        loop, p = self.loop, self.p
        st = loop.steer[k, 0]
        arr = self.sig.array
        h0 = arr.channel_response(self.ut[k], self.vt[k], st[0], st[1])[0]
        af2 = abs(h0 / arr.channel_gains[0]) ** 2
        if f is None:
            mu = mv = np.nan
            det = False
        else:
            scale = 2.0 ** -p.dc_frac_bits
            mu, mv = f["u"] * scale, f["v"] * scale
            s = complex(f["s_re"], f["s_im"])
            kc = arr.steering_correction(st[0], st[1]) * self.cal_n
            var = self.gn2 * float(np.sum(np.abs(kc) ** 2 * self.nv))
            det = abs(s) ** 2 > self.thr * var if var > 0 else abs(s) > 0
        loop.block(k, np.array([mu]), np.array([mv]), np.array([det]), np.array([af2]))
        self.next_block = k + 1
        nxt = k + loop.lead
        return self.writes_for(loop.steer[nxt, 0]) if nxt < self.K else []

    def late(self, k):
        """Block ``k`` is about to start and block ``k - 2``'s record has not come (lost in a
        fault run): that block counts as undetected (the DSP's deadline), and block ``k``
        runs on the registers in force, the last command (``steer[k - 1]``)."""
        while self.next_block <= k - 2:
            self.missing_blocks += 1
            self._block(self.next_block, None)      # its writes would come too late
        self.loop.steer[k] = self.loop.steer[k - 1]

    def finish(self):
        """Blocks whose record never came (fault runs): undetected."""
        out = []
        while self.next_block < self.K:
            self.missing_blocks += 1
            out += self._block(self.next_block, None)
        return out

    def __call__(self, call):
        from dsp.records import receive_records
        p, fp = self.p, self.p.fifo
        if not call.words.size:
            return ()
        words = call.words if self.faults is None or self.faults.fifo is None else \
            self.faults.fifo(call.words)
        b = receive_records(words, width=fp.width, record_words=fp.record_words,
                            parity=fp.parity, state=self.rx)
        out = []
        mask = (1 << p.block_bits) - 1
        for row in b.records:
            v = 0
            for j, w in enumerate(row):
                v |= int(w) << (j * fp.width)
            f = p.record.unpack(v)
            j = self.n_records
            self.n_records += 1
            if self.faults is None:
                if f["block"] != j & mask:
                    raise RuntimeError(f"monopulse record {j} carries block {f['block']}: a "
                                       f"record was lost (FIFO overflow?)")
                if j == 0:
                    continue                     # the preamble (reset registers)
                k = j - 1
                if k >= self.K:
                    raise RuntimeError(f"monopulse front end gave a record for block {k} of "
                                       f"a {self.K}-block scenario")
                got, want = self._steering_words(f), self._want(k)
                if got != want:
                    raise RuntimeError(
                        f"monopulse block {k} ran on the steering words {got}, not the "
                        f"command {want} meant for it: the DSP did not turn block {k - 2}'s "
                        f"record around before the block boundary")
                out += self._block(k, f)
                continue
            # Fault runs: validate, re-synchronise, never raise.
            k = self.next_block
            if k >= self.K:
                self.bad_records += 1
                continue
            if j == 0:
                continue                                 # the preamble
            tag = (f["block"] - 1) & mask               # the scenario block it claims
            if tag != k & mask:
                # one record lost: this one is block k + 1 (its steering words say so too)
                if tag == (k + 1) & mask and k + 1 < self.K and \
                        self._steering_words(f) == self._want(k + 1):
                    self.missing_blocks += 1
                    out += self._block(k, None)
                    out += self._block(k + 1, f)
                else:
                    self.bad_records += 1
                    out += self._block(k, None)
                continue
            if self._steering_words(f) != self._want(k):
                self.bad_records += 1
                out += self._block(k, None)
                continue
            out += self._block(k, f)
        return out


def hdl_closed_loop(run, sig, loop, cal, ut, vt, thr, faults: FaultHooks | None = None) -> dict:
    """Run ``loop`` (one trial) on the HDL front end of ``run.backend``; fills the loop's
    arrays and returns the FIFO/pipeline figures (``fifo_dropped``, digests, writes; with
    ``faults``: the bad and missing records and the record receiver's counters)."""
    from hdl.monopulse.params import pack_input
    from ..core.pipeline import Pipeline
    from ..core.session import RegisterSession
    from ..backends.factory import open_frontend
    from .signal import generate
    p = hdl_params(run, sig)
    check_hdl_timing(run, p)
    cal_n = np.asarray(cal, complex)
    cal_n = cal_n / max(1.0, float(np.max(np.abs(cal_n))))   # |k_i| <= 1: parts fit
    gain = record_gain(p, sig.adc_step)
    dsp = _HdlDsp(run, sig, p, loop, cal_n, ut, vt, thr, gain, faults)
    svc = _service(run)
    K, D, N = loop.K, sig.decimation, sig.snapshots
    boundary0 = N * D - 1 + p.latency_pre
    with RegisterSession(open_frontend(run.backend, p), p.registers) as fe:
        pipe = Pipeline(fe, svc, dsp, compute_cycles=run.compute_cycles,
                        control_latency_cycles=run.control_latency_cycles, keep_words=False)
        # Scenario blocks 0 and 1 (HDL blocks 1, 2): the first two search positions.
        pre = [(1, r, v) for r, v in dsp.writes_for(loop.steer[0, 0])]
        if K > 1:
            pre += [(boundary0 + 1, r, v) for r, v in dsp.writes_for(loop.steer[1, 0])]
        pipe.schedule(pre)
        pipe.feed(pack_input(np.zeros((N * D, 4), np.int64), np.zeros(N * D, np.int64), p))
        for k in range(K):
            if faults is not None and k >= 2 and dsp.next_block <= k - 2:
                dsp.late(k)
            rec = generate(sig, loop.steer[k, 0], first_block=k, n_blocks=1)
            chips = np.repeat((rec.replica[0] < 0).astype(np.int64), D)
            x = rec.samples if faults is None or faults.adc is None else faults.adc(k, rec.samples)
            pipe.feed(pack_input(np.asarray(x).T.astype(np.int64), chips, p))
        # flush: the last record leaves the front end, waits for a service, is read, and
        # the DSP's call comes compute_cycles after the read window
        turnaround = svc.latency_cycles + p.record_words * CYCLES_PER_WORD + run.compute_cycles
        pipe.idle(p.latency + svc.period_cycles + max(svc.period_cycles, turnaround) + 64)
        res = pipe.result()
        bus = list(fe.bus_writes)
    extra = {}
    if faults is not None:
        dsp.finish()
        extra = {"bad_records": dsp.bad_records, "missing_blocks": dsp.missing_blocks,
                 "rx": {k: int(v) for k, v in dict(dsp.rx.stats).items()}}
    elif dsp.n_records != K + 1:
        raise RuntimeError(f"monopulse front end gave {dsp.n_records} records for {K} blocks "
                           f"and the preamble (FIFO overflow count {res.overflow_count})")
    hb = hashlib.sha256(repr(bus).encode()).hexdigest()[:16]
    return {"fifo": f"{p.fifo.depth}-word FIFO, {p.record_words} words a record, read every "
                    f"{svc.period_cycles} cycles",
            "fifo_dropped": int(res.overflow_count),
            "digest": {"fifo_words": res.digest["words"], "fifo_cycles": res.digest["cycles"],
                       "writes": res.digest["writes"], "bus": hb},
            "records": dsp.n_records, "register_writes": len(res.writes),
            "cycles": int(res.n_cycles), "record_gain": gain * N, **extra}


#: Approximate simulated cycles per second of each backend on the closed loop (measured on
#: the 2-core development machine, results/monopulse.md): the run's wall-time estimate
#: (:func:`cosim.monopulse.checks.run_cost`).
CYCLES_PER_S = {"model": 7e5, "pysim": 2e3, "verilator": 1e6, "icarus": 1e3}


def check_hdl_run(run, sig) -> None:
    """Refuse, before work, an HDL closed loop the front end cannot run: its parameters
    (``hdl_changes``) and the DSP's turnaround (:func:`check_hdl_timing`). (Its size: the
    run's, :func:`cosim.monopulse.checks.check_run_size`.)"""
    check_hdl_timing(run, hdl_params(run, sig))

"""Golden (float64) model of the TACAN FPGA front end.

The same structure as the HDL chain, without quantisation, so that golden and hardware
differ only where the hardware rounds:

    ADC codes -> x 2 exp(-j w n) (NCO + mixer) -> CIC (N, R, M) -> FIR (CIC-compensated
    pulse-matched filter, decimation D) -> |z| -> pulse-peak search (noise-floor threshold)

The CIC runs here as its equivalent FIR (a boxcar of R*M convolved N times, DC gain 1), the
FIR with the float taps of :func:`dsp.design.design_pulse_fir`, the envelope is the exact
magnitude and the peak search is :func:`dsp.tacan.peak.peak_search_float` (the integer
model's twin). Amplitudes come out in units of ADC full scale (carrier peak amplitude);
timestamps in ADC sample ticks, delayed by :attr:`FrontendConfig.group_delay_samples`.

Runs in chunks with carried state: memory stays bounded for long records and the result
does not depend on the chunking.
"""
from __future__ import annotations

import math
from fractions import Fraction
from dataclasses import dataclass, field, replace

import numpy as np

from dsp.design import cic_taps, design_pulse_fir
from dsp.tacan.peak import peak_search_float
from dsp.tacan.peak_params import PeakParams, PeakState
from dsp.tacan.standard import PULSE_WIDTH_S, SOURCE_PAIR, SOURCE_PULSE, pair_spacing_s

PULSE_SIGMA_S = PULSE_WIDTH_S / (2.0 * math.sqrt(2.0 * math.log(2.0)))


#: The pulse detector's noise-floor profiles (``python -m cosim tacan --noise-floor``):
#:
#: * ``clipped`` (default): the block mean of ``min(e, 2 nu)``, threshold 3.0x;
#: * ``censored``: samples over ``2 nu`` count as ``nu`` (:attr:`dsp.tacan.peak_params.PeakParams.clip_to_floor`),
#:   threshold 3.44x (55/16). Bursts of pulses no longer lift the threshold after them,
#:   which biased the bearing near the noise floor; and since pulses no longer lift the
#:   floor at all, the factor is raised so that a 10 dB record gives the clipped floor's
#:   bearings (3.25x, the same false-alarm rate on noise alone, passed ~5 % more noise
#:   peaks at 10 dB and raised the RMSE 1-3 %). Measured (golden chain, seeds 100-103,
#:   3 s, RMSE deg clipped -> censored): 10 dB 0.083 / 0.081 -> 0.083 / 0.081 (90 / 270
#:   deg); 3 dB 0.237 / 0.350 -> 0.210 / 0.324; 1 dB 0.62 / 0.83 -> 0.60 / 0.51; 0 dB 0.83 /
#:   1.22 -> 0.85 / 0.70. Not the default: a clean 10 dB record of the fault test
#:   (``test_dsp_state_upsets_are_detected_and_recovered``) then flags 1 bearing in 203 --
#:   one more noise peak gated just before a reference, which the receiver's flag rule
#:   (one gated measurement flags the bearing) turns into a warning -- and `make study` /
#:   `make faults` have not been re-run with it.
NOISE_FLOORS = {
    "clipped": PeakParams(),
    "censored": PeakParams(clip_to_floor=True, thr_mult=55),
}

#: The pulse-pair detector (``python -m cosim tacan --detector pair``, experimental): the
#: search runs on ``e[n] + e[n - D]``, ``D`` the mode's pair spacing (:func:`pair_detector`),
#: with a censored floor smoothed over 2**10 blocks (~0.2 s) and threshold 2.875x (46/16) the
#: pair sum's floor. A clipped floor is lifted by the bursts and biases the bearing (+0.5 deg
#: at 3 dB, 270 deg). The threshold trades the pairs found in the envelope's deep trough,
#: which reference acquisition needs at 0 dB, 90 deg (46/16 acquired 4 of 8 records, 40/16
#: all 8), against the noise pairs (on noise alone ~30/s at 46/16, ~460/s at 40/16) and the
#: other mode's pulses that pass as pairs: at 40/16 a Y beacon heard by the X receiver gave
#: 150 main references and 9 valid bearings, 180 deg off, in 10 s at 10 dB (46/16: 1 and 0).
#: The DSP corrects the reports' bias near the threshold with the curve calibrated at this
#: threshold (``dsp.tacan.peakbias.PAIR_PEAK_BIAS``). The pair checks (``pair_balance`` 4: the
#: smaller pulse at least a quarter of the sum; ``pair_spread`` 8: the pulses 12 us +- 1.6 us
#: apart) keep the other mode out: without them a Y beacon heard by the X receiver gave 293
#: main references and 13 valid bearings in 60 s at 20 dB (its single pulses and its 15 us
#: auxiliary pulses pass a pair-sum test); with them 0 valid in 60 s at 20 and 10 dB. They
#: do not keep an X beacon out of the Y receiver at 10 dB: 900 main references and 105
#: valid bearings in 60 s (the X main burst's pairs, 30 us apart, are Y pairs; 20 dB: 0
#: valid). The floor keeps its 10 fraction bits (``floor_frac``): without them the integer
#: floor's truncation settled the HDL's threshold ~14 % below the float golden's (1.5 s at 10
#: dB: 6528 reports against 6368). Figures: ``python -m cosim bench tacan-accuracy``; the
#: choices: docs/experiments/README.md.
PAIR_DETECTOR = PeakParams(clip_to_floor=True, smooth_log2=10, floor_frac=True, thr_mult=46,
                           pair_balance=4, pair_spread=8)

#: The pair search beside the single-pulse one (``python -m cosim tacan --detector both``):
#: :data:`PAIR_DETECTOR` at threshold 2.5x (40/16). Here the references, the acquisition and
#: the mode check run on the single pulses, so the pair search's threshold only trades the
#: pairs measured in the envelope's trough against the noise pairs measured (~460/s on
#: noise alone; the DSP's noise-report rule drops most, ``dsp.tacan.peakbias.BOTH_PEAK_BIAS``).
#: Measured with both searches (golden chain, 8 records of 3 s, seeds 100-107, RMSE deg at
#: 90 / 270 deg; 46/16 -> 40/16): 0 dB 0.461 / 0.420 -> 0.294 / 0.267; 3 dB 0.184 / 0.189 ->
#: 0.231 / 0.204; 10 dB 0.082 / 0.081 both. The bound at 0 dB is 0.219 deg. Its floor keeps
#: its fraction bits as :data:`PAIR_DETECTOR`'s (``floor_frac``: the HDL's threshold is then the
#: golden's, not ~14 % below it).
BOTH_PAIR_SEARCH = replace(PAIR_DETECTOR, thr_mult=40)

#: The detectors of ``python -m cosim tacan --detector``: single pulses (with the profile of
#: ``--noise-floor``), pulse pairs, or both searches side by side (``FrontendConfig.pair_peak``:
#: the DSP decodes the references on the single pulses and measures on the pairs).
DETECTORS = ("pulse", "pair", "both")


def pair_spacing_samples(mode: str, env_rate_hz: float) -> int:
    """The mode's pair spacing (12 us X, 30 us Y) in envelope samples at ``env_rate_hz``
    (the partner readout's and the pair detection's ``D``)."""
    return int(round(pair_spacing_s(mode) * env_rate_hz))


def pair_detector(mode: str, env_rate_hz: float, base: PeakParams = PAIR_DETECTOR) -> PeakParams:
    """``base`` with pulse-pair detection at the mode's pair spacing."""
    return replace(base, pair_offset=pair_spacing_samples(mode, env_rate_hz))


@dataclass(frozen=True)
class FrontendConfig:
    """Structure and rates of the TACAN front end (shared by the golden model and the HDL).

    Parameters
    ----------
    fs_hz : float
        ADC sample rate (Hz).
    if_hz : float
        Digital IF after bandpass sampling (Hz), ``0 < if_hz < fs/2``.
    cic_stages, cic_rate, cic_delay : int
        CIC decimator N, R, M.
    fir_numtaps, fir_decim : int
        Pulse-matched FIR length (odd) and its decimation.
    pulse_sigma_s : float
        Gaussian pulse standard deviation the FIR is matched to.
    peak : PeakParams
        Pulse-peak search (noise-floor block, threshold factor, hold, max length).
    thr_min_fs : float
        Lowest detection threshold in the golden model (fraction of ADC full scale).
    pair_peak : PeakParams, optional
        A second search on the same envelope, a pulse-*pair* detection (``pair_offset > 0``,
        :func:`pair_detector`), run beside ``peak`` (single pulses): both report into one
        stream, each report tagged with its search (:attr:`Peaks.source`; ``python -m cosim
        tacan --detector both``). None: one search.
    """

    fs_hz: float = 20e6
    if_hz: float = 3e6
    cic_stages: int = 3
    cic_rate: int = 4
    cic_delay: int = 1
    fir_numtaps: int = 33
    fir_decim: int = 1
    pulse_sigma_s: float = PULSE_SIGMA_S
    peak: PeakParams = field(default_factory=PeakParams)
    thr_min_fs: float = 0.05
    pair_peak: PeakParams | None = None

    def __post_init__(self):
        for name in ("fs_hz", "if_hz", "pulse_sigma_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, not {v!r}")
        if not self.if_hz < self.fs_hz / 2:
            raise ValueError(f"digital IF must be below fs/2 = {self.fs_hz / 2:g} Hz, not {self.if_hz:g}")
        for name, lo in (("cic_stages", 1), ("cic_rate", 2), ("cic_delay", 1), ("fir_decim", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                what = "CIC decimation" if name == "cic_rate" else name
                raise ValueError(f"{what} must be an integer >= {lo}, not {v!r}")
        if isinstance(self.fir_numtaps, bool) or not isinstance(self.fir_numtaps, int) \
                or self.fir_numtaps < 3 or self.fir_numtaps % 2 == 0:
            raise ValueError(f"FIR numtaps must be an odd integer >= 3, not {self.fir_numtaps!r}")
        if self.peak.ts_step != self.decimation:
            raise ValueError(f"peak ts_step ({self.peak.ts_step}) must equal the total "
                             f"decimation cic_rate*fir_decim = {self.decimation}")
        if not self.thr_min_fs >= 0:
            raise ValueError(f"thr_min_fs must be >= 0, not {self.thr_min_fs}")
        if self.pair_peak is not None:
            if not isinstance(self.pair_peak, PeakParams) or not self.pair_peak.pair_offset:
                raise ValueError(f"pair_peak must be a PeakParams with pulse-pair detection "
                                 f"(pair_offset > 0), not {self.pair_peak!r}")
            if self.peak.pair_offset or self.peak.partner_offset:
                raise ValueError("with pair_peak, peak must be the single-pulse search (no "
                                 "pair_offset, no partner_offset): the pair search is pair_peak")
            if self.pair_peak.ts_step != self.decimation:
                raise ValueError(f"pair_peak ts_step ({self.pair_peak.ts_step}) must equal the "
                                 f"total decimation cic_rate*fir_decim = {self.decimation}")

    @property
    def decimation(self) -> int:
        return self.cic_rate * self.fir_decim

    @property
    def env_rate_hz(self) -> float:
        return self.fs_hz / self.decimation

    @property
    def fir_taps(self) -> np.ndarray:
        return design_pulse_fir(fs_in_hz=self.fs_hz, cic_stages=self.cic_stages,
                                cic_rate=self.cic_rate, cic_delay=self.cic_delay,
                                numtaps=self.fir_numtaps, pulse_sigma_s=self.pulse_sigma_s)

    @property
    def group_delay_samples(self) -> float:
        """Delay of a pulse peak through CIC + FIR, in ADC samples."""
        cic = self.cic_stages * (self.cic_rate * self.cic_delay - 1) / 2
        return cic + (self.fir_numtaps - 1) / 2 * self.cic_rate

    @classmethod
    def for_signal(cls, sig_cfg, **changes) -> "FrontendConfig":
        """The front end for a :class:`cosim.tacan.signal.TacanSignalConfig`'s rates."""
        kw = dict(fs_hz=sig_cfg.fs_hz, if_hz=sig_cfg.digital_if_hz, pulse_sigma_s=sig_cfg.pulse_sigma_s)
        kw.update(changes)
        return cls(**kw)


class _DecimatingFir:
    """Streaming FIR + decimation by ``down`` (output at input indices that are multiples
    of ``down``), with the history carried between chunks."""

    def __init__(self, taps: np.ndarray, down: int):
        self.h = np.asarray(taps, dtype=np.float64)
        self.down = down
        hist = len(self.h) - 1
        self.hist_len = -(-hist // down) * down  # multiple of down
        self.hist = np.zeros(self.hist_len, dtype=np.complex128)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        if len(x) % self.down:
            raise ValueError("chunk length must be a multiple of the decimation")
        buf = np.concatenate([self.hist, x])
        # upfirdn output m: sum_k h[k] buf[m*down - k]; keep outputs at buf index >= hist_len.
        from scipy.signal import upfirdn
        y = upfirdn(self.h, buf, up=1, down=self.down)
        m0 = self.hist_len // self.down
        y = y[m0:m0 + len(x) // self.down]
        self.hist = buf[len(buf) - self.hist_len:] if self.hist_len else self.hist
        return y


@dataclass
class Peaks:
    """Pulse peaks as the FPGA reports them."""

    timestamps: np.ndarray   # ADC sample ticks (int64, not wrapped)
    amplitudes: np.ndarray   # fraction of ADC full scale
    fs_hz: float
    #: With two searches (``FrontendConfig.pair_peak``): which search reported each peak
    #: (int8, :data:`SOURCE_PULSE` or :data:`SOURCE_PAIR`); None: one search.
    source: np.ndarray | None = None

    @property
    def times_s(self) -> np.ndarray:
        return self.timestamps / self.fs_hz



def merge_sources(pulse_ts, pulse_amp, pair_ts, pair_amp):
    """Two searches' reports as one stream in timestamp order (a pulse report before a pair
    report with the same timestamp): ``(timestamps, amplitudes, source)``."""
    ts = np.concatenate([pulse_ts, pair_ts])
    src = np.concatenate([np.full(len(pulse_ts), SOURCE_PULSE, np.int8),
                          np.full(len(pair_ts), SOURCE_PAIR, np.int8)])
    o = np.lexsort((src, ts))
    return ts[o], np.concatenate([pulse_amp, pair_amp])[o], src[o]


class GoldenFrontend:
    """Float64 front end; call :meth:`process` on consecutive chunks of ADC codes."""

    CHUNK = 1 << 20

    def __init__(self, cfg: FrontendConfig, adc_bits: int):
        self.cfg = cfg
        self.adc_bits = int(adc_bits)
        self.n = 0
        self.cic = _DecimatingFir(cic_taps(cfg.cic_stages, cfg.cic_rate, cfg.cic_delay), cfg.cic_rate)
        self.fir = _DecimatingFir(cfg.fir_taps, cfg.fir_decim)
        self.peak_state: PeakState | None = None
        self.pair_state: PeakState | None = None
        self.w = 2 * np.pi * cfg.if_hz / cfg.fs_hz
        # When f_IF / fs is a ratio of small integers (3/20 by default) the LO repeats every
        # `period` samples: one table serves every chunk, exactly (same bits for any chunking).
        ratio = Fraction(cfg.if_hz / cfg.fs_hz).limit_denominator(1 << 16)
        exact = abs(float(ratio) - cfg.if_hz / cfg.fs_hz) < 1e-15 and ratio.denominator <= 1 << 16
        self._period = ratio.denominator if exact else None
        if self._period:
            self._table = np.exp(-1j * self.w * np.arange(self._period))

    def _lo_at(self, n0: int, count: int) -> np.ndarray:
        if self._period:
            return self._table[(n0 + np.arange(count)) % self._period]
        return np.exp(-1j * self.w * np.arange(n0, n0 + count, dtype=np.float64))

    def envelope(self, codes: np.ndarray) -> np.ndarray:
        """Envelope samples (fraction of full scale) of the next chunk of ADC codes."""
        x = np.asarray(codes, dtype=np.float64) * (2.0 ** -(self.adc_bits - 1))
        lo = self._lo_at(self.n, len(x))
        self.n += len(x)
        z = (2.0 * x) * lo
        return np.abs(self.fir(self.cic(z)))

    def search(self, codes: np.ndarray, env: np.ndarray | None = None):
        """The peak search's full result (:class:`dsp.tacan.peak_params.PeakResult`: with the threshold
        of every envelope sample) on the next chunk of ADC codes (or on its ``env``)."""
        env = self.envelope(codes) if env is None else env
        res, self.peak_state = peak_search_float(env, self.cfg.peak, self.peak_state,
                                                 thr_min=self.cfg.thr_min_fs)
        return res

    def process(self, codes: np.ndarray) -> Peaks:
        env = self.envelope(codes)
        res = self.search(codes, env)
        # with the pair-partner readout, the FPGA reports the partner's envelope as the
        # amplitude (hdl.tacan.frontend)
        amp = res.partner if self.cfg.peak.partner_offset else res.amplitude
        ts = np.asarray(res.index, np.int64) * self.cfg.decimation
        amp = np.asarray(amp, np.float64)
        if self.cfg.pair_peak is None:
            return Peaks(timestamps=ts, amplitudes=amp, fs_hz=self.cfg.fs_hz)
        pr, self.pair_state = peak_search_float(env, self.cfg.pair_peak, self.pair_state,
                                                thr_min=self.cfg.thr_min_fs)
        ts, amp, src = merge_sources(ts, amp, np.asarray(pr.index, np.int64) * self.cfg.decimation,
                                     np.asarray(pr.amplitude, np.float64))
        return Peaks(timestamps=ts, amplitudes=amp, fs_hz=self.cfg.fs_hz, source=src)


def record_chunks(samples: np.ndarray, cfg: FrontendConfig):
    """``(first sample, chunk)`` of a record in :attr:`GoldenFrontend.CHUNK`-sized pieces, each
    a multiple of the decimation (a last partial output sample is dropped)."""
    samples = np.asarray(samples)
    step = GoldenFrontend.CHUNK - GoldenFrontend.CHUNK % cfg.decimation
    usable = len(samples) - len(samples) % cfg.decimation
    for c0 in range(0, usable, step):
        yield c0, samples[c0:min(usable, c0 + step)]


def run_golden_frontend(samples: np.ndarray, cfg: FrontendConfig, adc_bits: int) -> Peaks:
    """All peaks of a record of ADC codes (chunked internally)."""
    fe = GoldenFrontend(cfg, adc_bits)
    ts, amps, src = [], [], []
    for _, chunk in record_chunks(samples, cfg):
        p = fe.process(chunk)
        ts.append(p.timestamps)
        amps.append(p.amplitudes)
        src.append(p.source)
    out = Peaks(np.concatenate(ts) if ts else np.zeros(0, np.int64),
                np.concatenate(amps) if amps else np.zeros(0), cfg.fs_hz)
    if cfg.pair_peak is not None:
        out.source = np.concatenate(src) if src else np.zeros(0, np.int8)
    return out

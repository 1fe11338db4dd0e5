"""Bit-error studies: flip bits in the ADC samples, the FIFO words, an FPGA register or the
DSP core's state, and see what the TACAN receiver does.

Targets and what ``ber`` means for each
--------------------------------------
``adc``        each bit of each ADC sample flips with probability ``ber`` (two's complement
               codes, ``adc_bits`` wide), before the front end (bit-exact model).
``fifo``       each bit of each FIFO word read by the DSP (payload and tag) flips with
               probability ``ber``; the DSP's receiver (:mod:`dsp.tacan.fifo_rx`) rejects
               implausible timestamps and reserved tags.
``register``   the NCO frequency register: in each scrub period (the DSP rewrites its
               configuration registers every ``scrub_period_s``) each bit flips with
               probability ``ber`` at a random cycle, and stays wrong until the next scrub.
               Run cycle-accurately (Verilator, or pysim for tiny runs) or on the model.
``dsp-state``  each bit of the fixed-point Kalman state ``x`` and covariance ``P`` words
               (as stored: ``x`` and the upper triangle of ``P``) flips with probability
               ``ber`` per filter update, inside the compiled core between two updates.

``bits`` restricts the flips to chosen bit positions (e.g. the MSBs). ``fifo_parity`` builds
the front end with the FIFO's even-parity bit (``TacanFrontendParams.fifo_parity``), which
the DSP's receiver checks: the flips then cover the parity bit too (reports
``faults_<target>_parity.*``).

Reported per (target, BER): bearing RMSE and worst error after settling, NaN bearings (must
be 0), exceptions (must be 0), flips injected, the receiver's events (gated, re-initialised,
rejected timestamps, ...), the share of disturbed bearings (error > ``disturbed_deg``) and
the longest disturbance (s): the recovery time. Integrity, as for a bearing indicator with a
warning flag: the share of bearings the receiver flagged (``BearingTrack.valid`` False, for
the reasons listed at :class:`dsp.tacan.receiver.ReceiverConfig`), the share of
*misleading* bearings (disturbed but not flagged: what a user would be shown as good), and
the RMSE / worst error of the unflagged bearings. And, as every study reports them
(:mod:`cosim.studies.shown`, the receiver's estimates, valid flags and error bound), the three
figures of what a user sees beside the fault-free run of the same trials: accuracy of the
estimates shown valid, availability (epochs with a valid estimate, time to the first) and
integrity (estimates shown valid beyond the receiver's bound -- TACAN: 20 deg -- and those the
fault-free run does not also make).
"""
from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .shown import paired, pool

#: TACAN's targets (kept here for callers of the first registry; a receiver gives its own
#: in ``FaultModel.targets``).
TARGETS = ("adc", "fifo", "register", "dsp-state")


def fault_model(receiver: str):
    """The :class:`~cosim.core.receivers.FaultModel` of a registered receiver (ValueError if
    none)."""
    from cosim.core.receivers import get
    r = get(receiver)
    if r.faults is None or r.faults.model is None:
        raise ValueError(f"receiver {receiver!r} has no fault study model")
    return r.faults.model


def parse_bits(spec: str | None) -> tuple[int, ...] | None:
    """``--bits``: ``"0,3,7"`` -> ``(0, 3, 7)``; None or empty -> None (every bit)."""
    if not spec:
        return None
    try:
        return tuple(int(b) for b in spec.split(","))
    except ValueError:
        raise ValueError(f"--bits takes a comma list of bit positions, not {spec!r}") from None


def finish(a, fc: "FaultConfig", s: dict, row_text) -> int:
    """The end of every ``faults <receiver>`` command: print the rows (``--json``: one JSON
    object; otherwise ``row_text(row)`` per BER) and the report's path; exit 1 when any run
    raised or gave a NaN estimate (the receiver must give neither)."""
    import sys
    from cosim.core.validate import dumps
    if a.json:
        print(dumps({"target": fc.target, "rows": s["rows"], "elapsed_s": s["elapsed_s"],
                     "report": f"{a.out}/{report_stem(fc)}.md"}, default=str))
    else:
        print(f"{len(s['rows'])} bit error rates x {fc.trials} trials in {s['elapsed_s']:.0f} s")
        for r in s["rows"]:
            print(f"  BER {r['ber']:g}: {row_text(r)}")
        print(f"report: {a.out}/{report_stem(fc)}.md")
    q = fault_model(fc.receiver).quantity
    exc = sum(r["exceptions"] for r in s["rows"])
    nan = sum(r["nan_bearings"] for r in s["rows"])
    if exc or nan:
        first = next((r["exception"] for r in s.get("records", []) if r.get("exception")), "")
        print(f"error: the receiver must give no exception and no NaN {q}; got {exc} "
              f"exception(s), {nan} NaN {q}(s)" + (f" (first: {first})" if first else ""),
              file=sys.stderr)
        return 1
    return 0


def parse_ber(spec: str) -> tuple[float, ...]:
    """``"1e-6:1e-3"`` -> decades 1e-6, 1e-5, 1e-4, 1e-3; or a comma list."""
    spec = spec.strip()
    try:
        [float(p) for p in spec.replace(":", ",").split(",")]
    except ValueError:
        raise ValueError(f"BER must be lo:hi (decades) or a comma list of numbers, "
                         f"not {spec!r}") from None
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) != 2:
            raise ValueError(f"BER range must be lo:hi (decades), not {spec!r}")
        lo, hi = float(parts[0]), float(parts[1])
        if not (0 < lo <= hi < 1):
            raise ValueError(f"BER range must satisfy 0 < lo <= hi < 1, not {spec!r}")
        n = int(round(math.log10(hi / lo)))
        return tuple(float(f"{lo * 10 ** k:.3g}") for k in range(n + 1))
    vals = tuple(float(p) for p in spec.split(","))
    if not all(0 < v < 1 for v in vals):
        raise ValueError(f"BER values must lie in (0, 1) (BER 0, the baseline, is always run), "
                         f"not {spec!r}")
    return vals


def flip_bits(words, width: int, ber: float, rng, bits=None):
    """Flip each bit (of ``bits``, default all ``width``) of each word with probability ``ber``.

    Returns ``(new_words, word_index_of_each_flip, bit_of_each_flip)``; words are taken as
    unsigned ``width``-bit patterns of int64 values (callers handle signedness).
    """
    w = np.asarray(words, dtype=np.int64).copy()
    if not 0 <= ber < 1:
        raise ValueError(f"ber must lie in [0, 1), not {ber}")
    pos = np.arange(width) if bits is None else np.asarray(bits, dtype=np.int64)
    if pos.size == 0 or (pos < 0).any() or (pos >= width).any():
        raise ValueError(f"bit positions must lie in 0..{width - 1}, not {bits!r}")
    total = w.size * pos.size
    n = int(rng.binomial(total, ber)) if total and ber > 0 else 0
    if n == 0:
        return w, np.zeros(0, np.int64), np.zeros(0, np.int64)
    flat = np.unique(rng.integers(0, total, n))
    wi, bi = flat // pos.size, pos[flat % pos.size]
    np.bitwise_xor.at(w, wi, np.int64(1) << bi)
    return w, wi, bi


def flip_signed(codes, width, ber, rng, bits=None):
    """Bit flips (:func:`flip_bits`) in two's complement codes of ``width`` bits.

    Returns the flipped codes (signed, the dtype of ``codes``) and the word and bit indices
    of the flips, as :func:`flip_bits` does."""
    c = np.asarray(codes).astype(np.int64)
    m = (np.int64(1) << width) - 1
    u, wi, bi = flip_bits(c & m, width, ber, rng, bits)
    s = np.where(u >= (np.int64(1) << (width - 1)), u - (np.int64(1) << width), u)
    return s.astype(np.asarray(codes).dtype), wi, bi


@dataclass(frozen=True)
class FaultConfig:
    """One fault study (see the module doc)."""

    target: str = "adc"
    ber: tuple = (1e-6, 1e-5, 1e-4, 1e-3)
    bits: tuple | None = None
    snr_db: float = 10.0
    trials: int = 3
    duration_s: float = 2.0
    memory_s: float = 0.5
    seed: int = 0
    backend: str = "model"
    scrub_period_s: float = 0.01
    disturbed_deg: float = 1.0
    fifo_parity: bool = False
    receiver: str = "tacan"
    #: TACAN: the front end's peak search(es) (``TacanRunConfig.detector``); None: the
    #: receiver's default. Other receivers refuse it.
    detector: str | None = None

    def __post_init__(self):
        if not isinstance(self.fifo_parity, bool):
            raise ValueError(f"fifo_parity must be a bool, not {self.fifo_parity!r}")
        model = fault_model(self.receiver)
        if self.target not in model.targets:
            raise ValueError(f"target must be one of {list(model.targets)}, not {self.target!r}")
        if not self.ber or not all(0 <= b < 1 for b in self.ber):
            raise ValueError(f"ber values must lie in [0, 1), not {self.ber!r}")
        if isinstance(self.trials, bool) or not isinstance(self.trials, int) or self.trials < 1:
            raise ValueError(f"trials must be an integer >= 1, not {self.trials!r}")
        if not (math.isfinite(self.duration_s) and self.duration_s > 2 * self.memory_s + 0.1):
            raise ValueError(f"--duration-s must exceed {2 * self.memory_s + 0.1:g} s (scoring "
                             f"starts at twice the filter memory {self.memory_s:g} s, plus "
                             f"0.1 s to score), not {self.duration_s:g}")
        if self.backend not in ("model", "pysim", "verilator"):
            raise ValueError(f"backend must be model, pysim or verilator, not {self.backend!r}")
        if not (math.isfinite(self.scrub_period_s) and self.scrub_period_s > 0):
            raise ValueError(f"scrub_period_s must be > 0, not {self.scrub_period_s}")
        # the receiver's own rules (which targets run on which backend, ...)
        model.check(self)
        if self.bits is not None:
            w = self.word_width()
            if not self.bits or any(isinstance(b, bool) or not isinstance(b, (int, np.integer))
                                    or not 0 <= b < w for b in self.bits):
                raise ValueError(f"bits must be positions 0..{w - 1} of the {self.target} "
                                 f"words ({w} bits), not {list(self.bits)}")
        # Every trial's record is built (and its front end validated) before the first point,
        # and the study must fit the machine (memory of a record, total time).
        from cosim.core.validate import MAX_STUDY_S, check_budget
        model.check_size(self)
        n = self.trials * (len(set(self.ber) | {0.0}))
        check_budget(f"{n:,} runs of {self.duration_s:g} s", "--trials, --ber or --duration-s",
                     seconds=n * self.duration_s * model.cpu_s_per_record_s,
                     max_seconds=MAX_STUDY_S)

    def word_width(self) -> int:
        """Width (bits) of the words the target's flips hit (the receiver's
        ``FaultModel.word_width``)."""
        return int(fault_model(self.receiver).word_width(self))


def run_faults(fc: FaultConfig, out: str | Path | None = None, progress: bool = True) -> dict:
    """Run the study (BER 0 baseline included) and write the report under ``out``."""
    from tqdm import tqdm
    tqdm.monitor_interval = 0     # no monitor thread left behind in the caller's process
    import sys
    t0 = time.perf_counter()
    bers = tuple(sorted(set((0.0,) + tuple(fc.ber))))
    model = fault_model(fc.receiver)
    cache: dict = {}
    recs = []
    items = [(ber, tr) for tr in range(fc.trials) for ber in bers]
    for ber, tr in tqdm(items, desc=f"faults ({fc.target})", file=sys.stderr, disable=not progress):
        recs.append(model.record(fc, ber, tr, cache))
        if len(cache) > 4:          # keep memory bounded (signals are large)
            for k in [k for k in cache if k[1] != tr]:
                del cache[k]
    rows = []
    for ber in bers:
        rs = [r for r in recs if r["ber"] == ber]
        ok = [r for r in rs if r["exception"] is None and r.get("rmse_deg") is not None]
        ev: dict = {}
        for r in ok:
            for k, v in r["events"].items():
                ev[k] = ev.get(k, 0) + v
        rx: dict = {}
        for r in ok:
            for k, v in (r.get("rx") or {}).items():
                rx[k] = rx.get(k, 0) + v
        rows.append({
            "ber": ber, "trials": len(rs), "exceptions": sum(r["exception"] is not None for r in rs),
            "nan_bearings": int(sum(r.get("nan_bearings", 0) for r in rs)),
            "flips": int(sum(r["flips"] for r in rs)),
            "rmse_deg": float(np.sqrt(np.mean([r["rmse_deg"] ** 2 for r in ok]))) if ok else None,
            "max_abs_error_deg": max((r["max_abs_error_deg"] for r in ok), default=None),
            "disturbed_fraction": float(np.mean([r["disturbed_fraction"] for r in ok])) if ok else None,
            "longest_disturbance_s": max((r["longest_disturbance_s"] for r in ok), default=None),
            "flagged_fraction": _mean_of(ok, "flagged_fraction"),
            "misleading_fraction": _mean_of(ok, "misleading_fraction"),
            "valid_rmse_deg": _rms_of(ok, "valid_rmse_deg"),
            "valid_max_abs_error_deg": _max_of(ok, "valid_max_abs_error_deg"),
            "reinit": ev.get("reinit", 0), "gated": ev.get("gated", 0), "p_neg": ev.get("p_neg", 0),
            "state_faults": ev.get("state_faults"),      # None: the receiver has no such check
            "saturations": sum(v for k, v in ev.items() if k.startswith("sat_")),
            "rx": rx, **_shown_row(rs, [r for r in recs if r["ber"] == 0.0], ber)})
    from cosim.core.provenance import machine_info
    summary = {"study": "faults", "machine": machine_info(), "config": asdict(fc),
               "elapsed_s": time.perf_counter() - t0, "rows": rows,
               "records": [{k: v for k, v in r.items() if k != "traceback"} for r in recs]}
    if out is not None:
        _write(fc, summary, Path(out))
    return summary


def _shown_row(rs: list[dict], base: list[dict], ber: float) -> dict:
    """What a user sees at one BER (:mod:`cosim.studies.shown`: accuracy of the estimates
    shown valid, availability, misleading estimates), pooled over the trials, and beside the
    fault-free run (BER 0) of the same trials: the availability difference and the
    misleading estimates it does not also make. A run that raised is in the exceptions
    column (the study fails on it), not here."""
    figs = {r["trial"]: r["shown"] for r in rs if r.get("shown")}
    b = {r["trial"]: r["shown"] for r in base if r.get("shown")}
    if not figs:
        return {"shown": None}
    p = pool(list(figs.values()))
    common = sorted(t for t in figs if t in b)
    pr = paired([figs[t] for t in common], [b[t] for t in common],
                json.dumps(["faults", ber])) if common else {}
    return {"shown": p, "availability_diff": pr.get("availability_diff"),
            "excess_misleading": pr.get("excess_misleading")}


def report_stem(fc: FaultConfig) -> str:
    return (f"faults_{fc.target.replace('-', '_')}" + ("_parity" if fc.fifo_parity else "")
            + (f"_{fc.detector}" if fc.detector else ""))


def _values(recs, key):
    return [r[key] for r in recs if r.get(key) is not None]


def _mean_of(recs, key):
    v = _values(recs, key)
    return float(np.mean(v)) if v else None


def _rms_of(recs, key):
    v = _values(recs, key)
    return float(np.sqrt(np.mean(np.square(v)))) if v else None


def _max_of(recs, key):
    v = _values(recs, key)
    return float(max(v)) if v else None


def _shown_table(rows: list[dict], quantity: str) -> list[str]:
    """The report's table of what a user sees per BER (:func:`_shown_row`)."""
    f_ = lambda v, fmt: "-" if v is None else format(v, fmt)
    out = ["", f"What a user sees (accuracy, availability, integrity of the {quantity}s "
               "shown valid after settling; beside the fault-free run of the same trials): "
               "availability = mean fraction of display epochs whose latest estimate is "
               "valid; misleading = shown valid and beyond the receiver's error bound, with "
               "the rate's 95 % Wilson interval; beyond BER 0 = misleading estimates the "
               "fault-free run of the same trial does not also make.", "",
               "| BER | valid RMSE | valid mean err | availability | vs BER 0 | first valid s "
               "(median / worst) | never valid | misleading | rate 95 % CI | beyond BER 0 |",
               "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        p = r.get("shown")
        if not p:
            out.append(f"| {r['ber']:g} | - | - | - | - | - | - | - | - | - |")
            continue
        ci = p["misleading_rate_ci95"]
        out.append(f"| {r['ber']:g} | {f_(p['rmse'], '.4f')} | {f_(p['mean_error'], '+.4f')} | "
                   f"{f_(p['availability'], '.3f')} | {f_(r.get('availability_diff'), '+.3f')} | "
                   f"{f_(p['first_valid_s_median'], '.3f')} / "
                   f"{f_(p['first_valid_s_max'], '.3f')} | "
                   f"{p['never_valid']} | {p['misleading']} | "
                   f"{'-' if not ci else f'{ci[0]:.2g}-{ci[1]:.2g}'} | "
                   f"{f_(r.get('excess_misleading'), 'd')} |")
    return out


def _write(fc: FaultConfig, s: dict, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    model = fault_model(fc.receiver)
    stem = report_stem(fc)
    from cosim.core.validate import dumps
    (out / f"{stem}.json").write_text(dumps(s, indent=1, default=str))
    keys = ["ber", "trials", "exceptions", "nan_bearings", "flips", "rmse_deg",
            "max_abs_error_deg", "disturbed_fraction", "longest_disturbance_s",
            "flagged_fraction", "misleading_fraction", "valid_rmse_deg",
            "valid_max_abs_error_deg", "state_faults", "reinit", "gated", "p_neg", "saturations"]
    shown = ("rmse", "mean_error", "availability", "first_valid_s_median", "never_valid",
             "misleading", "misleading_rate")
    with open(out / f"{stem}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys + [f"shown_{k}" for k in shown]
                           + ["availability_diff", "excess_misleading"], extrasaction="ignore")
        w.writeheader()
        for r in s["rows"]:
            w.writerow({**r, **{f"shown_{k}": (r.get("shown") or {}).get(k) for k in shown}})
    from ..tools.plots import pyplot, save_figure
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4))
    rows = [r for r in s["rows"] if r["ber"] > 0 and r["rmse_deg"] is not None]
    base = next((r for r in s["rows"] if r["ber"] == 0), None)
    if rows:
        ax.loglog([r["ber"] for r in rows], [r["rmse_deg"] for r in rows], "o-", label="RMSE")
        ax.loglog([r["ber"] for r in rows], [r["max_abs_error_deg"] for r in rows], "s--",
                  label="worst error")
    if base and base["rmse_deg"]:
        ax.axhline(base["rmse_deg"], color="k", ls=":", label="no bit errors (RMSE)")
    ax.set_xlabel(f"bit error rate ({fc.target})")
    ax.set_ylabel(f"{model.quantity} error (deg)")
    ax.set_title(f"{model.plot_title} vs bit errors in {fc.target} (SNR {fc.snr_db:g} dB)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, out / f"{stem}.png")
    m = s["machine"]
    f_ = lambda v, fmt: "-" if v is None else format(v, fmt)
    lines = [f"# Bit errors in {fc.target}", "",
             f"`{m['command']}`, {m['date']}, {m['cpu']}, commit {m['commit']}, "
             f"{s['elapsed_s']:.0f} s. SNR {fc.snr_db:g} dB, {fc.trials} trials of "
             f"{fc.duration_s:g} s, fixed-point DSP, backend {fc.backend}"
             + (f", bits {list(fc.bits)}" if fc.bits else "")
             + (", FIFO words with an even-parity bit (checked by the DSP)" if fc.fifo_parity
                else "")
             + (f", detector {fc.detector}" if fc.detector else "") + ".", "",
             f"![{stem}.png]({stem}.png)", "",
             model.scores_note.format(disturbed_deg=fc.disturbed_deg), "",
             f"| BER | flips | exceptions | NaN {model.quantity}s | RMSE deg | worst deg | disturbed | "
             "longest disturbance s | flagged | misleading | unflagged RMSE deg | "
             "unflagged worst deg | state faults | re-inits | gated | saturations |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in s["rows"]:
        lines.append(f"| {r['ber']:g} | {r['flips']} | {r['exceptions']} | {r['nan_bearings']} | "
                     f"{f_(r['rmse_deg'], '.4f')} | {f_(r['max_abs_error_deg'], '.3f')} | "
                     f"{f_(r['disturbed_fraction'], '.2%')} | "
                     f"{f_(r['longest_disturbance_s'], '.3f')} | "
                     f"{f_(r.get('flagged_fraction'), '.2%')} | "
                     f"{f_(r.get('misleading_fraction'), '.2%')} | "
                     f"{f_(r.get('valid_rmse_deg'), '.4f')} | "
                     f"{f_(r.get('valid_max_abs_error_deg'), '.3f')} | "
                     f"{f_(r.get('state_faults'), 'd')} | {r['reinit']} | "
                     f"{r['gated']} | {r['saturations']} |")
    lines += _shown_table(s["rows"], model.quantity)
    if any(r["rx"] for r in s["rows"]):
        lines += ["", "DSP receiver (FIFO words): " + "; ".join(
            f"BER {r['ber']:g}: " + ", ".join(f"{k} {v}" for k, v in r["rx"].items() if v)
            for r in s["rows"] if r["rx"])]
    (out / f"{stem}.md").write_text("\n".join(lines) + "\n")

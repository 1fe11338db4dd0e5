"""The ``tacan-record`` benchmark: the CPU time of the accuracy judge's records
(:mod:`cosim.tacan.bench_accuracy`: signal, bit-exact front-end model, fixed-point DSP as
every detector), each record alone and the records of one seed together, in one run.

*Alone* is each record as a separate job: its IF noise drawn and filtered, and the pair
search alone running its own envelope chain (``one_record(it, share_envelope=False)``).
*Shared* is what the judge runs (:func:`~cosim.tacan.bench_accuracy.run_records`): the noise
drawn once for the seed's modes and SNRs (:func:`cosim.tacan.signal.unit_noise`) and the
envelope chain once per record (:class:`hdl.tacan.envelope_memo.EnvelopeMemo`). The records
must come out the same (``same_records``); the ratio of the CPU times (``time.process_time``
of this process, after a warm-up record that loads the compiled kernels) is the figure to
compare on a shared machine. Writes ``tacan_record.json`` / ``.md``.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

from ..core.provenance import machine_info


def tacan_record(out: Path, quick: bool = False, jobs: int | None = None) -> dict:
    from .bench_accuracy import VARIANTS, one_record, run_records
    snrs = (0.0, 10.0) if quick else (0.0, 3.0, 6.0, 10.0, 20.0)
    items = [dict(mode=m, snr_db=s, bearing_deg=40.0, seed=101, duration_s=3.0,
                  variants=VARIANTS) for m in ("X", "Y") for s in snrs]
    t0 = time.perf_counter()
    one_record(dict(items[0], duration_s=1.5, seed=1))          # load the kernels
    c0 = time.process_time()
    alone = [one_record(it, share_envelope=False) for it in items]
    c1 = time.process_time()
    shared = run_records(items, jobs=1)
    c2 = time.process_time()
    n = len(items)
    s = {"benchmark": "tacan-record", "machine": machine_info(), "quick": quick,
         "records": n, "record": {"duration_s": 3.0, "seed": 101, "bearing_deg": 40.0,
                                  "modes": ["X", "Y"], "snrs_db": list(snrs),
                                  "variants": list(VARIANTS)},
         "cpu_s_per_record_alone": (c1 - c0) / n, "cpu_s_per_record_shared": (c2 - c1) / n,
         "speedup": (c1 - c0) / (c2 - c1), "same_records": alone == shared,
         "elapsed_s": time.perf_counter() - t0}
    out.mkdir(parents=True, exist_ok=True)
    (out / "tacan_record.json").write_text(json.dumps(s, indent=1))
    m = s["machine"]
    (out / "tacan_record.md").write_text(
        f"TACAN accuracy-judge records (`{m['command']}`, {m['date']}, {m['cpu']}, commit "
        f"{m['commit']}): {n} records of 3 s (one seed, X and Y, SNR "
        f"{', '.join(f'{v:g}' for v in snrs)} dB; the default, pulse and pair detectors), "
        f"CPU per record: {s['cpu_s_per_record_alone']:.2f} s alone, "
        f"{s['cpu_s_per_record_shared']:.2f} s with the seed's noise and each record's "
        f"envelope shared ({s['speedup']:.2f}x); the same records: "
        f"{'yes' if s['same_records'] else 'NO'}.\n")
    return s

"""The TACAN record path's shared work, each the same bits as the work it saves: the IF
noise drawn and filtered once per seed (``cosim.tacan.signal.unit_noise``), the envelope
chain computed once per record for front ends that differ in their peak searches
(``hdl.tacan.envelope_memo``), and the accuracy judge running the records of one seed
together in grid order (``cosim.tacan.bench_accuracy.run_records``)."""
from dataclasses import replace

import numpy as np
import pytest

from cosim.tacan.signal import TacanSignalConfig, generate, noise_key, unit_noise


def _sig(**kw):
    return TacanSignalConfig(**({"duration_s": 0.03, "seed": 7, "snr_db": 6.0} | kw))


def test_a_shared_unit_noise_gives_the_bits_of_a_record_generated_alone():
    base = _sig()
    nz = unit_noise(base)
    assert nz.values.shape == (base.n_samples,) and nz.key == noise_key(base)
    # the noise does not depend on the SNR, the mode or the bearing: one draw serves all
    for kw in ({}, {"snr_db": 0.0}, {"mode": "Y", "snr_db": 20.0}, {"bearing_deg": 200.0}):
        cfg = replace(base, **kw)
        assert noise_key(cfg) == nz.key
        assert np.array_equal(generate(cfg, nz).samples, generate(cfg).samples), kw
    # another seed's (or length's) noise is refused, not used
    for kw in ({"seed": 8}, {"duration_s": 0.02}):
        with pytest.raises(ValueError, match="another record's"):
            generate(replace(base, **kw), nz)


def test_the_envelope_memo_gives_each_front_end_its_own_bits():
    """The default front end (both searches) and the pair search alone on one record: the
    second takes the first's envelope chunks back (every chunk a hit) and its FIFO words,
    cycles and range log are those it computes alone; another record misses every chunk."""
    from hdl.tacan.envelope_memo import EnvelopeMemo
    from cosim.tacan.config import TacanRunConfig
    from cosim.tacan.frontends import model_frontend
    sig = _sig(duration_s=0.06)
    x = generate(sig).samples
    run = TacanRunConfig(signal=sig, backend="model", detector="both", require_bearing=False)
    pair = replace(run, detector="pair")
    memo = EnvelopeMemo()
    a = model_frontend(x, run, memo)
    chunks = memo.misses
    assert chunks >= 2 and memo.hits == 0
    b = model_frontend(x, pair, memo)
    assert memo.hits == chunks and memo.misses == chunks
    alone = model_frontend(x, pair)
    for f in ("words", "cycles", "ticks", "amplitude_lsb"):
        assert np.array_equal(getattr(b, f), getattr(alone, f)), f
    assert b.extra["ranges"] == alone.extra["ranges"] == a.extra["ranges"]
    assert not np.array_equal(a.words, b.words)     # the searches differ, the words too
    y = x.copy()
    y[len(y) // 2] ^= 1                              # one ADC bit of the second half
    c = model_frontend(y, pair, memo)
    assert memo.misses > chunks                      # from that chunk on: computed
    assert np.array_equal(c.words, model_frontend(y, pair).words)


def test_the_records_of_a_seed_run_together_and_come_back_in_grid_order(monkeypatch):
    from cosim.tacan import bench_accuracy as B
    grid = B.AccuracyGrid(bearing_step_deg=120.0, snrs_db=(0.0, 10.0), records=2)
    items = grid.items()
    calls = []

    def fake(it, noise=None):
        calls.append((it["seed"], noise is not None))
        return {"seed": it["seed"], "mode": it["mode"], "snr_db": it["snr_db"],
                "bearing_deg": it["bearing_deg"]}
    monkeypatch.setattr(B, "one_record", fake)
    out = B.run_records(items, jobs=1)
    assert [(r["seed"], r["mode"], r["snr_db"], r["bearing_deg"]) for r in out] == [
        (it["seed"], it["mode"], it["snr_db"], it["bearing_deg"]) for it in items]
    seeds = [s for s, _ in calls]
    # each seed's records (2 modes x 2 SNRs) one after the other, sharing the noise
    assert all(len(set(seeds[i:i + 4])) == 1 for i in range(0, len(seeds), 4))
    assert len(set(seeds)) == len(items) // 4 and all(shared for _, shared in calls)
    with pytest.raises(ValueError, match="one noise key"):
        B.one_seed(items[:2] + [items[-1]])

"""Reference acquisition integrated across bursts (dsp/tacan/acquire.py, issue 18): a
burst-code matched detector folded on the 135 Hz grid, a grid tracker and a
likelihood-ratio main-slot test, used by ``decode`` when too few bursts decode alone."""
import numpy as np
import pytest

from cosim.tacan.signal import KIND_MAIN, TacanSignalConfig, pulse_schedule
from dsp.tacan.acquire import AcquireConfig, acquire_references
from dsp.tacan.decode import DecoderConfig, decode
from dsp.tacan.scoring import REF_MAIN


def _weak(mode, seed, keep, noise_per_s, duration_s=3.0, main_keep=None, **kw):
    """Pulse times as a detector near 0 dB gives them: ``keep`` of the beacon's pulses
    (``main_keep`` of the main bursts'), plus noise peaks."""
    cfg = TacanSignalConfig(mode=mode, duration_s=duration_s, seed=seed, **kw)
    t, kinds, mains, auxs = pulse_schedule(cfg)
    rng = np.random.default_rng(seed)
    p = np.where(kinds == KIND_MAIN, keep if main_keep is None else main_keep, keep)
    k = rng.random(t.size) < p
    extra = rng.uniform(0, duration_s, int(noise_per_s * duration_s))
    tt = np.sort(np.concatenate([t[k] + rng.normal(0, 0.1e-6, k.sum()), extra]))
    return tt, mains, auxs


def _nearest(x, ref):
    return np.min(np.abs(x[:, None] - ref[None, :]), axis=1)


@pytest.mark.parametrize("mode", ["X", "Y"])
@pytest.mark.parametrize("rate_off", [0.0, 0.01, -0.005])
def test_weak_beacon_every_reference_on_time(mode, rate_off):
    # 20 % of the pulses (5 % of the main burst's: the trough at 90 deg, 0 dB) and 1000
    # noise peaks/s: no burst passes min_fraction alone.
    tt, mains, auxs = _weak(mode, 7, 0.2, 1000.0, main_keep=0.05,
                            rotation_hz=15.0 * (1 + rate_off))
    alone = decode(tt, mode, DecoderConfig(mode=mode, acquire=False))
    assert alone.ref_times_s.size < 0.2 * (mains.size + auxs.size)
    d = decode(tt, mode)
    assert d.acquired_s is not None and d.acquired_s < 0.6
    m = d.ref_times_s[d.ref_kinds == REF_MAIN]
    a = d.ref_times_s[d.ref_kinds != REF_MAIN]
    # every main reference of the record after the first, none false, all on time
    assert m.size >= mains.size - 1 and _nearest(m, mains).max() < 0.3e-6
    assert a.size >= auxs.size - 9 and _nearest(a, auxs).max() < 0.3e-6
    assert d.rotation_hz == pytest.approx(15.0 * (1 + rate_off), rel=2e-5)
    # causal: nothing known before the grid is confirmed and the main slot declared
    assert d.main_slot_s >= d.acquired_s
    assert np.all(d.ref_done_s >= d.main_slot_s - 1e-12)
    assert np.all(d.ref_done_s >= d.ref_times_s)


@pytest.mark.parametrize("mode", ["X", "Y"])
@pytest.mark.parametrize("rate", [1000.0, 4000.0])
def test_noise_alone_confirms_no_grid(mode, rate):
    tt = np.sort(np.random.default_rng(int(rate)).uniform(0, 30.0, int(rate * 30)))
    assert acquire_references(tt, mode) is None


@pytest.mark.parametrize("beacon, rx", [("Y", "X"), ("X", "Y")])
@pytest.mark.parametrize("keep", [0.25, 0.9])
def test_other_mode_confirms_no_grid(beacon, rx, keep):
    # 3 of the 12-13 auxiliary pulses of the other mode match the template at one alignment
    tt, _, _ = _weak(beacon, 43, keep, 1000.0, duration_s=20.0)
    assert acquire_references(tt, rx) is None
    d = decode(tt, rx)
    assert d.acquired_s is None and d.n_inferred_main == 0


def test_grid_is_not_one_code_step_off():
    # The auxiliary code is periodic (12 us steps in X): a grid one step off still finds 11
    # of its 12 pulses. The matched detector and the alignment check must land on the
    # alignment with the most pulses (the real one).
    for seed in (1, 2, 3):
        tt, mains, _ = _weak("X", seed, 0.3, 2000.0)
        acq = acquire_references(tt, "X")
        assert acq is not None
        m = acq.ref_t[acq.kinds == REF_MAIN]
        assert _nearest(m, mains).max() < 0.3e-6


def test_period_alias_of_a_code_step_is_not_taken():
    # Candidate starts are ambiguous by code steps, so pairs of them n periods apart vote at
    # p + j step / n too; with few candidates in the first window such an alias outweighed
    # the period (this record: 0.2 % off, confirmed, no main slot ever declared). The
    # matched detector chooses among the histogram's peaks.
    from dsp.tacan.acquire import acquire
    from dsp.tacan.standard import F135
    tt, mains, _ = _weak("Y", 20, 0.2, 3500.0, main_keep=0.05)
    a, p, _ = acquire(tt, "Y", AcquireConfig())
    assert p * F135 == pytest.approx(1.0, abs=2e-5)
    acq = acquire_references(tt, "Y")
    assert acq is not None
    m = acq.ref_t[acq.kinds == REF_MAIN]
    assert m.size >= mains.size - 8 and _nearest(m, mains).max() < 0.3e-6
    with pytest.raises(ValueError, match="period_hypotheses"):
        AcquireConfig(period_hypotheses=0)


def test_complete_records_do_not_use_acquisition():
    t, _, _, _ = pulse_schedule(TacanSignalConfig(duration_s=2.0, seed=9))
    d = decode(t, "X")
    assert d.acquired_s is None


@pytest.mark.parametrize("kw, msg", [(dict(acquire=1), "acquire must be True or False"),
                                     (dict(acquire_below=1.5), "acquire_below must be in")])
def test_bad_config(kw, msg):
    with pytest.raises(ValueError, match=msg):
        DecoderConfig(**kw)


def test_slot_llr_controls_the_declaration():
    tt, mains, _ = _weak("X", 11, 0.2, 1000.0, main_keep=0.05)
    fast = acquire_references(tt, "X", AcquireConfig(slot_llr=5.0))
    slow = acquire_references(tt, "X", AcquireConfig(slot_llr=40.0))
    assert fast is not None and slow is not None
    assert slow.main_slot_s > fast.main_slot_s


def test_incomplete_bursts_are_not_measurements():
    # Bursts ~40 % complete (near the noise floor): their pulses leave the measurements,
    # the pairs outside them stay; complete bursts (high SNR) keep theirs.
    from dsp.tacan.decode import _in_bursts
    from dsp.tacan.standard import burst_offsets
    tt, _, _ = _weak("X", 13, 0.45, 200.0)
    d = decode(tt, "X", DecoderConfig(acquire=False))
    inb = _in_bursts(tt, d.ref_times_s, d.ref_kinds, burst_offsets("X", "main"),
                     burst_offsets("X", "aux"))
    assert d.ref_times_s.size > 100 and inb.sum() > 1000
    assert not np.any(d.measurement_mask & inb) and d.measurement_mask.sum() > 1000
    keep = decode(tt, "X", DecoderConfig(acquire=False, burst_complete_min=0.0))
    assert np.count_nonzero(keep.measurement_mask & inb) > 500
    t, _, _, _ = pulse_schedule(TacanSignalConfig(duration_s=1.0, seed=3))
    full = decode(t, "X")
    assert full.measurement_mask.all()


def _sector_case(seed, true=100.0, M=600, start_off=0.0):
    from dsp.tacan.bearing import deg_to_bangle
    rng = np.random.default_rng(seed)
    # a coarse bearing wandering by ~20 deg (as at 0 dB), a fine one within 0.3 deg
    coarse = (true + start_off + 15 * np.sin(np.arange(M) / 60)
              + 0.3 * np.cumsum(rng.normal(0, 1.5, M)))
    base = (true + rng.normal(0, 0.3, M)) % 40
    cand = base[:, None] + 40 * np.arange(9)[None, :]
    b = cand[np.arange(M), np.argmin(np.abs((cand - coarse[:, None] + 180) % 360 - 180), axis=1)]
    return deg_to_bangle(b)[None, :], deg_to_bangle(coarse)[None, :]


def test_sector_tracker_removes_slips():
    from dsp.tacan.bearing import bangle_to_deg, track_sector, wrap_deg
    b, c = _sector_case(0)
    assert np.count_nonzero(np.abs(wrap_deg(bangle_to_deg(b[0]) - 100.0)) > 20) >= 3
    t, _ = track_sector(b, c)
    assert np.abs(wrap_deg(bangle_to_deg(t[0]) - 100.0)).max() < 1.5
    # streaming: two blocks give the same as one
    t1, st = track_sector(b[:, :250], c[:, :250])
    t2, _ = track_sector(b[:, 250:], c[:, 250:], st)
    np.testing.assert_array_equal(np.concatenate([t1, t2], axis=1), t)


def test_sector_tracker_follows_a_real_sector_change():
    # The coarse bearing is 40 deg off for the first 100 outputs (a filter converging),
    # then right: the tracker holds the first sector, then moves once the average
    # disagreement passes half a sector.
    from dsp.tacan.bearing import bangle_to_deg, deg_to_bangle, track_sector, wrap_deg
    rng = np.random.default_rng(1)
    M = 400
    coarse = 100.0 + np.where(np.arange(M) < 100, 40.0, 0.0) + rng.normal(0, 3, M)
    base = (100.0 + rng.normal(0, 0.3, M)) % 40
    cand = base[:, None] + 40 * np.arange(9)[None, :]
    b = cand[np.arange(M), np.argmin(np.abs((cand - coarse[:, None] + 180) % 360 - 180), axis=1)]
    t, _ = track_sector(deg_to_bangle(b)[None, :], deg_to_bangle(coarse)[None, :])
    err = np.abs(wrap_deg(bangle_to_deg(t[0]) - 100.0))
    assert np.all(err[:100] > 38) and err[200:].max() < 1.5


@pytest.mark.parametrize("kw, msg", [(dict(flag_coarse_sigma_deg=0.0), "flag_coarse_sigma_deg"),
                                     (dict(sector_track=1), "sector_track must be")])
def test_receiver_bad_config(kw, msg):
    from dsp.tacan.receiver import ReceiverConfig
    with pytest.raises(ValueError, match=msg):
        ReceiverConfig(**kw)

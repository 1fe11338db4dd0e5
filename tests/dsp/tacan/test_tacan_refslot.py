"""The rotation-slot reference detector (dsp/tacan/decode.py ``_infer_main``): main
references placed from the 135 Hz grid when the main bursts themselves are lost."""
import numpy as np
import pytest

from cosim.tacan.signal import KIND_MAIN, TacanSignalConfig, pulse_schedule
from dsp.tacan.decode import REF_MAIN, DecoderConfig, decode
from dsp.tacan.receiver import ReceiverConfig, process_peaks


def _lossy(mode, seed, main_keep, aux_keep, extra_per_s=200.0, duration_s=3.0):
    cfg = TacanSignalConfig(mode=mode, duration_s=duration_s, seed=seed)
    t, kinds, mains, auxs = pulse_schedule(cfg)
    rng = np.random.default_rng(seed)
    keep = rng.random(t.size) < np.where(kinds == KIND_MAIN, main_keep, aux_keep)
    extra = rng.uniform(0, duration_s, int(extra_per_s * duration_s))
    tt = np.sort(np.concatenate([t[keep] + rng.normal(0, 0.1e-6, keep.sum()), extra]))
    return tt, mains, auxs


@pytest.mark.parametrize("mode", ["X", "Y"])
def test_lost_main_bursts_are_placed_on_the_grid(mode):
    # Main bursts 25 % complete (below min_fraction: never decoded alone), auxiliaries 70 %.
    tt, mains, auxs = _lossy(mode, 31, main_keep=0.25, aux_keep=0.7)
    off = decode(tt, mode, DecoderConfig(mode=mode, infer_main=False))
    alone = np.count_nonzero(off.ref_kinds == REF_MAIN)
    assert alone <= 0.1 * mains.size
    d = decode(tt, mode)
    m = d.ref_times_s[d.ref_kinds == REF_MAIN]
    # every rotation's main reference, each within 0.3 us of the true one, none false
    assert m.size >= mains.size - 1 and d.n_inferred_main + alone >= m.size
    assert np.max(np.min(np.abs(m[:, None] - mains[None, :]), axis=1)) < 0.3e-6
    a = d.ref_times_s[d.ref_kinds != REF_MAIN]
    assert np.max(np.min(np.abs(a[:, None] - auxs[None, :]), axis=1)) < 0.3e-6
    assert d.rotation_hz == pytest.approx(15.0, rel=1e-6)
    # causal: declared after min_rotations rotations; nothing known before the declaration
    assert d.main_slot_s >= 3 / 15.0
    done_main = d.ref_done_s[d.ref_kinds == REF_MAIN]
    assert np.all(done_main >= d.main_slot_s - 1e-12)


def test_complete_records_are_left_alone():
    cfg = TacanSignalConfig(duration_s=2.0, seed=9)
    t, _, _, _ = pulse_schedule(cfg)
    a, b = decode(t, "X"), decode(t, "X", DecoderConfig(infer_main=False))
    np.testing.assert_array_equal(a.ref_times_s, b.ref_times_s)
    np.testing.assert_array_equal(a.ref_kinds, b.ref_kinds)
    assert a.n_inferred_main == 0 and a.main_slot_s is None


def _valid_bearings(tt, mode_rx, seed):
    amps = np.random.default_rng(seed).rayleigh(1.0, tt.size)
    tr = process_peaks(tt, amps, ReceiverConfig(mode=mode_rx))
    return int(np.count_nonzero(tr.valid)), tr


def test_noise_only_gives_no_reference_and_no_valid_bearing():
    rng = np.random.default_rng(5)
    tt = np.sort(rng.uniform(0, 60.0, 7200 * 60))       # 60 s of random peaks at 7200/s
    d = decode(tt, "X")
    assert np.count_nonzero(d.ref_kinds == REF_MAIN) == 0 and d.n_inferred_main == 0
    n_valid, _ = _valid_bearings(tt, "X", 6)
    assert n_valid == 0


@pytest.mark.parametrize("beacon, rx", [("Y", "X"), ("X", "Y")])
def test_beacon_of_the_other_mode_gives_no_valid_bearing(beacon, rx):
    tt, _, _ = _lossy(beacon, 41, main_keep=0.9, aux_keep=0.9, duration_s=60.0)
    d = decode(tt, rx)
    assert d.n_inferred_main == 0
    n_valid, _ = _valid_bearings(tt, rx, 7)
    assert n_valid == 0


@pytest.mark.parametrize("kw, msg", [
    (dict(slot_margin=0), "slot_margin must be in (0, 2]"),
    (dict(min_rotations=0), "min_rotations must be >= 1"),
    (dict(min_slot_pulses=0), "min_slot_pulses must be >= 1"),
    (dict(min_grid_refs=2), "min_grid_refs must be >= 3"),
])
def test_slot_detector_bad_config(kw, msg):
    with pytest.raises(ValueError, match=msg.replace("(", r"\(").replace(")", r"\)")
                       .replace("[", r"\[").replace("]", r"\]")):
        DecoderConfig(**kw)

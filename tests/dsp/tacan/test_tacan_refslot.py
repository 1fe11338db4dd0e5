"""The rotation-slot reference detector (dsp/tacan/decode.py ``_infer_main``): main
references placed from the 135 Hz grid when the main bursts themselves are lost."""
import numpy as np
import pytest

from cosim.tacan.signal import KIND_MAIN, TacanSignalConfig, pulse_schedule
from dsp.tacan.decode import DecoderConfig, decode
from dsp.tacan.scoring import REF_MAIN
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


@pytest.mark.parametrize("beacon, rx", [
    pytest.param("Y", "X", marks=pytest.mark.slow),     # the mirror case of X-Y: 38 s
    ("X", "Y")])
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


@pytest.mark.parametrize("mode", ["X", "Y"])
def test_a_main_decoded_off_the_main_slot_becomes_an_auxiliary(mode):
    """Every main burst decoded, plus an auxiliary burst whose pulses were copied into the
    main code (what the main template takes near 0 dB in Y mode): it is moved to the
    auxiliaries, the true mains stay."""
    from dsp.tacan.standard import burst_offsets
    cfg = TacanSignalConfig(mode=mode, duration_s=1.0, seed=41)
    t, kinds, mains, auxs = pulse_schedule(cfg)
    fake = auxs[(auxs > mains[5]) & (auxs < mains[6])][3]          # an auxiliary's time
    aux_off = burst_offsets(mode, "aux")
    drop = np.any(np.abs(t[:, None] - (fake + aux_off)[None, :]) < 1e-9, axis=1)
    tt = np.sort(np.concatenate([t[~drop], fake + burst_offsets(mode, "main")]))
    plain = decode(tt, mode, DecoderConfig(mode=mode, infer_main=False))
    assert np.any(np.abs(plain.ref_times_s[plain.ref_kinds == REF_MAIN] - fake) < 1e-6)
    d = decode(tt, mode)
    m = d.ref_times_s[d.ref_kinds == REF_MAIN]
    assert d.n_main_off_slot == 1 and not np.any(np.abs(m - fake) < 1e-6)
    assert np.any(np.abs(d.ref_times_s - fake) < 1e-6)                 # kept, as an auxiliary
    assert np.max(np.min(np.abs(m[:, None] - mains[None, :]), axis=1)) < 1e-6
    assert m.size == mains.size


@pytest.mark.slow
def test_zero_db_y_mode_shows_no_misleading_bearing():
    """Y mode, 0 dB, 270 deg, seed 100: an auxiliary burst decoded as a main (7 of 13
    pulses) at 2.66 s moved two bearings 81 deg, both shown valid, before the main-slot
    vote."""
    from cosim.tacan.config import TacanRunConfig
    from cosim.tacan.run import run_tacan
    r = run_tacan(TacanRunConfig(signal=TacanSignalConfig(mode="Y", bearing_deg=270.0,
                                                          snr_db=0.0, seed=100)))
    assert r["misleading_bearings"] == 0 and r["n_valid_bearings"] > 100

"""The pair reports the DSP measures on with both searches (dsp.tacan.pairsource)."""
import numpy as np
import pytest

from cosim.tacan.signal import TacanSignalConfig, pulse_observations
from dsp.tacan.pairsource import choose_pairs, confirmed_pairs, paired_fraction
from dsp.tacan.receiver import ReceiverConfig, process_peaks


def test_a_pair_is_confirmed_only_with_both_its_pulses_among_the_single_pulses():
    us = 1e-6
    pulses = np.array([100, 112, 300, 512, 700]) * us     # unsorted input is sorted inside
    pairs = np.array([112.5, 312, 524, 900]) * us          # pair, half pair x2, noise pair
    np.testing.assert_array_equal(confirmed_pairs(pairs, pulses[::-1], "X", 1 * us),
                                  [True, False, False, False])
    # Y mode: 30 us spacing
    np.testing.assert_array_equal(confirmed_pairs(np.array([130.0]) * us,
                                                  np.array([100.0, 130.0]) * us, "Y", 1 * us),
                                  [True])
    assert not confirmed_pairs(np.array([114.0]) * us, pulses, "X", 1 * us).any()
    assert confirmed_pairs(np.empty(0), pulses, "X", 1 * us).size == 0
    assert not confirmed_pairs(pairs, np.empty(0), "X", 1 * us).any()
    assert paired_fraction(np.array([True, False, False, False])) == 0.25
    assert paired_fraction(np.empty(0, bool)) is None


def test_the_choice_follows_the_paired_fraction():
    us = 1e-6
    pulses = np.array([100, 112, 200, 212, 300]) * us
    pairs = np.array([112, 212, 312, 412]) * us            # 2 of 4 confirmed
    keep, f, on = choose_pairs(pairs, pulses, "X", us, 0.5)
    assert (f, on) == (0.5, "confirmed pairs") and keep.tolist() == [True, True, False, False]
    keep, f, on = choose_pairs(pairs, pulses, "X", us, 0.6)
    assert (f, on) == (0.5, "pairs") and keep.all()
    keep, f, on = choose_pairs(pairs, pulses, "X", us, None)
    assert on == "pairs" and keep.all()


@pytest.mark.parametrize("bad", [0.0, -0.1, 1.5])
def test_confirm_threshold_is_checked(bad):
    with pytest.raises(ValueError, match="confirm_pairs_above"):
        ReceiverConfig(confirm_pairs_above=bad)


def test_noise_pairs_are_left_out_above_the_threshold_and_measured_below():
    """An ideal front end with both searches plus pair reports that are no pairs (noise
    pairs at 60 % of the pulse level, one per 10 pairs): above the threshold the DSP leaves
    them out -- the measurements and bearings of the clean stream; with confirmation off
    (or the threshold above the paired fraction) it measures on them too."""
    from dsp.tacan.frontend import merge_sources
    from dsp.tacan.standard import SOURCE_PAIR
    t, amps, _ = pulse_observations(TacanSignalConfig(duration_s=1.2, snr_db=20, seed=6), [135.0])
    ticks = np.round(t * 20e6).astype(np.int64)
    second = np.flatnonzero(np.isin(ticks - 240, ticks))
    first = np.searchsorted(ticks, ticks[second] - 240)
    mean = (amps[0, first] + amps[0, second]) / 2
    rng = np.random.default_rng(3)
    noise_t = np.sort(rng.choice(np.arange(1000, int(1.2 * 20e6), 997), second.size // 10,
                                 replace=False))
    # away from every pulse, at both the pair's positions
    far = lambda x: np.abs(ticks[np.clip(np.searchsorted(ticks, x), 1, ticks.size - 1)
                                 [:, None] - [1, 0]] - x[:, None]).min(axis=1) > 100
    noise_t = noise_t[far(noise_t) & far(noise_t - 240)]
    pt = np.concatenate([ticks[second], noise_t])
    pa = np.concatenate([mean, np.full(noise_t.size, 0.6 * np.median(mean))])
    o = np.argsort(pt, kind="stable")
    tk, a, src = merge_sources(ticks, amps[0], pt[o], pa[o])
    clean_tk, clean_a, clean_src = merge_sources(ticks, amps[0], ticks[second], mean)
    clean = process_peaks(clean_tk / 20e6, clean_a, ReceiverConfig(), ticks=clean_tk,
                          source=clean_src)
    got = process_peaks(tk / 20e6, a, ReceiverConfig(), ticks=tk, source=src)
    n_pairs = int(np.count_nonzero(src == SOURCE_PAIR))
    assert got.measured_on == "confirmed pairs"
    assert got.paired_fraction == pytest.approx(second.size / n_pairs)
    assert got.n_measurements == clean.n_measurements
    np.testing.assert_allclose(got.bearing_deg, clean.bearing_deg, atol=1e-9)
    every = process_peaks(tk / 20e6, a, ReceiverConfig(confirm_pairs_above=min(
        1.0, got.paired_fraction + 0.01)), ticks=tk, source=src)
    assert every.measured_on == "pairs"
    assert every.n_measurements > clean.n_measurements
    single = process_peaks(ticks / 20e6, amps, ReceiverConfig(), ticks=ticks)
    assert single.measured_on == "pulses" and single.paired_fraction is None

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


def test_pair_centres():
    from dsp.tacan.pairsource import pair_centres
    a = np.array([[1.0, 2.0]])
    t, got, tk = pair_centres(np.array([1e-3, 2e-3]), a, "Y", ticks=np.array([20000, 40000]),
                              tick_hz=20e6)
    np.testing.assert_array_equal(tk, [20000 - 300, 40000 - 300])
    np.testing.assert_allclose(t, tk / 20e6)
    assert got is a or np.array_equal(got, a)
    t, _, tk = pair_centres(np.array([1e-3]), a[:, :1], "X")
    assert tk is None and t[0] == pytest.approx(1e-3 - 6e-6)


@pytest.mark.parametrize("mode", ["X", "Y"])
def test_pair_reports_in_the_reference_bursts_give_no_bearing_bias(mode):
    """An ideal front end with both searches (every pair reported at its second pulse with
    the mean of its pulses, 0.2 % amplitude noise): the bearing agrees with the single-pulse
    DSP's on the same pulses. The reference bursts are trains of pulses one pair spacing
    apart; taken as the pairs' two pulses, each train pulse carried the envelope half a
    spacing before it, at the bursts' fixed rotation phases: +0.003 (X) / +0.007 (Y) deg
    here, on every bearing."""
    from dsp.tacan.frontend import merge_sources
    from dsp.tacan.standard import pair_spacing_s
    bearings = [20.0, 140.0, 260.0]
    t, amps, _ = pulse_observations(TacanSignalConfig(mode=mode, duration_s=1.5, seed=4),
                                    bearings, rel_sigma=0.002)
    ticks = np.round(t * 20e6).astype(np.int64)
    d = int(round(pair_spacing_s(mode) * 20e6))
    second = np.flatnonzero(np.isin(ticks - d, ticks))
    first = np.searchsorted(ticks, ticks[second] - d)
    cfg = ReceiverConfig(mode=mode)
    single = process_peaks(ticks / 20e6, amps, cfg, ticks=ticks)
    both_b = []
    for b in range(len(bearings)):     # one trial per call: the sources interleave per row
        tk, a, src = merge_sources(ticks, amps[b], ticks[second],
                                   (amps[b, first] + amps[b, second]) / 2)
        got = process_peaks(tk / 20e6, a, cfg, ticks=tk, source=src)
        assert got.measured_on == "confirmed pairs"
        np.testing.assert_array_equal(got.times_s, single.times_s)
        both_b.append(got.bearing_deg[0])
    keep = single.times_s >= 0.7
    err = lambda x: ((np.asarray(x)[:, keep] - np.array(bearings)[:, None] + 180) % 360) - 180
    e_single, e_both = err(single.bearing_deg).mean(axis=1), err(both_b).mean(axis=1)
    np.testing.assert_allclose(e_both, e_single, atol=1.5e-3)


def test_the_confirmed_reports_are_expected_with_their_own_bias():
    """``PeakBias.confirmed`` is the model the filter uses when it measures on the confirmed
    pair reports, and only then."""
    from dsp.tacan.frontend import merge_sources
    from dsp.tacan.peakbias import BOTH_PEAK_BIAS, PeakBias
    with pytest.raises(ValueError, match="confirmed"):
        PeakBias(u=(1.0, 2.0), beta=(0.1, 0.0), confirmed=0.3)
    t, amps, _ = pulse_observations(TacanSignalConfig(duration_s=1.2, snr_db=3, seed=2), [50.0])
    ticks = np.round(t * 20e6).astype(np.int64)
    second = np.flatnonzero(np.isin(ticks - 240, ticks))
    first = np.searchsorted(ticks, ticks[second] - 240)
    tk, a, src = merge_sources(ticks, amps[0], ticks[second],
                               (amps[0, first] + amps[0, second]) / 2)
    other = PeakBias(u=(0.5, 1.0, 2.0), beta=(0.6, 0.4, 0.1), u_min=0.7)
    run = lambda pb, **kw: process_peaks(tk / 20e6, a, ReceiverConfig(peak_bias=pb, **kw),
                                         ticks=tk, source=src).bearing_deg
    with_own = PeakBias(**{**BOTH_PEAK_BIAS.__dict__, "confirmed": other})
    np.testing.assert_array_equal(run(with_own), run(other))
    assert not np.array_equal(run(with_own), run(BOTH_PEAK_BIAS))
    np.testing.assert_array_equal(run(with_own, confirm_pairs_above=None),
                                  run(BOTH_PEAK_BIAS, confirm_pairs_above=None))

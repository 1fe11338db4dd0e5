"""The pulse-pair detector's reports (``--detector pair``: each report at its pair's second
pulse, with the mean of the two pulses' envelope) on an ideal front end: the DSP measures
each report once at its pair's centre, so its bearings are those of the single pulses --
no constant bias (taken as two pulses at the report's amplitude, a pulse shared by two
reports keeping the earlier one's, the bursts' pulse trains shifted the bearing by +0.0035
deg in X and +0.0056 deg in Y at every bearing)."""
import numpy as np
import pytest

from cosim.tacan.signal import TacanSignalConfig, pulse_observations
from dsp.tacan.receiver import ReceiverConfig, bearing_stats, process_peaks
from dsp.tacan.scoring import match_nearest
from dsp.tacan.standard import pair_spacing_s

BEARINGS = np.array([0.0, 100.0, 230.0])


def _pair_reports(t, a, mode):
    """The ideal pair search: a report at every pulse with a pulse one spacing before it."""
    j, ok = match_nearest(t, t - pair_spacing_s(mode), 1e-7)
    ok &= j != np.arange(t.size)
    return t[ok], 0.5 * (a[:, j[ok]] + a[:, ok])


@pytest.mark.parametrize("mode", ["X", "Y"])
def test_pair_reports_give_the_single_pulses_bearing(mode):
    cfg = TacanSignalConfig(mode=mode, duration_s=2.0, seed=3)
    t, a, _ = pulse_observations(cfg, BEARINGS, rel_sigma=0.0)
    tr, ar = _pair_reports(t, a, mode)
    assert tr.size > 0.5 * t.size
    pulses = bearing_stats(process_peaks(t, a, ReceiverConfig(mode=mode)), BEARINGS, 1.0)
    pairs = bearing_stats(process_peaks(tr, ar, ReceiverConfig(mode=mode, pair_reports=True)),
                          BEARINGS, 1.0)
    assert pairs["n"] > 0 and pulses["n"] > 0
    d = pairs["mean_error_deg"] - pulses["mean_error_deg"]
    assert np.all(np.abs(d) < 5e-4), d

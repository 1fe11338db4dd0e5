"""``bearing_stats``' figures of the bearings shown valid are what a user sees of them
(:func:`dsp.shown.valid_figures`, as ``shown_figures`` scores them): counted from when each
bearing became available, with the same RMSE and misleading count."""
import numpy as np

from dsp.shown import shown_figures
from dsp.tacan.receiver import MISLEADING_DEG, BearingTrack, bearing_stats


def _track(bearings, valid, times, produced):
    b = np.asarray(bearings, np.float64)
    B = b.shape[0]
    z = np.zeros(B, np.int64)
    return BearingTrack(times_s=np.asarray(times, np.float64), ref_kinds=np.ones(b.shape[1]),
                        bearing_deg=b, coarse_deg=b.copy(), n_updates=0, n_peaks=0,
                        n_measurements=0, n_main_refs=0, n_aux_refs=0, n_refs_off_grid=0,
                        gated=z, reinit=z, r_est=np.zeros(B), valid=np.asarray(valid, bool),
                        produced_s=np.asarray(produced, np.float64))


def test_the_valid_bearings_are_scored_as_a_user_sees_them():
    truth = 10.0
    times = [0.5, 0.9, 1.2, 1.5, 1.8]
    produced = [0.6, 1.05, 1.3, 1.6, 1.9]     # the second: referenced before 1 s, shown after
    b = [[11.0, 12.0, 7.0, 10.0 + 25.0, 9.5],     # a misleading one (25 deg off)
         [10.0, 13.0, 10.5, 10.0, 370.0 - 0.5]]   # wrapped: -0.5 deg
    valid = [[True, True, True, True, False],
             [True, False, True, True, True]]
    st = bearing_stats(_track(b, valid, times, produced), truth, 1.0)
    for r in range(2):
        err = ((np.asarray(b[r]) - truth + 180.0) % 360.0) - 180.0
        f = shown_figures(np.asarray(produced), err, np.asarray(valid[r]), settle_s=1.0,
                          end_s=2.0, epoch_s=0.5, bound=MISLEADING_DEG)
        assert st["n_valid"][r] == f["n_valid"]
        assert st["valid_rmse_deg"][r] == f["rmse"]
        assert st["misleading"][r] == f["misleading"]
    # the bearing produced after settling counts although its reference came before
    assert st["n_valid"].tolist() == [3, 3] and st["misleading"].tolist() == [1, 0]
    assert st["valid_rmse_deg"][0] == np.sqrt(np.mean(np.array([2.0, -3.0, 25.0]) ** 2))
    # every bearing of a reference after settling, flagged or not, in the plain figures
    assert st["n"] == 3


def test_no_valid_bearing_gives_nan_not_zero():
    st = bearing_stats(_track([[10.0, 11.0]], [[False, False]], [1.2, 1.5], [1.3, 1.6]),
                       10.0, 1.0)
    assert st["n_valid"][0] == 0 and np.isnan(st["valid_rmse_deg"][0])
    assert st["misleading"][0] == 0

import numpy as np
import pytest

from dsp.gnss.loops_fixed import FLOAT, ChannelCore
from dsp.gnss.trackers import TrackerContext, make_tracker, tracker_names


def test_builtin_plls_are_the_channel_core():
    assert {"pll2", "pll3"} <= set(tracker_names())
    ctx = TrackerContext(fs_hz=16.368e6, if_hz=4.092e6, doppler0_hz=1200.0)
    t = make_tracker("pll3", ctx, FLOAT, bn_hz=10.0)
    ref = ChannelCore(FLOAT, 16.368e6, 1e-3, 3, 10.0, 1.0, 0.5, 4.092e6, False,
                      np.asarray(1200.0), np.asarray(0.0), True)
    iq = (1.0, 0.1, 2.0, 0.3, 0.9, -0.1)
    assert t.step(*iq) == ref.step(*iq)
    assert t.doppler_hz() == ref.doppler_hz()


def test_unknown_tracker_named():
    with pytest.raises(ValueError, match="unknown tracker 'pll9'; choose from"):
        make_tracker("pll9", TrackerContext(fs_hz=1e6), FLOAT)


def test_fast_path_runs_a_registered_tracker_like_the_core():
    from dsp.gnss.loops_fixed import FixedArith
    from cosim.gnss.dynamics import aukf_patent_dynamics
    from cosim.gnss.loopsim import track_fast, truth_for
    truth = truth_for(aukf_patent_dynamics(q=0), 0.3)
    a = track_fast(truth, 45.0, 200, arith=FixedArith(), seed=3)
    b = track_fast(truth, 45.0, 200, arith=FixedArith(), seed=3, tracker="pll3")
    assert np.array_equal(a.doppler_hz, b.doppler_hz)

import numpy as np
import pytest

from cosim.monopulse.trajectory import ConstantRate, CsvTrajectory, Manoeuvre


def test_constant_rate():
    u, v = ConstantRate(0.1, -0.2, 0.01, 0.02)(np.array([0.0, 2.0]))
    np.testing.assert_allclose(u, [0.1, 0.12])
    np.testing.assert_allclose(v, [-0.2, -0.16])


def test_constant_rate_leaving_the_visible_region_is_refused():
    tr = ConstantRate(0.5, 0.5, 0.2, 0.0)
    with pytest.raises(ValueError, match="target direction must lie in the visible region"):
        tr(np.linspace(0, 2, 11))


def test_manoeuvre_is_continuous_and_accelerates_inside_its_segment():
    tr = Manoeuvre(0.2, 0.1, 0.01, 0.0, segments=((0.5, 1.0, 0.04, -0.02),))
    dt = 1e-4
    t = np.arange(0, 2, dt)
    u, v = tr(t)
    acc = np.diff(u, 2) / dt ** 2
    inside = (t[1:-1] > 0.5 + 2 * dt) & (t[1:-1] < 1.0 - 2 * dt)
    outside = (t[1:-1] < 0.5 - 2 * dt) | (t[1:-1] > 1.0 + 2 * dt)
    np.testing.assert_allclose(acc[inside], 0.04, rtol=1e-5)
    np.testing.assert_allclose(acc[outside], 0.0, atol=1e-6)
    assert np.max(np.abs(np.diff(u))) < 0.0101 * dt * 10  # no jump
    u2, _ = tr(np.array([2.0]))
    # closed form after the segment: u0 + r t + a T^2/2 + a T (t - t1)
    assert u2[0] == pytest.approx(0.2 + 0.02 + 0.04 * 0.125 + 0.04 * 0.5 * 1.0)
    np.testing.assert_allclose(np.diff(v, 2)[inside] / dt ** 2, -0.02, rtol=1e-5)


@pytest.mark.parametrize("segs, msg", [
    (((1.0, 0.5, 0, 0),), "needs 0 <= t_start < t_end"),
    (((0.0, 1.0, 0, 0), (0.5, 2.0, 0, 0)), "must not overlap"),
    (((0.0, 1.0, 0),), "must be \\(t_start_s, t_end_s, a_u, a_v\\)"),
])
def test_bad_manoeuvre_is_refused(segs, msg):
    with pytest.raises(ValueError, match=msg):
        Manoeuvre(segments=segs)


def test_csv_round_trip(tmp_path):
    p = tmp_path / "traj.csv"
    p.write_text("time_s,u,v\n0,0.1,0.2\n1,0.3,0.0\n2,0.3,0.1\n")
    tr = CsvTrajectory.from_csv(p)
    u, v = tr(np.array([0.5, 1.5]))
    np.testing.assert_allclose(u, [0.2, 0.3])
    np.testing.assert_allclose(v, [0.1, 0.05])
    q = tmp_path / "noheader.csv"
    q.write_text("0,0.1,0.2\n1,0.3,0.0\n")
    np.testing.assert_allclose(CsvTrajectory.from_csv(q)(np.array([0.5]))[0], [0.2])
    with pytest.raises(ValueError, match=r"trajectory covers 0.0..2.0 s, not 0.0..2.5 s"):
        tr(np.array([0.0, 2.5]))


def test_bad_csv_is_refused():
    with pytest.raises(ValueError, match="strictly increasing, not 1.0 then 1.0"):
        CsvTrajectory([0, 1, 1], [0, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError, match="trajectory point must lie in the visible region"):
        CsvTrajectory([0, 1], [0, 0.9], [0, 0.9])

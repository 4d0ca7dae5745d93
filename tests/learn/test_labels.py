import numpy as np

from icrsumo.learn.labels import ARC_M, StopClock, resample_path


def test_straight_path_resamples_to_arc_lengths():
    wps = np.array([[1.0, 0.0], [30.0, 0.0]])
    out = resample_path(wps)
    assert out.shape == (len(ARC_M), 2) and out.dtype == np.float32
    np.testing.assert_allclose(out[:, 0], ARC_M, atol=1e-5)
    np.testing.assert_allclose(out[:, 1], 0.0, atol=1e-6)


def test_short_path_is_extended_straight():
    out = resample_path(np.array([[0.0, 2.0], [0.0, 4.0]]))   # heading left, 4 m long
    np.testing.assert_allclose(out[:, 0], 0.0, atol=1e-5)
    np.testing.assert_allclose(out[:, 1], ARC_M, atol=1e-5)


def test_degenerate_path_points_ahead():
    out = resample_path(np.zeros((3, 2)))
    np.testing.assert_allclose(out[:, 0], ARC_M)


def test_stop_clock_counts_time_stopped():
    c = StopClock()
    assert c.update(0.0, 5.0) == 0.0
    assert c.update(1.0, 0.0) == 0.0
    assert c.update(2.5, 0.05) == 1.5
    assert c.update(3.0, 1.0) == 0.0
    assert c.update(3.5, 0.0) == 0.0
    assert c.update(100.0, 0.0) == 10.0

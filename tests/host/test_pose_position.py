"""The 3-D stream's position is smoothed in metres, apart from the orientation (issue 30): the daemon's
default ``[stream] smoothing`` (tremor, thresholds in °/s) no longer touches ``position``."""

from __future__ import annotations

import numpy as np
import pytest

from sphere.daemon import config
from sphere.daemon.app import pose_filter
from sphere.smoothing.pose import PoseFilter

Q = (1.0, 0.0, 0.0, 0.0)


def _ramp_lag_ms(f: PoseFilter, speed_m_s: float, dt: float = 0.0035) -> float:
    """The lag of the filtered position behind a ramp at ``speed_m_s`` (ms), after 1 s."""
    x = 0.0
    for _ in range(int(1.0 / dt)):
        x += speed_m_s * dt
        _, p = f.update(Q, dt, (x, 0.0, 1.0))
    return 1000.0 * (x - p[0]) / speed_m_s


def test_the_daemon_default_smooths_position_in_metres_not_with_the_orientation_filter():
    cfg = config.Config()
    f = pose_filter(cfg)
    assert cfg.stream.smoothing == "tremor" and cfg.stream.position_smoothing == "one-euro"
    assert f.position_name == "one-euro"
    # a hand moving the ball: the old path (tremor's °/s thresholds on metres) lagged it by 26-53 ms
    old = PoseFilter("tremor", ("none", None))
    old._position = old._orientation.__class__()  # what the stream did before: the angle filter on metres
    for speed, before, now in ((0.1, 45.0, 13.0), (0.3, 30.0, 7.0), (1.0, 22.0, 3.5)):
        assert _ramp_lag_ms(old, speed) > before
        assert _ramp_lag_ms(pose_filter(cfg), speed) < now


def test_position_none_is_the_hybrid_estimate_exactly_and_a_loss_restarts_the_filter():
    f = PoseFilter("tremor", ("none", None))
    assert f.update(Q, 0.005, (0.1, -0.2, 0.9))[1] == (0.1, -0.2, 0.9)
    g = PoseFilter("none", ("one-euro", {"min_cutoff_hz": 0.5}))
    for _ in range(200):
        g.update(Q, 0.005, (0.0, 0.0, 1.0))
    assert g.update(Q, 0.005, None)[1] is None  # the position became unknown
    # when it comes back (the ball elsewhere) the output starts there, not 0.5 Hz away from the old place
    assert g.update(Q, 0.005, (0.3, 0.0, 1.0))[1] == pytest.approx((0.3, 0.0, 1.0))


def test_position_smoothing_steadies_a_still_ball_and_its_parameters_are_in_metres():
    rng = np.random.default_rng(1)
    f = PoseFilter("none", ("one-euro", {}))
    noise = rng.normal(0.0, 0.0005, (2000, 3))
    out = np.array([f.update(Q, 0.0035, tuple(np.array([0.0, 0.0, 1.0]) + n))[1] for n in noise])
    assert out[500:].std(axis=0).max() < 0.6 * noise.std(axis=0).min()  # a light touch: 16 Hz when still
    cfg = config.Config().with_overrides(config.parse_set(["position_smoothing.one-euro.beta=5"]), "--set")
    assert pose_filter(cfg)._position.beta == 5.0
    with pytest.raises(config.ConfigError, match="beta"):
        config.Config().with_overrides(config.parse_set(["position_smoothing.one-euro.beta=-1"]), "--set")
    with pytest.raises(config.ConfigError, match="position_smoothing"):
        config.Config().with_overrides(config.parse_set(["stream.position_smoothing=tremor"]), "--set")

"""Smoothing filters of sphere.smoothing, each checked against what its definition promises."""

import math

import numpy as np
import pytest

from sphere.smoothing.bilateral import BilateralAngleFilter
from sphere.smoothing.curve import WindowedCurveSmoother
from sphere.smoothing.kalman_rest import ConstantKalman
from sphere.smoothing.motion_state import MotionStateFilter
from sphere.smoothing.one_euro import OneEuroFilter
from sphere.smoothing.particle import ParticleFilterAR2
from sphere.smoothing.spring import CriticallyDampedSpring
from sphere.smoothing.tremor import TremorFilter
from sphere.smoothing.registry import FILTERS, grid, make_filter

DT = 0.005


def run(f, xs, dt=DT):
    return np.array([f.update(tuple(x), dt) for x in xs])


def test_spring_matches_its_differential_equation():
    """Closed form (eq. 9) against small-step integration of ÿ = f²(y_d − y) − 2fẏ (eq. 8)."""
    s = CriticallyDampedSpring(t_smooth_s=0.1)
    s.reset([0.0], [3.0])
    f = s.f
    y, v, h = 0.0, 3.0, 1e-5
    for step in range(200):
        out = s.update([10.0], DT)
        for _ in range(round(DT / h)):
            a = f * f * (10.0 - y) - 2 * f * v
            v += a * h
            y += v * h
        assert out[0] == pytest.approx(y, abs=2e-3)


def test_spring_never_overshoots_a_step_from_rest():
    s = CriticallyDampedSpring(0.05)
    s.reset([0.0])
    ys = [s.update([1.0], DT)[0] for _ in range(400)]
    assert max(ys) <= 1.0 + 1e-12 and ys[-1] == pytest.approx(1.0, abs=1e-6)
    assert all(b >= a for a, b in zip(ys, ys[1:]))


def test_one_euro_smooths_rest_and_follows_fast_motion():
    rng = np.random.default_rng(1)
    rest = rng.normal(0, 1.0, (2000, 1))
    f = OneEuroFilter(min_cutoff_hz=0.5, beta=0.05)
    assert run(f, rest)[200:].std() < 0.2  # a fifth of the noise or less
    f.reset()
    ramp = np.arange(400)[:, None] * 5.0  # 1000 units/s
    out = run(f, ramp)
    assert abs(out[-1, 0] - ramp[-1, 0]) < 5.0  # less than one sample behind


def test_constant_kalman_converges_to_the_mean_at_rest():
    rng = np.random.default_rng(2)
    x = 3.0 + rng.normal(0, 1.0, (4000, 2))
    out = run(ConstantKalman(q_per_s=0.01, r=1.0), x)
    assert np.allclose(out[-1], 3.0, atol=0.15)
    assert out[1000:].std(axis=0).max() < 0.15


def test_curve_smoother_keeps_a_straight_line_and_delays_by_m():
    line = np.stack([np.arange(100) * 2.0, np.arange(100) * -1.0], axis=1)
    f = WindowedCurveSmoother(m=3)
    out = run(f, line)
    assert np.allclose(out[10:], line[10 - 3 : -3], atol=1e-9)


def test_curve_smoother_reduces_noise_on_a_circle():
    rng = np.random.default_rng(3)
    t = np.linspace(0, 2 * np.pi, 600)
    clean = np.stack([100 * np.cos(t), 100 * np.sin(t)], axis=1)
    noisy = clean + rng.normal(0, 0.5, clean.shape)
    out = run(WindowedCurveSmoother(m=2), noisy)
    err_in = np.linalg.norm(noisy[10:-2] - clean[10:-2], axis=1).mean()
    err_out = np.linalg.norm(out[12:] - clean[10:-2], axis=1).mean()
    # directions are smoothed, edge lengths kept (as the paper defines it): a modest, real reduction
    assert err_out < 0.9 * err_in


def test_bilateral_keeps_an_edge_and_smooths_small_noise():
    f = BilateralAngleFilter(sigma_c=1.0, sigma_s_deg=2.0)
    steps = [0.0, 0.0, 0.0, 30.0, 30.0, 30.0]
    out = [f.update((a,))[0] for a in steps]
    assert out[3] == pytest.approx(0.0, abs=1e-3) and out[4] == pytest.approx(30.0, abs=1e-3)  # the edge survives (one late)
    f.reset()
    out = [f.update((a,))[0] for a in [0.0, 1.0, 0.0, 1.0, 0.0]]
    assert 0.2 < out[2] < 0.8  # small wiggles are averaged
    f.reset()
    out = [f.update((a,))[0] for a in [179.0, -179.0, 179.0]]
    assert abs(abs(out[2]) - 179.0) < 2.0  # wrap-around at ±180° is one small difference, not 358°


def test_particle_filter_tracks_a_ramp_and_is_reproducible():
    rng = np.random.default_rng(4)
    ramp = np.arange(600)[:, None] * np.array([[3.0, -1.0]]) + rng.normal(0, 1.0, (600, 2))
    a = run(ParticleFilterAR2(process_sigma=2.0, obs_sigma=1.0, seed=5), ramp)
    b = run(ParticleFilterAR2(process_sigma=2.0, obs_sigma=1.0, seed=5), ramp)
    assert np.array_equal(a, b)
    truth = np.arange(600)[:, None] * np.array([[3.0, -1.0]])
    assert np.abs(a[50:] - truth[50:]).mean() < 1.0


def test_motion_state_switches_with_hysteresis_and_never_jumps():
    f = MotionStateFilter(rest_speed=20.0, fast_speed=300.0, hysteresis=0.3, rest_q_per_s=5.0, rest_r=1.0, settle=0.05)
    rng = np.random.default_rng(6)
    speed = np.r_[np.zeros(400), np.full(400, 100.0), np.full(400, 2000.0), np.zeros(400)]  # px/s
    x = np.cumsum(speed * DT)[:, None] * np.array([[1.0, 0.5]]) + rng.normal(0, 0.05, (1600, 2))
    states, out = [], []
    for p in x:
        out.append(f.update(tuple(p), DT))
        states.append(f.state)
    assert states[300] == "rest" and states[700] == "slow" and states[1100] == "fast" and states[1599] == "rest"
    out = np.array(out)
    raw_steps = np.linalg.norm(np.diff(x, axis=0), axis=1)
    out_steps = np.linalg.norm(np.diff(out, axis=0), axis=1)
    # handovers go through the spring: catching up the slow state's two-sample delay takes a few
    # slightly larger steps, never one jump of the whole offset (2 × 10 px here)
    assert out_steps.max() <= raw_steps.max() * 1.35
    assert np.linalg.norm(out[-1] - x[-50:].mean(axis=0)) < 0.5  # settles where the signal rests
    assert np.abs(out[1100] - x[1100]).max() < 1.0  # fast: passes through, no trailing lag


@pytest.mark.parametrize("name", list(FILTERS))
def test_every_registered_filter_runs_on_every_grid_point(name):
    for params in list(grid(name))[:3] or [{}]:
        f = make_filter(name, **params)
        out = run(f, np.cumsum(np.ones((50, 2)), axis=0))
        assert np.isfinite(out).all()


def test_unknown_filter_name_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown smoothing filter 'kalmann'; choose from none, tremor"):
        make_filter("kalmann")


def test_bad_parameters_are_clear_errors():
    with pytest.raises(ValueError, match=r"notch_q = 0: must be between 0.1 and 20"):
        make_filter("tremor", notch_q=0)
    with pytest.raises(ValueError, match=r"unknown parameter 'betta'; parameters are min_cutoff_hz, beta"):
        make_filter("one-euro", betta=1)
    with pytest.raises(ValueError, match=r"m = 2.5: must be an integer"):
        make_filter("curve", m=2.5)


@pytest.mark.parametrize("name", list(FILTERS))
def test_every_filter_has_its_parameters_defined_once(name):
    """Defaults, units and ranges live in PARAMS; a filter built with no arguments uses exactly them, and
    every grid value is inside its parameter's range."""
    from sphere.smoothing.registry import filter_class, params

    for key, p in params(name).items():
        assert p.doc and (p.choices or p.lo <= p.default <= p.hi), key
    for key, values in filter_class(name).GRID.items():
        for v in values:
            params(name)[key].check(key, v)


@pytest.mark.parametrize("name", list(FILTERS))
def test_every_filter_holds_a_constant_and_follows_a_step(name):
    """Unit gain at DC: a held value comes out as it went in, and after a step the output settles on it."""
    f = make_filter(name)
    tol = 0.02 if name.endswith("particle") else 1e-6  # particles: a random cloud around the value
    held = run(f, np.full((200, 2), 3.0))
    assert np.allclose(held[-1], 3.0, atol=tol)
    step = run(f, np.full((600, 2), 4.0))
    assert np.allclose(step[-1], 4.0, atol=max(tol, 0.02)), step[-1]


def _tremor_and_ramp(seconds=6.0, tremor_deg=0.1, rate_dps=3.0):
    """A 10 Hz tremor (0.1° RMS) on a slow 3 °/s ramp that starts at 2 s, sampled at 200 Hz."""
    t = np.arange(int(seconds / DT)) * DT
    ramp = np.clip(t - 2.0, 0.0, None) * rate_dps
    trem = tremor_deg * math.sqrt(2) * np.sin(2 * np.pi * 10.0 * t)
    return t, ramp, np.stack([ramp + trem, np.zeros_like(t)], axis=1)


def test_tremor_filter_removes_10hz_tremor_and_keeps_slow_aiming():
    t, ramp, x = _tremor_and_ramp()
    out = run(TremorFilter(), x)
    rest = (t > 1.0) & (t < 2.0)
    residual = out[rest, 0] - out[rest, 0].mean()
    assert residual.std() < 0.1 * 0.1  # at least 20 dB off the tremor
    # on the 3 °/s ramp: no more than 40 ms behind, and the travel kept
    moving = t > 3.0
    behind_s = (ramp[moving] - out[moving, 0]).mean() / 3.0
    assert 0.0 < behind_s < 0.040
    assert abs(out[-1, 0] - ramp[-1]) < 0.15


def test_tremor_filter_passes_fast_moves_without_lag():
    t = np.arange(400) * DT
    x = np.stack([np.where(t > 0.5, (t - 0.5) * 150.0, 0.0), np.zeros_like(t)], axis=1)
    out = run(TremorFilter(), x)
    assert np.abs(out[t > 0.8, 0] - x[t > 0.8, 0]).max() < 0.02  # 150 °/s: < 1 px at 48 px/°

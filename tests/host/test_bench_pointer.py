"""`sphere bench pointer` on a short slice of the real trials: figures exist, make sense, JSON as specified."""

import json
import subprocess
import sys

import numpy as np
import pytest

from sphere.bench import pointer as bench


def test_metrics_on_constructed_paths():
    movement = np.r_[np.zeros(600, bool), np.ones(600, bool), np.zeros(600, bool)]
    t = np.arange(1800) / bench.RATE_HZ
    raw = np.stack([np.where(movement, 200 * np.sin(2 * np.pi * 0.7 * t), 0.0), np.zeros(1800)], axis=1)
    raw[:, 0] = np.cumsum(np.r_[0, np.diff(raw[:, 0])])
    delayed = np.roll(raw, 4, axis=0)  # 4 samples = 20 ms late
    delayed[:4] = raw[0]
    assert bench.lag_ms(delayed, raw, movement) == pytest.approx(20.0, abs=0.5)
    assert bench.lag_ms(raw, raw, movement) == pytest.approx(0.0, abs=0.5)
    rng = np.random.default_rng(0)
    shaky = raw + rng.normal(0, 0.2, raw.shape)
    j, n = bench.jitter_px(shaky, movement)
    assert n > 0 and 0.2 < j < 0.3  # RMS distance of 2-D noise of 0.2 per axis, minus the line fit
    assert bench.jitter_px(raw, movement)[0] == pytest.approx(0.0, abs=1e-9)


def test_overshoot_is_seen_past_a_stop():
    movement = np.r_[np.ones(400, bool), np.zeros(400, bool)]
    raw = np.stack([np.r_[np.arange(400) * 1.0, np.full(400, 399.0)], np.zeros(800)], axis=1)
    past = raw.copy()
    past[400:460, 0] += 5.0 * np.sin(np.linspace(0, np.pi, 60))  # 5 px beyond, then back
    assert bench.overshoot_px(past, raw, movement) == pytest.approx(5.0, abs=0.05)
    assert bench.overshoot_px(raw, raw, movement) == 0.0


def test_bench_pointer_command_on_real_trials(tmp_path):
    from sphere.broad import BroadMissing

    try:
        bench.with_breaks_trials()
    except BroadMissing as e:
        pytest.skip(str(e))
    out = tmp_path / "pointer.json"
    r = subprocess.run(
        [sys.executable, "-m", "sphere.cli", "bench", "pointer", "--seconds", "50", "--filters", "none,one-euro", "--json", str(out)],
        capture_output=True, text=True, timeout=600,
    )
    assert r.returncode == 0, r.stderr
    data = json.loads(out.read_text())
    assert set(data["filters"]) == {"none", "one-euro", "jsm-mapper"}
    for figures in data["filters"].values():
        assert set(figures) >= {"jitter_px", "lag_ms", "overshoot_px", "us_per_sample", "params"}
    assert data["default"] in data["filters"] and data["default"] != "none"
    none, euro = data["filters"]["none"], data["filters"]["one-euro"]
    assert none["lag_ms"] == pytest.approx(0.0, abs=0.5)
    assert euro["jitter_px"] < none["jitter_px"]  # smoothing does something on real data
    assert "jitter" in r.stdout and "one-euro" in r.stdout

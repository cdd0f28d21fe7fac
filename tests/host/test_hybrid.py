"""Chapter 3's hybrid tracker: the fixed-seed simulation repeats, spikes and dropouts are handled."""

from __future__ import annotations

import json

import numpy as np

from sphere.cli import main
from sphere.fusion import hybrid


def test_simulation_is_reproducible_with_its_fixed_seed():
    a, b = hybrid.simulate(), hybrid.simulate()
    for key in ("GT", "SF", "CV", "KF"):
        assert np.array_equal(a.orientation[key], b.orientation[key], equal_nan=True)
        assert np.array_equal(a.position[key], b.position[key], equal_nan=True)
    c = hybrid.simulate(seed=1)
    assert not np.array_equal(a.orientation["SF"], c.orientation["SF"])


def test_ground_truth_matches_the_tables_mean_and_sigma():
    r = hybrid.simulate()
    o, p = hybrid.table(r.orientation), hybrid.table(r.position)
    assert abs(o["GT"][0] - 90.0) < 0.5 and abs(o["GT"][1] - 63.67) < 0.5
    assert abs(p["GT"][0] - 0.31) < 0.01 and abs(p["GT"][1] - 0.35) < 0.01


def test_cv_spikes_are_removed_by_the_gate():
    r = hybrid.simulate()
    spikes = r.cv_spike
    assert spikes.sum() >= 3
    cv_err = np.abs(r.orientation["CV"][spikes] - r.orientation["GT"][spikes])
    kf_err = np.abs(r.orientation["KF"][spikes] - r.orientation["GT"][spikes])
    assert np.all(cv_err > 15.0)
    assert np.all(kf_err < 1.0)


def test_position_filter_stays_close_through_dropouts_while_sf_drifts():
    r = hybrid.simulate()
    p = hybrid.table(r.position)
    assert p["KF"][2] < 0.05
    assert p["SF"][2] > 5 * p["KF"][2]


def test_tracker_interface_takes_any_pose_source():
    trk = hybrid.HybridTracker()
    ang, pos = trk.sensor([10.0, 20.0, 30.0], [0.0, 0.0, 0.0])
    assert np.all(np.isnan(ang))  # the first CV sample initialises the orientation state
    trk.camera([10.1, 19.9, 30.2], [0.0, 0.0, 0.0])
    ang, pos = trk.sensor([10.0, 20.0, 30.0], [0.0, 0.0, 0.0])
    assert np.allclose(ang, [10.1, 19.9, 30.2], atol=0.01)
    trk.camera(None, None)  # the camera lost the target: SF carries on
    ang, _ = trk.sensor([11.0, 21.0, 31.0], [0.0, 0.0, 0.0])
    assert np.allclose(ang, [11.0, 21.0, 31.0])


def test_hybrid_sim_command_prints_both_tables(tmp_path, capsys):
    out = tmp_path / "h.json"
    assert main(["hybrid-sim", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Table 2: orientation" in text and "Table 3: position" in text and "dissertation" in text
    doc = json.loads(out.read_text())
    assert doc["seed"] == hybrid.SEED and set(doc["orientation"]) == {"GT", "SF", "CV", "KF"}

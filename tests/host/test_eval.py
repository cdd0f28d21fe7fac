"""`sphere eval`: the JSON schema of issue 5, the peers' earth frames, and the report."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sphere import broad
from sphere.cli import main


def _need_broad():
    try:
        return broad.trial_paths()
    except broad.BroadMissing as e:
        pytest.skip(f"BROAD trials not available: {e}")


def _installed(module):
    import importlib.util

    return importlib.util.find_spec(module) is not None


PEERS_HERE = [n for n, m in (("vqf", "vqf"), ("fusion", "imufusion")) if _installed(m)]


@pytest.fixture(scope="module")
def eval_doc(tmp_path_factory):
    _need_broad()
    out = tmp_path_factory.mktemp("eval") / "eval.json"
    # 55 s of trial 02: movement starts at 40 s, so 15 s of motion count
    names = ",".join(["madgwick", "dissertation-kf", "sphere"] + PEERS_HERE)
    rc = main(["eval", "--only", "02", "--seconds", "55", "--filters", names, "--jobs", "1", "--json", str(out),
               "--quiet"])
    assert rc == 0
    return json.loads(out.read_text())


def test_json_schema(eval_doc):
    assert set(eval_doc["filters"]) == {"madgwick", "dissertation-kf", "sphere", *PEERS_HERE}
    for name, f in eval_doc["filters"].items():
        assert set(f) == {"trials", "mean", "us_per_sample", "settings"}, name
        assert set(f["mean"]) == {"total", "heading", "inclination"}
        (trial, errs), = f["trials"].items()
        assert trial == "02_undisturbed_slow_rotation_B"
        assert set(errs) == {"total", "heading", "inclination"}
        assert all(isinstance(v, float) and 0.0 <= v < 180.0 for v in errs.values())
        assert f["us_per_sample"] > 0
        assert isinstance(f["settings"], dict) and f["settings"]
    assert "heading offset" in eval_doc["metric"]


def test_our_filters_are_accurate_on_the_slice(eval_doc):
    for name in ("madgwick", "dissertation-kf", "sphere"):
        assert eval_doc["filters"][name]["mean"]["total"] < 5.0, name


def test_peer_settings_are_stated(eval_doc):
    if len(PEERS_HERE) < 2:
        pytest.skip("vqf and imufusion (the 'peers' extra) are not both installed")
    assert eval_doc["filters"]["vqf"]["settings"]["tauAcc"] == 3.0  # VQF's documented default
    assert eval_doc["filters"]["fusion"]["settings"]["gain"] == 0.5  # Fusion's documented default
    assert eval_doc["filters"]["fusion"]["settings"]["earth_frame"] == "NWU"


@pytest.mark.parametrize("name", ["ahrs-madgwick", "ahrs-mahony", "ahrs-ekf"])
def test_ahrs_peers_earth_frames(name):
    """Each peer's stated earth frame puts it within a few degrees of the optical reference."""
    paths = _need_broad()
    from sphere.commands.eval import run_filter
    from sphere.fusion.peers import PeerMissing

    t = broad.load_trial(paths[0]).seconds(30.0, 20.0)
    try:
        r = run_filter(name, t)
    except PeerMissing as e:
        pytest.skip(str(e))
    assert r["errors"]["total"] < 10.0, r


def test_missing_trials_folder_is_a_clear_error(tmp_path, capsys):
    assert main(["eval", "--trials", str(tmp_path)]) == 2
    assert "no BROAD trials" in capsys.readouterr().err


def test_unknown_filter_is_refused(capsys):
    _need_broad()
    assert main(["eval", "--filters", "nope"]) == 2
    assert "unknown filter" in capsys.readouterr().err


def test_report_has_a_mean_table_and_us_column():
    from sphere.commands.eval import format_report

    doc = {"filters": {"x": {"trials": {"t1": {"total": 1.0, "heading": 0.5, "inclination": 0.4}},
                             "mean": {"total": 1.0, "heading": 0.5, "inclination": 0.4}, "us_per_sample": 12.5,
                             "settings": {"a": 1}}},
           "groups": {}, "heading_offset_deg": {"x": {"t1": 0.3}}, "metric": "m", "dataset": "d"}
    text = format_report(doc)
    assert "mean over 1 trials" in text and "us_per_sample" in text and "12.50" in text
    assert np.isfinite(1.0)


TUNED_ON = ("02_undisturbed_slow_rotation_B", "03_undisturbed_slow_rotation_C",
            "05_undisturbed_slow_rotation_with_breaks_B", "07_undisturbed_fast_rotation_B",
            "09_undisturbed_fast_rotation_with_breaks_B", "10_undisturbed_slow_translation_A",
            "14_undisturbed_slow_translation_with_breaks_B", "16_undisturbed_fast_translation_B",
            "24_disturbed_tapping_A", "27_disturbed_phone_vibration_B", "30_disturbed_stationary_magnet_C",
            "32_disturbed_attached_magnet_1cm")


@pytest.mark.slow
def test_kf_beats_tuned_madgwick_on_the_mean_of_all_trials():
    """Issue 5: the dissertation KF beats plain Madgwick on the mean total RMSE over the shipped trials, each
    with one parameter set for all trials; and Madgwick's β is at its optimum (both neighbours are worse),
    so the KF does not win against a detuned Madgwick."""
    # exactly the trials the parameters were tuned on (a full BROAD download holds more)
    by_name = {p.stem: p for p in _need_broad()}
    missing = [n for n in TUNED_ON if n not in by_name]
    if missing:
        pytest.skip(f"needs the BROAD trials the filters were tuned on; missing: {', '.join(missing)}")
    paths = [by_name[n] for n in TUNED_ON]
    from sphere.commands.eval import evaluate, summarise
    from sphere.fusion import peers, registry

    doc = summarise(evaluate(paths, ["madgwick", "dissertation-kf"], jobs=2), ["madgwick", "dissertation-kf"])
    mad = doc["filters"]["madgwick"]["mean"]["total"]
    kf = doc["filters"]["dissertation-kf"]["mean"]["total"]
    assert kf < mad - 0.1, (kf, mad)
    assert doc["filters"]["dissertation-kf"]["settings"]["robust"] == "huber-norm"

    beta = registry.TUNED_MADGWICK_BETA
    totals = {}
    for b in (0.9 * beta, 1.1 * beta):
        errs = []
        for p in paths:
            t = broad.load_trial(p)
            bias = registry.startup_gyro_bias(t.gyr_rad_s, t.dt_s)
            f = registry.make("madgwick", t.dt_s, t.acc_m_s2[0], t.mag_uT[0], gyro_bias_rad_s=bias, beta=b)
            q = f.update_batch(t.gyr_rad_s, t.acc_m_s2, t.mag_uT, t.dt_s)
            errs.append(broad.orientation_error(peers.to_enu(q, f.earth_frame), t).total)
        totals[b] = float(np.mean(errs))
    assert all(v > mad for v in totals.values()), (mad, totals)

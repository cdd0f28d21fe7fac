"""sphere-mouse config: defaults, TOML loading, validation messages, --set and flags."""

from __future__ import annotations

import pytest

from sphere.daemon import config as C
from sphere.daemon.cli import build_parser, settings_from_args


def write(tmp_path, text):
    p = tmp_path / "config.toml"
    p.write_text(text)
    return p


def test_defaults_are_valid_against_their_own_schema():
    cfg = C.Config()
    assert C.validate(cfg.as_dict(), "defaults") == cfg.as_dict()
    assert cfg.pointer.slow_deg_per_width == 40.0
    assert cfg.events.single_tap == "left_click"


def test_missing_default_file_means_defaults(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    assert C.load().as_dict() == C.Config().as_dict()
    assert C.default_path() == tmp_path / "sphere-mouse" / "config.toml"


def test_file_values_are_read_and_converted(tmp_path):
    cfg = C.load(write(tmp_path, '[pointer]\nslow_deg_per_width = 30\naxes = "local"\n[events]\ndouble_tap = "right_click"\n'))
    assert cfg.pointer.slow_deg_per_width == 30.0 and isinstance(cfg.pointer.slow_deg_per_width, float)
    assert cfg.pointer.axes == "local"
    assert cfg.events.double_tap == "right_click"
    assert cfg.pointer.fast_deg_per_width == 40.0  # untouched keys keep their default


@pytest.mark.parametrize("text, message", [
    ("[pointer]\nslow_deg_per_widht = 30\n", "unknown key [pointer] slow_deg_per_widht (did you mean 'slow_deg_per_width'?)"),
    ("[pointr]\n", "unknown section [pointr] (did you mean 'pointer'?)"),
    ("[pointer]\nslow_deg_per_width = -3\n", "[pointer] slow_deg_per_width = -3: must be between 0.5 and 3600"),
    ("[pointer]\nslow_deg_per_width = \"fast\"\n", "must be a number"),
    ("[pointer]\naxes = \"wrld\"\n", "must be one of 'world', 'local' (did you mean 'world'?)"),
    ("[events]\nsingle_tap = \"click\"\n", "[events] single_tap = 'click': must be one of"),
    ("[mode]\ncycle = [\"pointer\", \"fly\"]\n", "unknown mode(s) ['fly']"),
    ("[pointer]\naccel_low_dps = 50.0\naccel_high_dps = 40.0\n", "accel_high_dps = 40.0 must be greater than accel_low_dps = 50.0"),
    ("[pointer]\naccel_low_dps = 200.0\n", "accel_high_dps = 120.0 must be greater than accel_low_dps = 200.0"),
    ("[stream]\nport = 70000\n", "must be a TCP port number"),
    ("[freeze]\ntap_after_ms = 1.5\n", "must be an integer"),
    ("[gyro]\nauto_bias = 1\n", "must be true or false"),
    ("pointer = 3\n", "must be a [pointer] table"),
    ("[pointer\n", "not valid TOML"),
    ("[pointer]\nsmoothing_dps = 8\n", "[pointer] smoothing_dps moved to [smoothing.tiered] smoothing_dps"),
])
def test_bad_values_give_clear_errors(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(C.ConfigError) as e:
        C.load(path)
    assert message in str(e.value)
    assert str(path) in str(e.value)


def test_named_file_must_exist(tmp_path):
    with pytest.raises(C.ConfigError, match="no such config file"):
        C.load(tmp_path / "nope.toml")


def test_set_overrides_parse_toml_values_and_bare_words():
    d = C.parse_set(["pointer.axes=local", "tilt.exponent=2", "pointer.invert_x=true", "mode.cycle=[\"pointer\",\"3d\"]"])
    assert d == {"pointer": {"axes": "local", "invert_x": True}, "tilt": {"exponent": 2}, "mode": {"cycle": ["pointer", "3d"]}}
    with pytest.raises(C.ConfigError, match="SECTION.KEY=VALUE"):
        C.parse_set(["axes=local"])


def test_flags_override_file_and_set_overrides_flags(tmp_path):
    path = write(tmp_path, "[pointer]\nslow_deg_per_width = 30\n[output]\nbackend = \"uinput\"\n")
    args = build_parser().parse_args(["--config", str(path), "--backend", "log", "--sensitivity", "55",
                                      "--set", "pointer.fast_deg_per_width=25", "--replay", "x.bin", "--speed", "0"])
    cfg = settings_from_args(args)
    assert cfg.output.backend == "log"
    assert cfg.pointer.slow_deg_per_width == 55.0 and cfg.pointer.fast_deg_per_width == 25.0
    assert cfg.source.kind == "replay" and cfg["source.replay"].file == "x.bin" and cfg["source.replay"].speed == 0.0


def test_keys_of_earlier_releases_load_in_their_new_place_with_one_note_each(tmp_path, capsys):
    """A config.toml written before the sources and backends had sections of their own still loads; each
    old key is read in its new place and named in one line that says what to rename."""
    path = write(tmp_path, "[source]\nport = \"/dev/rfcomm0\"\nbaud = 9600\nsim_trace = \"synthetic:taps\"\n"
                           "[output]\ndisplay = \":5\"\n")
    cfg = C.load(path)
    assert cfg["source.serial"].port == "/dev/rfcomm0" and cfg["source.serial"].baud == 9600
    assert cfg["source.simulate"].trace == "synthetic:taps" and cfg["backend.x11"].display == ":5"
    assert cfg.notes == [f"{path}: [source] port is now [source.serial] port (read as that; rename it there)",
                         f"{path}: [source] baud is now [source.serial] baud (read as that; rename it there)",
                         f"{path}: [source] sim_trace is now [source.simulate] trace (read as that; rename it there)",
                         f"{path}: [output] display is now [backend.x11] display (read as that; rename it there)"]
    with pytest.raises(C.ConfigError, match=r"\[source.serial\] baud = 7: "):  # checked as the new key
        C.Config().with_overrides(C.parse_set(["source.baud=7"]), "--set")
    from sphere.daemon.cli import main

    assert main(["--config", str(path), "--check-config"]) == 0
    err = capsys.readouterr().err
    assert "[source] port is now [source.serial] port" in err and err.count("is now") == 4


def test_bad_set_is_reported_as_such():
    args = build_parser().parse_args(["--set", "smoothing.tiered.smoothing_time_s=5"])
    with pytest.raises(C.ConfigError, match=r"--set: \[smoothing.tiered\] smoothing_time_s = 5: must be between"):
        settings_from_args(args)


def test_every_key_is_documented_in_the_user_guide():
    from sphere.paths import repo_path

    doc = repo_path("host", "docs", "sphere-mouse.md").read_text()
    assert C.markdown() in doc, "regenerate the key reference: python -m sphere.daemon.config --markdown"


def test_check_config_command(tmp_path, capsys):
    from sphere.daemon.cli import main

    assert main(["--config", str(write(tmp_path, "[tilt]\nexponent = 2.0\n")), "--check-config"]) == 0
    assert main(["--config", str(write(tmp_path, "[tilt]\nexponent = 9.0\n")), "--check-config"]) == 2
    err = capsys.readouterr().err
    assert "config error" in err and "[tilt] exponent = 9.0: must be between 0.5 and 4.0" in err

"""Where the tools find things: $SPHERE_BROAD_DIR / $SPHERE_FIRMWARE win, then the [paths] table of the
config file shared with sphere-mouse, then the checkout's defaults; example:NAME names a shipped capture."""

import pytest

from sphere import paths


@pytest.fixture
def config_home(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    monkeypatch.delenv("SPHERE_BROAD_DIR", raising=False)
    monkeypatch.delenv("SPHERE_FIRMWARE", raising=False)
    (tmp_path / "sphere-mouse").mkdir()
    return tmp_path / "sphere-mouse" / "config.toml"


def test_defaults_in_a_checkout(config_home):
    assert paths.in_checkout()
    assert paths.broad_dir() == paths.REPO_ROOT.parent / "shared" / "data" / "broad"
    assert paths.firmware_image(".hex") == paths.REPO_ROOT / "firmware" / "build" / "sphere.hex"


def test_config_file_then_environment(config_home, tmp_path, monkeypatch):
    config_home.write_text(f'[paths]\nbroad_dir = "{tmp_path}/broad"\nfirmware = "{tmp_path}/fw/sphere.elf"\n')
    assert paths.broad_dir() == tmp_path / "broad"
    assert paths.firmware_image(".hex") == tmp_path / "fw" / "sphere.hex"
    monkeypatch.setenv("SPHERE_BROAD_DIR", "/elsewhere")
    monkeypatch.setenv("SPHERE_FIRMWARE", "/fw2/sphere.elf")
    assert str(paths.broad_dir()) == "/elsewhere" and str(paths.firmware_image()) == "/fw2/sphere.elf"


def test_a_broken_config_file_is_one_clear_line(config_home):
    config_home.write_text("[paths\nbroad_dir = 1\n")
    with pytest.raises(SystemExit, match=r"config.toml: .*; fix the file \(\[paths\] broad_dir"):
        paths.broad_dir()


def test_example_captures():
    assert paths.resolve_capture("example:broad_fast_rotation_4s").is_file()
    assert str(paths.resolve_capture("some/file.cap")) == "some/file.cap"
    with pytest.raises(FileNotFoundError, match="the package ships: example:broad_fast_rotation_4s"):
        paths.resolve_capture("example:nope")
    assert paths.vectors_file().is_file()

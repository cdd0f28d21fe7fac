"""The config seam: a module declares its own section (a dataclass) and the file, --set, the checks and the
reference follow, with no central table to edit; the source registry is the one list of sources."""

from __future__ import annotations

import pytest

from sphere.daemon import config as C

NAMES = ["alpha", "beta"]


@pytest.fixture
def widget():
    @C.section("outputs.widget")
    class Widget:
        enabled: bool = C.option(False, "turn it on")
        rate_hz: float = C.option(30.0, "how often", C.in_range(1.0, 100.0))
        kind: str = C.option("alpha", "which one", choices=lambda: tuple(NAMES))
        ports: list = C.option([1, 2], "ports", lambda v: None if all(isinstance(p, int) for p in v) else "ints")

        def check(self):
            return "rate_hz must be 50 or less when enabled" if self.enabled and self.rate_hz > 50 else None

    yield Widget
    C.SECTIONS.pop("outputs.widget")


def test_a_declared_section_is_read_from_nested_tables(tmp_path, widget):
    path = tmp_path / "c.toml"
    path.write_text("[outputs.widget]\nenabled = true\nrate_hz = 20\nkind = \"beta\"\n")
    cfg = C.load(path)
    w = cfg["outputs.widget"]
    assert (w.enabled, w.rate_hz, w.kind, w.ports) == (True, 20.0, "beta", [1, 2])
    assert C.Config()["outputs.widget"].ports == [1, 2] and C.Config()["outputs.widget"].ports is not widget().ports


@pytest.mark.parametrize("text, message", [
    ("[outputs.widget]\nrate_hz = 500\n", "[outputs.widget] rate_hz = 500: must be between 1.0 and 100.0"),
    ("[outputs.widget]\nkind = \"gamma\"\n", "must be one of 'alpha', 'beta'"),
    ("[outputs.widget]\nrate_hz = inf\n", "finite"),
    ("[outputs.widget]\nenabled = true\nrate_hz = 60\n", "[outputs.widget] rate_hz must be 50 or less"),
    ("[outputs.widgit]\n", "unknown section [outputs.widgit] (did you mean 'outputs.widget'?)"),
    ("[outputs.widget]\nrat_hz = 1\n", "unknown key [outputs.widget] rat_hz (did you mean 'rate_hz'?)"),
])
def test_its_values_are_checked(tmp_path, widget, text, message):
    path = tmp_path / "c.toml"
    path.write_text(text)
    with pytest.raises(C.ConfigError) as e:
        C.load(path)
    assert message in str(e.value)


def test_set_and_reference_and_registry_choices(widget):
    cfg = C.Config().with_overrides(C.parse_set(["outputs.widget.kind=beta", "outputs.widget.rate_hz=5"]), "--set")
    assert cfg["outputs.widget"].kind == "beta" and cfg["outputs.widget"].rate_hz == 5.0
    NAMES.append("gamma")  # a registry that grew: its names are the choices, no table to edit
    try:
        assert C.Config().with_overrides({"outputs.widget": {"kind": "gamma"}}, "t")["outputs.widget"].kind == "gamma"
    finally:
        NAMES.remove("gamma")
    md = C.markdown()
    assert "### [outputs.widget]" in md and "| `rate_hz` | `30.0` | how often |" in md


def test_source_registry_is_the_list_of_kinds():
    from sphere.daemon import sources

    for kind in sources.REGISTRY:
        cls = sources.source_class(kind)
        assert cls.NAME == kind and issubclass(cls, sources.Source)
        assert hasattr(cls, "from_config")
    kinds = dict(C.sections()["source"].__dataclass_fields__)["kind"].metadata["choices"]()
    assert set(kinds) == {"auto", *sources.REGISTRY}

"""The component model (sphere.settings): a component declares NAME and PARAMS in its own module, one registry
line makes it known, and the config file, --set, the checks, the reference and the build follow with no
other table to edit. The fixtures write a trivial component as a real module in a temporary folder and
register it with one line, as host/docs/where-things-go.md says."""

from __future__ import annotations

import sys
import textwrap

import pytest

from sphere import settings
from sphere.daemon import config as C

WIDGET = '''
from sphere.daemon.outputs.base import Output
from sphere.settings import Param

NAMES = ["alpha", "beta"]
SENT = []


def _ints(v):
    return None if all(isinstance(p, int) for p in v) else "must be a list of integers"


class WidgetOutput(Output):
    NAME = "widget"
    PARAMS = {
        "enabled": Param(False, doc="turn it on"),
        "rate_hz": Param(30.0, "Hz", 1.0, 100.0, "how often"),
        "kind": Param("alpha", doc="which one", choices=lambda: tuple(NAMES)),
        "ports": Param([1, 2], doc="ports", check=_ints),
    }

    @classmethod
    def check_settings(cls, s):
        return "rate_hz must be 50 or less when enabled" if s.enabled and s.rate_hz > 50 else None

    @classmethod
    def from_settings(cls, s, log=None):
        return cls(s.kind, s.rate_hz)

    def __init__(self, kind, rate_hz):
        super().__init__(rate_hz)
        self.kind = kind

    def describe(self):
        return f"widget {self.kind}"

    def send_pose(self, q, angles_deg, moved_m, position_m, t_us):
        SENT.append((self.kind, q))
'''


def fixture_module(tmp_path, monkeypatch, name: str, text: str):
    """A component's module, written to a folder on sys.path: what a contributor adds."""
    (tmp_path / f"{name}.py").write_text(textwrap.dedent(text))
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop(name, None)
    return name


@pytest.fixture
def widget(tmp_path, monkeypatch):
    from sphere.daemon.outputs import REGISTRY

    module = fixture_module(tmp_path, monkeypatch, "widget_output", WIDGET)
    REGISTRY.add("widget", f"{module}:WidgetOutput")  # the one registry line
    try:
        yield sys.modules.get(module) or __import__(module)
    finally:
        REGISTRY.remove("widget")
        sys.modules.pop(module, None)


def test_a_declared_section_is_read_from_nested_tables(tmp_path, widget):
    path = tmp_path / "c.toml"
    path.write_text("[outputs.widget]\nenabled = true\nrate_hz = 20\nkind = \"beta\"\n")
    cfg = C.load(path)
    w = cfg["outputs.widget"]
    assert (w.enabled, w.rate_hz, w.kind, w.ports) == (True, 20.0, "beta", [1, 2])
    assert C.Config()["outputs.widget"].ports == [1, 2]
    assert C.Config()["outputs.widget"].ports is not widget.WidgetOutput.PARAMS["ports"].default


@pytest.mark.parametrize("text, message", [
    ("[outputs.widget]\nrate_hz = 500\n", "[outputs.widget] rate_hz = 500: must be between 1.0 and 100.0 Hz"),
    ("[outputs.widget]\nkind = \"gamma\"\n", "must be one of 'alpha', 'beta'"),
    ("[outputs.widget]\nrate_hz = inf\n", "finite"),
    ("[outputs.widget]\nports = [1, \"x\"]\n", "[outputs.widget] ports = [1, 'x']: must be a list of integers"),
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


def test_set_reference_choices_and_build(widget):
    from sphere.daemon.outputs.fanout import attach

    cfg = C.Config().with_overrides(C.parse_set(["outputs.widget.kind=beta", "outputs.widget.rate_hz=5",
                                                 "outputs.widget.enabled=true"]), "--set")
    assert cfg["outputs.widget"].kind == "beta" and cfg["outputs.widget"].rate_hz == 5.0
    widget.NAMES.append("gamma")  # a registry that grew: its names are the choices, no table to edit
    try:
        assert C.Config().with_overrides({"outputs.widget": {"kind": "gamma"}}, "t")["outputs.widget"].kind == "gamma"
    finally:
        widget.NAMES.remove("gamma")
    md = C.markdown()
    assert "### [outputs.widget]" in md and "| `rate_hz` | `30.0` | how often (Hz) |" in md
    cfg = cfg.with_overrides(C.parse_set(["outputs.page.enabled=false"]), "--set")
    out = attach(cfg)  # the daemon's build path: enabled outputs are built from their settings
    out.publish_orientation((1.0, 0.0, 0.0, 0.0), 0)
    out.stop()
    assert widget.SENT == [("beta", (1.0, 0.0, 0.0, 0.0))]


def test_source_registry_is_the_list_of_kinds():
    from sphere.daemon import sources
    from sphere.daemon.sources.base import Source

    for kind in sources.REGISTRY:
        cls = sources.source_class(kind)
        assert cls.NAME == kind and issubclass(cls, Source)
        assert "from_settings" in vars(cls)
    kinds = C.sections()["source"].params["kind"].allowed()
    assert set(kinds) == {"auto", *sources.REGISTRY}


def test_param_types_ranges_and_messages():
    p = settings.Param(4, "samples", 2, 50, "delay")
    assert p.kind is int and p.check("m", 5.0) == 5 and isinstance(p.check("m", 5.0), int)
    with pytest.raises(settings.ParamError, match=r"m = 2.5: must be an integer"):
        p.check("m", 2.5)
    with pytest.raises(settings.ParamError, match=r"m = 60: must be between 2 and 50 samples"):
        p.check("m", 60)
    with pytest.raises(settings.ParamError, match="is too large"):
        p.convert(2 ** 70)
    f = settings.Param(1.0, "Hz", 0.1, None, "cutoff")
    assert f.check("f", 3) == 3.0 and isinstance(f.check("f", 3), float)
    with pytest.raises(settings.ParamError, match="must be at least 0.1 Hz"):
        f.convert(0.0)
    with pytest.raises(settings.ParamError, match="must be a number"):
        f.convert(True)
    s = settings.Param("a", doc="x", choices=("a", "b"))
    with pytest.raises(settings.ParamError, match="must be one of 'a', 'b'"):
        s.convert("c")
    assert settings.Param(False, doc="x").kind is bool and settings.Param([], doc="x").kind is list


def test_registry_imports_an_entry_only_when_asked(tmp_path, monkeypatch):
    module = fixture_module(tmp_path, monkeypatch, "lazy_entry", """
        from sphere.settings import Param

        class Thing:
            NAME = "thing"
            PARAMS = {"size": Param(2.0, "m", 0.0, 10.0, "how big")}
            GRID = {"size": [1.0, 3.0]}

            def __init__(self, size):
                self.size = size
        """)
    reg = settings.Registry("thing", {"thing": f"{module}:Thing"})
    assert module not in sys.modules  # a registry line costs no import
    assert reg.build("thing", {"size": 3}).size == 3.0 and module in sys.modules
    assert reg.build("thing").size == 2.0 and reg.grid("thing") == [{"size": 1.0}, {"size": 3.0}]
    with pytest.raises(settings.ParamError, match="size = 11: must be between 0.0 and 10.0 m"):
        reg.build("thing", {"size": 11})
    with pytest.raises(settings.UnknownComponent, match="unknown thing 'nope'; choose from thing"):
        reg.load("nope")
    assert reg.section("thing") == "thing.thing"

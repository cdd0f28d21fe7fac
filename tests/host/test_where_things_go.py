"""host/docs/where-things-go.md is true: every registry it names exists, lists only modules of the folder it
names, and each entry is a component (NAME = its registry name, PARAMS of sphere.settings.Param, GRID inside
its ranges, a config section the reference documents). Then a trivial orientation filter, smoothing filter,
source, backend and output, each written as a module of its own in a temporary folder and made known by ONE
registry line, run through sphere-mouse's own config and build path (its command line, in this process)."""

from __future__ import annotations

import os
import re
import signal
import sys
import textwrap

import pytest

from sphere import settings
from sphere.daemon import config as C
from sphere.paths import repo_path

DOC = repo_path("host", "docs", "where-things-go.md")

#: where-things-go.md's rows whose "add one line to" is a registry: row word → (module, attribute)
KINDS = {
    "source": ("sphere.daemon.sources", "REGISTRY"),
    "backend": ("sphere.daemon.backends", "REGISTRY"),
    "output": ("sphere.daemon.outputs", "REGISTRY"),
    "filter": ("sphere.fusion.registry", "REGISTRY"),
    "smoothing": ("sphere.smoothing.registry", "REGISTRY"),
}


def doc_rows() -> dict:
    """The table's rows by their bold word: (the folder of the module to write, the file of the registry)."""
    rows = {}
    for line in DOC.read_text().splitlines():
        m = re.match(r"\| (?:an? |a pointer |an orientation )?(?:\w+ )?\*\*(\w+)\*\*.*?\| `(host/sphere/[\w/]+)/NAME\.py`"
                     r".*?\| `(\w+)` in `(host/sphere/[\w/]+\.py)`", line)
        if m:
            rows[m.group(1)] = (m.group(2), m.group(3), m.group(4))
    return rows


def test_every_registry_the_guide_names_is_one_line_per_module_of_its_folder():
    rows = doc_rows()
    assert set(KINDS) <= set(rows), f"where-things-go.md lost a row: {set(KINDS) - set(rows)}"
    for word, (module, attr) in KINDS.items():
        folder, name, registry_file = rows[word]
        assert name == attr and repo_path(*registry_file.split("/")).is_file(), word
        assert registry_file.replace("/", ".").removeprefix("host.").removesuffix(".py").removesuffix(".__init__") \
            == module, word
        registry = settings.load(f"{module}:{attr}")
        assert isinstance(registry, settings.Registry) and len(registry) >= 2, word
        package = folder.replace("/", ".").removeprefix("host.")
        for entry, spec in registry.entries.items():
            mod = spec.split(":")[0]
            assert mod.rsplit(".", 1)[0] == package, f"{word} {entry}: {spec} is not a module of {folder}/"
            assert repo_path("host", *mod.split(".")).with_suffix(".py").is_file(), spec


def walked():
    """(registry, name, class) of every component the daemon's config composes, and of the fusion and smoothing
    registries (also used by `sphere eval` and `sphere bench pointer`)."""
    regs = C.registries()
    for extra in ("sphere.fusion.registry:REGISTRY", "sphere.smoothing.registry:POSITION"):
        reg = settings.load(extra)
        if reg not in regs:
            regs.append(reg)
    for reg in regs:
        for name in reg:
            yield reg, name, reg.load(name)


def test_every_component_of_every_registry_declares_name_and_params():
    sections = C.sections()
    reference = C.markdown()
    seen = 0
    for reg, name, cls in walked():
        seen += 1
        assert getattr(cls, "NAME", None) == name, f"{reg.kind} {name}: NAME is {getattr(cls, 'NAME', None)!r}"
        params = getattr(cls, "PARAMS", {})
        assert isinstance(params, dict) and all(isinstance(p, settings.Param) and p.doc for p in params.values()), name
        for key, p in params.items():
            assert p.check(key, p.default) == p.default, (name, key)  # the default is allowed
        for key, values in (getattr(cls, "GRID", None) or {}).items():
            for v in values:
                params[key].check(key, v)  # every grid value is inside its parameter's range
        section = reg.section(name)
        if params and getattr(cls, "LIVE", True):
            assert section in sections and f"### [{section}]" in reference, section
        else:
            assert section not in sections, section
    assert seen >= 40


def test_print_config_round_trips_to_the_defaults_of_every_section(tmp_path):
    from sphere.daemon.print_config import defaults_toml

    path = tmp_path / "config.toml"
    path.write_text(defaults_toml())
    cfg = C.load(path)
    assert cfg.as_dict() == C.Config().as_dict() and cfg.notes == []
    assert set(cfg.as_dict()) == set(C.sections())


# ---- one module + one registry line each, through the daemon --------------------------------------

FIXTURES = {
    "fixture_filter": '''
        from sphere.settings import Param

        CALLS = []


        class HoldFilter:
            """An orientation filter that holds its start (the daemon can run it: LIVE)."""

            NAME = "fixture"
            PARAMS = {"gain": Param(0.5, "", 0.0, 1.0, "how much it trusts nothing")}
            GRID = {"gain": (0.25, 0.5)}
            LIVE = True
            earth_frame = "NWU"

            @classmethod
            def from_settings(cls, s, dt_s=None, q0=(1.0, 0.0, 0.0, 0.0), gyro_bias_rad_s=None):
                return cls(s.gain, q0)

            def __init__(self, gain, q0):
                self.gain, self.quat = gain, tuple(q0)

            def update(self, gyr, acc, mag, dt, acc_valid=True):
                CALLS.append(self.gain)
                return self.quat
        ''',
    "fixture_smoothing": '''
        from sphere.settings import Param

        CALLS = []


        class Halfway:
            NAME = "fixture"
            PARAMS = {"keep": Param(0.0, "", 0.0, 0.9, "share of the last output kept")}
            GRID = {"keep": [0.0, 0.5]}

            def __init__(self, keep=0.0):
                self.keep = keep
                self.reset()

            def reset(self):
                self.y = None

            def update(self, x, dt_s):
                CALLS.append(self.keep)
                self.y = tuple(x) if self.y is None else tuple(self.keep * a + (1 - self.keep) * b
                                                                for a, b in zip(self.y, x))
                return self.y
        ''',
    "fixture_source": '''
        from sphere.daemon.scripted_sphere import script_bytes
        from sphere.daemon.sources.base import Source, SourceEnded
        from sphere.settings import Param


        class TurnSource(Source):
            """A sphere that turns left once, then is gone."""

            NAME = "fixture"
            PARAMS = {"turn_dps": Param(20.0, "°/s", 1.0, 500.0, "how fast it turns left for half a second")}

            @classmethod
            def from_settings(cls, s, log=None, cfg=None):
                return cls(s.turn_dps)

            def __init__(self, turn_dps):
                super().__init__(reconnect_interval_s=0.0)
                self.data = script_bytes([("still", 0.3), ("turn", (0, 0, 1), turn_dps, 0.5), ("still", 0.3)])
                self.state = "fixture"

            def _connect(self):
                return []

            def _read(self):
                if self.data is None:
                    raise SourceEnded()
                data, self.data = self.data, None
                return data
        ''',
    "fixture_backend": '''
        from sphere.daemon.backends.base import Backend
        from sphere.settings import Param

        MOVES = []


        class ListBackend(Backend):
            NAME = "fixture"
            PARAMS = {"width_px": Param(1000, "px", 100, 10000, "the screen width it reports")}

            def __init__(self, width_px):
                self.width_px = width_px

            def screen_size(self):
                return (self.width_px, 800)

            def move(self, dx, dy):
                MOVES.append((dx, dy))

            def press(self, button):
                pass

            def release(self, button):
                pass

            def close(self):
                pass
        ''',
    "fixture_output": '''
        from sphere.daemon.outputs.base import Output
        from sphere.settings import Param

        SENT = []


        class ListOutput(Output):
            NAME = "fixture"
            PARAMS = {"enabled": Param(False, doc="on"), "label": Param("a", doc="what it calls the poses")}

            @classmethod
            def from_settings(cls, s, log=None):
                out = cls(rate_hz=0.0)
                out.label = s.label
                return out

            def describe(self):
                return "a list"

            def send_pose(self, q, angles_deg, moved_m, position_m, t_us):
                SENT.append((self.label, angles_deg))
        ''',
}

#: (registry "module:attribute", the fixture module, its class): the one line each adds
LINES = [
    ("sphere.fusion.registry:REGISTRY", "fixture_filter", "HoldFilter"),
    ("sphere.smoothing.registry:REGISTRY", "fixture_smoothing", "Halfway"),
    ("sphere.daemon.sources:REGISTRY", "fixture_source", "TurnSource"),
    ("sphere.daemon.backends:REGISTRY", "fixture_backend", "ListBackend"),
    ("sphere.daemon.outputs:REGISTRY", "fixture_output", "ListOutput"),
]


@pytest.fixture
def fixtures(tmp_path, monkeypatch):
    for name, text in FIXTURES.items():
        (tmp_path / f"{name}.py").write_text(textwrap.dedent(text))
    monkeypatch.syspath_prepend(str(tmp_path))
    mods = {}
    try:
        for registry, module, cls in LINES:
            settings.load(registry).add("fixture", f"{module}:{cls}")  # the one registry line
        yield lambda m: mods.setdefault(m, __import__(m))
    finally:
        for registry, module, _ in LINES:
            settings.load(registry).remove("fixture")
            sys.modules.pop(module, None)


def test_a_new_filter_smoothing_source_backend_and_output_are_one_module_and_one_line_each(fixtures, capsys):
    from sphere.daemon import cli

    sections = C.sections()
    for s in ("orientation.fixture", "smoothing.fixture", "source.fixture", "backend.fixture", "outputs.fixture"):
        assert s in sections and f"### [{s}]" in C.markdown(), s
    argv = ["--config", os.devnull, "--no-stream", "--quiet", "--backend", "fixture",
            "--set", "source.kind=fixture", "--set", "source.fixture.turn_dps=40",
            "--set", "backend.fixture.width_px=1200", "--set", "orientation.filter=fixture",
            "--set", "orientation.fixture.gain=0.25", "--set", "pointer.smoothing=fixture",
            "--set", "smoothing.fixture.keep=0.5", "--set", "outputs.fixture.enabled=true",
            "--set", "outputs.fixture.label=b", "--set", "pointer.tightening_dps=0"]
    handlers = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGINT, signal.SIGUSR1, signal.SIGUSR2)}
    try:
        assert cli.main(argv) == 0, capsys.readouterr().err
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)
    err = capsys.readouterr().err
    assert "source fixture, backend fixture" in err and "output fixture: a list" in err, err
    moves = fixtures("fixture_backend").MOVES
    # 40 °/s left for 0.5 s at 40° per 1200 px: 600 px left (the smoothing keeps every degree it is given)
    assert sum(dx for dx, _ in moves) == pytest.approx(-600, abs=6) and sum(dy for _, dy in moves) == 0, moves
    assert fixtures("fixture_filter").CALLS and set(fixtures("fixture_filter").CALLS) == {0.25}
    assert fixtures("fixture_smoothing").CALLS and set(fixtures("fixture_smoothing").CALLS) == {0.5}
    sent = fixtures("fixture_output").SENT
    assert sent and {label for label, _ in sent} == {"b"}
    # and a value outside a fixture's range is the config's one line, exit 2, before anything starts
    assert cli.main(["--config", os.devnull, "--check-config", "--set", "source.fixture.turn_dps=900"]) == 2
    assert "[source.fixture] turn_dps = 900: must be between 1.0 and 500.0 °/s" in capsys.readouterr().err

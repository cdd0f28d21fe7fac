"""The host package's layers hold: no module imports a higher layer, and the imports have no cycle. Read from
the source (every ``import`` and ``from … import`` of a sphere module, at module level or inside a function), so
a new upward import fails here before it fails anyone at run time. The order is documented in
host/docs/where-things-go.md ("Layers"). Imports sit at a module's top: one inside a function says why on its
line (an optional dependency, …); ``python tests/host/test_layers.py`` lists them."""

from __future__ import annotations

import ast
import functools
import io
import re
import subprocess
import sys
import tokenize
from collections import defaultdict
from pathlib import Path

import sphere

PACKAGE = Path(sphere.__file__).resolve().parent
#: Bottom to top. A module may import its own layer and the ones below it, never one above.
LAYERS = (
    ("bottom", ("sphere", "sphere.errors", "sphere.quaternion", "sphere.chips", "sphere.paths", "sphere.settings",
                "sphere.lazy")),
    ("protocol", ("sphere.protocol", "sphere.broad")),
    ("core", ("sphere.link", "sphere.calibration", "sphere.fusion", "sphere.smoothing")),
    ("sim and camera", ("sphere.sim", "sphere.camera")),
    ("daemon", ("sphere.daemon",)),
    ("commands", ("sphere.commands", "sphere.bench", "sphere.cli", "sphere.mouse", "sphere.argtypes", "sphere.progress")),
)


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in PACKAGE.rglob("*.py") if "data" not in p.relative_to(PACKAGE).parts[:1]}


def _resolve(name: str) -> str:
    """The module ``name`` refers to (``sphere.protocol.FrameDecoder`` → ``sphere.protocol``)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name


@functools.cache
def tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(), str(path))


@functools.cache
def imports() -> dict[str, set[str]]:
    """module → the sphere modules it imports, anywhere in it."""
    out = defaultdict(set)
    for module, path in MODULES.items():
        for node in ast.walk(tree(path)):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
                    for _ in range(node.level - 1):
                        package = package.rpartition(".")[0]
                    base = f"{package}.{base}" if base else package
                names = [f"{base}.{a.name}" for a in node.names]
            else:
                continue
            for name in names:
                target = _resolve(name) if name.split(".")[0] == "sphere" else ""
                if target and target != module:
                    out[module].add(target)
    return out


def layer(module: str) -> int:
    best = max(((len(p), i) for i, (_, prefixes) in enumerate(LAYERS) for p in prefixes
                if module == p or module.startswith(p + ".")), default=None)
    assert best is not None, f"{module} is in no layer: add it to LAYERS (and to where-things-go.md)"
    return best[1]


def test_every_module_has_a_layer():
    for module in MODULES:
        layer(module)


def test_no_module_imports_a_higher_layer():
    upward = sorted(f"{m} ({LAYERS[layer(m)][0]}) imports {t} ({LAYERS[layer(t)][0]})"
                    for m, targets in imports().items() for t in targets if layer(t) > layer(m))
    assert not upward, "\n".join(upward)


def _with_packages(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """Importing ``a.b.c`` first runs ``a/__init__`` and ``a/b/__init__``: edges to those packages too (not to
    the importer's own packages, which are already running)."""
    out = defaultdict(set)
    for m, targets in graph.items():
        own = {m.rsplit(".", k)[0] for k in range(m.count(".") + 1)}
        for t in targets:
            parts = t.split(".")
            out[m].update({".".join(parts[:k]) for k in range(1, len(parts) + 1)} - own - {m})
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


#: None left: the last one (daemon/config.py → the sources' registry → sources/replay.py → config's ConfigError)
#: went with the component model (the sources' package imports no entry; replay raises SourceError).
KNOWN_CYCLES: list = []


def test_no_import_cycle():
    assert cycles(_with_packages(imports())) == KNOWN_CYCLES


def test_the_checks_see_what_they_check():
    """They cannot pass on nothing: the walk sees known imports, and a cycle and an upward import are found."""
    graph = imports()
    assert "sphere.protocol.packets" in graph["sphere.protocol.decoder"]
    assert "sphere.protocol" in graph["sphere.daemon.app"] and layer("sphere.daemon.app") > layer("sphere.protocol")
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert "sphere.daemon" in _with_packages({"sphere.fusion.x": {"sphere.daemon.config"}})["sphere.fusion.x"]


#: What may keep an import inside a function, as its comment says (on the import's line or the line above):
#: "optional: …" a dependency the package runs without (an extra: OpenCV, matplotlib, the peers, the backends'
#: X11/evdev/pynput, websockets; the camera), "POSIX only" (fcntl, termios), "--against" (the daemon bench running
#: an older revision's package, whose modules may not exist). A required import is made at the top even where it
#: is slow: a light path stays light by what its modules import (sphere.daemon.config reads the orientation
#: filters' names from sphere.fusion.registry, which builds none; sphere.fusion.factory builds them, with numpy).
#: `sphere` imports a subcommand with importlib (not a statement here).
REASONS = ("optional", "POSIX only", "--against")


def _comments(source: str) -> dict[int, str]:
    """line → the comment on it."""
    return {tok.start[0]: tok.string for tok in tokenize.generate_tokens(io.StringIO(source).readline)
            if tok.type == tokenize.COMMENT}


def imports_in_functions(source: str, name: str = "<source>", parsed: ast.Module | None = None
                         ) -> list[tuple[int, str, str]]:
    """(line, the import, its comment) of every import made inside a function (or a method, a nested one)."""
    lines, found = source.splitlines(), []

    class Walk(ast.NodeVisitor):
        depth = 0

        def visit_FunctionDef(self, node):
            self.depth += 1
            self.generic_visit(node)
            self.depth -= 1

        visit_AsyncFunctionDef = visit_Lambda = visit_FunctionDef

        def visit_Import(self, node):
            if self.depth:
                found.append(node)

        visit_ImportFrom = visit_Import

    Walk().visit(parsed or ast.parse(source, name))
    comments = _comments(source) if found else {}  # tokenizing is the slow part: only where it is needed
    out = []
    for node in found:
        own = " ".join(comments[n] for n in range(node.lineno, node.end_lineno + 1) if n in comments)
        above = lines[node.lineno - 2].strip() if node.lineno > 1 else ""
        text = lines[node.lineno - 1].split("#")[0].strip()
        out.append((node.lineno, text, own or (above if above[:1] == "#" else "")))
    return out


@functools.cache
def all_imports_in_functions() -> list[tuple[str, int, str, str]]:
    """(module's path in the package, line, the import, its comment) over every module."""
    indented = re.compile(r"^[ \t]+(import|from)[ \t]", re.M)  # only a module with one can have one in a function
    return [(str(path.relative_to(PACKAGE.parent)), *found) for path in sorted(MODULES.values())
            if indented.search(source := path.read_text())
            for found in imports_in_functions(source, str(path), tree(path))]


def test_imports_inside_functions_say_why():
    """0 imports inside functions except for a reason REASONS names, written beside it."""
    found = all_imports_in_functions()
    bare = [f"{path}:{line}: {text}" for path, line, text, comment in found
            if not any(reason in comment for reason in REASONS)]
    assert not bare, ("imports inside functions without a reason (move them to the module's top, or say why: "
                      f"{', '.join(REASONS)}):\n" + "\n".join(bare))
    print(f"{len(found)} imports inside functions in {len({f[0] for f in found})} modules, each with its reason")


def test_the_import_walk_sees_nested_imports_and_their_comments():
    source = ("import os\n"
              "def f():\n"
              "    import json\n"
              "    # optional: cv2 (the camera extra)\n"
              "    import cv2\n"
              "    class C:\n"
              "        def g(self):\n"
              "            from x import (a,\n"
              "                           b)  # --against: x\n"
              "    return lambda: __import__('y')\n")
    assert imports_in_functions(source) == [(3, "import json", ""),
                                            (5, "import cv2", "# optional: cv2 (the camera extra)"),
                                            (8, "from x import (a,", "# --against: x")]
    assert any("sphere/daemon/backends/x11.py" in f[0] and "Xlib" in f[2] for f in all_imports_in_functions())



def test_the_config_imports_without_numpy():
    """Importing sphere.daemon.config (and with it the registries' names: sources, backends, smoothing filters, the
    orientation filters the daemon can run) loads no numpy: the ≤ 40 ms import of issue 25 rests on that, and the
    registries are read without importing their entries until a section is composed."""
    code = "import sys, sphere.daemon.config; print(sorted(m for m in sys.modules if m.split('.')[0] == 'numpy'))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True).stdout
    assert out.strip() == "[]", out

if __name__ == "__main__":  # the list, by module, with each one's reason
    for path, line, text, comment in all_imports_in_functions():
        print(f"{path}:{line}: {text}  {comment}", file=sys.stdout)
    found = all_imports_in_functions()
    print(f"{len(found)} imports inside functions in {len({f[0] for f in found})} modules")

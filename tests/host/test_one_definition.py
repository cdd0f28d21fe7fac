"""One definition of each concept in the host package: the quaternion product (sphere.quaternion.mul), gravity
(sphere.chips.STANDARD_GRAVITY_M_S2) and the NWU → ENU earth-frame rotation (sphere.quaternion.Q_NWU_TO_ENU).
Found in the source itself, so a copy written anew anywhere fails here."""

from __future__ import annotations

import ast
import functools
from collections import Counter
from pathlib import Path

import sphere

PACKAGE = Path(sphere.__file__).resolve().parent
#: SphereFilter writes its per-sample products out: as quaternion.mul calls its update is 5 % slower
#: (fusion/sphere_filter.py; tests/host/test_fusion.py checks that they give quaternion.mul's bits)
WRITTEN_OUT = {"fusion/sphere_filter.py": 5}


@functools.cache
def sources() -> tuple:
    return tuple((path.relative_to(PACKAGE).as_posix(), ast.parse(path.read_text(), str(path)))
                 for path in sorted(PACKAGE.rglob("*.py")) if not path.relative_to(PACKAGE).as_posix().startswith("data/"))


def _product(n) -> bool:
    return isinstance(n, ast.BinOp) and isinstance(n.op, ast.Mult)


def _hamilton_scalar_part(n) -> bool:
    """``a*b - c*d - e*f - g*h``: the w component of a Hamilton product, however its variables are named."""
    for _ in range(3):
        if not (isinstance(n, ast.BinOp) and isinstance(n.op, ast.Sub) and _product(n.right)):
            return False
        n = n.left
    return _product(n)


def count(predicate) -> Counter:
    c = Counter()
    for rel, tree in sources():
        c.update(rel for node in ast.walk(tree) if predicate(node))
    return c


def test_the_quaternion_product_is_written_once():
    assert count(_hamilton_scalar_part) == Counter({"quaternion.py": 1, **WRITTEN_OUT})


def test_gravity_is_defined_once():
    def gravity(n):
        return isinstance(n, ast.Constant) and isinstance(n.value, float) and 9.78 <= n.value <= 9.84  # g on earth
    assert count(gravity) == Counter({"chips.py": 1})


def test_the_earth_frame_rotation_is_defined_once():
    """√½ appears in a unit quaternion of a quarter turn; NWU → ENU is one, in sphere.quaternion. (The NED → ENU
    rotation of the peers' frames is another constant: it stays beside them in fusion/peers.py.)"""
    def half_root(n):
        return (isinstance(n, ast.Call) and len(n.args) == 1 and isinstance(n.args[0], ast.Constant)
                and n.args[0].value == 0.5 and getattr(n.func, "attr", getattr(n.func, "id", "")) == "sqrt")
    assert count(half_root) == Counter({"quaternion.py": 2, "fusion/peers.py": 2})

"""Where the project finds things that are not inside the Python package."""

from __future__ import annotations

import os
from pathlib import Path

#: The repository root when the package runs from a checkout (editable install or PYTHONPATH).
REPO_ROOT = Path(__file__).resolve().parents[2]


def repo_path(*parts: str) -> Path:
    """A path inside the repository checkout (protocol vectors, captures, firmware build)."""
    return REPO_ROOT.joinpath(*parts)


def broad_dir() -> Path:
    """The folder of BROAD trials.

    Set ``SPHERE_BROAD_DIR`` to point elsewhere; the default is ``../shared/data/broad`` beside the
    repository checkout.
    """
    env = os.environ.get("SPHERE_BROAD_DIR")
    if env:
        return Path(env)
    return REPO_ROOT.parent / "shared" / "data" / "broad"

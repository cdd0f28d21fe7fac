"""Another revision of this repository's host package, for the benchmarks' ``--against REV`` (side by side)."""

from __future__ import annotations

import os
import subprocess

from sphere.errors import SphereError


class RevisionError(SphereError):
    """``--against`` named something that is not a revision here (or git cannot give it): one line, exit 2."""


def tree_of(rev: str, into: str) -> str:
    """``host/`` of revision ``rev`` of the repository this file is in, extracted into ``into``."""
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    git = ["git", "-C", repo]
    try:
        ok = subprocess.run(git + ["rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}"],
                            capture_output=True, text=True)
    except FileNotFoundError:
        raise RevisionError("--against needs git on PATH") from None
    if ok.returncode != 0:
        raise RevisionError(f"--against {rev}: not a commit of the repository at {repo} (this needs a git checkout "
                            "of the project; `git log --oneline` lists the revisions)")
    archive = subprocess.run(git + ["archive", "--format=tar", ok.stdout.strip(), "host"], capture_output=True)
    if archive.returncode != 0:
        raise RevisionError(f"--against {rev}: git archive failed: {archive.stderr.decode(errors='replace').strip()}")
    subprocess.run(["tar", "-x", "-C", into], input=archive.stdout, check=True)
    return os.path.join(into, "host")

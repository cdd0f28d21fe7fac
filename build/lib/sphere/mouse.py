"""`sphere-mouse`: the daemon that turns the sphere into a pointer and a 3-D controller.

The work is in :mod:`sphere.daemon` (see host/docs/sphere-mouse.md); this is only the entry point.
"""

from __future__ import annotations

import sys

from sphere.daemon.cli import main

if __name__ == "__main__":
    sys.exit(main())

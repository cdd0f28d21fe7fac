"""The ``[paths]`` section of ~/.config/sphere-mouse/config.toml: where the tools find data that is not in
the package. :mod:`sphere.paths` reads it (the environment variables win); declared here so that
sphere-mouse accepts, checks and documents it (``--print-config``)."""

from __future__ import annotations

from sphere.settings import Param


class PathsSettings:
    NAME = "paths"
    PARAMS = {
        "broad_dir": Param("", doc="folder of the BROAD trials (`data_mat`) for `sphere eval` and `sphere sim`; "
                                "\"\" = $SPHERE_BROAD_DIR, else ../shared/data/broad beside a checkout, else "
                                "~/.local/share/marg-sphere/broad"),
        "firmware": Param("", doc="firmware image (sphere.elf, with sphere.hex beside it) for `sphere sim` and "
                               "`sphere flash`; \"\" = $SPHERE_FIRMWARE, else the checkout's build, else the package's"),
    }

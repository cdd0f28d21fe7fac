"""Where the project finds things that are not Python code: the firmware image, the virtual board's
sources and build, the example capture, the golden vectors, the BROAD trials.

Everything a command needs is found from an installed package, not only from a checkout:

- the data the package ships (``sphere/data``: example captures, golden vectors, the virtual board's C
  sources, the firmware image when the wheel was built after ``make -C firmware``); in a checkout these
  are symbolic links into ``protocol/``, ``hardware/sim/`` and ``firmware/build/``;
- the firmware image: ``$SPHERE_FIRMWARE`` or ``[paths] firmware`` (an .elf with its .hex beside it),
  else the checkout's ``firmware/build/sphere.elf``, else the one in the package;
- the virtual board: built in the checkout's ``hardware/sim/build``, or, installed, on first use into
  ``$XDG_CACHE_HOME/marg-sphere/sim`` (``~/.cache/marg-sphere/sim``);
- BROAD: ``$SPHERE_BROAD_DIR``, else ``broad_dir`` in the ``[paths]`` table of
  ``~/.config/sphere-mouse/config.toml``, else
  ``../shared/data/broad`` beside a checkout, else ``~/.local/share/marg-sphere/broad``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from sphere.errors import SphereError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10: the tomli package (a dependency there) is the same parser
    import tomli as tomllib

PACKAGE_DIR = Path(__file__).resolve().parent
#: The package's data folder (installed with it; links into the repository in a checkout).
DATA_DIR = PACKAGE_DIR / "data"
#: The repository root when the package runs from a checkout (editable install or PYTHONPATH).
REPO_ROOT = PACKAGE_DIR.parents[1]

FIRMWARE_ENV = "SPHERE_FIRMWARE"
BROAD_ENV = "SPHERE_BROAD_DIR"
EXAMPLE_PREFIX = "example:"


def in_checkout() -> bool:
    """True when the package is the one inside a repository checkout (not an installed copy)."""
    return (REPO_ROOT / "pyproject.toml").is_file() and (REPO_ROOT / "firmware").is_dir()


def repo_path(*parts: str) -> Path:
    """A path inside the repository checkout (for tests and tools that only make sense there)."""
    return REPO_ROOT.joinpath(*parts)


def _xdg(var: str, default: str) -> Path:
    value = os.environ.get(var)
    return Path(value) if value else Path.home() / default


def cache_dir() -> Path:
    """Where built things go when the package is installed (``$XDG_CACHE_HOME/marg-sphere``)."""
    return _xdg("XDG_CACHE_HOME", ".cache") / "marg-sphere"


def config_file() -> Path:
    """The config file shared with sphere-mouse (its ``[paths]`` table holds ``broad_dir``)."""
    return _xdg("XDG_CONFIG_HOME", ".config") / "sphere-mouse" / "config.toml"


class ConfigFileError(SphereError, ValueError):
    """A config file that cannot be read as TOML; the message names the file and says why."""


def read_config(path: Path | str | None = None, explicit: bool | None = None) -> dict:
    """The TOML tables of a config file: the one reader of ``config.toml`` (sphere-mouse's settings and the
    tools' ``[paths]``). ``path`` None reads :func:`config_file`. A missing file is ``{}`` (the defaults)
    unless it was named (``explicit``, by default: a path was given), then an error; so are a folder, a device
    or FIFO (reading one might never end), bad TOML, a file not in UTF-8 and one that cannot be read, each
    a :class:`ConfigFileError` with one line."""
    if explicit is None:
        explicit = path is not None
    path = Path(path) if path is not None else config_file()
    try:
        exists = path.exists()
    except OSError as e:  # a folder on the way that cannot be searched
        raise ConfigFileError(f"{path}: cannot read: {e.strerror}") from None
    if not exists:
        if explicit:
            raise ConfigFileError(f"{path}: no such config file")
        return {}
    if path.is_dir():
        raise ConfigFileError(f"{path} is a folder, not a config file")
    if not path.is_file() and str(path) != os.devnull:
        raise ConfigFileError(f"{path} is not a regular file: give a TOML text file "
                              "(sphere-mouse --print-config writes one)")
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise ConfigFileError(f"{path}: not valid TOML: {e}") from None
    except UnicodeDecodeError as e:
        raise ConfigFileError(f"{path}: not a UTF-8 text file (byte {e.start}): save it as UTF-8") from None
    except OSError as e:
        raise ConfigFileError(f"{path}: cannot read: {e.strerror}") from None


def data_home() -> Path:
    return _xdg("XDG_DATA_HOME", ".local/share") / "marg-sphere"


# ---- firmware image ---------------------------------------------------------------------------------

def firmware_build_dir() -> Path | None:
    """The checkout's firmware build folder (``make -C firmware`` writes there), or None when installed."""
    return REPO_ROOT / "firmware" / "build" if in_checkout() else None


def firmware_image(suffix: str = ".elf") -> Path:
    """The firmware image (``.elf`` for the simulator, ``.hex`` for avrdude), which may not exist yet.

    ``$SPHERE_FIRMWARE`` or ``[paths] firmware`` names an image (its other format is looked for beside
    it); otherwise the checkout's build, otherwise the copy shipped in the package.
    """
    env = os.environ.get(FIRMWARE_ENV)
    if env:
        return Path(env).expanduser().with_suffix(suffix)
    from_config = configured("firmware")
    if from_config is not None:
        return from_config.with_suffix(suffix)
    build = firmware_build_dir()
    if build is not None:
        return build / f"sphere{suffix}"
    return DATA_DIR / "firmware" / f"sphere{suffix}"


def firmware_missing_hint() -> str:
    if in_checkout() and not os.environ.get(FIRMWARE_ENV) and configured("firmware") is None:
        return "build it with `make -C firmware`"
    return (f"set {FIRMWARE_ENV}=/path/to/sphere.elf (from `make -C firmware` in a checkout of the "
            "repository), or reinstall a package built after `make -C firmware`")


# ---- the virtual board --------------------------------------------------------------------------------

def sim_source_dir() -> Path:
    """The virtual board's C sources and Makefile."""
    if in_checkout():
        return REPO_ROOT / "hardware" / "sim"
    return DATA_DIR / "sim"


def sim_build_root() -> Path:
    """The folder `make` runs in for the board: the checkout's hardware/sim, or the user's cache copy."""
    if in_checkout():
        return REPO_ROOT / "hardware" / "sim"
    return cache_dir() / "sim"


def sim_build_command() -> str:
    return "make -C hardware/sim" if in_checkout() else f"make -C {sim_build_root()}"


# ---- shipped data -------------------------------------------------------------------------------------

def example_captures() -> dict[str, Path]:
    """The captures shipped with the package, by name (file name without .cap)."""
    folder = DATA_DIR / "examples"
    return {p.stem: p for p in sorted(folder.glob("*.cap"))} if folder.is_dir() else {}


def resolve_capture(path: str | os.PathLike) -> Path:
    """A capture path as given, or ``example:NAME`` for a capture shipped with the package."""
    text = os.fspath(path)
    if text.startswith(EXAMPLE_PREFIX):
        name = text[len(EXAMPLE_PREFIX):]
        examples = example_captures()
        if name not in examples:
            raise FileNotFoundError(
                f"{text}: no such example capture; the package ships: "
                + (", ".join(EXAMPLE_PREFIX + n for n in examples) or "none"))
        return examples[name]
    return Path(text)


def vectors_file() -> Path:
    """The golden vectors (protocol/vectors/frames.txt), shipped with the package."""
    return DATA_DIR / "vectors" / "frames.txt"


# ---- BROAD --------------------------------------------------------------------------------------------

def configured(key: str) -> Path | None:
    """``[paths] KEY`` of the config file shared with sphere-mouse (sphere.daemon.paths_config), or None."""
    path = config_file()
    try:
        table = read_config(path, explicit=False).get("paths", {})
    except ConfigFileError as e:
        raise SystemExit(f"sphere: {e}; fix the file ([paths] {key} = \"/some/path\")") from None
    value = table.get(key) if isinstance(table, dict) else None
    if not isinstance(table, dict) or (value is not None and not isinstance(value, str)):
        raise SystemExit(f"sphere: {path}: [paths] must be a table and {key} a string; fix the file "
                         f"([paths] {key} = \"/some/path\")")
    return Path(value).expanduser() if value else None


def broad_dir() -> Path:
    """The folder of BROAD trials.

    ``$SPHERE_BROAD_DIR``, else ``broad_dir`` in the ``[paths]`` table of ``~/.config/sphere-mouse/config.toml``,
    else ``../shared/data/broad`` beside a repository checkout, else ``~/.local/share/marg-sphere/broad``.
    """
    env = os.environ.get(BROAD_ENV)
    if env:
        return Path(env)
    from_config = configured("broad_dir")
    if from_config is not None:
        return from_config
    if in_checkout():
        return REPO_ROOT.parent / "shared" / "data" / "broad"
    return data_home() / "broad"

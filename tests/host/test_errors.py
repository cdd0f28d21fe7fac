"""One exception base: every error class the package defines for a person to read derives from
sphere.errors.SphereError (one ``except SphereError`` catches them all), and there is one LinkLost."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import sphere
from sphere.errors import LinkLost, SphereError

#: Exceptions that are not errors for a person: control flow inside the daemon.
NOT_ERRORS = {"sphere.daemon.sources.base.SourceEnded"}
#: Optional dependencies a module may need at import (the module is skipped without them).
OPTIONAL = ("cv2", "Xlib", "evdev", "websockets", "pynput", "hid", "pythonosc", "matplotlib", "vqf", "imufusion", "ahrs")


def exception_classes():
    for info in pkgutil.walk_packages(sphere.__path__, "sphere."):
        try:
            module = importlib.import_module(info.name)
        except ImportError as e:
            if e.name and e.name.split(".")[0] in OPTIONAL:
                continue
            raise
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if cls.__module__ == info.name and issubclass(cls, BaseException):
                yield f"{info.name}.{cls.__qualname__}", cls


def test_every_error_is_a_sphere_error():
    found = dict(exception_classes())
    assert len(found) >= 20  # the walk found the package's errors
    outside = sorted(name for name, cls in found.items() if not issubclass(cls, SphereError) and name not in NOT_ERRORS)
    assert not outside, f"derive these from sphere.errors.SphereError: {outside}"


def test_builtin_kinds_are_kept_for_callers_that_catch_them():
    from sphere.broad import BroadMissing
    from sphere.link.device_settings import SettingError
    from sphere.protocol.framing import FrameTooLong

    assert issubclass(BroadMissing, FileNotFoundError) and issubclass(SettingError, ValueError)
    assert issubclass(FrameTooLong, ValueError)


def test_one_link_lost():
    from sphere.daemon.sources import base
    from sphere.link import device

    assert base.LinkLost is LinkLost and device.LinkLost is LinkLost
    assert [name for name, _ in exception_classes() if name.endswith(".LinkLost")] == ["sphere.errors.LinkLost"]

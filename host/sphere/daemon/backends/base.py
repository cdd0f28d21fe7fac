"""The backend interface (see :mod:`sphere.daemon.backends`)."""

from __future__ import annotations

from sphere.errors import SphereError

BUTTONS = ("left", "right", "middle")


class BackendUnavailable(SphereError):
    """This backend cannot start here; the message says why and what to do."""


class BackendLost(SphereError):
    """Where the moves went is gone during the run (the X server closed the connection: the session ended or X
    restarted); the daemon stops with one line saying so, exit status 1."""


class Backend:
    NAME = "base"
    #: the settings of ``[backend.NAME]`` (sphere.settings.Param); none for most backends
    PARAMS: dict = {}

    @classmethod
    def from_settings(cls, settings, stream=None) -> "Backend":
        """The backend from its settings; ``stream`` is where a backend that prints (``log``) writes."""
        return cls(**settings.as_dict())

    def move(self, dx: int, dy: int) -> None:
        raise NotImplementedError

    def press(self, button: str) -> None:
        raise NotImplementedError

    def release(self, button: str) -> None:
        raise NotImplementedError

    def click(self, button: str = "left", count: int = 1) -> None:
        for _ in range(count):
            self.press(button)
            self.release(button)

    def move_to(self, x: int, y: int) -> None:
        """Absolute position; backends that cannot do it ignore it."""

    def screen_size(self):
        """(width, height) in pixels, or None when the backend cannot know."""
        return None

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

"""``sphere-mouse --print-config``: every setting with its default, as a commented config file.

The text is valid TOML that loads to the defaults (tests/host/test_print_config.py checks that); each key
has its meaning and allowed values in the comment above it, so a user copies it to
~/.config/sphere-mouse/config.toml and changes what they want.
"""

from __future__ import annotations

import json
import textwrap

from sphere import __version__
from sphere.daemon import config


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # a TOML basic string is a JSON string
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def defaults_toml(path_hint: str = "~/.config/sphere-mouse/config.toml") -> str:
    out = [f"# sphere-mouse {__version__}: every setting with its default (sphere-mouse --print-config).",
           f"# Copy to {path_hint}, keep the keys you change, delete the rest.",
           "# Reference with examples: host/docs/sphere-mouse.md", ""]
    for name, spec in config.sections().items():
        out.append(f"[{name}]")
        for key, p in spec.params.items():
            doc = p.describe()
            choices = p.allowed()
            if choices:
                doc += " — one of: " + ", ".join(str(c) for c in choices)
            for line in textwrap.wrap(doc, 100) or [""]:
                out.append(f"# {line}".rstrip())
            out.append(f"{key} = {_toml_value(p.default)}")
        out.append("")
    return "\n".join(out)

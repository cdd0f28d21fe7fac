"""Registries name their entries as ``"module:attribute"`` strings, imported on first use: a registry line
costs no import (and no import cycle) until the entry is asked for."""

from __future__ import annotations

import importlib


def load(spec: str):
    """The object a ``"package.module:attribute"`` string names."""
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)

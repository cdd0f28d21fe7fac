"""Subcommands of `sphere`; each module here is one subcommand (see :mod:`sphere.cli`)."""

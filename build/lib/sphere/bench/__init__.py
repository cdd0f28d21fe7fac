"""Benchmarks: each module here is a `sphere bench NAME` and defines HELP, add_arguments, run."""

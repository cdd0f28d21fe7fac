"""Per-sample smoothing filters against jitter and tremor (seed digest §8, the 1€ filter, JoyShockMapper's
tiered smoothing, and a tremor band-stop), all by name from :mod:`sphere.smoothing.registry`.

Every filter has the same shape: ``update(x, dt_s) -> y`` for one sample of a vector signal and
``reset()``, with its ``NAME`` and its parameters (default, unit, range) in ``PARAMS``. They hold no I/O.
The daemon's pointer (:class:`sphere.daemon.pointer.PointerMapper`, on the pointer's angles in degrees),
its 3-D page (on the pose) and `sphere bench pointer` (which runs the daemon's own packet path) all take
them from the registry, chosen by the config keys ``pointer.smoothing`` and ``stream.smoothing``; their
parameters are the sections ``[smoothing.NAME]``. This package imports none of them.
"""

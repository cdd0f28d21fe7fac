"""The virtual sphere's host side: motion traces for the simulated board (hardware/sim) and running it.

- :mod:`sphere.sim.trace` — motion in physical units (BROAD trials, synthetic motions) resampled to
  the chips' output rates, converted to chip units with :mod:`sphere.chips`, written as the board's
  trace file.
- :mod:`sphere.sim.board` — build and run ``hardware/sim/build/sphere-board`` on a firmware image.
"""

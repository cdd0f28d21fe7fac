"""Calibration of the sphere's three sensors (``sphere calibrate``): the fits (:mod:`.fit`: gyro bias,
accelerometer six-position, magnetometer ellipsoid), what the guided session waits for (:mod:`.session`) and the
axis check (:mod:`.axis_check`). Pure functions on arrays; the command does the I/O."""

"""Orientation filters. Every filter has per-sample ``update(gyr_rad_s, acc_m_s2, mag_uT, dt_s)``
(``mag_uT=None`` when absent), ``.quat`` (w, x, y, z, sensor-to-earth), ``update_batch(gyr, acc, mag, dt_s)``
returning (N, 4), and a class attribute ``earth_frame`` ("NWU" or "ENU").

- :mod:`sphere.fusion.madgwick` — Madgwick MARG, double precision, the firmware's reference (NWU).
- :mod:`sphere.fusion.kalman` — the dissertation's quaternion Kalman filter (NWU).
- :mod:`sphere.fusion.sphere_filter` — our best filter, :class:`SphereFilter` (ENU).
- :mod:`sphere.fusion.hybrid` — chapter 3's hybrid CV + sensor-fusion tracker.
- :mod:`sphere.fusion.peers` — adapters for published filters (VQF, x-io Fusion, ahrs).
"""

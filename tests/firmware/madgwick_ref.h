// Double-precision reference of the Madgwick MARG update, a line-by-line port of
// host/sphere/fusion/madgwick.py (madgwick_step): the definition the fixed-point MargFilter follows.
#pragma once
#include <cmath>

struct MadgwickRef {
    double q[4] = {1, 0, 0, 0};
    double beta = 0.041;

    void update(double gx, double gy, double gz, double ax, double ay, double az, double mx, double my, double mz,
                double dt, bool acc_valid, bool mag_valid) {
        double q0 = q[0], q1 = q[1], q2 = q[2], q3 = q[3];
        double d0 = 0.5 * (-q1 * gx - q2 * gy - q3 * gz);
        double d1 = 0.5 * (q0 * gx + q2 * gz - q3 * gy);
        double d2 = 0.5 * (q0 * gy - q1 * gz + q3 * gx);
        double d3 = 0.5 * (q0 * gz + q1 * gy - q2 * gx);
        if (acc_valid && !(ax == 0.0 && ay == 0.0 && az == 0.0)) {
            double n = 1.0 / std::sqrt(ax * ax + ay * ay + az * az);
            ax *= n; ay *= n; az *= n;
            double fg0 = 2.0 * (q1 * q3 - q0 * q2) - ax;
            double fg1 = 2.0 * (q0 * q1 + q2 * q3) - ay;
            double fg2 = 2.0 * (0.5 - q1 * q1 - q2 * q2) - az;
            double s0 = -2.0 * q2 * fg0 + 2.0 * q1 * fg1;
            double s1 = 2.0 * q3 * fg0 + 2.0 * q0 * fg1 - 4.0 * q1 * fg2;
            double s2 = -2.0 * q0 * fg0 + 2.0 * q3 * fg1 - 4.0 * q2 * fg2;
            double s3 = 2.0 * q1 * fg0 + 2.0 * q2 * fg1;
            if (mag_valid && !(mx == 0.0 && my == 0.0 && mz == 0.0)) {
                n = 1.0 / std::sqrt(mx * mx + my * my + mz * mz);
                mx *= n; my *= n; mz *= n;
                double hx = 2.0 * (mx * (0.5 - q2 * q2 - q3 * q3) + my * (q1 * q2 - q0 * q3) + mz * (q1 * q3 + q0 * q2));
                double hy = 2.0 * (mx * (q1 * q2 + q0 * q3) + my * (0.5 - q1 * q1 - q3 * q3) + mz * (q2 * q3 - q0 * q1));
                double hz = 2.0 * (mx * (q1 * q3 - q0 * q2) + my * (q2 * q3 + q0 * q1) + mz * (0.5 - q1 * q1 - q2 * q2));
                double bx = std::sqrt(hx * hx + hy * hy), bz = hz;
                double fb0 = 2.0 * bx * (0.5 - q2 * q2 - q3 * q3) + 2.0 * bz * (q1 * q3 - q0 * q2) - mx;
                double fb1 = 2.0 * bx * (q1 * q2 - q0 * q3) + 2.0 * bz * (q0 * q1 + q2 * q3) - my;
                double fb2 = 2.0 * bx * (q0 * q2 + q1 * q3) + 2.0 * bz * (0.5 - q1 * q1 - q2 * q2) - mz;
                s0 += -2.0 * bz * q2 * fb0 + (-2.0 * bx * q3 + 2.0 * bz * q1) * fb1 + 2.0 * bx * q2 * fb2;
                s1 += 2.0 * bz * q3 * fb0 + (2.0 * bx * q2 + 2.0 * bz * q0) * fb1 + (2.0 * bx * q3 - 4.0 * bz * q1) * fb2;
                s2 += (-4.0 * bx * q2 - 2.0 * bz * q0) * fb0 + (2.0 * bx * q1 + 2.0 * bz * q3) * fb1 +
                      (2.0 * bx * q0 - 4.0 * bz * q2) * fb2;
                s3 += (-4.0 * bx * q3 + 2.0 * bz * q1) * fb0 + (-2.0 * bx * q0 + 2.0 * bz * q2) * fb1 + 2.0 * bx * q1 * fb2;
            }
            double ns = std::sqrt(s0 * s0 + s1 * s1 + s2 * s2 + s3 * s3);
            if (ns > 0.0) {
                ns = beta / ns;
                d0 -= ns * s0; d1 -= ns * s1; d2 -= ns * s2; d3 -= ns * s3;
            }
        }
        q0 += d0 * dt; q1 += d1 * dt; q2 += d2 * dt; q3 += d3 * dt;
        double n = 1.0 / std::sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3);
        q[0] = q0 * n; q[1] = q1 * n; q[2] = q2 * n; q[3] = q3 * n;
    }
};

// Angle in degrees between two orientations (sign of q ignored).
inline double quatAngleDeg(const double a[4], const double b[4]) {
    double na = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + a[3] * a[3]);
    double nb = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2] + b[3] * b[3]);
    double d = std::fabs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]) / (na * nb);
    if (d > 1.0) d = 1.0;
    return 2.0 * std::acos(d) * 180.0 / M_PI;
}

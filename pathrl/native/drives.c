/* The drive-train loop of the calibrated controller model: a native build of
 * pathrl.industrial.drives.drive_loop_python (the reference; read pathrl.industrial.drives for the model). One
 * semi-implicit Euler step per sample, six axes, the operations in the reference's order (no fused multiply-add:
 * C99 contracts nothing unless told to), so both agree to rounding (the reference's 6x6 matrix-vector product
 * goes through BLAS, whose summation order may differ in the last bits; tanh is the C library's).
 *
 * Layout: th_r, thd_r, tau_ff, h (n, 6) and minv (n, 6, 6) row-major, at the integration rate; kp, kv, ki,
 * tau_max, k_gear, d_gear, b, fc, fv (6,); the state th, thd, q, qd, integ (6,) is read as the initial state
 * and left as the final one. Output q_out (n, 6): the link angles after each step.
 */
#include <math.h>
#include <stdint.h>

#define AXES 6

/* np.clip(x, lo, hi) = minimum(maximum(x, lo), hi), NaN propagating */
static inline double clip(double x, double lo, double hi) {
    if (isnan(x) || isnan(lo) || isnan(hi)) return NAN;
    double y = x > lo ? x : lo;
    return y < hi ? y : hi;
}

void pathrl_drive_loop(const double *th_r, const double *thd_r, const double *tau_ff, const double *h,
                       const double *minv, int64_t n, const double *kp, const double *kv, const double *ki,
                       const double *tau_max, const double *k_gear, const double *d_gear, const double *b,
                       const double *fc, const double *fv, double f_scale, double ff_vel, double dt, double *th,
                       double *thd, double *q, double *qd, double *integ, double *q_out) {
    double tau_s[AXES], load[AXES];
    for (int64_t k = 0; k < n; k++) {
        const double *row = minv + k * AXES * AXES;
        for (int j = 0; j < AXES; j++) {
            const int64_t i = k * AXES + j;
            const double ev = kp[j] * (th_r[i] - th[j]) + ff_vel * thd_r[i] - thd[j];
            integ[j] = integ[j] + ev * dt;
            const double tau_m = clip(kv[j] * ev + ki[j] * integ[j] + tau_ff[i], -tau_max[j], tau_max[j]);
            tau_s[j] = k_gear[j] * (th[j] - q[j]) + d_gear[j] * (thd[j] - qd[j]);
            const double fr = f_scale * (fc[j] * tanh(thd[j] / 0.01) + fv[j] * thd[j]);
            thd[j] = thd[j] + dt * (tau_m - tau_s[j] - fr) / b[j];
            load[j] = tau_s[j] - h[i];
        }
        for (int j = 0; j < AXES; j++) {
            double acc = 0.0;
            for (int c = 0; c < AXES; c++) acc += row[j * AXES + c] * load[c];
            qd[j] = qd[j] + dt * acc;
            th[j] = th[j] + dt * thd[j];
            q[j] = q[j] + dt * qd[j];
            q_out[k * AXES + j] = q[j];
        }
    }
}

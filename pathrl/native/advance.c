/* The env's step kernel, one env at a time: a native build of pathrl.envs.tracking.advance (the reference;
 * read it for the definitions). Integrates the step, measures the progress along the path as the polyline
 * length of `substeps` intermediate positions of the path joints, and their weighted distance to the
 * reference at the same arc length (linear interpolation in the path table, pathset.table_position).
 *
 * Layout: pos, vel, acc, a1 (N, D); path_index (M,); s, end_s (N,); path (N,) long; table (P, S, M);
 * length (P,); dev_weights (M,). Outputs p1, v1 (N, D); moved, dev_max, dev_mean (N,).
 */
#include <math.h>
#include <stdint.h>

#define MAX_PATH_JOINTS 64
#define MAX_SUBSTEPS 64

static inline double tmin(double a, double b) { return (isnan(a) || isnan(b)) ? NAN : (a < b ? a : b); }
static inline double tmax(double a, double b) { return (isnan(a) || isnan(b)) ? NAN : (a > b ? a : b); }

int pathrl_advance(const double *pos, const double *vel, const double *acc, const double *a1, int64_t row0,
                   int64_t row1, int64_t dof, const int64_t *path_index, int64_t m, const double *s,
                   const double *end_s, const int64_t *path, const double *table, int64_t n_s,
                   const double *length, const double *dev_weights, double dt, int64_t substeps, double table_step,
                   double *p1_out, double *v1_out, double *moved_out, double *dev_max_out, double *dev_mean_out) {
    if (m > MAX_PATH_JOINTS || substeps > MAX_SUBSTEPS || substeps < 1 || n_s < 2) return -1;
    double t[MAX_SUBSTEPS];
    for (int64_t k = 0; k < substeps; k++) t[k] = (double)(k + 1) * (dt / (double)substeps);
    for (int64_t r = row0; r < row1; r++) {
        const double *p0 = pos + r * dof, *v0 = vel + r * dof, *a0 = acc + r * dof, *a_end = a1 + r * dof;
        for (int64_t d = 0; d < dof; d++) {
            p1_out[r * dof + d] = p0[d] + v0[d] * dt + (a0[d] / 3.0 + a_end[d] / 6.0) * dt * dt;
            v1_out[r * dof + d] = v0[d] + 0.5 * (a0[d] + a_end[d]) * dt;
        }
        double prev[MAX_PATH_JOINTS], q[MAX_PATH_JOINTS], half_a[MAX_PATH_JOINTS], jerk[MAX_PATH_JOINTS];
        for (int64_t j = 0; j < m; j++) {
            int64_t d = path_index[j];
            prev[j] = p0[d];
            half_a[j] = 0.5 * a0[d];
            jerk[j] = (a_end[d] - a0[d]) / dt;
        }
        const double *rows = table + path[r] * n_s * m;
        double last = length[path[r]] / table_step;
        double cum = 0.0, dev_max = -INFINITY, dev_sum = 0.0, dev_weighted = 0.0;
        for (int64_t k = 0; k < substeps; k++) {
            double tk = t[k], seg = 0.0;
            double t2 = tk * tk, t3 = tk * tk * tk;
            for (int64_t j = 0; j < m; j++) {
                int64_t d = path_index[j];
                q[j] = p0[d] + v0[d] * tk + half_a[j] * t2 + jerk[j] * t3 / 6.0;
                double dq = q[j] - prev[j];
                seg += dq * dq;
                prev[j] = q[j];
            }
            seg = sqrt(seg);
            cum += seg;
            double x = tmin(s[r] + cum, end_s[r]) / table_step;
            x = tmin(x < 0.0 ? 0.0 : x, last);
            double f = floor(x);
            int64_t i0 = (int64_t)f;
            if (i0 > n_s - 2) i0 = n_s - 2;
            double w = x - (double)i0;
            const double *r0 = rows + i0 * m, *r1 = r0 + m;
            double dev = 0.0;
            for (int64_t j = 0; j < m; j++) {
                double e = (r0[j] + w * (r1[j] - r0[j]) - q[j]) * dev_weights[j];
                dev += e * e;
            }
            dev = sqrt(dev);
            dev_max = tmax(dev_max, dev);
            dev_sum += dev;
            dev_weighted += dev * seg;
        }
        moved_out[r] = cum;
        dev_max_out[r] = dev_max;
        dev_mean_out[r] = cum > 1e-12 ? dev_weighted / cum : dev_sum / (double)substeps;
    }
    return 0;
}

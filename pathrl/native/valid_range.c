/* Valid acceleration range, one element at a time: a native build of pathrl/limits/feasible.py.
 *
 * Each function below mirrors the torch function of the same name in feasible.py, _braking.py,
 * _knot.py and _velocity.py (read those for the derivations); the torch code is the reference and the
 * tests compare both. Where the torch code works on data-dependent subsets and masked iterations, this
 * code branches per element, so only the work an element needs is done.
 *
 * NaN semantics follow torch: minimum/maximum/clamp propagate NaN (tmin, tmax, cmin0 below), comparisons
 * with NaN are false. Build without -ffast-math: inf and NaN carry meaning here.
 *
 * Layout: p, v, a, lo, hi, overlap are (rows, dof) row-major; limits are per joint (dof). Side 0 bounds
 * from above; side 1 is the mirrored joint (-p, -v, -a, limit -pos_lo), whose upper bound is minus the
 * lower bound.
 */
#include <math.h>
#include <stddef.h>
#include <stdint.h>

#define SETTLE 0.01        /* feasible.SETTLE_FACTOR */
#define CONFLICT_TOL 1e-3  /* feasible.CONFLICT_TOL */
#define OUTSIDE_TOL 1e-9   /* feasible.OUTSIDE_TOL */
#define KNOT_SLACK 0.3     /* feasible.KNOT_SLACK */
#define VEL_SKIP_MARGIN 0.25
#define PLAN_MARGIN 1e-10
#define NEWTON_TOL 1e-13
#define NEWTON_MAX_ITER 60 /* _braking.descend, a multiple of UNROLL */
#define BRACKET_XTOL 1e-7
#define BRACKET_MAX_ITER 16

static inline double tmin(double a, double b) { return (isnan(a) || isnan(b)) ? NAN : (a < b ? a : b); }
static inline double tmax(double a, double b) { return (isnan(a) || isnan(b)) ? NAN : (a > b ? a : b); }
static inline double cmin0(double x) { return x < 0.0 ? 0.0 : x; }         /* clamp_min(0), NaN kept */
static inline double cmin(double x, double lo) { return x < lo ? lo : x; }  /* clamp_min(lo), NaN kept */
static inline double clampd(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }

typedef struct {
    double p, v, a, pmax, amax, jmax, vmax;
} Side;

typedef struct {
    double value, slope, time;
    int phase;
    double ramp;
} Peak;

/* ------------------------------------------------------------------ _velocity.py */

static double velocity_bound(double v0, double a0, double vmax, double amax, double jmax, double dt,
                             double settle) {
    double c = v0 + 0.5 * a0 * dt;
    double room = vmax - v0;
    int tiny = (fabs(a0) < 1e-8) || ((fabs(room) < 1e-8) && (a0 <= 0.0));
    double safe_room = a0 > 0.0 ? cmin(room, 1e-300) : (tiny ? 1.0 : room);
    double in_step = tiny ? 0.0 : a0 * (1.0 - 0.5 * a0 * dt / safe_room);
    double gap = cmin0(vmax - c);
    double tau = 0.5 * dt + sqrt(0.25 * dt * dt + 2.0 * gap / jmax);
    double ramp = jmax * (tau - dt);
    double q = tau / dt;
    double n = cmin(ceil(q) - 1.0, 1.0);
    double a_pin = -settle * amax;
    int pinned = (ceil(q) > q) && (ramp - jmax * dt * n < a_pin);
    double w = vmax - c - jmax * dt * dt * n * (n - 1.0) / 2.0;
    double root;
    if (settle > 0.0) {
        double b = dt * (n - 0.5) * a_pin + w;
        double s = sqrt(cmin0(b * b - 4.0 * n * dt * w * a_pin));
        root = b >= 0.0 ? (b + s) / (2.0 * n * dt) : -2.0 * w * a_pin / (s - b);
    } else {
        root = w / (n * dt);
    }
    if (pinned) ramp = root + jmax * dt * (n - 1.0);
    return c >= vmax ? in_step : ramp;
}

static int velocity_emergency(double v0, double a0, double vmax, double amax, double dt) {
    double overshoot = 0.5 * a0 * a0 * dt / (a0 + amax);
    return (a0 > 0.0) && (v0 - 1e-8 > vmax - overshoot);
}

static double velocity_floor(double v, double a, double vmax, double amax, double jmax, double dt,
                             double settle) {
    double floor_ = -velocity_bound(-v, -a, vmax, amax, jmax, dt, settle);
    return velocity_emergency(-v, -a, vmax, amax, dt) ? amax : floor_;
}

/* ------------------------------------------------------------------ _braking.py */

static double last_down_crossing(double v, double a, double k) {
    double disc = a * a + 2.0 * k * v;
    double s = sqrt(cmin0(disc));
    double w = a >= 0.0 ? (a + s) / k : 2.0 * v / (s - a);
    return disc >= 0.0 ? w : NAN;
}

static double in_step_bound(const Side *s, double dt) {
    double room = cmin0(s->pmax - s->p);
    double disc = 4.0 * s->v * s->v + 6.0 * s->a * room;
    double q = -(2.0 * s->v + (s->v >= 0.0 ? 1.0 : -1.0) * sqrt(cmin0(disc)));
    double best = INFINITY;
    double taus[2] = {q / s->a, -6.0 * room / q};
    for (int i = 0; i < 2; i++) {
        double tau = taus[i];
        double x = s->a - 2.0 * dt * (s->v + s->a * tau) / (tau * tau);
        int turning = s->a + (x - s->a) * tau / dt < 0.0;
        if ((disc >= 0.0) && (tau > 0.0) && (tau < dt) && turning && (x < best)) best = x;
    }
    return (room == 0.0 && s->v > 1e-9) ? -INFINITY : best;
}

static Peak greedy_peak(double x, const Side *s, double dt) {
    double amax = s->amax, jmax = s->jmax;
    double p1 = s->p + s->v * dt + (s->a / 3.0 + x / 6.0) * dt * dt;
    double v1 = s->v + 0.5 * (s->a + x) * dt;
    double dp1 = dt * dt / 6.0, dv1 = 0.5 * dt;

    double m = cmin0(floor((x + amax) / (jmax * dt)));
    double tr = m * dt;
    double ur = last_down_crossing(v1, x, jmax);
    int in_r = (ur >= 0.0) && (ur <= tr);
    if (!in_r) ur = 0.0;
    double f_r = p1 + v1 * ur + 0.5 * x * ur * ur - jmax * ur * ur * ur / 6.0;
    double g_r = dp1 + dv1 * ur + 0.5 * ur * ur;
    double a_r = x - jmax * tr;
    double v_r = v1 + x * tr - 0.5 * jmax * tr * tr;
    double p_r = p1 + v1 * tr + 0.5 * x * tr * tr - jmax * tr * tr * tr / 6.0;
    double dv_r = dv1 + tr;
    double dp_r = dp1 + dv1 * tr + 0.5 * tr * tr;

    double k = (a_r + amax) / dt;
    double wp = last_down_crossing(v_r, a_r, k);
    int in_p = (wp >= 0.0) && (wp <= dt) && !in_r;
    if (!in_p) wp = 0.0;
    double f_p = p_r + v_r * wp + 0.5 * a_r * wp * wp - k * wp * wp * wp / 6.0;
    double g_p = dp_r + dv_r * wp + 0.5 * wp * wp - wp * wp * wp / (6.0 * dt);

    double v_h = v_r + 0.5 * (a_r - amax) * dt;
    double p_h = p_r + v_r * dt + (a_r / 3.0 - amax / 6.0) * dt * dt;
    int in_h = (v_h > 0.0) && !in_r && !in_p;
    double vh = cmin0(v_h);
    double f_h = p_h + vh * vh / (2.0 * amax);
    double g_h = dp_r + dv_r * dt + dt * dt / 3.0 + vh * (dv_r + 0.5 * dt) / amax;

    Peak pk;
    pk.value = in_r ? f_r : (in_p ? f_p : (in_h ? f_h : p1));
    pk.slope = in_r ? g_r : (in_p ? g_p : (in_h ? g_h : dp1));
    pk.time = dt + (in_r ? ur : (in_p ? tr + wp : (in_h ? tr + dt + vh / amax : 0.0)));
    pk.phase = in_r ? 1 : (in_p ? 2 : (in_h ? 3 : 0));
    pk.ramp = m;
    if (pk.value < p1) { /* velocity negative right after the step: the step end is the highest point */
        pk.value = p1;
        pk.slope = dp1;
        pk.time = dt;
        pk.phase = 0;
    }
    return pk;
}

static void greedy_state(double x, const Side *s, double dt, double t, double *pos, double *vel, double *acc) {
    double amax = s->amax, jmax = s->jmax;
    double p1 = s->p + s->v * dt + (s->a / 3.0 + x / 6.0) * dt * dt;
    double v1 = s->v + 0.5 * (s->a + x) * dt;
    double m = cmin0(floor((x + amax) / (jmax * dt)));
    double u = cmin0(t - dt);
    double ur = tmin(u, m * dt);
    double a_r = x - jmax * ur;
    double v_r = v1 + x * ur - 0.5 * jmax * ur * ur;
    double p_r = p1 + v1 * ur + 0.5 * x * ur * ur - jmax * ur * ur * ur / 6.0;
    double v_h = v_r + 0.5 * (a_r - amax) * dt;
    double p_h = p_r + v_r * dt + (a_r / 3.0 - amax / 6.0) * dt * dt;
    double w = cmin0(u - (m + 1.0) * dt);
    int hold = u >= (m + 1.0) * dt - 1e-12;
    *pos = hold ? p_h + v_h * w - 0.5 * amax * w * w : p_r;
    *vel = hold ? v_h - amax * w : v_r;
    *acc = hold ? -amax : a_r;
}

static double velocity_aware_peak(double x, const Side *s, double dt, const Peak *peak, double settle) {
    double start = dt + cmin0(floor((peak->time - dt) / dt - 1e-12)) * dt;
    double ps, vs, a_s;
    greedy_state(x, s, dt, start, &ps, &vs, &a_s);
    double greedy_end = tmax(a_s - s->jmax * dt, -s->amax);
    double end = tmax(greedy_end, velocity_floor(vs, a_s, s->vmax, s->amax, s->jmax, dt, settle));
    double w = last_down_crossing(vs, a_s, -(end - a_s) / dt);
    int inside = (w >= 0.0) && (w <= dt);
    if (!inside) w = dt;
    double value = ps + vs * w + 0.5 * a_s * w * w + (end - a_s) * w * w * w / (6.0 * dt);
    int raised = (end > greedy_end) && (peak->phase > 0);
    return raised ? tmax(value, peak->value) : peak->value;
}

/* The velocity-aware peak and the greedy slope (_braking._aware_value). */
static double aware_value(double x, const Side *s, double dt, double *slope) {
    Peak pk = greedy_peak(x, s, dt);
    if (slope) *slope = pk.slope;
    return velocity_aware_peak(x, s, dt, &pk, SETTLE);
}

static void hold_state(const Side *s, double dt, double tr, double x, double *ph, double *vh) {
    double v1 = s->v + 0.5 * (s->a + x) * dt;
    double p1 = s->p + s->v * dt + (s->a / 3.0 + x / 6.0) * dt * dt;
    double a_r = x - s->jmax * tr;
    double v_r = v1 + x * tr - 0.5 * s->jmax * tr * tr;
    double p_r = p1 + v1 * tr + 0.5 * x * tr * tr - s->jmax * tr * tr * tr / 6.0;
    *ph = p_r + v_r * dt + (a_r / 3.0 - s->amax / 6.0) * dt * dt;
    *vh = v_r + 0.5 * (a_r - s->amax) * dt;
}

static double hold_root(const Side *s, double dt, double ramp, double *v_h) {
    double tr = ramp * dt;
    double pz, vz, po, vo;
    hold_state(s, dt, tr, 0.0, &pz, &vz);
    hold_state(s, dt, tr, 1.0, &po, &vo);
    double dp = po - pz, dv = vo - vz;
    double qa = dv * dv / (2.0 * s->amax), qb = dp + vz * dv / s->amax;
    double qc = pz + vz * vz / (2.0 * s->amax) - s->pmax;
    double x = (-qb + sqrt(cmin0(qb * qb - 4.0 * qa * qc))) / (2.0 * qa);
    *v_h = vz + dv * x;
    return x;
}

/* Newton's method on the greedy peak from `x` (_braking.descend). */
static double descend(double x, const Side *s, double dt) {
    for (int it = 0; it < NEWTON_MAX_ITER; it++) {
        Peak pk = greedy_peak(x, s, dt);
        double r = pk.value - s->pmax;
        if (!(fabs(r) > NEWTON_TOL)) break;
        x = x - r / pk.slope;
    }
    return x;
}

/* Root of greedy_peak(x) = pmax below `probe`: hold-phase closed forms, else Newton (_braking.greedy_root). */
static double greedy_root(const Side *s, double dt, double probe) {
    /* Structures m > floor((probe + amax) / (jmax dt)) cannot fit a root x <= probe. */
    double most = cmin0(floor((probe + s->amax) / (s->jmax * dt)));
    double start = probe;
    for (double m = 0.0; m == 0.0 || m <= most; m += 1.0) {
        double v_h;
        double x = hold_root(s, dt, m, &v_h);
        if (m == 0.0) start = (isfinite(x) && x < probe) ? x : probe;
        if ((v_h > 0.0) && (cmin0(floor((x + s->amax) / (s->jmax * dt))) == m) && (x <= probe)) return x;
    }
    return descend(start, s, dt);
}

/* Largest x <= hi with aware_value(x) <= pmax (_braking.bracket_below): doubling steps down, then
 * Illinois regula falsi with a bisection fallback. */
static double bracket_below(double hi, const Side *s, double dt) {
    double slope;
    double r_hi = aware_value(hi, s, dt, &slope) - s->pmax;
    double step = r_hi / slope;
    double lo = hi - step;
    double r_lo = aware_value(lo, s, dt, NULL) - s->pmax;
    for (int it = 0; it < BRACKET_MAX_ITER; it++) {
        if (!(r_lo > 0.0)) break;
        step = 2.0 * step;
        hi = lo;
        r_hi = r_lo;
        lo = hi - step;
        r_lo = aware_value(lo, s, dt, NULL) - s->pmax;
    }
    int keep_hi = 0, keep_lo = 0;
    for (int it = 0; it < BRACKET_MAX_ITER; it++) {
        if (!((hi - lo) > BRACKET_XTOL * (1.0 + fabs(lo)))) break;
        double w_hi = (keep_hi ? 0.5 : 1.0) * r_hi;
        double w_lo = (keep_lo ? 0.5 : 1.0) * r_lo;
        double x = hi - w_hi * (hi - lo) / (w_hi - w_lo);
        if (!((x > lo) && (x < hi))) x = 0.5 * (lo + hi);
        double r = aware_value(x, s, dt, NULL) - s->pmax;
        int up = r > 0.0;
        if (up) {
            hi = x;
            r_hi = r;
        } else {
            lo = x;
            r_lo = r;
        }
        keep_hi = !up;
        keep_lo = up;
    }
    return lo;
}

/* Upper bound on the greedy braking peak for every x <= x_probe (_braking.reach_top). */
static double ramp_reach(double v, double a, double amax, double jmax) {
    double tr = cmin0(a + amax) / jmax;
    double u = last_down_crossing(v, a, jmax);
    int in_ramp = (u >= 0.0) && (u <= tr);
    if (!in_ramp) u = tr;
    double v_r = v + a * u - 0.5 * jmax * u * u;
    double reach = v * u + 0.5 * a * u * u - jmax * u * u * u / 6.0;
    double vr0 = cmin0(v_r);
    return cmin0(reach + (in_ramp ? 0.0 : vr0 * vr0 / (2.0 * amax)));
}

static double reach_top(double p0, double v0, double a0, double amax, double jmax, double dt, double x) {
    double g2 = tmax(x - jmax * dt, -amax);
    double p1 = p0 + v0 * dt + (a0 / 3.0 + x / 6.0) * dt * dt;
    double v1 = v0 + 0.5 * (a0 + x) * dt;
    double p2 = p1 + v1 * dt + (x / 3.0 + g2 / 6.0) * dt * dt;
    double v2 = v1 + 0.5 * (x + g2) * dt;
    double top1 = p0 + cmin0(v0) * dt + 0.5 * cmin0(tmax(a0, x)) * dt * dt;
    double top2 = p1 + cmin0(v1) * dt + 0.5 * cmin0(x) * dt * dt;
    double p3 = p2 + v2 * dt + 0.5 * g2 * dt * dt;
    double v3 = v2 + g2 * dt;
    int stops = (g2 < 0.0) && (v2 > 0.0) && (v3 <= 0.0);
    double top3 = stops ? p2 + v2 * v2 / cmin(-2.0 * g2, 1e-300) : p3 + ramp_reach(v3, g2, amax, jmax);
    if ((v2 <= 0.0) && (g2 <= 0.0)) top3 = p2;
    return tmax(tmax(top1, top2), tmax(tmax(p1, p2), top3));
}

/* ------------------------------------------------------------------ _knot.py */

static double knot_solve(const Side *s, double dt, double stop, double turn, double ramp) {
    double big_t = dt, jm = s->jmax, am = s->amax;
    double n_r = cmin0(tmin(turn, ramp + 1.0) - 1.0);
    double n_h = turn - 1.0 - n_r;
    double on_ramp = turn <= ramp + 1.0 ? 1.0 : 0.0;
    double turn_const = turn <= ramp + 1.0 ? -jm * big_t * (turn - 1.0) : -am;
    double up = stop - turn;
    double s1 = n_r * (n_r + 1.0) / 2.0, s2 = n_r * (n_r + 1.0) * (2.0 * n_r + 1.0) / 6.0;
    double hold_sum = (2.0 + n_r + turn) * n_h / 2.0;
    double t2 = big_t * big_t, t3 = big_t * big_t * big_t;
    double up_v = big_t * (up - 0.5), up_p = t2 * ((up - 1.0) * up / 2.0 + 1.0 / 6.0);
    double up_vc = jm * t2 * (up - 1.0) * (up - 1.0) / 2.0;
    double up_pc = jm * t3 * (up - 1.0) * (up - 1.0) * (up - 1.0) / 6.0;
    double av = big_t * (1.0 + n_r) + on_ramp * up_v;
    double ap = t2 * ((stop - 1.0) * (1.0 + n_r) - s1) + on_ramp * up_p;
    double bv = big_t * up_v, bp = big_t * up_p;
    double cv = s->v + 0.5 * big_t * s->a - jm * t2 * s1 - am * big_t * n_h + turn_const * up_v + up_vc;
    double cp = s->p + s->v * stop * big_t + t2 * s->a * (1.0 / 3.0 + 0.5 * (stop - 1.0))
                + jm * t3 * (s2 - (stop - 1.0) * s1) - am * t2 * (n_h * stop - hold_sum)
                + turn_const * up_p + up_pc;
    double det = av * bp - bv * ap;
    double rhs = s->pmax - cp;
    double x = (-cv * bp - bv * rhs) / det;
    double j = (av * rhs + cv * ap) / det;
    double a_turn = on_ramp * x + turn_const;
    double a_ramp = x - jm * big_t * ramp;
    double tol = 1e-6;
    int ok = (fabs(j) <= jm + 1e-4) && (a_turn > -am - tol) && (a_turn + j * big_t > -am - tol);
    ok = ok && (a_ramp > -am - tol) && ((turn <= ramp + 1.0) || (a_ramp + am <= jm * big_t * (1.0 + 1e-6)));
    ok = ok && (x > s->a - jm * big_t - tol) && (turn >= 1.0) && (turn < stop) && (det != 0.0);
    return ok ? x : NAN;
}

static double knot_stop_bound(const Side *s, double dt, const Peak *peak) {
    if (!((peak->time > dt + 1e-8) && (peak->phase > 0))) return INFINITY;
    double m = peak->ramp;
    int phase = peak->phase;
    double time = peak->time;
    if (phase == 2) {
        double v_h;
        hold_root(s, dt, m, &v_h);
        time = 2.0 * dt + m * dt + v_h / s->amax;
    }
    double stop = cmin(ceil(time / dt), 2.0);
    double lowest = cmin(stop - floor(s->amax / (s->jmax * dt)) - 1.0, 1.0);
    double fewer = cmin0(m - 1.0);
    /* (ramp structure, first turning knot, last turning knot, applies) in klimits' order */
    double ramps[4] = {fewer, m, fewer, m};
    double firsts[4] = {stop - 1.0, stop - 1.0, stop - 1.0, tmin(stop - 1.0, phase == 1 ? stop : m + 1.0)};
    double lasts[4] = {m + 1.0, m + 2.0, m + 1.0, lowest};
    int applies[4] = {(phase == 2) && (m >= 1.0), phase == 3, (phase == 3) && (m >= 1.0), phase > 0};
    for (int k = 0; k < 4; k++) {
        if (!applies[k]) continue;
        double last = tmax(lasts[k], lowest);
        for (double turn = firsts[k]; turn >= last; turn -= 1.0) {
            double x = knot_solve(s, dt, stop, turn, ramps[k]);
            if (!isnan(x)) return x;
        }
    }
    return INFINITY;
}

/* ------------------------------------------------------------------ feasible.py */

/* Safe and knot-refined position bounds of one side-element that passed the reach_top filter
 * (feasible._position_subset). */
static void position_subset(Side s, double dt, double probe, int stop_at_knot, double *safe_out,
                            double *knot_out) {
    double inside = in_step_bound(&s, dt);
    s.pmax = s.pmax - PLAN_MARGIN;
    double floor_at_rest = velocity_floor(0.0, -s.amax, s.vmax, s.amax, s.jmax, dt, SETTLE);
    int aware = floor_at_rest > -s.amax;
    double plain = INFINITY, after_safe = INFINITY, knot = INFINITY;
    Peak probe_peak = greedy_peak(probe, &s, dt);
    int solved = probe_peak.value > s.pmax;
    Peak peak;
    if (solved) {
        double root = greedy_root(&s, dt, probe);
        peak = greedy_peak(root, &s, dt);
        double safe = root;
        if (aware && velocity_aware_peak(root, &s, dt, &peak, SETTLE) > s.pmax + 1e-13)
            safe = bracket_below(root, &s, dt);
        plain = root;
        after_safe = safe;
    }
    int outside = s.p > s.pmax + PLAN_MARGIN + OUTSIDE_TOL;
    double recover = 6.0 * (s.pmax - s.p - s.v * dt) / (dt * dt) - 2.0 * s.a;
    plain = outside ? recover : tmin(inside, plain);
    if (!stop_at_knot) {
        *safe_out = plain;
        *knot_out = plain;
        return;
    }
    double safe_all = outside ? recover : tmin(inside, after_safe);
    if (solved) knot = knot_stop_bound(&s, dt, &peak);
    *safe_out = safe_all;
    *knot_out = outside ? safe_all : tmin(knot, safe_all);
}

/* Velocity upper bound of one side-element (+inf where it cannot bind) and its emergency flag. */
static double velocity_side(double v0, double a0, double vmax, double amax, double jmax, double dt, int *urgent) {
    double c = v0 + 0.5 * dt * a0;
    double skip_below = vmax - 0.5 * (amax * dt + amax * amax / jmax) - VEL_SKIP_MARGIN * amax * dt;
    *urgent = 0;
    if (!(c > skip_below)) return INFINITY;
    *urgent = velocity_emergency(v0, a0, vmax, amax, dt);
    return velocity_bound(v0, a0, vmax, amax, jmax, dt, SETTLE);
}

/* Rows [row0, row1) of the valid range. pos_lim is (dof, 2); radius (dof,) is feasible._reach_radius. */
void pathrl_valid_range(const double *p, const double *v, const double *a, int64_t row0, int64_t row1,
                        int64_t dof, const double *pos_lim, const double *vel, const double *acc,
                        const double *jerk, const double *radius, double dt, int stop_at_knot, double *lo_out,
                        double *hi_out, uint8_t *overlap_out) {
    for (int64_t r = row0; r < row1; r++) {
        for (int64_t d = 0; d < dof; d++) {
            int64_t i = r * dof + d;
            double amax = acc[d], jmax = jerk[d], vmax = vel[d];
            double ps[2] = {p[i], -p[i]}, vs[2] = {v[i], -v[i]}, as[2] = {a[i], -a[i]};
            double pm[2] = {pos_lim[2 * d + 1], -pos_lim[2 * d]};
            double jerk_hi[2], vel_hi[2], pos_hi[2], knot_hi[2];
            int urgent[2];
            for (int k = 0; k < 2; k++) {
                jerk_hi[k] = as[k] + jmax * dt;
                vel_hi[k] = velocity_side(vs[k], as[k], vmax, amax, jmax, dt, &urgent[k]);
            }
            for (int k = 0; k < 2; k++) { /* the other side must brake: klimits leaves +acc here */
                if (urgent[1 - k]) vel_hi[k] = amax;
            }
            for (int k = 0; k < 2; k++) {
                if (urgent[k]) vel_hi[k] = -amax;
            }
            for (int k = 0; k < 2; k++) {
                pos_hi[k] = INFINITY;
                knot_hi[k] = INFINITY;
                if (!((pm[k] - ps[k]) <= radius[d])) continue;
                double cap = tmin(tmin(jerk_hi[k], vel_hi[k]), amax);
                double probe = cap + KNOT_SLACK * amax;
                if (!(reach_top(ps[k], vs[k], as[k], amax, jmax, dt, probe) >= pm[k] - 1e-9)) continue;
                Side s = {ps[k], vs[k], as[k], pm[k], amax, jmax, vmax};
                position_subset(s, dt, probe, stop_at_knot, &pos_hi[k], &knot_hi[k]);
            }
            /* feasible._combine */
            double lo_k = -knot_hi[1], hi_k = knot_hi[0];
            int crossed = lo_k > hi_k;
            double mid = 0.5 * (lo_k + hi_k);
            int refine = lo_k - hi_k < CONFLICT_TOL;
            double lo_p = refine ? (crossed ? mid : lo_k) : -pos_hi[1];
            double hi_p = refine ? (crossed ? mid : hi_k) : pos_hi[0];
            double lo_v = -vel_hi[1], hi_v = vel_hi[0];
            double lo_j = -jerk_hi[1], hi_j = jerk_hi[0];
            double lo = tmax(tmax(lo_j, lo_v), lo_p);
            double hi = tmin(tmin(hi_j, hi_v), hi_p);
            int overlap = lo <= hi;
            double lo_vp = tmax(lo_v, lo_p), hi_vp = tmin(hi_v, hi_p);
            if (lo_vp - hi_vp > CONFLICT_TOL) { /* velocity against position: keep velocity */
                lo_vp = lo_p > hi_v ? hi_v : lo_v;
                hi_vp = lo_vp;
            }
            if (lo - hi > CONFLICT_TOL) { /* jerk against the rest: keep the rest */
                lo = lo_vp > hi_j ? lo_vp : hi_vp;
                hi = lo;
            }
            mid = 0.5 * (lo + hi);
            if (lo > hi) {
                lo = mid;
                hi = mid;
            }
            overlap = overlap && (hi >= -amax) && (lo <= amax);
            lo_out[i] = clampd(lo, -amax, amax);
            hi_out[i] = clampd(hi, -amax, amax);
            overlap_out[i] = (uint8_t)overlap;
        }
    }
}

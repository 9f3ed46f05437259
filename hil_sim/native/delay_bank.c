/* The online estimator's per-tick arithmetic (runtime/estimation: gate.py, noise.py, bank.py and
 * DelayBankEstimator.update/_close_window/_select/_restart_failing of estimator.py), in C.
 *
 * A twin, not a second design: every line mirrors the Python it names, in the same IEEE double
 * operations in the same order (Python's min(x, y) is "y < x ? y : x", max(x, y) "y > x ? y : x",
 * its % on a negative int the floor modulo), so the estimates are the same bits. Python builds the
 * reports (Estimate objects) from the numbers this leaves in the state; hil_sim/native/estimator.py
 * fills the settings and tests/hil_sim/native/test_estimator.py holds both to each other.
 * Compiled with plumbing/native_build.py's flags (no contraction, no fast math).
 */
#include <math.h>
#include <stdint.h>

#define DB_MAX_MODELS 64
#define DB_MAX_RING 128

enum { V_OK = 0, V_DIVERGED = 1, V_K_IMPLAUSIBLE = 2, V_T_IMPLAUSIBLE = 3, V_LEARNING = 4 };

typedef struct {
    /* settings (filled by the caller) */
    int32_t n, n_win, per_tick, ring_len, min_age, flat_ticks;
    double window_s, prior_K, prior_T_s, prior_rel_std, baseline_std, q_a2, q_b2, q_c2, jump2,
        forget, a_lo, a_hi, reseed, learn, tau_offset, drift, K_lo, K_hi, T_lo, T_hi;
    double g_lo, g_hi, g_jump, g_slew_per_tick, nz_floor, nz_gain;
    int32_t delay_windows[DB_MAX_MODELS];
    double delays_s[DB_MAX_MODELS], pen[DB_MAX_MODELS];
    /* gate state */
    double g_last, g_prev;
    int64_t g_since, g_run, g_rejected;
    int32_t g_reason; /* index into gate.REASONS */
    /* window noise state */
    double nz_y1, nz_y2, nz_y3, nz_var;
    /* decimation and bank bookkeeping */
    int32_t phase, ny, nu, next, learned, rejection;
    int64_t j, updates;
    double ysum, usum, y_dev, dT, y_ref;
    double uring[DB_MAX_RING];
    int32_t order[DB_MAX_MODELS];
    double w[DB_MAX_MODELS];
    /* the models: theta [a, b, c], P [00, 01, 02, 11, 12, 22], sim [x, dx/da, dx/db, last u] */
    double theta[DB_MAX_MODELS][3], P[DB_MAX_MODELS][6], sim[DB_MAX_MODELS][4], nll[DB_MAX_MODELS];
    int64_t age[DB_MAX_MODELS];
    /* the last _select's outcome: kind V_OK (an estimate below) or the fallback's reason */
    int32_t out_kind, out_healthy;
    double out_K, out_T, out_tau, out_K_std, out_T_std, out_tau_lo, out_tau_hi, out_confidence;
} bank_t;

uint32_t db_state_size(void) { return (uint32_t)sizeof(bank_t); }

static double pymin(double x, double y) { return y < x ? y : x; }
static double pymax(double x, double y) { return y > x ? y : x; }

/* DelayModel.reset */
static void model_reset(bank_t *s, int m, double y_dev, double nll) {
    double a = exp(-s->window_s / s->prior_T_s);
    double *th = s->theta[m], *P = s->P[m], *sim = s->sim[m];
    double x = s->prior_K * sim[3];
    double sa, sb, sc;
    th[0] = a;
    th[1] = s->prior_K * (1.0 - a);
    th[2] = y_dev == y_dev ? y_dev - x : 0.0;
    sa = a * s->window_s / s->prior_T_s * s->prior_rel_std;
    sb = th[1] * s->prior_rel_std;
    sc = s->baseline_std;
    P[0] = sa * sa;
    P[1] = 0.0;
    P[2] = 0.0;
    P[3] = sb * sb;
    P[4] = 0.0;
    P[5] = sc * sc;
    sim[0] = x;
    sim[1] = x / (1.0 - a);
    sim[2] = sim[3] / (1.0 - a);
    s->nll[m] = nll;
    s->age[m] = 0;
}

/* DelayModel.copy_from */
static void model_copy(bank_t *s, int m, int from, double nll) {
    int i;
    for (i = 0; i < 3; ++i) s->theta[m][i] = s->theta[from][i];
    for (i = 0; i < 6; ++i) s->P[m][i] = s->P[from][i];
    for (i = 0; i < 4; ++i) s->sim[m][i] = s->sim[from][i];
    s->age[m] = s->age[from];
    s->nll[m] = nll;
}

/* DelayModel.step */
static int model_step(bank_t *s, int m, double u_ml_h, double y, double dT, double r2) {
    double *sim = s->sim[m], *th = s->theta[m], *P = s->P[m];
    double a, b, c, x, x_new, pa, pb, u;
    double p00, p01, p02, p11, p12, p22, e, g0, g1, g2, sv, nu2, inv, k;
    if (dT > 0.0 && y == y && 0.0 < th[0] && th[0] < 1.0) {
        double a_old = th[0];
        double K = th[1] / (1.0 - a_old);
        double a_new = exp(-s->window_s / (dT - s->window_s / log(a_old)));
        th[0] = pymin(a_new, s->a_hi);
        th[1] = K * (1.0 - th[0]);
    }
    u = u_ml_h == u_ml_h ? u_ml_h : sim[3];
    sim[3] = u;
    a = th[0];
    b = th[1];
    c = th[2];
    x = sim[0];
    x_new = a * x + b * u;
    pa = x + a * sim[1];
    pb = u + a * sim[2];
    sim[0] = x_new;
    sim[1] = pa;
    sim[2] = pb;
    if (y != y) return 0;
    p00 = P[0] + s->q_a2;
    p01 = P[1];
    p02 = P[2];
    p11 = P[3] + s->q_b2;
    p12 = P[4];
    p22 = P[5] + s->q_c2;
    e = y - x_new - c;
    g0 = p00 * pa + p01 * pb + p02;
    g1 = p01 * pa + p11 * pb + p12;
    g2 = p02 * pa + p12 * pb + p22;
    sv = pa * g0 + pb * g1 + g2 + r2;
    nu2 = e * e / sv;
    s->nll[m] = s->forget * s->nll[m] + pymin(nu2, 25.0) + log(sv);
    if (nu2 > s->jump2) {
        p22 += e * e;
        g2 += e * e;
        sv += e * e;
    }
    inv = 1.0 / sv;
    k = e * inv;
    th[0] = pymin(pymax(a + g0 * k, s->a_lo), s->a_hi);
    th[1] = b + g1 * k;
    th[2] = c + g2 * k;
    P[0] = p00 - g0 * g0 * inv;
    P[1] = p01 - g0 * g1 * inv;
    P[2] = p02 - g0 * g2 * inv;
    P[3] = p11 - g1 * g1 * inv;
    P[4] = p12 - g1 * g2 * inv;
    P[5] = p22 - g2 * g2 * inv;
    s->age[m] += 1;
    if (!(P[0] > 0.0 && P[3] > 0.0 && P[5] > 0.0 && isfinite(th[1] + th[2] + x_new)))
        model_reset(s, m, y, s->nll[m]);
    return 1;
}

static int finite_below(double p) { return -INFINITY < p && p < 1e300; }

/* DelayModel.verdict */
static int model_verdict(const bank_t *s, int m) {
    const double *th = s->theta[m], *P = s->P[m];
    double a = th[0], b = th[1], c = th[2], K, T;
    if (!(isfinite(a + b + c) && finite_below(P[0]) && finite_below(P[1]) && finite_below(P[2]) &&
          finite_below(P[3]) && finite_below(P[4]) && finite_below(P[5])))
        return V_DIVERGED;
    if (!(0.0 < a && a < 1.0)) return V_T_IMPLAUSIBLE;
    K = b / (1.0 - a);
    if (!(s->K_lo <= K && K <= s->K_hi)) return V_K_IMPLAUSIBLE;
    T = -s->window_s / log(a);
    if (!(s->T_lo <= T && T <= s->T_hi)) return V_T_IMPLAUSIBLE;
    return V_OK;
}

/* SampleGate.accept; reasons as gate.REASONS: ok, nonfinite, quality, range, spike, flatline */
static int gate_accept(bank_t *s, double map_mmhg, int64_t quality) {
    int reason = 0;
    s->g_since += 1;
    if (!isfinite(map_mmhg)) {
        reason = 1;
        s->g_run = 0;
    } else {
        s->g_run = map_mmhg == s->g_prev ? s->g_run + 1 : 1;
        if (quality)
            reason = 2;
        else if (!(s->g_lo <= map_mmhg && map_mmhg <= s->g_hi))
            reason = 3;
        else if (s->g_run >= s->flat_ticks)
            reason = 5;
        else if (s->g_last == s->g_last &&
                 fabs(map_mmhg - s->g_last) > s->g_jump + s->g_slew_per_tick * (double)s->g_since)
            reason = 4;
    }
    s->g_prev = map_mmhg;
    s->g_reason = reason;
    if (reason != 0) {
        s->g_rejected += 1;
        return 0;
    }
    s->g_last = map_mmhg;
    s->g_since = 0;
    return 1;
}

/* WindowNoise.update */
static void noise_update(bank_t *s, double y) {
    double d3 = y - 3.0 * s->nz_y1 + 3.0 * s->nz_y2 - s->nz_y3;
    if (d3 == d3) {
        double sample = pymin(d3 * d3 / 20.0, 25.0 * s->nz_var);
        s->nz_var = pymax(s->nz_floor, s->nz_var + s->nz_gain * (sample - s->nz_var));
    }
    s->nz_y3 = s->nz_y2;
    s->nz_y2 = s->nz_y1;
    s->nz_y1 = y;
}

/* DelayBankEstimator._close_window */
static void close_window(bank_t *s) {
    int nw = s->n_win;
    double y = 2 * s->ny >= nw ? s->ysum / s->ny : NAN;
    double u = s->nu == nw ? s->usum / nw : NAN;
    s->phase = s->ny = s->nu = 0;
    s->ysum = s->usum = 0.0;
    s->j += 1;
    s->uring[s->j % s->ring_len] = u;
    s->dT = u == u ? s->drift * u : 0.0;
    noise_update(s, y);
    if (s->y_ref != s->y_ref && y == y) s->y_ref = y;
    s->y_dev = y - s->y_ref;
    s->next = 0;
}

/* DelayBankEstimator._restart_failing (the order kept between calls, sorted stably by nll) */
static void restart_failing(bank_t *s) {
    int n = s->n, i, m, donor = -1;
    double worst;
    for (i = 1; i < n; ++i) { /* stable insertion sort of the kept order */
        int v = s->order[i], k = i - 1;
        while (k >= 0 && s->nll[v] < s->nll[s->order[k]]) {
            s->order[k + 1] = s->order[k];
            --k;
        }
        s->order[k + 1] = v;
    }
    for (i = 0; i < n; ++i)
        if (model_verdict(s, s->order[i]) == V_OK) {
            donor = s->order[i];
            break;
        }
    worst = s->nll[s->order[n - 1]];
    for (m = 0; m < n; ++m) {
        if (m == donor) continue;
        if (donor < 0) {
            if (model_verdict(s, m) != V_OK) model_reset(s, m, s->y_dev, worst);
        } else if (model_verdict(s, m) != V_OK || s->nll[m] - s->nll[donor] > s->reseed) {
            model_copy(s, m, donor, s->nll[donor] + 0.5 * s->reseed);
        }
    }
}

static void fallback(bank_t *s, int reason, int healthy) {
    s->out_kind = reason;
    s->out_healthy = healthy;
}

/* DelayBankEstimator._select */
static void select_best(bank_t *s) {
    int n = s->n, best = 0, m, verdict, lo_i, hi_i;
    double *pen = s->pen, lmin, total, acc, tau, a, b, one_a, K, la, T, dKa, dKb, K_std, T_std;
    double rel;
    for (m = 1; m < n; ++m)
        if (s->nll[m] + pen[m] < s->nll[best] + pen[best]) best = m;
    verdict = model_verdict(s, best);
    restart_failing(s);
    if (verdict != V_OK) {
        s->rejection = verdict;
        fallback(s, verdict, 0);
        return;
    }
    if (s->rejection && s->learned && s->age[best] < s->min_age) {
        fallback(s, s->rejection, 0);
        return;
    }
    s->rejection = 0;
    lmin = s->nll[best] + pen[best];
    total = 0.0;
    for (m = 0; m < n; ++m) {
        s->w[m] = exp(-0.5 * pymin(s->nll[m] + pen[m] - lmin, 700.0));
        total += s->w[m];
    }
    lo_i = 0;
    hi_i = n - 1;
    acc = 0.0;
    for (m = 0; m < n; ++m) {
        acc += s->w[m] / total;
        if (acc < 0.05) lo_i = m + 1;
    }
    acc = 0.0;
    for (m = n - 1; m >= 0; --m) {
        acc += s->w[m] / total;
        if (acc < 0.05) hi_i = m - 1;
    }
    tau = s->delays_s[best] - s->tau_offset;
    if (0 < best && best < n - 1) {
        double l0 = s->nll[best - 1] + pen[best - 1], l2 = s->nll[best + 1] + pen[best + 1];
        double curv = l0 - 2.0 * lmin + l2;
        if (curv > 0.0) tau += 0.5 * s->window_s * (l0 - l2) / curv;
    }
    a = s->theta[best][0];
    b = s->theta[best][1];
    one_a = 1.0 - a;
    K = b / one_a;
    la = log(a);
    T = -s->window_s / la;
    dKa = K / one_a;
    dKb = 1.0 / one_a;
    K_std = sqrt(pymax(dKa * dKa * s->P[best][0] + 2.0 * dKa * dKb * s->P[best][1] +
                           dKb * dKb * s->P[best][3],
                       0.0));
    T_std = sqrt(s->P[best][0]) * T / (a * fabs(la));
    rel = pymax(K_std / K / 0.05, T_std / T / 0.1);
    if (pymax(K_std / K, T_std / T) < s->learn) s->learned = 1;
    if (!s->learned) {
        fallback(s, V_LEARNING, 1);
        return;
    }
    s->out_kind = V_OK;
    s->out_healthy = 1;
    s->out_K = K;
    s->out_T = T;
    s->out_tau = tau;
    s->out_K_std = K_std;
    s->out_T_std = T_std;
    s->out_tau_lo = s->delays_s[lo_i] - s->tau_offset;
    s->out_tau_hi = s->delays_s[hi_i > lo_i ? hi_i : lo_i] - s->tau_offset;
    s->out_confidence = 1.0 / (1.0 + rel * rel);
}

/* Every model from the prior (after the settings are filled): DelayModel.__init__. */
void db_init(bank_t *s) {
    int m;
    for (m = 0; m < s->n; ++m) {
        s->sim[m][0] = s->sim[m][1] = s->sim[m][2] = s->sim[m][3] = 0.0;
        s->nll[m] = 0.0;
        s->age[m] = 0;
        s->order[m] = m;
        s->w[m] = 0.0;
        model_reset(s, m, NAN, 0.0);
    }
}

/* DelayBankEstimator.update: 1 when the bank's selection ran (a new report in out_*), else 0. */
int32_t db_update(bank_t *s, double map_mmhg, int64_t quality, double delivered_ml_h) {
    int n = s->n;
    if (gate_accept(s, map_mmhg, quality)) {
        s->ysum += map_mmhg;
        s->ny += 1;
    }
    if (isfinite(delivered_ml_h) && delivered_ml_h >= 0.0) {
        s->usum += delivered_ml_h;
        s->nu += 1;
    }
    s->phase += 1;
    if (s->phase == s->n_win) close_window(s);
    if (s->next < n && s->y_ref == s->y_ref) {
        int stop = s->next + s->per_tick < n ? s->next + s->per_tick : n, m;
        double y = s->y_dev, dT = s->dT, r2 = s->nz_var;
        for (m = s->next; m < stop; ++m) {
            int64_t i = (s->j - s->delay_windows[m]) % s->ring_len;
            if (i < 0) i += s->ring_len; /* Python's floor modulo */
            s->updates += model_step(s, m, s->uring[i], y, dT, r2);
        }
        s->next = stop;
        if (stop == n) {
            select_best(s);
            return 1;
        }
    }
    return 0;
}

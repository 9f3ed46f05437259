/* The drug patient models' steps (hil_sim/patients/phenylephrine.py: Phenylephrine2C.step,
 * norepinephrine.py: Norepinephrine1C.step, both on drug_patient.py's DrugPatient with its
 * VariableDelayBuffer; pkpd.py: PkpdPatient, IndependentPatient.step), in C.
 *
 * A twin: every line mirrors the Python it names, in the same IEEE double operations in the same
 * order (Python's x ** y on a positive x is libm's pow, math.exp libm's exp), so a patient's MAP
 * and K are the same bits. Each step also leaves what the world reads every tick (MAP, ΔMAP, K)
 * in the state, evaluated as the Python properties evaluate them on the new state.
 * hil_sim/native/drug_patient.py fills the state from a fresh patient and
 * tests/hil_sim/native/test_drug_patient.py holds both to each other. Compiled with
 * plumbing/native_build.py's flags (no contraction, no fast math).
 */
#include <math.h>
#include <stdint.h>

#define DP_MAX_RING 8192

/* hil_sim/patients/patient.py: VariableDelayBuffer */
typedef struct {
    double h, total;
    int64_t size, n;
    int32_t error, pad; /* error: a delay beyond the buffer was asked for */
    double ring[DP_MAX_RING];
} delay_t;

/* DrugPatient's counter-regulation and E (Phenylephrine2C, Norepinephrine1C) */
typedef struct {
    double q, g, counter_tau_s, baseline_mmhg, delay_s;
    double time_s, counter_mmhg, effect_now, delta_map_mmhg, map_mmhg, K;
} drug_t;

typedef struct {
    double conc_ug_ml, a[9], b[3], emax_mmhg, ec50_ng_ml, fast_dc_ng_ml;
    double a1_ug, a2_ug, ce_ng_ml;
    drug_t d;
    delay_t buf;
} phenylephrine_t;

typedef struct {
    double conc_ug_ml, a[4], b[2], endogenous_ug_min, emax_mmhg, ec50_ng_ml, hill, h_endo;
    double dc_ng_ml;
    double plasma_ng_ml, ce_ng_ml, hill_now;
    drug_t d;
    delay_t buf;
} norepinephrine_t;

typedef struct {
    double ts_s, conc_ug_ml, baseline_mmhg, cl_l_min, v1_l, q_l_min, v2_l, effect_lag_s;
    double emax_mmhg, ec50_ng_ml, hill, tolerance_tau_s, tolerance_gain, fast_dc_ng_ml;
    double a1_ug, a2_ug, ce_ng_ml, tol_ng_ml, t_s, delta_map_mmhg, map_mmhg, K;
    int64_t pipe_len, pipe_head;
    double pipe[DP_MAX_RING];
} pkpd_t;

uint32_t dp_phenylephrine_size(void) { return (uint32_t)sizeof(phenylephrine_t); }
uint32_t dp_norepinephrine_size(void) { return (uint32_t)sizeof(norepinephrine_t); }
uint32_t dp_pkpd_size(void) { return (uint32_t)sizeof(pkpd_t); }

/* VariableDelayBuffer.push */
static void push(delay_t *s, double mean_input) {
    s->total += mean_input * s->h;
    s->n += 1;
    s->ring[s->n % s->size] = s->total;
}

/* VariableDelayBuffer.cumulative_at */
static double cumulative_at(delay_t *s, double time_s) {
    double x = time_s / s->h, frac, u0;
    int64_t j;
    if (x <= 0.0) return 0.0;
    j = (int64_t)x;
    if (j >= s->n) return s->total;
    if (s->n - j > s->size - 1) {
        s->error = 1;
        return NAN;
    }
    frac = x - (double)j;
    u0 = s->ring[j % s->size];
    return u0 + frac * (s->ring[(j + 1) % s->size] - u0);
}

/* VariableDelayBuffer.delayed_mean */
static double delayed_mean(delay_t *s, double delay_start_s, double delay_end_s) {
    double t_end = (double)s->n * s->h;
    double a = t_end - s->h - delay_start_s;
    double b = t_end - delay_end_s;
    double width = b - a, m, eps;
    if (width > 1e-9 * s->h) return (cumulative_at(s, b) - cumulative_at(s, a)) / width;
    m = 0.5 * (a + b);
    eps = 1e-6 * s->h;
    return (cumulative_at(s, m + eps) - cumulative_at(s, m)) / eps;
}

/* DrugPatient._delayed_rate_ml_h */
static double delayed_rate_ml_h(drug_t *d, delay_t *buf, double rate_ml_h) {
    push(buf, rate_ml_h);
    return delayed_mean(buf, d->delay_s, d->delay_s);
}

/* DrugPatient._regulate, then the delta_map_mmhg and map_mmhg properties on the new state */
static void regulate(drug_t *d, delay_t *buf, double e0, double e1) {
    double q = d->q, g = d->g;
    double ramp = 1.0 - d->counter_tau_s * (1.0 - q) / buf->h;
    d->counter_mmhg = q * d->counter_mmhg + g * (e0 * (1.0 - q) + (e1 - e0) * ramp);
    d->time_s = (double)buf->n * buf->h;
    d->effect_now = e1;
    d->delta_map_mmhg = e1 - d->counter_mmhg;
    d->map_mmhg = d->baseline_mmhg + d->delta_map_mmhg;
}

/* Phenylephrine2C.effect_mmhg */
static double ph_effect(phenylephrine_t *s, double ce) {
    return ce > 0.0 ? s->emax_mmhg * ce / (s->ec50_ng_ml + ce) : 0.0;
}

/* Phenylephrine2C.step, then its K; 0, or 1 when a delay beyond the buffer was asked for */
int32_t dp_phenylephrine_step(phenylephrine_t *s, double rate_ml_h) {
    const double *a = s->a, *b = s->b;
    double u = delayed_rate_ml_h(&s->d, &s->buf, rate_ml_h) * s->conc_ug_ml / 3600.0;
    double x0 = s->a1_ug, x1 = s->a2_ug, x2 = s->ce_ng_ml, e0 = s->d.effect_now;
    s->a1_ug = a[0] * x0 + a[1] * x1 + a[2] * x2 + b[0] * u;
    s->a2_ug = a[3] * x0 + a[4] * x1 + a[5] * x2 + b[1] * u;
    s->ce_ng_ml = a[6] * x0 + a[7] * x1 + a[8] * x2 + b[2] * u;
    regulate(&s->d, &s->buf, e0, ph_effect(s, s->ce_ng_ml));
    s->d.K = ph_effect(s, s->ce_ng_ml + s->fast_dc_ng_ml) - s->d.effect_now;
    return s->buf.error;
}

/* Norepinephrine1C.hill_mmhg */
static double ne_hill(norepinephrine_t *s, double level) {
    double x;
    if (level <= 0.0) return 0.0;
    x = pow(level / s->ec50_ng_ml, s->hill);
    return s->emax_mmhg * x / (1.0 + x);
}

/* Norepinephrine1C.step, then its K; 0, or 1 when a delay beyond the buffer was asked for */
int32_t dp_norepinephrine_step(norepinephrine_t *s, double rate_ml_h) {
    const double *a = s->a, *b = s->b;
    double u = delayed_rate_ml_h(&s->d, &s->buf, rate_ml_h) * s->conc_ug_ml / 3600.0
               + s->endogenous_ug_min / 60.0;
    double x0 = s->plasma_ng_ml, x1 = s->ce_ng_ml, e0 = s->d.effect_now, h1;
    s->plasma_ng_ml = a[0] * x0 + a[1] * x1 + b[0] * u;
    s->ce_ng_ml = a[2] * x0 + a[3] * x1 + b[1] * u;
    s->hill_now = h1 = ne_hill(s, s->ce_ng_ml);
    regulate(&s->d, &s->buf, e0, h1 - s->h_endo);
    s->d.K = ne_hill(s, s->ce_ng_ml + s->dc_ng_ml) - s->hill_now;
    return s->buf.error;
}

/* IndependentPatient.effect_mmhg */
static double pk_effect(pkpd_t *s, double ce, double tol) {
    double ec50, x;
    if (ce <= 0.0) return 0.0;
    ec50 = s->ec50_ng_ml + s->tolerance_gain * tol;
    x = pow(ce / ec50, s->hill);
    return s->emax_mmhg * x / (1.0 + x);
}

/* IndependentPatient.step (the pipe a deque of pipe_len rates), then PkpdPatient's delta_map_mmhg,
 * map_mmhg (IndependentPatient's, its disturbances off: + 0.0) and K */
void dp_pkpd_step(pkpd_t *s, double rate_ml_h) {
    double h = s->ts_s, in_ug_s, c1, c2, transfer_ug_s, rise;
    in_ug_s = s->pipe[s->pipe_head] * s->conc_ug_ml / 3600.0; /* append, then popleft */
    s->pipe[s->pipe_head] = rate_ml_h;
    s->pipe_head = s->pipe_head + 1 == s->pipe_len ? 0 : s->pipe_head + 1;
    c1 = s->a1_ug / s->v1_l;
    c2 = s->a2_ug / s->v2_l;
    transfer_ug_s = s->q_l_min / 60.0 * (c1 - c2);
    s->a1_ug += h * (in_ug_s - s->cl_l_min / 60.0 * c1 - transfer_ug_s);
    s->a2_ug += h * transfer_ug_s;
    s->tol_ng_ml += h * (s->ce_ng_ml - s->tol_ng_ml) / s->tolerance_tau_s;
    s->ce_ng_ml += h * (c1 - s->ce_ng_ml) / s->effect_lag_s;
    s->t_s += h;
    rise = pk_effect(s, s->ce_ng_ml, s->tol_ng_ml);
    s->delta_map_mmhg = rise;
    s->map_mmhg = s->baseline_mmhg + rise + 0.0;
    s->K = pk_effect(s, s->ce_ng_ml + s->fast_dc_ng_ml, s->tol_ng_ml) - rise;
}

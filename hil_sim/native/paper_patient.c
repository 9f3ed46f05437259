/* The paper's nonlinear patient step (hil_sim/patients/patient.py: Patient.step on PatientParams, with
 * its VariableDelayBuffer), in C.
 *
 * A twin: every line mirrors the Python it names, in the same IEEE double operations in the same
 * order (Python's min(x, y) is "y < x ? y : x", max(x, y) "y > x ? y : x"), so a patient's MAP, K,
 * T and tau are the same bits. hil_sim/native/patient.py fills the state from a fresh Patient and
 * tests/hil_sim/native/test_patient.py holds both to each other. Compiled with
 * plumbing/native_build.py's flags (no contraction, no fast math).
 */
#include <math.h>
#include <stdint.h>

#define PP_MAX_RING 8192

typedef struct {
    /* constants (filled by the caller) */
    double h, tau_rate_ref, tau_min, tau_gain, tau_max, T_min, T_max;
    double k_decay, a00, a01, a10, a11, b0, b1, b_tau1, k0, k1, b_T;
    int64_t size;
    /* state */
    double time_s, delta_map_mmhg, infused_ml_h_s, K, T_s, tau_s, x1, x2, total;
    int64_t n;
    int32_t started, error; /* error: a delay beyond the buffer was asked for */
    double ring[PP_MAX_RING];
} patient_t;

uint32_t pp_state_size(void) { return (uint32_t)sizeof(patient_t); }

static double pymin(double x, double y) { return y < x ? y : x; }
static double pymax(double x, double y) { return y > x ? y : x; }

/* VariableDelayBuffer.cumulative_at */
static double cumulative_at(patient_t *s, double time_s) {
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
static double delayed_mean(patient_t *s, double delay_start_s, double delay_end_s) {
    double t_end = (double)s->n * s->h;
    double a = t_end - s->h - delay_start_s;
    double b = t_end - delay_end_s;
    double width = b - a, m, eps;
    if (width > 1e-9 * s->h) return (cumulative_at(s, b) - cumulative_at(s, a)) / width;
    m = 0.5 * (a + b);
    eps = 1e-6 * s->h;
    return (cumulative_at(s, m + eps) - cumulative_at(s, m)) / eps;
}

/* Patient.step (nonlinear); 0, or 1 when a delay beyond the buffer was asked for. */
int32_t pp_step(patient_t *s, double rate_ml_h) {
    double h = s->h, tau0, inp, x1_new, x2_new, tau1, u, K, d, kd;
    /* VariableDelayBuffer.push */
    s->total += rate_ml_h * h;
    s->n += 1;
    s->ring[s->n % s->size] = s->total;
    s->infused_ml_h_s += rate_ml_h * h;
    s->time_s = (double)s->n * h;
    tau0 = s->tau_s;
    inp = rate_ml_h / s->tau_rate_ref;
    x1_new = s->a00 * s->x1 + s->a01 * s->x2 + s->b0 * inp;
    x2_new = s->a10 * s->x1 + s->a11 * s->x2 + s->b1 * inp;
    s->x1 = x1_new;
    s->x2 = x2_new;
    if (rate_ml_h > 0.0) s->started = 1;
    if (s->started) {
        double y = x1_new + s->b_tau1 * x2_new;
        tau1 = pymin(pymax(s->tau_min + s->tau_gain * y, s->tau_min), s->tau_max);
    } else {
        tau1 = s->tau_min;
    }
    u = delayed_mean(s, tau0, tau1);
    K = s->K;
    d = exp(-h / s->T_s);
    s->delta_map_mmhg = d * s->delta_map_mmhg + (1.0 - d) * K * u;
    kd = s->k_decay;
    s->K = kd * K + (1.0 - kd) * s->k0 * exp(-s->k1 * rate_ml_h);
    s->T_s = pymin(pymax(s->T_min + s->b_T * s->infused_ml_h_s, s->T_min), s->T_max);
    s->tau_s = tau1;
    return s->error;
}

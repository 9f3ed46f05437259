/* The hourly dose limit's bookkeeping (runtime/core/dose_guard.py: DoseGuard._hour with _charge,
 * _window_ml, _leaving_by and _taper_cap), in C.
 *
 * A twin: every line mirrors the Python it names, in the same IEEE double operations in the same
 * order (Python's min(x, y) is "y < x ? y : x", max(x, y) "y > x ? y : x"; math.fsum is CPython's
 * exactly rounded sum, ported below), so the cap and the hour's volume are the same bits. The two
 * deques of (start, end, ml) segments are rings of capacity `cap` the wrapper allocates
 * (hil_sim/native/dose_guard.py); tests/hil_sim/native/test_dose_guard.py holds both to each
 * other. Near the hourly maximum the taper walks up to taper_s / period segments a call: in
 * Python that was most of a sweep's time. Compiled with plumbing/native_build.py's flags.
 */
#include <math.h>
#include <stdint.h>

#define HOUR_S 3600.0
#define FSUM_PARTIALS 256

typedef struct {
    double t0, t1, ml;
} seg_t;

typedef struct {
    /* constants (filled by the caller) */
    double period_s, taper_s, hard_max_ml_h, max_ml_per_hour;
    int64_t cap; /* capacity of each ring (segments) */
    seg_t *leaving, *recent;
    /* state */
    double leaving_ml, recent_ml;
    int64_t calls, lv_head, lv_len, rc_head, rc_len;
    int32_t error; /* 1: a ring overflowed; 2: fsum's partials overflowed */
    int32_t pad;
} guard_t;

uint32_t dg_state_size(void) { return (uint32_t)sizeof(guard_t); }

static double pymin(double x, double y) { return y < x ? y : x; }
static double pymax(double x, double y) { return y > x ? y : x; }

static seg_t *at(seg_t *ring, int64_t head, int64_t i, int64_t cap) {
    int64_t k = head + i;
    return &ring[k >= cap ? k - cap : k];
}

/* math.fsum over a ring's ml (CPython 3.11 Modules/mathmodule.c math_fsum, finite inputs: the
 * guard's volumes are finite and >= 0) */
static double fsum_ml(guard_t *s, seg_t *ring, int64_t head, int64_t len) {
    double p[FSUM_PARTIALS], x, y, t, hi, yr, lo = 0.0;
    int64_t i, j, n = 0, k;
    for (k = 0; k < len; k++) {
        x = at(ring, head, k, s->cap)->ml;
        for (i = j = 0; j < n; j++) {
            y = p[j];
            if (fabs(x) < fabs(y)) {
                t = x;
                x = y;
                y = t;
            }
            hi = x + y;
            yr = hi - x;
            lo = y - yr;
            if (lo != 0.0) p[i++] = lo;
            x = hi;
        }
        n = i;
        if (x != 0.0) {
            if (n >= FSUM_PARTIALS) {
                s->error = 2;
                return NAN;
            }
            p[n++] = x;
        }
    }
    hi = 0.0;
    if (n > 0) {
        hi = p[--n];
        while (n > 0) {
            x = hi;
            y = p[--n];
            hi = x + y;
            yr = hi - x;
            lo = y - yr;
            if (lo != 0.0) break;
        }
        if (n > 0 && ((lo < 0.0 && p[n - 1] < 0.0) || (lo > 0.0 && p[n - 1] > 0.0))) {
            y = lo * 2.0;
            x = hi + y;
            yr = x - hi;
            if (y == yr) hi = x;
        }
    }
    return hi;
}

/* DoseGuard._charge; last_s is NaN for None (both skip the charge) */
static void charge(guard_t *s, double now_s, double last_s, double last_ml_h) {
    double start, edge, ml;
    seg_t seg;
    if (now_s > last_s) {
        ml = last_ml_h * (now_s - last_s) / HOUR_S;
        if (ml > 0.0) {
            if (s->rc_len >= s->cap) {
                s->error = 1;
                return;
            }
            seg_t *r = at(s->recent, s->rc_head, s->rc_len, s->cap);
            r->t0 = last_s;
            r->t1 = now_s;
            r->ml = ml;
            s->rc_len += 1;
            s->recent_ml += ml;
        }
    }
    start = now_s - HOUR_S;
    while (s->lv_len && s->leaving[s->lv_head].t1 <= start) {
        s->leaving_ml -= s->leaving[s->lv_head].ml;
        s->lv_head = s->lv_head + 1 == s->cap ? 0 : s->lv_head + 1;
        s->lv_len -= 1;
    }
    edge = start + s->taper_s;
    while (s->rc_len && s->recent[s->rc_head].t0 < edge) {
        seg = s->recent[s->rc_head];
        s->rc_head = s->rc_head + 1 == s->cap ? 0 : s->rc_head + 1;
        s->rc_len -= 1;
        s->recent_ml -= seg.ml;
        if (seg.t1 > start) {
            if (s->lv_len >= s->cap) {
                s->error = 1;
                return;
            }
            *at(s->leaving, s->lv_head, s->lv_len, s->cap) = seg;
            s->lv_len += 1;
            s->leaving_ml += seg.ml;
        }
    }
    s->calls += 1;
    if (s->calls % 36000 == 0) {
        s->leaving_ml = fsum_ml(s, s->leaving, s->lv_head, s->lv_len);
        s->recent_ml = fsum_ml(s, s->recent, s->rc_head, s->rc_len);
    }
}

/* DoseGuard._window_ml */
static double window_ml(guard_t *s, double now_s) {
    double start = now_s - HOUR_S, partial = 0.0;
    if (s->lv_len) {
        seg_t *g = &s->leaving[s->lv_head];
        if (g->t0 < start && start < g->t1) partial = g->ml * (start - g->t0) / (g->t1 - g->t0);
    }
    return pymax(s->leaving_ml - partial, 0.0) + pymax(s->recent_ml, 0.0);
}

/* DoseGuard._leaving_by */
static double leaving_by(guard_t *s, double now_s, double tau_s) {
    double start = now_s - HOUR_S, end = start + tau_s, out = 0.0, lo, hi;
    int64_t k;
    for (k = 0; k < s->lv_len; k++) {
        seg_t *g = at(s->leaving, s->lv_head, k, s->cap);
        if (g->t0 >= end) break;
        lo = pymax(g->t0, start);
        hi = pymin(g->t1, end);
        if (hi > lo) out += g->ml * (hi - lo) / (g->t1 - g->t0);
    }
    return out;
}

/* DoseGuard._taper_cap */
static double taper_cap(guard_t *s, double now_s, double room_ml) {
    double start, cap = INFINITY, left_ml = 0.0;
    int64_t k;
    if (room_ml * HOUR_S / s->taper_s >= s->hard_max_ml_h) return INFINITY;
    start = now_s - HOUR_S;
    for (k = 0; k < s->lv_len; k++) {
        seg_t *g = at(s->leaving, s->lv_head, k, s->cap);
        if (g->t1 <= start) continue;
        if (g->t0 > start) {
            cap = pymin(cap, (room_ml + left_ml) / (g->t0 - start));
            left_ml += g->ml;
        } else {
            left_ml += g->ml * (g->t1 - start) / (g->t1 - g->t0);
        }
    }
    cap = pymin(cap, (room_ml + left_ml) / s->taper_s);
    return cap * HOUR_S;
}

/* DoseGuard._hour: the cap (ml/h), the hour's volume in *used (ml); NaN and s->error on overflow */
double dg_hour(guard_t *s, double now_s, double last_s, double last_ml_h, double *used) {
    double room, tick_ml, hour_cap;
    charge(s, now_s, last_s, last_ml_h);
    if (s->error) return NAN;
    *used = window_ml(s, now_s);
    room = pymax(s->max_ml_per_hour - *used, 0.0);
    tick_ml = room + leaving_by(s, now_s, s->period_s);
    hour_cap = pymin(tick_ml / (s->period_s / HOUR_S), taper_cap(s, now_s, room));
    return hour_cap * (1.0 - 1e-12);
}

/* The model interface of the framework (framework.h) over the generated equations.
 *
 * model_initialize: copies the FMU's parameters into the generated code's p (by the
 * table P_OF_VR), evaluates the dependent parameters (generated: md_dependent), refuses a
 * parameter below its Modelica min attribute or a non-positive rk4_step (naming it and its
 * value), and sets the states to their start values.  model_advance: classical RK4 on
 * rhs(), or on rhs_rigid() (the same generated rhs with the effect switches constant, so
 * that the compiler drops what they switch off) when the parameters give the rigid
 * configuration, integrating only the states it can change (RIGID_ACTIVE).  model_calculateValues: observe() into the outputs (table OBS_OF_VR). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "framework.h"
#include "solver.h"
#include "generated.c"

static inline void model_beginStep(ModelData *d, const double *x) { (void)d; (void)x; }

static inline void derivatives(const ModelData *d, const double *x, double *dx) {
    rhs(0.0, x, d->p, (double *)d->w, dx);
}

RK4_DEFINE(rk4_all, NX, NX, derivatives)

#if HAVE_RHS_RIGID
static inline void derivatives_rigid(const ModelData *d, const double *x, double *dx) {
    rhs_rigid(0.0, x, d->p, (double *)d->w, dx);
}

/* Classical RK4 as solver.h's, over the states the rigid rhs can change only (the others
 * have derivative 0 there and keep their values exactly, as in the full loop). */
static int rk4_rigid(Snapshot *s, long long n) {
    const double h = s->h, h2 = 0.5 * s->h, h6 = s->h / 6.0;
    double x[NX], k1[NX], k2[NX], k3[NX], k4[NX], xt[NX];
    int a, i, bad = -1;
    long long k;
    for (i = 0; i < NX; i++) x[i] = xt[i] = s->x[i];
    for (k = 0; k < n; k++) {
        derivatives_rigid(&s->d, x, k1);
        for (a = 0; a < N_RIGID_ACTIVE; a++) { i = RIGID_ACTIVE[a]; xt[i] = x[i] + h2 * k1[i]; }
        derivatives_rigid(&s->d, xt, k2);
        for (a = 0; a < N_RIGID_ACTIVE; a++) { i = RIGID_ACTIVE[a]; xt[i] = x[i] + h2 * k2[i]; }
        derivatives_rigid(&s->d, xt, k3);
        for (a = 0; a < N_RIGID_ACTIVE; a++) { i = RIGID_ACTIVE[a]; xt[i] = x[i] + h * k3[i]; }
        derivatives_rigid(&s->d, xt, k4);
        double acc = 0.0;
        for (a = 0; a < N_RIGID_ACTIVE; a++) {
            i = RIGID_ACTIVE[a];
            x[i] += h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
            acc += 0.0 * x[i]; /* NaN iff some x[i] is Inf or NaN */
        }
        if (!(acc == 0.0)) {
            for (a = 0; a < N_RIGID_ACTIVE && bad < 0; a++)
                if (!isfinite(x[RIGID_ACTIVE[a]])) bad = RIGID_ACTIVE[a];
            break;
        }
    }
    s->nSteps += k;
    s->time = s->startTime + (double)s->nSteps * h;
    for (i = 0; i < NX; i++) s->x[i] = x[i];
    return bad;
}
#endif

static int refuse(ModelInstance *comp, int vr, const char *why) {
    logError(comp, "parameter %s = %.17g refused: %s", VR_NAME[vr], comp->s.r[vr], why);
    return 1;
}

int model_initialize(ModelInstance *comp) {
    Snapshot *s = &comp->s;
    ModelData *d = &s->d;
    const double *r = s->r;
    char why[160];
    if (!(r[vr_rk4_step] > 0.0)) return refuse(comp, vr_rk4_step, "the RK4 step must be > 0");
    for (int k = 0; k < N_PARAM_VR; k++) {
        const int vr = PARAM_VR[k];
        if (PARAM_HAS_MIN[k] && !(r[vr] >= PARAM_MIN[k])) {
            snprintf(why, sizeof why, "below its minimum %g (the model's min attribute)", PARAM_MIN[k]);
            return refuse(comp, vr, why);
        }
    }
    memcpy(d->p, P_START, sizeof P_START);
    for (int k = 0; k < N_PARAM_VR; k++) d->p[PARAM_SLOT[k]] = r[PARAM_VR[k]];
    md_dependent(d->p);
#if HAVE_RHS_RIGID
    d->rigid = md_is_rigid(d->p);
#else
    d->rigid = 0;
#endif
    for (int k = 0; k < NP; k++) {
        if (!isfinite(d->p[k])) {
            logError(comp, "derived parameter %s = %g is not finite (check the parameters it is "
                     "computed from)", P_NAME[k], d->p[k]);
            return 1;
        }
    }
    memset(d->w, 0, sizeof d->w);
    s->h = r[vr_rk4_step];
    s->nx = NX;
    memcpy(s->x, X_START, sizeof X_START);
    model_latchInputs(s);
    return 0;
}

void model_latchInputs(Snapshot *s) {
    for (int k = 0; k < NU; k++) s->d.p[NP + k] = s->r[INPUT_VR[k]];
}

int model_advance(Snapshot *s, long long n) {
#if HAVE_RHS_RIGID
    if (s->d.rigid) return rk4_rigid(s, n);
#endif
    return rk4_all(s, n);
}

void model_calculateValues(Snapshot *s) {
    double out[NOBS];
    ModelData local = s->d;   /* reading outputs never changes the trajectory */
    for (int k = 0; k < NU; k++) local.p[NP + k] = s->r[INPUT_VR[k]];
    observe(s->time, s->x, local.p, local.w, out);
    for (int k = 0; k < N_OUTPUT_VR; k++) s->r[OUTPUT_VR[k]] = out[OUTPUT_SLOT[k]];
}

const char *model_stateName(const ModelData *d, int i) {
    (void)d;
    return (i >= 0 && i < NX) ? X_NAME[i] : "?";
}

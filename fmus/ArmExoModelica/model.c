/* The model interface of the framework (framework.h) over the generated equations.
 *
 * model_initialize: copies the FMU's parameters into the generated code's p (by the
 * table P_OF_VR), evaluates the dependent parameters (generated: md_dependent), refuses a
 * parameter below its Modelica min attribute or a non-positive rk4_step (naming it and its
 * value), sets the states to their start values and picks the RK4 loop of the effect
 * switches' combination (generated: md_variant, MD_RK4: the generated rhs with the
 * switches constant, inlined into a loop over the states that combination can change, so
 * that the compiler drops what they switch off).  model_advance: classical RK4 in that
 * loop (or md_rk4_generic, the switches read from p).  model_calculateValues: observe()
 * into the outputs (table OBS_OF_VR). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "framework.h"
#include "generated.c"

static inline void model_beginStep(ModelData *d, const double *x) { (void)d; (void)x; }

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
    d->variant = md_variant(d->p);
    for (int k = 0; k < NP; k++) {
        if (!isfinite(d->p[k])) {
            logError(comp, "derived parameter %s = %g is not finite (check the parameters it is "
                     "computed from)", P_NAME[k], d->p[k]);
            return 1;
        }
    }
    memset(d->w, 0, sizeof d->w);
    for (int k = 0; k < NROT; k++) d->w[MD_ROT_OFFSET + 3 * k] = NAN;  /* no sin/cos reference yet */
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
    return s->d.variant >= 0 ? MD_RK4[s->d.variant](s, n) : md_rk4_generic(s, n);
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

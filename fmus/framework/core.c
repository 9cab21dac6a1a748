/* Version-neutral core of the framework: state names, logging, allowed-call checks,
 * values by value reference, and the time grid of doStep.  The FMI front ends
 * (fmi2.c, fmi3.c) map their entry points onto these functions.
 *
 * Time: the FMU lives on its own grid startTime + n * h (h = rk4_step).  An
 * importer's communication point and step end are mapped onto that grid.  A
 * contiguous step (tc equal to the previous tc + H, as FMI 2.0 section 4.2.2
 * defines the master's clock) is accepted whatever the drift of an added-up clock
 * (t += H): its point is the FMU's current grid point.  Another point must lie
 * within what rounding of the importer's clock explains (see clockTolerance).
 */
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "framework.h"

enum { CORE_OK = 0, CORE_ERROR = 1 };

static const char *stateName(ModelState s) {
    switch (s) {
    case StartAndEnd: return "StartAndEnd";
    case Instantiated: return "Instantiated";
    case InitializationMode: return "InitializationMode";
    case StepComplete: return "StepComplete";
    case StepInProgress: return "StepInProgress";
    case StepFailed: return "StepFailed";
    case StepCanceled: return "StepCanceled";
    case Terminated: return "Terminated";
    case Error: return "Error";
    case Fatal: return "Fatal";
    case ConfigurationMode: return "ConfigurationMode";
    }
    return "?";
}

/* ---- logging ------------------------------------------------------------------ */

static void vlog(ModelInstance *comp, int isError, const char *category, const char *fmt, va_list ap) {
    char buf[1024];
    if (!comp || !comp->sink) return;
    vsnprintf(buf, sizeof buf, fmt, ap);
    comp->sink(comp, isError, category, buf);
}

void logError(ModelInstance *comp, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vlog(comp, 1, "logStatusError", fmt, ap);
    va_end(ap);
}

void logDebug(ModelInstance *comp, const char *fmt, ...) {
    va_list ap;
    if (!comp || !comp->loggingOn) return;
    va_start(ap, fmt);
    vlog(comp, 0, "logCalls", fmt, ap);
    va_end(ap);
}

/* Returns 1 when f may be called in the current state, else logs and returns 0. */
static int allowed(ModelInstance *comp, const char *f, int mask) {
    if (!comp) return 0;
    if (comp->s.state & mask) {
        logDebug(comp, "%s", f);
        return 1;
    }
    logError(comp, "%s must not be called in state %s", f, stateName(comp->s.state));
    return 0;
}

static void setDefaults(ModelInstance *comp) {
    Snapshot *s = &comp->s;
    memset(s, 0, sizeof *s);
    memcpy(s->r, VR_START, sizeof s->r);
    s->state = Instantiated;
    s->valuesDirty = 1;
}

/* A new instance, or NULL (out of memory). */
static ModelInstance *core_new(const char *instanceName, LogSink sink, AnyFunction logger, void *environment,
                               int loggingOn) {
    ModelInstance *comp = (ModelInstance *)calloc(1, sizeof(ModelInstance));
    if (!comp) return NULL;
    comp->instanceName = (char *)malloc(strlen(instanceName) + 1);
    if (!comp->instanceName) { free(comp); return NULL; }
    strcpy(comp->instanceName, instanceName);
    comp->sink = sink;
    comp->logger = logger;
    comp->environment = environment;
    comp->loggingOn = loggingOn ? 1 : 0;
    setDefaults(comp);
    return comp;
}

static void core_free(ModelInstance *comp) {
    free(comp->instanceName);
    free(comp);
}

/* ---- values ----------------------------------------------------------------------- */

static int checkVRs(ModelInstance *comp, const char *f, const unsigned int vr[], size_t nvr, int nTotal) {
    if (nvr > 0 && !vr) {
        logError(comp, "%s: vr is NULL", f);
        return 0;
    }
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= (unsigned int)nTotal) {
            logError(comp, "%s: unknown value reference %u", f, (unsigned)vr[i]);
            return 0;
        }
    }
    return 1;
}

/* Recompute the outputs if they are requested and stale (parameters and inputs
 * are stored values and need no computation).  Returns nonzero when refused. */
static int updateValues(ModelInstance *comp, const unsigned int vr[], size_t nvr) {
    Snapshot *s = &comp->s;
    size_t i;
    if (!s->valuesDirty) return 0;
    for (i = 0; i < nvr; i++)
        if (VR_CAUSALITY[vr[i]] == CAUS_OUTPUT) break;
    if (i == nvr) return 0;
    if (s->state == InitializationMode) {
        /* parameters may still change: derive them now (the initial state is all zero) */
        if (model_initialize(comp)) return 1;
    }
    model_calculateValues(s);
    s->valuesDirty = 0;
    return 0;
}

static int core_getReals(ModelInstance *comp, const char *f, const unsigned int vr[], size_t nvr,
                         double value[]) {
    if (!checkVRs(comp, f, vr, nvr, N_VR)) return CORE_ERROR;
    if (nvr > 0 && !value) { logError(comp, "%s: value is NULL", f); return CORE_ERROR; }
    if (updateValues(comp, vr, nvr)) return CORE_ERROR;
    for (size_t i = 0; i < nvr; i++) value[i] = comp->s.r[vr[i]];
    return CORE_OK;
}

/* Parameters may be set in the states of `parameterMask` only. */
static int core_setReals(ModelInstance *comp, const char *f, const unsigned int vr[], size_t nvr,
                         const double value[], int parameterMask) {
    if (!checkVRs(comp, f, vr, nvr, N_VR)) return CORE_ERROR;
    if (nvr > 0 && !value) { logError(comp, "%s: value is NULL", f); return CORE_ERROR; }
    /* check everything first, so that a refused call changes nothing */
    for (size_t i = 0; i < nvr; i++) {
        const char *name = VR_NAME[vr[i]];
        switch (VR_CAUSALITY[vr[i]]) {
        case CAUS_OUTPUT:
            logError(comp, "%s: %s is an output and cannot be set", f, name);
            return CORE_ERROR;
        case CAUS_PARAMETER:
            if (!(comp->s.state & parameterMask)) {
                logError(comp, "%s: %s is a fixed parameter and cannot be set in state %s "
                         "(only before ExitInitializationMode)", f, name, stateName(comp->s.state));
                return CORE_ERROR;
            }
            break;
        default:
            break;
        }
        if (!isfinite(value[i])) {
            logError(comp, "%s: %s = %g is not finite", f, name, value[i]);
            return CORE_ERROR;
        }
    }
    for (size_t i = 0; i < nvr; i++) comp->s.r[vr[i]] = value[i];
    if (nvr > 0) comp->s.valuesDirty = 1;
    return CORE_OK;
}

/* ---- initialisation ------------------------------------------------------------------ */

static int core_setStartTime(ModelInstance *comp, const char *f, double startTime) {
    if (!isfinite(startTime)) {
        logError(comp, "%s: startTime = %g is not finite", f, startTime);
        return CORE_ERROR;
    }
    comp->s.startTime = startTime;
    comp->s.time = startTime;
    return CORE_OK;
}

/* Derive the model; on success the instance is at startTime in StepComplete. */
static int core_exitInitialization(ModelInstance *comp) {
    if (model_initialize(comp)) {
        comp->s.state = Error;
        return CORE_ERROR;
    }
    comp->s.nSteps = 0;
    comp->s.nCalls = 0;
    comp->s.time = comp->s.startTime;
    comp->s.clock = comp->s.startTime;
    comp->s.valuesDirty = 1;
    comp->s.state = StepComplete;
    return CORE_OK;
}

/* ---- the time grid of doStep ------------------------------------------------------------ */

/* Largest clock error that an importer's rounding explains at time t [s]: each of its
 * nCalls steps may round t += H once (at most DBL_EPSILON |t| / 2), and computing
 * t0 + k H or t + H costs a few roundings more (the 16).  Measured errors of t += H stay
 * below a quarter of this bound (docs/plant.md).  Capped at h / 4 so that a point names
 * one grid point unambiguously. */
static double clockTolerance(const Snapshot *s, double t) {
    const double scale = fmax(1.0, fmax(fabs(t), fabs(s->startTime)));
    return fmin((double)(s->nCalls + 16) * DBL_EPSILON * scale, 0.25 * s->h);
}

/* Largest rounding error of a step size H computed by an importer near time t [s] (as
 * a difference of two clock values, e.g. stop - t): a few roundings of t and H. */
static double stepTolerance(double t, double H) {
    return 16.0 * DBL_EPSILON * fmax(1.0, fmax(fabs(t), fabs(H)));
}

/* One communication step from tc over H, mapped onto the grid.
 *
 * The point: a contiguous step (tc == the importer's clock after the previous step,
 * bit for bit) starts at the FMU's current grid point, whatever the drift of an
 * added-up clock; another point must lie within clockTolerance of it.
 * The end: the step covers round(H / h) RK4 steps when H is a whole multiple of h (up
 * to the rounding of H); otherwise its end tc + H must lie on the grid (up to the
 * rounding of the clock: a step cut to the stop time, stop - t, or a residual step of
 * an added-up clock).  A step that ends on the grid point where it starts is a no-op. */
static int core_doStep(ModelInstance *comp, const char *f, double tc, double H) {
    Snapshot *s = &comp->s;
    const double h = s->h;
    if (!isfinite(tc) || !isfinite(H) || H <= 0.0) {
        logError(comp, "%s: communication step size must be finite and > 0, got %.15g "
                 "(communication point %.15g)", f, H, tc);
        return CORE_ERROR;
    }
    const double tEnd = tc + H;
    const double tol = clockTolerance(s, tEnd);
    const int contiguous = (tc == s->clock);
    if (!contiguous && fabs(tc - s->time) > tol) {
        logError(comp, "%s: expected communication point %.15g but got %.15g (off by %.3g s; "
                 "rounding of the importer's clock explains at most %.3g s here, and the point "
                 "is not the end %.15g of the previous step)",
                 f, s->time, tc, tc - s->time, tol, s->clock);
        return CORE_ERROR;
    }
    const double ratio = H / h;
    const double steps = (tEnd - s->startTime) / h;
    if (!(ratio < 9.0e15) || !(steps < 9.0e15)) {
        logError(comp, "%s: the step to t = %.15g s needs more than 9e15 steps of rk4_step = %.15g s",
                 f, tEnd, h);
        return CORE_ERROR;
    }
    /* the step as a span from the current grid point */
    const long long nSpan = llround(ratio);
    const double spanOff = H - (double)nSpan * h;
    /* the step's end as a point of the importer's clock */
    const long long nEnd = llround(steps);
    const double endOff = tEnd - (s->startTime + (double)nEnd * h);
    long long n;
    if (nSpan > 0 && fabs(spanOff) <= stepTolerance(tc, H)) {
        n = nSpan;
    } else if (nEnd >= s->nSteps && fabs(endOff) <= tol) {
        n = nEnd - s->nSteps;
    } else {
        logError(comp, "%s: communication step size %.15g s (%.15g rk4_step) is not a whole multiple "
                 "of rk4_step = %.15g s (off by %.3g s), and the step would end at t = %.15g s, "
                 "%.3g s from the nearest point t = %.15g s of the FMU's time grid startTime + n "
                 "rk4_step (rounding of the importer's clock explains at most %.3g s here)",
                 f, H, ratio, h, spanOff, tEnd, endOff, tEnd - endOff, tol);
        return CORE_ERROR;
    }
    s->nCalls++;
    s->clock = tEnd;
    if (n == 0) return CORE_OK;
    model_latchInputs(s);
    int bad = model_advance(s, n);
    s->valuesDirty = 1;
    if (bad >= 0) {
        logError(comp, "%s: state %s became non-finite (%g) in the RK4 step from t = %.15g s to %.15g s; "
                 "the step is stopped", f, model_stateName(&s->d, bad), s->x[bad], s->time, s->time + h);
        s->state = Error;
        return CORE_ERROR;
    }
    return CORE_OK;
}

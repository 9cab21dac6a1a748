/* FMI 2.0 Co-Simulation entry points of the shared framework.
 *
 * Every call is checked against the FMI 2.0 allowed-call table (Co-Simulation
 * state machine, FMI 2.0.x standard section 4.2.4).  A call in a state where it is
 * not allowed returns fmi2Error with a logged message and leaves the state
 * unchanged.  A failure of the model itself (refused parameters, non-finite
 * state) returns fmi2Error and moves the instance to the Error state, from
 * which fmi2Reset, fmi2SetFMUstate, fmi2Get* and fmi2FreeInstance are allowed.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "framework.h"

#define ALL_STATES (Instantiated | InitializationMode | StepComplete | StepInProgress | \
                    StepFailed | StepCanceled | Terminated | Error | Fatal)
#define MASK_SET_DEBUG_LOGGING (ALL_STATES & ~Fatal)
#define MASK_SETUP_EXPERIMENT  (Instantiated)
#define MASK_ENTER_INIT        (Instantiated)
#define MASK_EXIT_INIT         (InitializationMode)
#define MASK_TERMINATE         (StepComplete | StepFailed)
#define MASK_RESET             (Instantiated | InitializationMode | StepComplete | StepFailed | \
                                StepCanceled | Terminated | Error)
#define MASK_FREE_INSTANCE     MASK_RESET
#define MASK_GET               (InitializationMode | StepComplete | StepFailed | StepCanceled | \
                                Terminated | Error)
#define MASK_SET               (Instantiated | InitializationMode | StepComplete)
#define MASK_SET_PARAMETER     (Instantiated | InitializationMode)
#define MASK_FMU_STATE         (Instantiated | InitializationMode | StepComplete | StepFailed | \
                                StepCanceled | Terminated | Error)
#define MASK_DIR_DERIVATIVE    (InitializationMode | StepComplete | StepFailed | StepCanceled | \
                                Terminated | Error)
#define MASK_SET_INPUT_DER     (Instantiated | InitializationMode | StepComplete)
#define MASK_GET_OUTPUT_DER    (StepComplete | StepFailed | StepCanceled | Terminated | Error)
#define MASK_DO_STEP           (StepComplete)
#define MASK_CANCEL_STEP       (StepInProgress)
#define MASK_GET_STATUS        (StepComplete | StepInProgress | StepFailed | Terminated)

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
    }
    return "?";
}

static void vlog(ModelInstance *comp, fmi2Status status, const char *category, const char *fmt, va_list ap) {
    char buf[1024];
    if (!comp || !comp->logger) return;
    vsnprintf(buf, sizeof buf, fmt, ap);
    comp->logger(comp->componentEnvironment, comp->instanceName, status, category, buf);
}

void logError(ModelInstance *comp, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vlog(comp, fmi2Error, "logStatusError", fmt, ap);
    va_end(ap);
}

void logDebug(ModelInstance *comp, const char *fmt, ...) {
    va_list ap;
    if (!comp || !comp->loggingOn) return;
    va_start(ap, fmt);
    vlog(comp, fmi2OK, "logCalls", fmt, ap);
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

#define CHECK(f, mask) do { if (!allowed(comp, f, mask)) return fmi2Error; } while (0)

static fmi2Status fail(ModelInstance *comp) {
    comp->s.state = Error;
    return fmi2Error;
}

static void setDefaults(ModelInstance *comp) {
    Snapshot *s = &comp->s;
    memset(s, 0, sizeof *s);
    memcpy(s->r, VR_START, sizeof s->r);
    s->state = Instantiated;
    s->valuesDirty = 1;
}

/* ---- inquiry ------------------------------------------------------------ */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)nCategories; (void)categories;
    CHECK("fmi2SetDebugLogging", MASK_SET_DEBUG_LOGGING);
    comp->loggingOn = loggingOn ? 1 : 0;
    return fmi2OK;
}

/* ---- creation and destruction ------------------------------------------- */

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    ModelInstance tmp;
    (void)fmuResourceLocation; (void)visible;
    memset(&tmp, 0, sizeof tmp);
    tmp.instanceName = (char *)(instanceName ? instanceName : "?");
    if (functions) {
        tmp.logger = functions->logger;
        tmp.componentEnvironment = functions->componentEnvironment;
    }
    if (!instanceName || !*instanceName) {
        logError(&tmp, "fmi2Instantiate: missing instance name");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        logError(&tmp, "fmi2Instantiate: " MODEL_IDENTIFIER_STRING " supports Co-Simulation only (fmuType = %d)", (int)fmuType);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        logError(&tmp, "fmi2Instantiate: wrong GUID %s, expected %s", fmuGUID ? fmuGUID : "(null)", INSTANTIATION_TOKEN);
        return NULL;
    }
    ModelInstance *comp = (ModelInstance *)calloc(1, sizeof(ModelInstance));
    if (!comp) return NULL;
    comp->instanceName = (char *)malloc(strlen(instanceName) + 1);
    if (!comp->instanceName) { free(comp); return NULL; }
    strcpy(comp->instanceName, instanceName);
    comp->logger = tmp.logger;
    comp->componentEnvironment = tmp.componentEnvironment;
    comp->loggingOn = loggingOn ? 1 : 0;
    setDefaults(comp);
    return comp;
}

void fmi2FreeInstance(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!comp) return;
    if (!allowed(comp, "fmi2FreeInstance", MASK_FREE_INSTANCE)) return;
    free(comp->instanceName);
    free(comp);
}

/* ---- initialisation, termination, reset --------------------------------- */

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    CHECK("fmi2SetupExperiment", MASK_SETUP_EXPERIMENT);
    if (!isfinite(startTime)) {
        logError(comp, "fmi2SetupExperiment: startTime = %g is not finite", startTime);
        return fmi2Error;
    }
    comp->s.startTime = startTime;
    comp->s.time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2EnterInitializationMode", MASK_ENTER_INIT);
    comp->s.state = InitializationMode;
    comp->s.valuesDirty = 1;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2ExitInitializationMode", MASK_EXIT_INIT);
    if (model_initialize(comp)) return fail(comp);
    comp->s.nSteps = 0;
    comp->s.time = comp->s.startTime;
    comp->s.valuesDirty = 1;
    comp->s.state = StepComplete;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2Terminate", MASK_TERMINATE);
    comp->s.state = Terminated;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2Reset", MASK_RESET);
    setDefaults(comp);
    return fmi2OK;
}

/* ---- getting and setting values ------------------------------------------ */

static int checkVRs(ModelInstance *comp, const char *f, const fmi2ValueReference vr[], size_t nvr, int nTotal) {
    if (nvr > 0 && !vr) {
        logError(comp, "%s: vr is NULL", f);
        return 0;
    }
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= (fmi2ValueReference)nTotal) {
            logError(comp, "%s: unknown value reference %u", f, (unsigned)vr[i]);
            return 0;
        }
    }
    return 1;
}

/* Recompute the outputs if they are requested and stale (parameters and inputs
 * are stored values and need no computation). */
static int updateValues(ModelInstance *comp, const fmi2ValueReference vr[], size_t nvr) {
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

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2GetReal", MASK_GET);
    if (!checkVRs(comp, "fmi2GetReal", vr, nvr, N_VR)) return fmi2Error;
    if (nvr > 0 && !value) { logError(comp, "fmi2GetReal: value is NULL"); return fmi2Error; }
    if (updateValues(comp, vr, nvr)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = comp->s.r[vr[i]];
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2SetReal", MASK_SET);
    if (!checkVRs(comp, "fmi2SetReal", vr, nvr, N_VR)) return fmi2Error;
    if (nvr > 0 && !value) { logError(comp, "fmi2SetReal: value is NULL"); return fmi2Error; }
    /* check everything first, so that a refused call changes nothing */
    for (size_t i = 0; i < nvr; i++) {
        const char *name = VR_NAME[vr[i]];
        switch (VR_CAUSALITY[vr[i]]) {
        case CAUS_OUTPUT:
            logError(comp, "fmi2SetReal: %s is an output and cannot be set", name);
            return fmi2Error;
        case CAUS_PARAMETER:
            if (!(comp->s.state & MASK_SET_PARAMETER)) {
                logError(comp, "fmi2SetReal: %s is a fixed parameter and cannot be set in state %s "
                         "(only before fmi2ExitInitializationMode)", name, stateName(comp->s.state));
                return fmi2Error;
            }
            break;
        default:
            break;
        }
        if (!isfinite(value[i])) {
            logError(comp, "fmi2SetReal: %s = %g is not finite", name, value[i]);
            return fmi2Error;
        }
    }
    for (size_t i = 0; i < nvr; i++) comp->s.r[vr[i]] = value[i];
    if (nvr > 0) comp->s.valuesDirty = 1;
    return fmi2OK;
}

static fmi2Status noVariables(ModelInstance *comp, const char *f, const fmi2ValueReference vr[], size_t nvr) {
    if (!checkVRs(comp, f, vr, nvr, 0)) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)value;
    CHECK("fmi2GetInteger", MASK_GET);
    return noVariables(comp, "fmi2GetInteger", vr, nvr);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)value;
    CHECK("fmi2GetBoolean", MASK_GET);
    return noVariables(comp, "fmi2GetBoolean", vr, nvr);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)value;
    CHECK("fmi2GetString", MASK_GET);
    return noVariables(comp, "fmi2GetString", vr, nvr);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)value;
    CHECK("fmi2SetInteger", MASK_SET);
    return noVariables(comp, "fmi2SetInteger", vr, nvr);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)value;
    CHECK("fmi2SetBoolean", MASK_SET);
    return noVariables(comp, "fmi2SetBoolean", vr, nvr);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)value;
    CHECK("fmi2SetString", MASK_SET);
    return noVariables(comp, "fmi2SetString", vr, nvr);
}

/* ---- FMU state ------------------------------------------------------------- */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2GetFMUstate", MASK_FMU_STATE);
    if (!FMUstate) { logError(comp, "fmi2GetFMUstate: FMUstate is NULL"); return fmi2Error; }
    Snapshot *snap = (Snapshot *)*FMUstate;
    if (!snap) {
        snap = (Snapshot *)malloc(sizeof(Snapshot));
        if (!snap) { logError(comp, "fmi2GetFMUstate: out of memory"); return fmi2Error; }
        *FMUstate = snap;
    }
    memcpy(snap, &comp->s, sizeof(Snapshot));
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2SetFMUstate", MASK_FMU_STATE);
    if (!FMUstate) { logError(comp, "fmi2SetFMUstate: FMUstate is NULL"); return fmi2Error; }
    memcpy(&comp->s, FMUstate, sizeof(Snapshot));
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2FreeFMUstate", MASK_FMU_STATE);
    if (FMUstate && *FMUstate) {
        free(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)FMUstate; (void)size;
    CHECK("fmi2SerializedFMUstateSize", MASK_FMU_STATE);
    logError(comp, "fmi2SerializedFMUstateSize: serialization is not supported (canSerializeFMUstate = false)");
    return fmi2Error;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)FMUstate; (void)serializedState; (void)size;
    CHECK("fmi2SerializeFMUstate", MASK_FMU_STATE);
    logError(comp, "fmi2SerializeFMUstate: serialization is not supported (canSerializeFMUstate = false)");
    return fmi2Error;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size, fmi2FMUstate *FMUstate) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)FMUstate; (void)serializedState; (void)size;
    CHECK("fmi2DeSerializeFMUstate", MASK_FMU_STATE);
    logError(comp, "fmi2DeSerializeFMUstate: serialization is not supported (canSerializeFMUstate = false)");
    return fmi2Error;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    CHECK("fmi2GetDirectionalDerivative", MASK_DIR_DERIVATIVE);
    logError(comp, "fmi2GetDirectionalDerivative is not supported (providesDirectionalDerivative = false)");
    return fmi2Error;
}

/* ---- Co-Simulation ------------------------------------------------------------ */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)vr; (void)nvr; (void)order; (void)value;
    CHECK("fmi2SetRealInputDerivatives", MASK_SET_INPUT_DER);
    logError(comp, "fmi2SetRealInputDerivatives is not supported (canInterpolateInputs = false): inputs are held constant over a step");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)vr; (void)nvr; (void)order; (void)value;
    CHECK("fmi2GetRealOutputDerivatives", MASK_GET_OUTPUT_DER);
    logError(comp, "fmi2GetRealOutputDerivatives is not supported (maxOutputDerivativeOrder = 0)");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    ModelInstance *comp = (ModelInstance *)c;
    Snapshot *s;
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK("fmi2DoStep", MASK_DO_STEP);
    s = &comp->s;
    const double H = communicationStepSize, h = s->h;
    if (!isfinite(currentCommunicationPoint) || !isfinite(H) || H <= 0.0) {
        logError(comp, "fmi2DoStep: communication step size must be finite and > 0, got %.15g "
                 "(communication point %.15g)", H, currentCommunicationPoint);
        return fmi2Error;
    }
    /* The master's clock must equal ours up to rounding (a tiny fraction of h). */
    double tol = 1e-9 * fmax(1.0, fabs(s->time));
    if (tol > 1e-3 * h) tol = 1e-3 * h;
    if (fabs(currentCommunicationPoint - s->time) > tol) {
        logError(comp, "fmi2DoStep: expected communication point %.15g but got %.15g", s->time,
                 currentCommunicationPoint);
        return fmi2Error;
    }
    const double ratio = H / h;
    const long long n = llround(ratio);
    if (n < 1 || fabs((double)n * h - H) > 1e-9 * H) {
        logError(comp, "fmi2DoStep: communication step size %.15g is not a whole multiple of rk4_step = %.15g "
                 "(ratio %.15g)", H, h, ratio);
        return fmi2Error;
    }
    model_latchInputs(s);
    int bad = model_advance(s, n);
    s->valuesDirty = 1;
    if (bad >= 0) {
        logError(comp, "fmi2DoStep: state %s became non-finite (%g) in the RK4 step from t = %.15g s to %.15g s; "
                 "the step is stopped", model_stateName(&s->d, bad), s->x[bad], s->time, s->time + h);
        return fail(comp);
    }
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2CancelStep", MASK_CANCEL_STEP);
    return fmi2Error; /* unreachable: doStep is synchronous */
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2GetStatus", MASK_GET_STATUS);
    if (s == fmi2DoStepStatus && value) { *value = fmi2OK; return fmi2OK; }
    logError(comp, "fmi2GetStatus: status kind %d not available", (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2GetRealStatus", MASK_GET_STATUS);
    if (s == fmi2LastSuccessfulTime && value) { *value = comp->s.time; return fmi2OK; }
    logError(comp, "fmi2GetRealStatus: status kind %d not available", (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)value;
    CHECK("fmi2GetIntegerStatus", MASK_GET_STATUS);
    logError(comp, "fmi2GetIntegerStatus: status kind %d not available", (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2GetBooleanStatus", MASK_GET_STATUS);
    if (s == fmi2Terminated && value) { *value = fmi2False; return fmi2OK; }
    logError(comp, "fmi2GetBooleanStatus: status kind %d not available", (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)value;
    CHECK("fmi2GetStringStatus", MASK_GET_STATUS);
    logError(comp, "fmi2GetStringStatus: status kind %d not available", (int)s);
    return fmi2Discard;
}

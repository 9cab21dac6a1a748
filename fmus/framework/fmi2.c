/* FMI 2.0 Co-Simulation entry points of the shared framework.
 *
 * Every call is checked against the FMI 2.0 allowed-call table (Co-Simulation
 * state machine, FMI 2.0.x standard section 4.2.4).  A call in a state where it is
 * not allowed returns fmi2Error with a logged message and leaves the state
 * unchanged.  A failure of the model itself (refused parameters, non-finite
 * state) returns fmi2Error and moves the instance to the Error state, from
 * which fmi2Reset, fmi2SetFMUstate, fmi2Get* and fmi2FreeInstance are allowed.
 * The version-neutral work is in core.c.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "framework.h"
#include "core.c"

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

#define CHECK(f, mask) do { if (!allowed(comp, f, mask)) return fmi2Error; } while (0)
#define STATUS(x) ((x) == CORE_OK ? fmi2OK : fmi2Error)

/* The FMI 2.0 logger treats its message as a printf format (standard section 2.1.5):
 * every '%' of the finished text is doubled, so that it prints as itself and text an
 * importer gave (a GUID, an instance name) can never act as a conversion. */
static void fmi2Sink(ModelInstance *comp, int isError, const char *category, const char *message) {
    char buf[2 * 1024 + 1];
    size_t j = 0;
    for (const char *p = message; *p && j + 2 < sizeof buf; p++) {
        if (*p == '%') buf[j++] = '%';
        buf[j++] = *p;
    }
    buf[j] = '\0';
    ((fmi2CallbackLogger)comp->logger)((fmi2ComponentEnvironment)comp->environment, comp->instanceName,
                                       isError ? fmi2Error : fmi2OK, category, buf);
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
    if (functions && functions->logger) {
        tmp.sink = fmi2Sink;
        tmp.logger = (AnyFunction)functions->logger;
        tmp.environment = functions->componentEnvironment;
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
    return core_new(instanceName, tmp.sink, tmp.logger, tmp.environment, loggingOn);
}

void fmi2FreeInstance(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!comp) return;
    if (!allowed(comp, "fmi2FreeInstance", MASK_FREE_INSTANCE)) return;
    core_free(comp);
}

/* ---- initialisation, termination, reset --------------------------------- */

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    CHECK("fmi2SetupExperiment", MASK_SETUP_EXPERIMENT);
    return STATUS(core_setStartTime(comp, "fmi2SetupExperiment", startTime));
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
    return STATUS(core_exitInitialization(comp));
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

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2GetReal", MASK_GET);
    return STATUS(core_getReals(comp, "fmi2GetReal", vr, nvr, value));
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    CHECK("fmi2SetReal", MASK_SET);
    return STATUS(core_setReals(comp, "fmi2SetReal", vr, nvr, value, MASK_SET_PARAMETER));
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
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK("fmi2DoStep", MASK_DO_STEP);
    return STATUS(core_doStep(comp, "fmi2DoStep", currentCommunicationPoint, communicationStepSize));
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

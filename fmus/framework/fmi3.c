/* FMI 3.0 Co-Simulation entry points of the shared framework (compile with FMI_VERSION=3).
 *
 * The same model and core as the FMI 2.0 front end: Step Mode is the core's
 * StepComplete, the variables are the Float64 of the one variable table, plus the
 * independent variable `time` (value reference N_VR, read-only).  Event mode,
 * clocks, configuration mode, Model Exchange and Scheduled Execution are not
 * provided (the model description says so); their functions exist, as the
 * standard requires, and return fmi3Error with a message.  A call in a state where
 * it is not allowed returns fmi3Error and leaves the state unchanged.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "framework.h"
#include "core.c"

#define VR_TIME N_VR

#define ALL_STATES (Instantiated | InitializationMode | StepComplete | Terminated | Error | Fatal | \
                    ConfigurationMode)
#define MASK_SET_DEBUG_LOGGING (ALL_STATES & ~Fatal)
#define MASK_ENTER_INIT        (Instantiated)
#define MASK_EXIT_INIT         (InitializationMode)
#define MASK_TERMINATE         (StepComplete | Error)
#define MASK_RESET             (ALL_STATES & ~Fatal)
#define MASK_GET               (InitializationMode | StepComplete | Terminated | Error)
#define MASK_SET               (Instantiated | InitializationMode | StepComplete)
#define MASK_SET_PARAMETER     (Instantiated | InitializationMode)
#define MASK_FMU_STATE         (Instantiated | InitializationMode | StepComplete | Terminated | Error)
#define MASK_DO_STEP           (StepComplete)

#define CHECK(f, mask) do { if (!allowed(comp, f, mask)) return fmi3Error; } while (0)
#define STATUS(x) ((x) == CORE_OK ? fmi3OK : fmi3Error)

/* FMI 3.0 log messages are plain text (no format, no arguments): passed as they are. */
static void fmi3Sink(ModelInstance *comp, int isError, const char *category, const char *message) {
    ((fmi3LogMessageCallback)comp->logger)((fmi3InstanceEnvironment)comp->environment,
                                           isError ? fmi3Error : fmi3OK, category, message);
}

static fmi3Status unsupported(ModelInstance *comp, const char *f, const char *why) {
    if (comp) logError(comp, "%s is not supported: %s", f, why);
    return fmi3Error;
}

/* ---- inquiry, creation, destruction ----------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    ModelInstance *comp = (ModelInstance *)instance;
    (void)nCategories; (void)categories;
    CHECK("fmi3SetDebugLogging", MASK_SET_DEBUG_LOGGING);
    comp->loggingOn = loggingOn ? 1 : 0;
    return fmi3OK;
}

static ModelInstance *instantiate(const char *f, fmi3String instanceName, fmi3String token,
                                  fmi3Boolean loggingOn, fmi3InstanceEnvironment env,
                                  fmi3LogMessageCallback logMessage, int coSimulation) {
    ModelInstance tmp;
    memset(&tmp, 0, sizeof tmp);
    tmp.instanceName = (char *)(instanceName ? instanceName : "?");
    if (logMessage) {
        tmp.sink = fmi3Sink;
        tmp.logger = (AnyFunction)logMessage;
        tmp.environment = env;
    }
    if (!instanceName || !*instanceName) {
        logError(&tmp, "%s: missing instance name", f);
        return NULL;
    }
    if (!coSimulation) {
        logError(&tmp, "%s: " MODEL_IDENTIFIER_STRING " supports Co-Simulation only", f);
        return NULL;
    }
    if (!token || strcmp(token, INSTANTIATION_TOKEN) != 0) {
        logError(&tmp, "%s: wrong instantiationToken %s, expected %s", f, token ? token : "(null)",
                 INSTANTIATION_TOKEN);
        return NULL;
    }
    return core_new(instanceName, tmp.sink, tmp.logger, tmp.environment, loggingOn);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible,
                                         fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
                                         fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    /* no events and no intermediate variables: eventModeUsed and early return change nothing */
    (void)resourcePath; (void)visible; (void)eventModeUsed; (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables; (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    return instantiate("fmi3InstantiateCoSimulation", instanceName, instantiationToken, loggingOn,
                       instanceEnvironment, logMessage, 1);
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)resourcePath; (void)visible;
    return instantiate("fmi3InstantiateModelExchange", instanceName, instantiationToken, loggingOn,
                       instanceEnvironment, logMessage, 0);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible,
                                               fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)resourcePath; (void)visible; (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    return instantiate("fmi3InstantiateScheduledExecution", instanceName, instantiationToken, loggingOn,
                       instanceEnvironment, logMessage, 0);
}

void fmi3FreeInstance(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (comp) core_free(comp);
}

/* ---- initialisation, termination, reset ------------------------------------------------ */

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    ModelInstance *comp = (ModelInstance *)instance;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    CHECK("fmi3EnterInitializationMode", MASK_ENTER_INIT);
    if (core_setStartTime(comp, "fmi3EnterInitializationMode", startTime) != CORE_OK) return fmi3Error;
    comp->s.state = InitializationMode;
    comp->s.valuesDirty = 1;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    CHECK("fmi3ExitInitializationMode", MASK_EXIT_INIT);
    return STATUS(core_exitInitialization(comp));
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    CHECK("fmi3EnterEventMode", 0);
    return fmi3Error;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    CHECK("fmi3Terminate", MASK_TERMINATE);
    comp->s.state = Terminated;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    CHECK("fmi3Reset", MASK_RESET);
    setDefaults(comp);
    return fmi3OK;
}

/* ---- Float64 values (and the independent variable time) ------------------------------- */

static int checkCount(ModelInstance *comp, const char *f, size_t nvr, size_t nValues) {
    if (nvr == nValues) return 1;
    logError(comp, "%s: %zu values for %zu value references (all variables are scalars)", f, nValues, nvr);
    return 0;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          fmi3Float64 values[], size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    CHECK("fmi3GetFloat64", MASK_GET);
    if (!checkCount(comp, "fmi3GetFloat64", nvr, nValues)) return fmi3Error;
    if (!checkVRs(comp, "fmi3GetFloat64", vr, nvr, N_VR + 1)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] == VR_TIME) {
            values[i] = comp->s.time;
        } else if (core_getReals(comp, "fmi3GetFloat64", &vr[i], 1, &values[i]) != CORE_OK) {
            return fmi3Error;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    CHECK("fmi3SetFloat64", MASK_SET);
    if (!checkCount(comp, "fmi3SetFloat64", nvr, nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        if (vr && vr[i] == VR_TIME) {
            logError(comp, "fmi3SetFloat64: time is the independent variable and cannot be set");
            return fmi3Error;
        }
    }
    return STATUS(core_setReals(comp, "fmi3SetFloat64", vr, nvr, values, MASK_SET_PARAMETER));
}

/* No variables of the other types: any value reference is unknown. */
#define NO_VARIABLES_GET(NAME, T)                                                                   \
    fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, T values[],   \
                    size_t nValues) {                                                               \
        ModelInstance *comp = (ModelInstance *)instance;                                            \
        (void)values; (void)nValues;                                                                \
        CHECK(#NAME, MASK_GET);                                                                     \
        return checkVRs(comp, #NAME, vr, nvr, 0) ? fmi3OK : fmi3Error;                              \
    }
#define NO_VARIABLES_SET(NAME, T)                                                                   \
    fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,               \
                    const T values[], size_t nValues) {                                             \
        ModelInstance *comp = (ModelInstance *)instance;                                            \
        (void)values; (void)nValues;                                                                \
        CHECK(#NAME, MASK_SET);                                                                     \
        return checkVRs(comp, #NAME, vr, nvr, 0) ? fmi3OK : fmi3Error;                              \
    }

NO_VARIABLES_GET(fmi3GetFloat32, fmi3Float32)
NO_VARIABLES_GET(fmi3GetInt8, fmi3Int8)
NO_VARIABLES_GET(fmi3GetUInt8, fmi3UInt8)
NO_VARIABLES_GET(fmi3GetInt16, fmi3Int16)
NO_VARIABLES_GET(fmi3GetUInt16, fmi3UInt16)
NO_VARIABLES_GET(fmi3GetInt32, fmi3Int32)
NO_VARIABLES_GET(fmi3GetUInt32, fmi3UInt32)
NO_VARIABLES_GET(fmi3GetInt64, fmi3Int64)
NO_VARIABLES_GET(fmi3GetUInt64, fmi3UInt64)
NO_VARIABLES_GET(fmi3GetBoolean, fmi3Boolean)
NO_VARIABLES_GET(fmi3GetString, fmi3String)
NO_VARIABLES_SET(fmi3SetFloat32, fmi3Float32)
NO_VARIABLES_SET(fmi3SetInt8, fmi3Int8)
NO_VARIABLES_SET(fmi3SetUInt8, fmi3UInt8)
NO_VARIABLES_SET(fmi3SetInt16, fmi3Int16)
NO_VARIABLES_SET(fmi3SetUInt16, fmi3UInt16)
NO_VARIABLES_SET(fmi3SetInt32, fmi3Int32)
NO_VARIABLES_SET(fmi3SetUInt32, fmi3UInt32)
NO_VARIABLES_SET(fmi3SetInt64, fmi3Int64)
NO_VARIABLES_SET(fmi3SetUInt64, fmi3UInt64)
NO_VARIABLES_SET(fmi3SetBoolean, fmi3Boolean)
NO_VARIABLES_SET(fmi3SetString, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    (void)valueSizes; (void)values; (void)nValues;
    CHECK("fmi3GetBinary", MASK_GET);
    return checkVRs(comp, "fmi3GetBinary", vr, nvr, 0) ? fmi3OK : fmi3Error;
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    (void)valueSizes; (void)values; (void)nValues;
    CHECK("fmi3SetBinary", MASK_SET);
    return checkVRs(comp, "fmi3SetBinary", vr, nvr, 0) ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    (void)vr; (void)nvr; (void)values;
    return unsupported((ModelInstance *)instance, "fmi3GetClock", "the FMU has no clocks");
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Clock values[]) {
    (void)vr; (void)nvr; (void)values;
    return unsupported((ModelInstance *)instance, "fmi3SetClock", "the FMU has no clocks");
}

/* ---- dependencies, FMU state, derivatives ----------------------------------------------- */

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference; (void)nDependencies;
    return unsupported((ModelInstance *)instance, "fmi3GetNumberOfVariableDependencies",
                  "dependencies are given in the model description only");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[], size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents;
    (void)elementIndicesOfIndependents; (void)dependencyKinds; (void)nDependencies;
    return unsupported((ModelInstance *)instance, "fmi3GetVariableDependencies",
                  "dependencies are given in the model description only");
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    ModelInstance *comp = (ModelInstance *)instance;
    CHECK("fmi3GetFMUState", MASK_FMU_STATE);
    if (!FMUState) { logError(comp, "fmi3GetFMUState: FMUState is NULL"); return fmi3Error; }
    Snapshot *snap = (Snapshot *)*FMUState;
    if (!snap) {
        snap = (Snapshot *)malloc(sizeof(Snapshot));
        if (!snap) { logError(comp, "fmi3GetFMUState: out of memory"); return fmi3Error; }
        *FMUState = snap;
    }
    memcpy(snap, &comp->s, sizeof(Snapshot));
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    ModelInstance *comp = (ModelInstance *)instance;
    CHECK("fmi3SetFMUState", MASK_FMU_STATE);
    if (!FMUState) { logError(comp, "fmi3SetFMUState: FMUState is NULL"); return fmi3Error; }
    memcpy(&comp->s, FMUState, sizeof(Snapshot));
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    ModelInstance *comp = (ModelInstance *)instance;
    CHECK("fmi3FreeFMUState", MASK_FMU_STATE);
    if (FMUState && *FMUState) {
        free(*FMUState);
        *FMUState = NULL;
    }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    (void)FMUState; (void)size;
    return unsupported((ModelInstance *)instance, "fmi3SerializedFMUStateSize", "canSerializeFMUState = false");
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    (void)FMUState; (void)serializedState; (void)size;
    return unsupported((ModelInstance *)instance, "fmi3SerializeFMUState", "canSerializeFMUState = false");
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    (void)FMUState; (void)serializedState; (void)size;
    return unsupported((ModelInstance *)instance, "fmi3DeserializeFMUState", "canSerializeFMUState = false");
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                        size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    return unsupported((ModelInstance *)instance, "fmi3GetDirectionalDerivative", "providesDirectionalDerivatives = false");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                    const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                    size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    return unsupported((ModelInstance *)instance, "fmi3GetAdjointDerivative", "providesAdjointDerivatives = false");
}

/* ---- configuration mode, clocks, discrete states: not provided ------------------------------- */

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return unsupported((ModelInstance *)instance, "fmi3EnterConfigurationMode", "the FMU has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return unsupported((ModelInstance *)instance, "fmi3ExitConfigurationMode", "the FMU has no structural parameters");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)nvr; (void)intervals; (void)qualifiers;
    return unsupported((ModelInstance *)instance, "fmi3GetIntervalDecimal", "the FMU has no clocks");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; (void)qualifiers;
    return unsupported((ModelInstance *)instance, "fmi3GetIntervalFraction", "the FMU has no clocks");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts;
    return unsupported((ModelInstance *)instance, "fmi3GetShiftDecimal", "the FMU has no clocks");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    return unsupported((ModelInstance *)instance, "fmi3GetShiftFraction", "the FMU has no clocks");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[]) {
    (void)vr; (void)nvr; (void)intervals;
    return unsupported((ModelInstance *)instance, "fmi3SetIntervalDecimal", "the FMU has no clocks");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    return unsupported((ModelInstance *)instance, "fmi3SetIntervalFraction", "the FMU has no clocks");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts;
    return unsupported((ModelInstance *)instance, "fmi3SetShiftDecimal", "the FMU has no clocks");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    return unsupported((ModelInstance *)instance, "fmi3SetShiftFraction", "the FMU has no clocks");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    return unsupported((ModelInstance *)instance, "fmi3EvaluateDiscreteStates", "the FMU has no event mode");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    (void)discreteStatesNeedUpdate; (void)terminateSimulation; (void)nominalsOfContinuousStatesChanged;
    (void)valuesOfContinuousStatesChanged; (void)nextEventTimeDefined; (void)nextEventTime;
    return unsupported((ModelInstance *)instance, "fmi3UpdateDiscreteStates", "the FMU has no event mode");
}

/* ---- Model Exchange: not provided ---------------------------------------------------------- */

#define NOT_ME(f) unsupported((ModelInstance *)instance, f, "the FMU is Co-Simulation only")

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) { return NOT_ME("fmi3EnterContinuousTimeMode"); }

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    return NOT_ME("fmi3CompletedIntegratorStep");
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    (void)time;
    return NOT_ME("fmi3SetTime");
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 x[], size_t nx) {
    (void)x; (void)nx;
    return NOT_ME("fmi3SetContinuousStates");
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[], size_t nx) {
    (void)derivatives; (void)nx;
    return NOT_ME("fmi3GetContinuousStateDerivatives");
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t ni) {
    (void)eventIndicators; (void)ni;
    return NOT_ME("fmi3GetEventIndicators");
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 x[], size_t nx) {
    (void)x; (void)nx;
    return NOT_ME("fmi3GetContinuousStates");
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nx) {
    (void)nominals; (void)nx;
    return NOT_ME("fmi3GetNominalsOfContinuousStates");
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *ni) {
    (void)ni;
    return NOT_ME("fmi3GetNumberOfEventIndicators");
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nx) {
    (void)nx;
    return NOT_ME("fmi3GetNumberOfContinuousStates");
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    return unsupported((ModelInstance *)instance, "fmi3ActivateModelPartition", "the FMU is Co-Simulation only");
}

/* ---- Co-Simulation ----------------------------------------------------------------------- */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    return unsupported((ModelInstance *)instance, "fmi3EnterStepMode",
                  "the FMU has no event mode (it enters Step Mode from initialization)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues) {
    (void)vr; (void)nvr; (void)orders; (void)values; (void)nValues;
    return unsupported((ModelInstance *)instance, "fmi3GetOutputDerivatives", "maxOutputDerivativeOrder = 0");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    ModelInstance *comp = (ModelInstance *)instance;
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK("fmi3DoStep", MASK_DO_STEP);
    int status = core_doStep(comp, "fmi3DoStep", currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    /* the importer's own clock on success (the step may have been mapped onto the grid) */
    if (lastSuccessfulTime)
        *lastSuccessfulTime = status == CORE_OK ? currentCommunicationPoint + communicationStepSize : comp->s.time;
    return STATUS(status);
}

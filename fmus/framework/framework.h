/* Shared FMI Co-Simulation framework: instance, state machine, model interface.
 *
 * A model provides config.h (identifier, value references via variables.h, the
 * ModelData struct, NX_MAX) and model.c implementing the functions declared at
 * the end of this file.  The framework is version-neutral core (core.c: state
 * machine, logging, values, the time grid) under one thin front end per FMI
 * version: fmi2.c (FMI 2.0 CS) or fmi3.c (FMI 3.0 CS), chosen at compile time
 * with FMI_VERSION (2 by default).  solver.h is the fixed-step classical RK4
 * integrator (instantiated by the model for its state layouts, so that the
 * equations inline into the integration loop).
 */
#ifndef FRAMEWORK_H
#define FRAMEWORK_H

#include <stddef.h>
#include "config.h"

/* Co-Simulation states (bit flags, for allowed-call masks).  FMI 3.0 Step Mode is
 * StepComplete; ConfigurationMode is FMI 3.0 only. */
typedef enum {
    StartAndEnd        = 1 << 0,
    Instantiated       = 1 << 1,
    InitializationMode = 1 << 2,
    StepComplete       = 1 << 3,
    StepInProgress     = 1 << 4,
    StepFailed         = 1 << 5,
    StepCanceled       = 1 << 6,
    Terminated         = 1 << 7,
    Error              = 1 << 8,
    Fatal              = 1 << 9,
    ConfigurationMode  = 1 << 10
} ModelState;

/* Everything that fmi2GetFMUstate / fmi2SetFMUstate copy. */
typedef struct {
    ModelState state;
    double startTime;
    long long nSteps;      /* internal RK4 steps since startTime */
    long long nCalls;      /* doStep calls since initialisation (bounds an importer's clock error) */
    double time;           /* = startTime + nSteps * h, never accumulated */
    double clock;          /* the importer's clock: tc + H of the last accepted doStep */
    double h;              /* internal step (rk4_step), fixed at initialisation */
    int valuesDirty;       /* outputs must be recomputed before fmi2GetReal */
    double r[N_VR];        /* every real variable, indexed by value reference */
    int nx;                /* number of active continuous states */
    double x[NX_MAX];      /* continuous state vector (flat) */
    ModelData d;           /* derived model constants and flags */
} Snapshot;

typedef struct ModelInstance ModelInstance;

/* Any function pointer (ISO C converts between function pointer types, not to void *). */
typedef void (*AnyFunction)(void);

/* Passes one finished message to the importer's logger (set by the FMI front end). */
typedef void (*LogSink)(ModelInstance *comp, int isError, const char *category, const char *message);

struct ModelInstance {
    char *instanceName;
    LogSink sink;          /* NULL: the importer gave no logger */
    AnyFunction logger;    /* the importer's callback, called by sink only */
    void *environment;     /* its componentEnvironment / instanceEnvironment */
    int loggingOn;
    Snapshot s;
};

/* Logging (core.c).  fmt is the framework's own; the finished text is handed to the
 * importer as data (see the front ends), so values may contain any character. */
void logError(ModelInstance *comp, const char *fmt, ...);
void logDebug(ModelInstance *comp, const char *fmt, ...);

/* ---- model interface (model.c) ---------------------------------------- */

/* Validate the parameters in s->r, derive the constants in s->d, choose the
 * state layout and set the initial state.  Logs and returns nonzero when a
 * parameter is refused. */
int model_initialize(ModelInstance *comp);

/* Called once at the start of every RK4 step with the state at its start. */
static inline void model_beginStep(ModelData *d, const double *x);

/* Advance s->x by n RK4 steps of size s->h with the inputs latched in s->d,
 * updating nSteps and time (see solver.h).  Returns -1 on success, else the
 * index of a state that became non-finite. */
int model_advance(Snapshot *s, long long n);

/* Compute the outputs in s->r from s->x and the inputs in s->r. */
void model_calculateValues(Snapshot *s);

/* Copy the inputs from s->r into s->d before a step. */
void model_latchInputs(Snapshot *s);

/* Name of state i in the current layout (for error messages). */
const char *model_stateName(const ModelData *d, int i);

#endif

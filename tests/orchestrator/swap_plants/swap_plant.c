/* SwapPlant: a hand-written FMI 2.0 Co-Simulation plant of the plant contract, made the way
 * a user outside this project would make one (directly on the FMI 2.0 headers that fmpy
 * ships, no shared framework), to test swapping plants into the master.
 *
 *   (M_r + M_h) theta'' + B_h theta' + K_h theta = tau_m,   tau_h = M_h theta'' + B_h theta' + K_h theta
 *
 * with a constant robot mass matrix M_r (the reference robot at its posture), classical RK4
 * at 1e-4 s inside each communication step.  Compile-time variants (tests/orchestrator/
 * swap_plants/__init__.py builds them):
 *   UNIT_DEG           theta in deg and omega in deg/s (the XML states the conversion)
 *   RESET_FAILS        fmi2Reset returns fmi2Error
 *   RESET_KEEPS_STATE  fmi2Reset returns fmi2OK but keeps the state
 *   START_OFFSET=x     theta[1] starts at x rad instead of 0 (not the start state)
 *   FIXED_STEP=h       fmi2DoStep accepts communication steps of h only
 *   MOTOR_ENABLE       an input motor_enable outside the contract (start 0) multiplies tau_m
 *   ONCE_PER_PROCESS   one instance at a time (fmi2Instantiate refuses a second live one)
 *   ONCE_EVER          one instance per process, ever (not even after fmi2FreeInstance and an
 *                      unload of the library: the mark is the process's environment)
 *   NO_LICENCE         fmi2Instantiate logs a licence error and returns NULL
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2Functions.h"

#define GUID "{5a1d0c1e-0000-4000-8000-5a1d0c1e0001}"
#define N 2
#define H_INT 1e-4
#define RAD2DEG 57.29577951308232
#ifndef START_OFFSET
#define START_OFFSET 0.0
#endif

#ifdef MOTOR_ENABLE
#define ENABLE_START 0.0
#else
#define ENABLE_START 1.0
#endif

enum { VR_TAU_M = 0, VR_THETA = 2, VR_TAU_H = 4, VR_OMEGA = 6, VR_MH = 8, VR_BH = 12, VR_KH = 16,
       VR_ENABLE = 20, N_VR = 21 };

static const double M_R[N][N] = {{0.2090303562, 0.0524026781}, {0.0524026781, 0.050825}};
static const double START[N_VR] = {0, 0, 0, 0, 0, 0, 0, 0,
                                   0.187, 0.084, 0.079, 0.060,
                                   0.651, 0.239, 0.236, 0.407,
                                   7.967, 3.187, 1.663, 6.901, ENABLE_START};

typedef struct {
    fmi2CallbackFunctions cb;
    char name[64];
    double r[N_VR];   /* inputs, parameters (outputs are computed) */
    double x[2 * N];  /* theta, omega [rad, rad/s] */
    double time;
    int initialized;
} Plant;

static void logError(Plant *p, const char *msg) {
    if (p->cb.logger) p->cb.logger(p->cb.componentEnvironment, p->name, fmi2Error, "logStatusError", "%s", msg);
}

static void accel(const Plant *p, const double *x, double *a) {
    const double *mh = &p->r[VR_MH], *bh = &p->r[VR_BH], *kh = &p->r[VR_KH];
    double m[N][N], f[N];
    for (int i = 0; i < N; i++) {
        f[i] = p->r[VR_TAU_M + i] * p->r[VR_ENABLE];
        for (int j = 0; j < N; j++) {
            m[i][j] = M_R[i][j] + mh[N * i + j];
            f[i] -= bh[N * i + j] * x[N + j] + kh[N * i + j] * x[j];
        }
    }
    const double det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    a[0] = (m[1][1] * f[0] - m[0][1] * f[1]) / det;
    a[1] = (m[0][0] * f[1] - m[1][0] * f[0]) / det;
}

static void deriv(const Plant *p, const double *x, double *dx) {
    dx[0] = x[2];
    dx[1] = x[3];
    accel(p, x, &dx[2]);
}

static void rk4(Plant *p, double h) {
    double k1[4], k2[4], k3[4], k4[4], xt[4];
    deriv(p, p->x, k1);
    for (int i = 0; i < 4; i++) xt[i] = p->x[i] + 0.5 * h * k1[i];
    deriv(p, xt, k2);
    for (int i = 0; i < 4; i++) xt[i] = p->x[i] + 0.5 * h * k2[i];
    deriv(p, xt, k3);
    for (int i = 0; i < 4; i++) xt[i] = p->x[i] + h * k3[i];
    deriv(p, xt, k4);
    for (int i = 0; i < 4; i++) p->x[i] += h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
}

static double output(const Plant *p, unsigned vr) {
    double a[N];
    if (vr >= VR_THETA && vr < VR_THETA + N) {
#ifdef UNIT_DEG
        return RAD2DEG * p->x[vr - VR_THETA];
#else
        return p->x[vr - VR_THETA];
#endif
    }
    if (vr >= VR_OMEGA && vr < VR_OMEGA + N) {
#ifdef UNIT_DEG
        return RAD2DEG * p->x[N + vr - VR_OMEGA];
#else
        return p->x[N + vr - VR_OMEGA];
#endif
    }
    if (vr >= VR_TAU_H && vr < VR_TAU_H + N) {
        const int i = vr - VR_TAU_H;
        const double *mh = &p->r[VR_MH], *bh = &p->r[VR_BH], *kh = &p->r[VR_KH];
        accel(p, p->x, a);
        double t = 0.0;
        for (int j = 0; j < N; j++) t += mh[N * i + j] * a[j] + bh[N * i + j] * p->x[N + j] + kh[N * i + j] * p->x[j];
        return t;
    }
    return p->r[vr];
}

static void startState(Plant *p) {
    memset(p->x, 0, sizeof p->x);
    p->x[0] = START_OFFSET;
    p->time = 0.0;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

static int liveInstances = 0, everInstances = 0;

static fmi2Component refuse(const fmi2CallbackFunctions *cb, fmi2String name, const char *msg) {
    if (cb && cb->logger) cb->logger(cb->componentEnvironment, name, fmi2Error, "logStatusError", "%s", msg);
    return NULL;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String location,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)location; (void)visible; (void)loggingOn;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, GUID) != 0) return NULL;
#ifdef NO_LICENCE
    return refuse(cb, name, "licence server 27000@licence.example unreachable: no licence for SwapPlant");
#endif
#ifdef ONCE_PER_PROCESS
    if (liveInstances > 0) return refuse(cb, name, "fmi2Instantiate: an instance is already live in this process");
#endif
#ifdef ONCE_EVER
    char pid[32];
    snprintf(pid, sizeof pid, "%ld", (long)getpid());
    const char *mark = getenv("SWAP_PLANT_INSTANTIATED_IN");
    if (mark && strcmp(mark, pid) == 0)
        return refuse(cb, name, "fmi2Instantiate: this plant was instantiated in this process before");
    setenv("SWAP_PLANT_INSTANTIATED_IN", pid, 1);
#endif
    Plant *p = (Plant *)calloc(1, sizeof(Plant));
    if (!p) return NULL;
    liveInstances++;
    everInstances++;
    if (cb) p->cb = *cb;
    snprintf(p->name, sizeof p->name, "%s", name ? name : "?");
    memcpy(p->r, START, sizeof p->r);
    startState(p);
    return p;
}

void fmi2FreeInstance(fmi2Component c) {
    if (c) liveInstances--;
    free(c);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDef, fmi2Real stop) {
    (void)tolDef; (void)tol; (void)stopDef; (void)stop;
    ((Plant *)c)->time = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    ((Plant *)c)->initialized = 1;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2Reset(fmi2Component c) {
    Plant *p = (Plant *)c;
#if defined(RESET_FAILS)
    logError(p, "fmi2Reset: not supported by this plant");
    return fmi2Error;
#elif defined(RESET_KEEPS_STATE)
    p->initialized = 0;  /* claims success, keeps x */
    return fmi2OK;
#else
    memcpy(p->r, START, sizeof p->r);
    startState(p);
    p->initialized = 0;
    return fmi2OK;
#endif
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= N_VR) return fmi2Error;
        value[i] = output((Plant *)c, vr[i]);
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Plant *p = (Plant *)c;
    for (size_t i = 0; i < nvr; i++) {
        const unsigned v = vr[i];
        if (v >= N_VR || (v >= VR_THETA && v < VR_MH) || (v >= VR_MH && p->initialized)) {
            logError(p, "fmi2SetReal: variable cannot be set");
            return fmi2Error;
        }
        p->r[v] = value[i];
    }
    return fmi2OK;
}

#define NO_VARS(NAME, T, CONST)                                                                     \
    fmi2Status NAME(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, CONST T value[]) {  \
        (void)c; (void)vr; (void)value;                                                             \
        return nvr ? fmi2Error : fmi2OK;                                                            \
    }
NO_VARS(fmi2GetInteger, fmi2Integer, )
NO_VARS(fmi2GetBoolean, fmi2Boolean, )
NO_VARS(fmi2GetString, fmi2String, )
NO_VARS(fmi2SetInteger, fmi2Integer, const)
NO_VARS(fmi2SetBoolean, fmi2Boolean, const)
NO_VARS(fmi2SetString, fmi2String, const)

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c; (void)s; (void)n;
    return fmi2Error;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)c; (void)s; (void)b; (void)n;
    return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)c; (void)s; (void)b; (void)n;
    return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference k[], size_t nk, const fmi2Real dk[],
                                        fmi2Real du[]) {
    (void)c; (void)u; (void)nu; (void)k; (void)nk; (void)dk; (void)du;
    return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)c; (void)vr; (void)nvr; (void)order; (void)value;
    return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)c; (void)vr; (void)nvr; (void)order; (void)value;
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real H, fmi2Boolean noSetPrior) {
    Plant *p = (Plant *)c;
    (void)t; (void)noSetPrior;
#ifdef FIXED_STEP
    if (fabs(H - FIXED_STEP) > 1e-12) {
        logError(p, "fmi2DoStep: this plant only takes its fixed communication step");
        return fmi2Error;
    }
#endif
    const long n = (long)ceil(H / H_INT - 1e-9);
    for (long k = 0; k < n; k++) rk4(p, H / (double)n);
    p->time += H;
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)c; (void)s; (void)v;
    return fmi2Discard;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    (void)s;
    *v = ((Plant *)c)->time;
    return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)c; (void)s; (void)v;
    return fmi2Discard;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)c; (void)s; (void)v;
    return fmi2Discard;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)c; (void)s; (void)v;
    return fmi2Discard;
}

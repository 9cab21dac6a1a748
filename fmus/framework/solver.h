/* Fixed-step classical 4th-order Runge-Kutta solver of the framework.
 *
 * RK4_DEFINE(name, NX, NLOOP, DERIV) defines
 *     static int name(Snapshot *s, long long n)
 * which advances the first NLOOP entries of s->x (NLOOP <= NX, an expression that
 * may use s, e.g. s->nx) by n steps of s->h with the derivative function
 *     static inline void DERIV(const ModelData *d, const double *x, double *dx).
 * With NLOOP a compile-time constant the compiler keeps the state in registers.
 * model_beginStep(d, x) is called once at the start of every step.
 * Time is startTime + nSteps * h, never accumulated.  Returns -1 on success, else
 * the index of a state that became non-finite (s->time is then the start of the
 * failing step).
 */
#ifndef SOLVER_H
#define SOLVER_H

#include <math.h>
#include "framework.h"

#define RK4_DEFINE(name, NX, NLOOP, DERIV)                                                \
    static int name(Snapshot *s, long long n) {                                       \
        const double h = s->h, h2 = 0.5 * s->h, h6 = s->h / 6.0;                      \
        double x[NX], k1[NX], k2[NX], k3[NX], k4[NX], xt[NX];                         \
        const int nl = (NLOOP);                                                       \
        int i, bad = -1;                                                              \
        long long k;                                                                  \
        for (i = 0; i < nl; i++) x[i] = s->x[i];                                      \
        for (k = 0; k < n; k++) {                                                     \
            model_beginStep(&s->d, x);                                                \
            DERIV(&s->d, x, k1);                                                      \
            for (i = 0; i < nl; i++) xt[i] = x[i] + h2 * k1[i];                       \
            DERIV(&s->d, xt, k2);                                                     \
            for (i = 0; i < nl; i++) xt[i] = x[i] + h2 * k2[i];                       \
            DERIV(&s->d, xt, k3);                                                     \
            for (i = 0; i < nl; i++) xt[i] = x[i] + h * k3[i];                        \
            DERIV(&s->d, xt, k4);                                                     \
            double acc = 0.0;                                                         \
            for (i = 0; i < nl; i++) {                                                \
                x[i] += h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);                 \
                acc += 0.0 * x[i]; /* NaN iff some x[i] is Inf or NaN */              \
            }                                                                         \
            if (!(acc == 0.0)) {                                                      \
                for (i = 0; i < nl && bad < 0; i++)                                   \
                    if (!isfinite(x[i])) bad = i;                                     \
                break;                                                                \
            }                                                                         \
        }                                                                             \
        s->nSteps += k;                                                               \
        s->time = s->startTime + (double)s->nSteps * h;                               \
        for (i = 0; i < nl; i++) s->x[i] = x[i];                                      \
        return bad;                                                                   \
    }

#endif

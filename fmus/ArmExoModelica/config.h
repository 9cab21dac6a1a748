/* Configuration of the FMU exported from the Modelica source (fmus/modelica_build.py).
 *
 * The equations are the C that modelica 0.0.205 generates from modelica/ArmExo
 * (generated.c: rhs and observe over the state y, the parameters p and the observed
 * slots), wrapped in the project's FMI framework (fmus/framework) with the same
 * fixed-step RK4 grid as the hand-written C FMU.  variables.h and generated.c are
 * written by the build for each plant; they define
 *   NX (states), NP (parameters of the generated code), NU (inputs), NOBS (observed
 *   slots), the value-reference table, and the maps between the two. */
#ifndef CONFIG_H
#define CONFIG_H

#include "variables.h"

#define NX_MAX NX

typedef struct {
    double p[NP + NU + NHOIST]; /* parameters in the generated code's order, the inputs, the
                                   parameter-only expressions hoisted out of rhs */
    double w[NOBS + 1 + 3 * NROT]; /* the generated code's workspace, then the sin/cos references */
    int variant;            /* the RK4 loop of the effect switches' combination (MD_RK4), -1: generic */
} ModelData;

#endif

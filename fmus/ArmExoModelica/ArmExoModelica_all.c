/* Single translation unit of an FMU exported from the Modelica source.  Build, from a
 * folder holding these sources and the FMI headers:
 *   cc -O3 -fPIC -shared -fvisibility=hidden -fno-math-errno -o MODEL.so MODEL_all.c -lm
 * FMI 3.0 Co-Simulation from the same sources: add -DFMI_VERSION=3. */
#ifndef FMI_VERSION
#define FMI_VERSION 2
#endif

#include "model.c"
#if FMI_VERSION == 3
#include "fmi3.c"
#else
#include "fmi2.c"
#endif

/* Single translation unit of the ArmExoPlant FMU (lets the compiler inline the
 * model equations into the RK4 loop).  Build, from a folder holding these sources
 * and the FMI headers (fmi2*.h for FMI 2.0, fmi3*.h for FMI 3.0):
 *   cc -O2 -fPIC -shared -fvisibility=hidden -fno-math-errno -o ArmExoPlant.so ArmExoPlant_all.c -lm
 * FMI 3.0 Co-Simulation from the same sources: add -DFMI_VERSION=3.
 */
#ifndef FMI_VERSION
#define FMI_VERSION 2
#endif

#include "model.c"
#if FMI_VERSION == 3
#include "fmi3.c"
#else
#include "fmi2.c"
#endif

/* Single translation unit of the ArmExoPlant FMU (lets the compiler inline the
 * model equations into the RK4 loop).  Build, from a folder holding these sources
 * and the FMI 2.0 headers:
 *   cc -O2 -fPIC -shared -fvisibility=hidden -fno-math-errno -o ArmExoPlant.so ArmExoPlant_all.c -lm
 */
#include "model.c"
#include "fmi2.c"

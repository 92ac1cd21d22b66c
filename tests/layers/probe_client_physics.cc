// Must not compile: the client layer cannot see the physics (tests/layers/CMakeLists.txt).
#include "vdyn/physics/state.h"

// Must not compile: the viewer (on the client layer) cannot see the physics.
#include "vdyn/physics/simulator.h"

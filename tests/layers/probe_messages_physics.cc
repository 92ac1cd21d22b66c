// Must not compile: messages (and so transport) sit beside the physics, not above it.
#include "vdyn/physics/params.h"

// Must not compile: the client layer cannot see the server runtime.
#include "vdyn/runtime/session.h"

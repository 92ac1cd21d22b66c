// Must not compile: the physics cannot see the generated protobuf code.
#include "vdyn/state.pb.h"

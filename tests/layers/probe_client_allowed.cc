// Must compile: what the client layer may use (the probes' control).
#include "vdyn/client/session_view.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/transport/dds.h"
int vdyn_probe_client_allowed() { return 0; }

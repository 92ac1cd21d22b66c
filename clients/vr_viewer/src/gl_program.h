// A GL program from a vertex and a fragment shader's source, compiled and linked once for the
// renderer and the headset's copy into its swapchain (renderer.cc). Needs a current context;
// throws GlError naming `what` with the driver's log when a stage does not compile or link.
#pragma once

#include <epoxy/gl.h>

#include <string>

namespace vdyn::viewer {

GLuint LinkProgram(const std::string& vertex, const std::string& fragment, const char* what);

}  // namespace vdyn::viewer

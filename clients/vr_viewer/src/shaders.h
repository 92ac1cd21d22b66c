// The viewer's GLSL (OpenGL 3.3 core), put together for a quality: the common part (the sun, the
// sky's light, fog, sRGB encoding, the sun's shadow map) and each program's stages.
#pragma once

#include <string>

namespace vdyn::viewer::shaders {

struct Options {
  bool high = true;     // specular paint, glass and chrome; the large-scale surface variation
  bool shadows = true;  // the sun's shadow map
  bool clouds = true;
  bool grid = false;  // terrain: a grid on the ground (the map)
  int style = 0;      // terrain: the SurfaceStyle
};

// A fragment shader: the version line, the options as #defines, the common part, the body.
std::string Fragment(const Options& o, const char* body);
std::string Vertex(const char* body);
// A vertex shader with the fragment shaders' common part (the lighting and the fog).
std::string VertexLit(const Options& o, const char* body);

extern const char* const kTerrainVs;
extern const char* const kTerrainFs;
extern const char* const kModelVs;
extern const char* const kModelFs;
extern const char* const kListVs;
extern const char* const kListFs;
extern const char* const kSkyVs;
extern const char* const kSkyFs;
extern const char* const kHillsVs;
extern const char* const kHillsFs;
extern const char* const kWorldQuadVs;  // contact shadows and mirrors
extern const char* const kContactFs;
extern const char* const kMirrorFs;
extern const char* const kDepthVs;
extern const char* const kDepthFs;

}  // namespace vdyn::viewer::shaders

#include "vdyn/viewer/renderer.h"

#include <epoxy/gl.h>
#include <stb_image_write.h>

#include <algorithm>
#include <cstddef>

namespace vdyn::viewer {
namespace {

// Light from the south-west, high: a face turned straight up is lit exactly 1.0 (so the roof of a
// vehicle shows its palette colour); walls get 0.55 to 0.9.
constexpr const char* kLightGlsl = R"(
const vec3 kLight = normalize(vec3(-0.35, -0.25, 0.9));
float Shade(vec3 n) { return clamp(0.55 + 0.45 * dot(n, kLight) / kLight.z, 0.3, 1.0); }
const vec3 kHaze = vec3(0.78, 0.85, 0.93);
)";

constexpr const char* kTerrainVs = R"(#version 330 core
layout(location = 0) in vec3 a_pos;
uniform mat4 u_view_proj;
out vec3 v_pos;
void main() {
  v_pos = a_pos;
  gl_Position = u_view_proj * vec4(a_pos, 1.0);
}
)";

// Flat shading from the screen-space derivatives of the position (no normals in the buffers), a
// grid in world X/Y, haze with distance.
constexpr const char* kTerrainFs = R"(
in vec3 v_pos;
uniform vec4 u_colour;
uniform vec3 u_eye;
uniform float u_grid;
uniform float u_haze;
out vec4 o_colour;
void main() {
  vec3 n = normalize(cross(dFdx(v_pos), dFdy(v_pos)));
  if (dot(n, u_eye - v_pos) < 0.0) n = -n;
  vec3 c = u_colour.rgb * Shade(n);
  if (u_grid > 0.0) {
    vec2 g = v_pos.xy / u_grid;
    vec2 w = fwidth(g);
    vec2 d = abs(fract(g - 0.5) - 0.5) / max(w, vec2(1e-6));
    float line = 1.0 - clamp(min(d.x, d.y), 0.0, 1.0);
    float fade = clamp(1.0 - max(w.x, w.y) * 4.0, 0.0, 1.0);  // no moire far away
    c = mix(c, c * 0.72, line * fade);
  }
  float dist = length(u_eye - v_pos);
  float haze = u_haze * (1.0 - exp(-dist * 0.0012));
  o_colour = vec4(mix(c, kHaze, haze), u_colour.a);
}
)";

constexpr const char* kLitVs = R"(#version 330 core
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec4 a_colour;
uniform mat4 u_view_proj;
out vec3 v_normal;
out vec4 v_colour;
void main() {
  v_normal = a_normal;
  v_colour = a_colour;
  gl_Position = u_view_proj * vec4(a_pos, 1.0);
}
)";

// A zero normal means unlit: the arrows keep the legend's exact colours.
constexpr const char* kLitFs = R"(
in vec3 v_normal;
in vec4 v_colour;
uniform float u_alpha;
out vec4 o_colour;
void main() {
  vec4 c = v_colour;
  float len = length(v_normal);
  if (len > 0.5) c.rgb *= Shade(v_normal / len);
  c.a *= u_alpha;
  o_colour = c;
}
)";

constexpr const char* kSkyVs = R"(#version 330 core
out vec2 v_ndc;
void main() {
  vec2 p = vec2((gl_VertexID == 1) ? 3.0 : -1.0, (gl_VertexID == 2) ? 3.0 : -1.0);
  v_ndc = p;
  gl_Position = vec4(p, 1.0, 1.0);
}
)";

constexpr const char* kSkyFs = R"(
in vec2 v_ndc;
uniform mat4 u_inv_view_proj;
out vec4 o_colour;
void main() {
  vec4 a = u_inv_view_proj * vec4(v_ndc, -1.0, 1.0);
  vec4 b = u_inv_view_proj * vec4(v_ndc, 1.0, 1.0);
  vec3 dir = normalize(b.xyz / b.w - a.xyz / a.w);
  vec3 zenith = vec3(0.32, 0.52, 0.82);
  vec3 ground = vec3(0.62, 0.64, 0.60);
  vec3 c = dir.z >= 0.0 ? mix(kHaze, zenith, pow(clamp(dir.z, 0.0, 1.0), 0.6))
                        : mix(kHaze, ground, clamp(-dir.z * 8.0, 0.0, 1.0));
  o_colour = vec4(c, 1.0);
}
)";

std::string Log(GLuint object, bool program) {
  GLint len = 0;
  if (program) {
    glGetProgramiv(object, GL_INFO_LOG_LENGTH, &len);
  } else {
    glGetShaderiv(object, GL_INFO_LOG_LENGTH, &len);
  }
  std::string s(static_cast<std::size_t>(std::max(len, 1)), '\0');
  if (program) {
    glGetProgramInfoLog(object, len, nullptr, s.data());
  } else {
    glGetShaderInfoLog(object, len, nullptr, s.data());
  }
  return s;
}

GLuint Compile(GLenum type, const std::string& source, const char* what) {
  const GLuint s = glCreateShader(type);
  const char* src = source.c_str();
  glShaderSource(s, 1, &src, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    const std::string log = Log(s, false);
    glDeleteShader(s);
    throw GlError(std::string("viewer shader '") + what + "' does not compile: " + log);
  }
  return s;
}

GLuint Program(const char* vs, const char* fs_body, const char* what) {
  const std::string fs = std::string("#version 330 core\n") + kLightGlsl + fs_body;
  const GLuint v = Compile(GL_VERTEX_SHADER, vs, what);
  const GLuint f = Compile(GL_FRAGMENT_SHADER, fs, what);
  const GLuint p = glCreateProgram();
  glAttachShader(p, v);
  glAttachShader(p, f);
  glLinkProgram(p);
  glDeleteShader(v);
  glDeleteShader(f);
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok) {
    const std::string log = Log(p, true);
    glDeleteProgram(p);
    throw GlError(std::string("viewer shader '") + what + "' does not link: " + log);
  }
  return p;
}

void SetMat(GLuint prog, const char* name, const Mat4& m) {
  const auto f = m.Floats();
  glUniformMatrix4fv(glGetUniformLocation(prog, name), 1, GL_FALSE, f.data());
}

int ClampSamples(int samples) {
  if (samples <= 1) return 0;
  GLint max_samples = 0;
  glGetIntegerv(GL_MAX_SAMPLES, &max_samples);
  return std::min(samples, static_cast<int>(max_samples));
}

void CheckFramebuffer(const char* what) {
  const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
  if (status != GL_FRAMEBUFFER_COMPLETE) {
    throw GlError(std::string("viewer framebuffer '") + what + "' incomplete (status 0x" + [&] {
      char b[16];
      std::snprintf(b, sizeof b, "%x", status);
      return std::string(b);
    }() + ")");
  }
}

}  // namespace

bool WritePng(const std::string& path, const Image& image) {
  if (image.width <= 0 || image.height <= 0) return false;
  return stbi_write_png(path.c_str(), image.width, image.height, 4, image.rgba.data(),
                        image.width * 4) != 0;
}

// --- RenderTarget -------------------------------------------------------------------------------

RenderTarget::~RenderTarget() {
  Release();
}

void RenderTarget::Release() {
  if (msaa_fbo_ != 0) glDeleteFramebuffers(1, &msaa_fbo_);
  if (msaa_colour_ != 0) glDeleteRenderbuffers(1, &msaa_colour_);
  if (msaa_depth_ != 0) glDeleteRenderbuffers(1, &msaa_depth_);
  if (resolve_fbo_ != 0) glDeleteFramebuffers(1, &resolve_fbo_);
  if (colour_tex_ != 0) glDeleteTextures(1, &colour_tex_);
  if (resolve_depth_ != 0) glDeleteRenderbuffers(1, &resolve_depth_);
  msaa_fbo_ = msaa_colour_ = msaa_depth_ = resolve_fbo_ = colour_tex_ = resolve_depth_ = 0;
}

void RenderTarget::Resize(int width, int height, int samples, bool external_colour) {
  Release();
  width_ = std::max(width, 1);
  height_ = std::max(height, 1);
  samples_ = ClampSamples(samples);
  use_external_ = external_colour;
  external_ = 0;
  glGenFramebuffers(1, &resolve_fbo_);
  glBindFramebuffer(GL_FRAMEBUFFER, resolve_fbo_);
  if (!use_external_) {
    glGenTextures(1, &colour_tex_);
    glBindTexture(GL_TEXTURE_2D, colour_tex_);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, width_, height_, 0, GL_RGBA, GL_UNSIGNED_BYTE,
                 nullptr);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, colour_tex_, 0);
  }
  if (samples_ == 0) {
    // No multisampling: the scene is drawn straight into the resolve framebuffer.
    glGenRenderbuffers(1, &resolve_depth_);
    glBindRenderbuffer(GL_RENDERBUFFER, resolve_depth_);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, width_, height_);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, resolve_depth_);
  } else {
    glGenFramebuffers(1, &msaa_fbo_);
    glBindFramebuffer(GL_FRAMEBUFFER, msaa_fbo_);
    glGenRenderbuffers(1, &msaa_colour_);
    glBindRenderbuffer(GL_RENDERBUFFER, msaa_colour_);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples_, GL_RGBA8, width_, height_);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, msaa_colour_);
    glGenRenderbuffers(1, &msaa_depth_);
    glBindRenderbuffer(GL_RENDERBUFFER, msaa_depth_);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples_, GL_DEPTH_COMPONENT24, width_,
                                     height_);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, msaa_depth_);
    CheckFramebuffer("multisampled scene");
  }
  if (!use_external_) {
    glBindFramebuffer(GL_FRAMEBUFFER, resolve_fbo_);
    CheckFramebuffer("resolved scene");
  }
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
}

void RenderTarget::SetExternalColour(std::uint32_t texture) {
  external_ = texture;
  glBindFramebuffer(GL_FRAMEBUFFER, resolve_fbo_);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, texture, 0);
  CheckFramebuffer("swapchain image");
}

void RenderTarget::BeginScene() {
  glBindFramebuffer(GL_FRAMEBUFFER, samples_ > 0 ? msaa_fbo_ : resolve_fbo_);
  glViewport(0, 0, width_, height_);
}

void RenderTarget::Resolve() {
  if (samples_ > 0) {
    glBindFramebuffer(GL_READ_FRAMEBUFFER, msaa_fbo_);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, resolve_fbo_);
    glBlitFramebuffer(0, 0, width_, height_, 0, 0, width_, height_, GL_COLOR_BUFFER_BIT,
                      GL_NEAREST);
  }
  glBindFramebuffer(GL_FRAMEBUFFER, resolve_fbo_);
  glViewport(0, 0, width_, height_);
}

Image RenderTarget::Read() const {
  Image img;
  img.width = width_;
  img.height = height_;
  img.rgba.resize(static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_) * 4);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, resolve_fbo_);
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width_, height_, GL_RGBA, GL_UNSIGNED_BYTE, img.rgba.data());
  // OpenGL's rows run bottom up; images top down.
  const std::size_t row = static_cast<std::size_t>(width_) * 4;
  std::vector<std::uint8_t> tmp(row);
  for (int y = 0; y < height_ / 2; ++y) {
    std::uint8_t* a = img.rgba.data() + static_cast<std::size_t>(y) * row;
    std::uint8_t* b = img.rgba.data() + static_cast<std::size_t>(height_ - 1 - y) * row;
    std::copy(a, a + row, tmp.data());
    std::copy(b, b + row, a);
    std::copy(tmp.data(), tmp.data() + row, b);
  }
  return img;
}

// --- Renderer -----------------------------------------------------------------------------------

Renderer::Renderer() {
  terrain_prog_ = Program(kTerrainVs, kTerrainFs, "terrain");
  lit_prog_ = Program(kLitVs, kLitFs, "vehicles and arrows");
  sky_prog_ = Program(kSkyVs, kSkyFs, "sky");
  glGenVertexArrays(1, &sky_vao_);
  glGenVertexArrays(1, &dyn_vao_);
  glGenBuffers(1, &dyn_vbo_);
  glBindVertexArray(dyn_vao_);
  glBindBuffer(GL_ARRAY_BUFFER, dyn_vbo_);
  const auto stride = static_cast<GLsizei>(sizeof(Vertex));
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride,
                        reinterpret_cast<const void*>(offsetof(Vertex, p)));
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride,
                        reinterpret_cast<const void*>(offsetof(Vertex, n)));
  glEnableVertexAttribArray(2);
  glVertexAttribPointer(2, 4, GL_UNSIGNED_BYTE, GL_TRUE, stride,
                        reinterpret_cast<const void*>(offsetof(Vertex, rgba)));
  glBindVertexArray(0);
  if (const GLenum e = glGetError(); e != GL_NO_ERROR) {
    throw GlError("OpenGL error 0x" + std::to_string(e) + " while setting up the viewer");
  }
}

Renderer::~Renderer() {
  ClearTerrain();
  glDeleteProgram(terrain_prog_);
  glDeleteProgram(lit_prog_);
  glDeleteProgram(sky_prog_);
  glDeleteVertexArrays(1, &sky_vao_);
  glDeleteVertexArrays(1, &dyn_vao_);
  glDeleteBuffers(1, &dyn_vbo_);
}

void Renderer::ClearTerrain() {
  for (Mesh& m : meshes_) {
    glDeleteVertexArrays(1, &m.vao);
    glDeleteBuffers(1, &m.vbo);
    glDeleteBuffers(1, &m.ibo);
  }
  meshes_.clear();
  terrain_triangles_ = 0;
}

void Renderer::SetTerrain(const TerrainData& t) {
  ClearTerrain();
  for (const TerrainMesh& tm : t.meshes) {
    Mesh m;
    m.look = LookOf(tm.kind);
    m.count = static_cast<std::int32_t>(tm.indices.size());
    glGenVertexArrays(1, &m.vao);
    glBindVertexArray(m.vao);
    glGenBuffers(1, &m.vbo);
    glBindBuffer(GL_ARRAY_BUFFER, m.vbo);
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(tm.positions_W.size() * sizeof(float)),
                 tm.positions_W.data(), GL_STATIC_DRAW);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), nullptr);
    glGenBuffers(1, &m.ibo);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, m.ibo);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER,
                 static_cast<GLsizeiptr>(tm.indices.size() * sizeof(std::uint32_t)),
                 tm.indices.data(), GL_STATIC_DRAW);
    glBindVertexArray(0);
    meshes_.push_back(m);
  }
  // Opaque meshes first, translucent ones (the glass barrier) last.
  std::stable_sort(meshes_.begin(), meshes_.end(),
                   [](const Mesh& a, const Mesh& b) { return a.look.alpha > b.look.alpha; });
  terrain_triangles_ = t.triangles;
}

void Renderer::DrawList(const viewer::DrawList& list, Pass pass, const View& v) {
  if (list.vertices().empty()) return;
  glUseProgram(lit_prog_);
  SetMat(lit_prog_, "u_view_proj", v.proj * v.view);
  glUniform1f(glGetUniformLocation(lit_prog_, "u_alpha"), pass == Pass::kGhost ? 0.35f : 1.0f);
  glBindVertexArray(dyn_vao_);
  glBindBuffer(GL_ARRAY_BUFFER, dyn_vbo_);
  // Orphan and refill: the driver need not wait for the previous frame's draw.
  const auto bytes = static_cast<GLsizeiptr>(list.vertices().size() * sizeof(Vertex));
  glBufferData(GL_ARRAY_BUFFER, bytes, nullptr, GL_STREAM_DRAW);
  glBufferSubData(GL_ARRAY_BUFFER, 0, bytes, list.vertices().data());
  if (pass != Pass::kOpaque) {
    glEnable(GL_BLEND);
    glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
    glDepthMask(GL_FALSE);
  }
  // The ghost: only where something nearer hides the arrow.
  if (pass == Pass::kGhost) glDepthFunc(GL_GREATER);
  glDrawArrays(GL_TRIANGLES, 0, static_cast<GLsizei>(list.vertices().size()));
  glDepthFunc(GL_LEQUAL);
  if (pass != Pass::kOpaque) {
    glDisable(GL_BLEND);
    glDepthMask(GL_TRUE);
  }
  glBindVertexArray(0);
}

void Renderer::Draw(const View& v, const FrameLists& lists) {
  glDisable(GL_CULL_FACE);
  glDisable(GL_SCISSOR_TEST);
  glDisable(GL_BLEND);
  glClearColor(0.78f, 0.85f, 0.93f, 1.0f);
  glClearDepth(1.0);
  glDepthMask(GL_TRUE);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);

  const Mat4 view_proj = v.proj * v.view;
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);

  // Opaque terrain, then vehicles and arrows, then what is translucent.
  glUseProgram(terrain_prog_);
  SetMat(terrain_prog_, "u_view_proj", view_proj);
  glUniform3f(glGetUniformLocation(terrain_prog_, "u_eye"), static_cast<float>(v.eye_W.x),
              static_cast<float>(v.eye_W.y), static_cast<float>(v.eye_W.z));
  glUniform1f(glGetUniformLocation(terrain_prog_, "u_haze"), v.haze ? 1.0f : 0.0f);
  const GLint colour_loc = glGetUniformLocation(terrain_prog_, "u_colour");
  const GLint grid_loc = glGetUniformLocation(terrain_prog_, "u_grid");
  auto draw_mesh = [&](const Mesh& m) {
    glUniform4f(colour_loc, m.look.colour.r / 255.0f, m.look.colour.g / 255.0f,
                m.look.colour.b / 255.0f, m.look.alpha);
    glUniform1f(grid_loc, m.look.alpha < 1.0f ? 0.0f : static_cast<float>(v.grid_step_m));
    glBindVertexArray(m.vao);
    glDrawElements(GL_TRIANGLES, m.count, GL_UNSIGNED_INT, nullptr);
  };
  for (const Mesh& m : meshes_) {
    if (m.look.alpha >= 1.0f) draw_mesh(m);
  }
  DrawList(lists.opaque, Pass::kOpaque, v);
  // The sky at the far plane, after what is opaque: only the pixels nothing covers are shaded
  // (a software renderer pays for every pixel).
  glUseProgram(sky_prog_);
  SetMat(sky_prog_, "u_inv_view_proj", Inverse(view_proj));
  glDepthMask(GL_FALSE);
  glBindVertexArray(sky_vao_);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  glDepthMask(GL_TRUE);

  glUseProgram(terrain_prog_);
  glEnable(GL_BLEND);
  glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
  glDepthMask(GL_FALSE);
  for (const Mesh& m : meshes_) {
    if (m.look.alpha < 1.0f) draw_mesh(m);
  }
  glDepthMask(GL_TRUE);
  glDisable(GL_BLEND);
  DrawList(lists.translucent, Pass::kTranslucent, v);
  DrawList(lists.arrows, Pass::kOpaque, v);
  DrawList(lists.arrows, Pass::kGhost, v);
  glBindVertexArray(0);
  glUseProgram(0);
}

void Renderer::PresentToWindow(const RenderTarget& t, int window_width, int window_height) {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, t.resolve_framebuffer());
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, 0);
  glViewport(0, 0, window_width, window_height);
  glClearColor(0, 0, 0, 1);
  glClear(GL_COLOR_BUFFER_BIT);
  // Fit the image into the window, keeping its aspect ratio.
  const double sx = static_cast<double>(window_width) / t.width();
  const double sy = static_cast<double>(window_height) / t.height();
  const double s = std::min(sx, sy);
  const int w = static_cast<int>(t.width() * s), h = static_cast<int>(t.height() * s);
  const int x0 = (window_width - w) / 2, y0 = (window_height - h) / 2;
  glBlitFramebuffer(0, 0, t.width(), t.height(), x0, y0, x0 + w, y0 + h, GL_COLOR_BUFFER_BIT,
                    GL_LINEAR);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
}

}  // namespace vdyn::viewer

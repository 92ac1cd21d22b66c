#include "vdyn/viewer/renderer.h"

#include <epoxy/gl.h>
#include <stb_image_write.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <map>

#include "gl_program.h"
#include "shaders.h"
#include "vdyn/viewer/camera.h"
#include "vdyn/viewer/lighting.h"
#include "vdyn/viewer/textures.h"

namespace vdyn::viewer {
namespace {

// A draw list's vertex (position, normal, colour) as the bound vertex array's attributes 0-2.
void VertexLayout() {
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
}

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

void SetMat(GLint location, const Mat4& m) {
  const auto f = m.Floats();
  glUniformMatrix4fv(location, 1, GL_FALSE, f.data());
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

// The texture unit of a mirror's image (surfaces 0, the shadow map 1, clouds 2).
constexpr int kMirrorUnit = 3;

// Uniform locations of a program, looked up once.
struct Uniforms {
  GLint view_proj = -1, model = -1, eye = -1, fog = -1, paint = -1, alpha = -1;
  GLint frame = -1, half_size = -1, strip = -1, grid = -1, surfaces = -1;
  GLint shadow_map = -1, shadow_mat = -1, shadow_box = -1, shadow_texel = -1;
  GLint inv_view_proj = -1, clouds = -1, strength = -1, radius = -1, lights = -1;
  GLint z_range = -1, poster_a = -1, poster_b = -1,
        relief = -1;  // terrain: the mesh's heights, its poster
};

Vec3 Linear(Rgb8 c) {
  return {ToLinear(c.r), ToLinear(c.g), ToLinear(c.b)};
}

void SetVec3(GLint location, const Vec3& v) {
  glUniform3f(location, static_cast<float>(v.x), static_cast<float>(v.y), static_cast<float>(v.z));
}

Mat4 Scaled(const Mat3& R, double s, const Vec3& t) {
  Mat4 m;
  for (int c = 0; c < 3; ++c) {
    const Vec3& col = R.c[static_cast<std::size_t>(c)];
    m(0, c) = col.x * s;
    m(1, c) = col.y * s;
    m(2, c) = col.z * s;
  }
  m(0, 3) = t.x;
  m(1, 3) = t.y;
  m(2, 3) = t.z;
  return m;
}

// The far plane of a perspective projection (infinity for an orthographic one).
double FarOf(const Mat4& proj) {
  if (std::abs(proj(3, 2)) < 1e-9) return 1e9;
  return proj(2, 3) / (proj(2, 2) + 1.0);
}

std::vector<std::int64_t> GeometryKey(const VehicleGeometry& g, bool coarse) {
  std::vector<std::int64_t> k;
  auto mm = [&](double v) { k.push_back(static_cast<std::int64_t>(std::llround(v * 1000))); };
  for (int w = 0; w < kWheels; ++w) {
    const auto i = static_cast<std::size_t>(w);
    mm(g.mount_B[i].x);
    mm(g.mount_B[i].y);
    mm(g.mount_B[i].z);
    mm(g.radius[i]);
    mm(g.free_length[i]);
  }
  mm(g.front);
  mm(g.rear);
  mm(g.half_width);
  k.push_back(coarse ? 1 : 0);
  return k;
}

// Surfaces that cast the sun's shadow (the flat ones do not: drawing them would cost the whole
// map's area).
bool CastsShadow(SurfaceStyle s) {
  return s == SurfaceStyle::kConcrete || s == SurfaceStyle::kHazard || s == SurfaceStyle::kPainted;
}

}  // namespace

GLuint LinkProgram(const std::string& vs, const std::string& fs, const char* what) {
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

std::string_view QualityName(Quality q) {
  return q == Quality::kLow ? "low" : "high";
}

std::optional<Quality> QualityFromName(std::string_view name) {
  if (name == "low") return Quality::kLow;
  if (name == "high") return Quality::kHigh;
  return std::nullopt;
}

RenderSettings SettingsFor(Quality q) {
  RenderSettings s;
  s.quality = q;
  if (q == Quality::kLow) {
    s.shadows = false;
    s.clouds = false;
    s.high_shading = false;
    s.texture_px = 256;
    s.srgb_textures = false;
    s.mirror_px = 128;
    s.mirror_interval = 3;  // one of the three mirrors a frame
  }
  return s;
}

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

void RenderTarget::UseWindow(int width, int height) {
  Release();
  width_ = std::max(width, 1);
  height_ = std::max(height, 1);
  samples_ = 0;
  use_external_ = false;
  external_ = 0;
  in_window_ = true;  // resolve_fbo_ 0: the window's framebuffer
}

bool WindowHasDepthStencil() {
  GLint bound = 0;
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &bound);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  // A buffer that is not there has the type GL_NONE (its sizes may not be asked).
  auto bits = [](GLenum buffer, GLenum size) {
    GLint type = GL_NONE, n = 0;
    glGetFramebufferAttachmentParameteriv(GL_FRAMEBUFFER, buffer,
                                          GL_FRAMEBUFFER_ATTACHMENT_OBJECT_TYPE, &type);
    if (type == GL_NONE) return 0;
    glGetFramebufferAttachmentParameteriv(GL_FRAMEBUFFER, buffer, size, &n);
    return n;
  };
  const bool enough = bits(GL_DEPTH, GL_FRAMEBUFFER_ATTACHMENT_DEPTH_SIZE) >= 24 &&
                      bits(GL_STENCIL, GL_FRAMEBUFFER_ATTACHMENT_STENCIL_SIZE) >= 8;
  glBindFramebuffer(GL_FRAMEBUFFER, static_cast<GLuint>(bound));
  return enough;
}

void RenderTarget::Resize(int width, int height, int samples, bool external_colour) {
  Release();
  in_window_ = false;
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
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH24_STENCIL8, width_, height_);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_STENCIL_ATTACHMENT, GL_RENDERBUFFER,
                              resolve_depth_);
  } else {
    glGenFramebuffers(1, &msaa_fbo_);
    glBindFramebuffer(GL_FRAMEBUFFER, msaa_fbo_);
    glGenRenderbuffers(1, &msaa_colour_);
    glBindRenderbuffer(GL_RENDERBUFFER, msaa_colour_);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples_, GL_RGBA8, width_, height_);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, msaa_colour_);
    glGenRenderbuffers(1, &msaa_depth_);
    glBindRenderbuffer(GL_RENDERBUFFER, msaa_depth_);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples_, GL_DEPTH24_STENCIL8, width_,
                                     height_);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_STENCIL_ATTACHMENT, GL_RENDERBUFFER,
                              msaa_depth_);
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
  glReadBuffer(in_window_ ? GL_BACK : GL_COLOR_ATTACHMENT0);
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

struct Renderer::Program {
  GLuint id = 0;
  Uniforms u;
  Program(const std::string& vs, const std::string& fs, const char* what) {
    id = LinkProgram(vs, fs, what);
    auto at = [&](const char* name) { return glGetUniformLocation(id, name); };
    u.view_proj = at("u_view_proj");
    u.model = at("u_model");
    u.eye = at("u_eye");
    u.fog = at("u_fog_m");
    u.paint = at("u_paint");
    u.alpha = at("u_alpha");
    u.frame = at("u_frame");
    u.half_size = at("u_half_size");
    u.strip = at("u_strip");
    u.grid = at("u_grid");
    u.surfaces = at("u_surfaces");
    u.shadow_map = at("u_shadow_map");
    u.shadow_mat = at("u_shadow_mat");
    u.shadow_box = at("u_shadow_box");
    u.shadow_texel = at("u_shadow_texel_uv");
    u.inv_view_proj = at("u_inv_view_proj");
    u.clouds = at("u_clouds");
    u.strength = at("u_strength");
    u.radius = at("u_radius");
    u.lights = at("u_lights");
    u.z_range = at("u_z_range");
    u.relief = at("u_relief");
    u.poster_a = at("u_poster_a");
    u.poster_b = at("u_poster_b");
    // Texture units: surfaces 0, the shadow map 1, clouds 2.
    glUseProgram(id);
    if (u.surfaces >= 0) glUniform1i(u.surfaces, 0);
    if (u.shadow_map >= 0) glUniform1i(u.shadow_map, 1);
    if (u.clouds >= 0) glUniform1i(u.clouds, 2);
    glUseProgram(0);
  }
  ~Program() { glDeleteProgram(id); }
  Program(const Program&) = delete;
  Program& operator=(const Program&) = delete;
};

namespace {

// An RGBA8 sRGB image as a texture layer, mipmapped.
void UploadLayer(GLenum target, int layer, const TextureImage& img) {
  if (target == GL_TEXTURE_2D_ARRAY) {
    glTexSubImage3D(target, 0, 0, 0, layer, img.size, img.size, 1, GL_RGBA, GL_UNSIGNED_BYTE,
                    img.rgba.data());
  } else {
    glTexImage2D(target, 0, GL_SRGB8_ALPHA8, img.size, img.size, 0, GL_RGBA, GL_UNSIGNED_BYTE,
                 img.rgba.data());
  }
}

// The image's colour (not its alpha) from sRGB to linear light, rounded to 8 bits.
void ToLinearBytes(TextureImage& img) {
  std::array<std::uint8_t, 256> table{};
  for (int i = 0; i < 256; ++i) {
    table[static_cast<std::size_t>(i)] =
        static_cast<std::uint8_t>(std::lround(255 * ToLinear(static_cast<std::uint8_t>(i))));
  }
  for (std::size_t k = 0; k < img.rgba.size(); ++k) {
    if (k % 4 != 3) img.rgba[k] = table[img.rgba[k]];
  }
}

}  // namespace

Renderer::Renderer(const RenderSettings& settings) : settings_(settings) {
  const std::string gl_renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  software_ = gl_renderer.find("llvmpipe") != std::string::npos ||
              gl_renderer.find("softpipe") != std::string::npos;
  shaders::Options o;
  o.high = settings_.high_shading;
  o.shadows = settings_.shadows;
  o.clouds = settings_.clouds;
  using shaders::Fragment;
  auto Vs = [](const char* body) { return shaders::Vertex(body); };
  for (SurfaceStyle style : {SurfaceStyle::kGrass, SurfaceStyle::kAsphalt}) {
    TerrainProgram(style, false, true);  // the common ones now, the rest when first drawn
    TerrainProgram(style, false, false);
  }
  model_ = std::make_unique<Program>(Vs(shaders::kModelVs), Fragment(o, shaders::kModelFs),
                                     "bodies and wheels");
  list_ = std::make_unique<Program>(Vs(shaders::kListVs), Fragment(o, shaders::kListFs),
                                    "arrows and landmarks");
  sky_ = std::make_unique<Program>(Vs(shaders::kSkyVs), Fragment(o, shaders::kSkyFs), "sky");
  hills_ =
      std::make_unique<Program>(Vs(shaders::kHillsVs), Fragment(o, shaders::kHillsFs), "far hills");
  contact_ = std::make_unique<Program>(Vs(shaders::kWorldQuadVs), Fragment(o, shaders::kContactFs),
                                       "contact shadows");
  depth_ = std::make_unique<Program>(Vs(shaders::kDepthVs), Vs(shaders::kDepthFs), "shadow map");
  mirror_ = std::make_unique<Program>(Vs(shaders::kWorldQuadVs), Fragment(o, shaders::kMirrorFs),
                                      "mirrors");
  glUseProgram(mirror_->id);
  glUniform1i(glGetUniformLocation(mirror_->id, "u_image"), kMirrorUnit);
  glUseProgram(0);
  glGenVertexArrays(1, &sky_vao_);
  {
    // The far hills' outline: elevation angles (rad) from a few waves around the horizon; the
    // ring's foot below the horizon, where the grass hides it.
    std::vector<float> v;
    constexpr int kSteps = 360;
    for (int i = 0; i <= kSteps; ++i) {
      const double az = 2 * kPi * i / kSteps;
      const double top = 0.011 + 0.006 * std::sin(3 * az + 0.7) + 0.004 * std::sin(7 * az + 2.1) +
                         0.002 * std::sin(17 * az + 0.3) + 0.0012 * std::sin(41 * az + 1.3);
      for (double e : {-0.02, top}) {
        v.insert(v.end(), {static_cast<float>(std::cos(az)), static_cast<float>(std::sin(az)),
                           static_cast<float>(e)});
      }
    }
    hills_vertices_ = static_cast<std::int32_t>(v.size() / 3);
    glGenVertexArrays(1, &hills_vao_);
    glGenBuffers(1, &hills_vbo_);
    glBindVertexArray(hills_vao_);
    glBindBuffer(GL_ARRAY_BUFFER, hills_vbo_);
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(v.size() * sizeof(float)), v.data(),
                 GL_STATIC_DRAW);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), nullptr);
    glBindVertexArray(0);
  }

  // The frame's lists: position, normal, colour.
  glGenVertexArrays(1, &dyn_vao_);
  glGenBuffers(1, &dyn_vbo_);
  glBindVertexArray(dyn_vao_);
  glBindBuffer(GL_ARRAY_BUFFER, dyn_vbo_);
  VertexLayout();
  // Contact shadows: position, corner.
  glGenVertexArrays(1, &contact_vao_);
  glGenBuffers(1, &contact_vbo_);
  glBindVertexArray(contact_vao_);
  glBindBuffer(GL_ARRAY_BUFFER, contact_vbo_);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 5 * sizeof(float), nullptr);
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 2, GL_FLOAT, GL_FALSE, 5 * sizeof(float),
                        reinterpret_cast<const void*>(3 * sizeof(float)));
  glBindVertexArray(0);

  // Textures, made in code: the surfaces as one array, the clouds.
  const int px = settings_.texture_px;
  glGenTextures(1, &surfaces_tex_);
  glBindTexture(GL_TEXTURE_2D_ARRAY, surfaces_tex_);
  const TextureLayer layers[] = {TextureLayer::kGrass,    TextureLayer::kAsphalt,
                                 TextureLayer::kConcrete, TextureLayer::kDirt,
                                 TextureLayer::kMacro,    TextureLayer::kPoster};
  constexpr int kLayers = static_cast<int>(std::size(layers));
  glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, settings_.srgb_textures ? GL_SRGB8_ALPHA8 : GL_RGBA8, px, px,
               kLayers, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
  for (int i = 0; i < kLayers; ++i) {
    TextureImage img = MakeTexture(layers[i], px);
    if (!settings_.srgb_textures) ToLinearBytes(img);
    UploadLayer(GL_TEXTURE_2D_ARRAY, i, img);
  }
  glGenerateMipmap(GL_TEXTURE_2D_ARRAY);
  // Low: one mip level a pixel (half the texels of trilinear filtering).
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER,
                  settings_.high_shading ? GL_LINEAR_MIPMAP_LINEAR : GL_LINEAR_MIPMAP_NEAREST);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_REPEAT);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_REPEAT);
  // (llvmpipe's anisotropic filtering costs seconds a frame.)
  if (!software_ && settings_.high_shading &&
      epoxy_has_gl_extension("GL_EXT_texture_filter_anisotropic")) {
    glTexParameterf(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAX_ANISOTROPY_EXT, 4.0f);
  }
  if (settings_.clouds) {
    glGenTextures(1, &clouds_tex_);
    glBindTexture(GL_TEXTURE_2D, clouds_tex_);
    UploadLayer(GL_TEXTURE_2D, 0, MakeTexture(TextureLayer::kClouds, 256));
    glGenerateMipmap(GL_TEXTURE_2D);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_REPEAT);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_REPEAT);
  }
  if (settings_.shadows) {
    const int s = settings_.shadow_map_px;
    glGenTextures(1, &shadow_tex_);
    glBindTexture(GL_TEXTURE_2D, shadow_tex_);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_DEPTH_COMPONENT16, s, s, 0, GL_DEPTH_COMPONENT,
                 GL_UNSIGNED_SHORT, nullptr);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_MODE, GL_COMPARE_REF_TO_TEXTURE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_FUNC, GL_LEQUAL);
    glGenFramebuffers(1, &shadow_fbo_);
    glBindFramebuffer(GL_FRAMEBUFFER, shadow_fbo_);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, shadow_tex_, 0);
    glDrawBuffer(GL_NONE);
    glReadBuffer(GL_NONE);
    CheckFramebuffer("sun's shadow map");
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
  }
  glBindTexture(GL_TEXTURE_2D, 0);
  glBindTexture(GL_TEXTURE_2D_ARRAY, 0);

  wheel_fine_ = Upload(BuildWheel(24));
  wheel_coarse_ = Upload(BuildWheel(10));
  if (const GLenum e = glGetError(); e != GL_NO_ERROR) {
    throw GlError("OpenGL error 0x" + std::to_string(e) + " while setting up the viewer");
  }
}

Renderer::~Renderer() {
  ClearTerrain();
  Free(wheel_fine_);
  Free(wheel_coarse_);
  Free(car_model_mesh_);
  for (auto& [key, mesh] : bodies_) Free(mesh);
  glDeleteVertexArrays(1, &sky_vao_);
  glDeleteVertexArrays(1, &hills_vao_);
  glDeleteBuffers(1, &hills_vbo_);
  glDeleteVertexArrays(1, &dyn_vao_);
  glDeleteBuffers(1, &dyn_vbo_);
  glDeleteVertexArrays(1, &contact_vao_);
  glDeleteBuffers(1, &contact_vbo_);
  glDeleteTextures(1, &surfaces_tex_);
  if (clouds_tex_ != 0) glDeleteTextures(1, &clouds_tex_);
  if (shadow_tex_ != 0) glDeleteTextures(1, &shadow_tex_);
  if (shadow_fbo_ != 0) glDeleteFramebuffers(1, &shadow_fbo_);
}

Renderer::GpuMesh Renderer::Upload(const ModelMesh& m) {
  GpuMesh g;
  g.count = static_cast<std::int32_t>(m.indices.size());
  glGenVertexArrays(1, &g.vao);
  glBindVertexArray(g.vao);
  glGenBuffers(1, &g.vbo);
  glBindBuffer(GL_ARRAY_BUFFER, g.vbo);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(m.vertices.size() * sizeof(ModelVertex)),
               m.vertices.data(), GL_STATIC_DRAW);
  const auto stride = static_cast<GLsizei>(sizeof(ModelVertex));
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride,
                        reinterpret_cast<const void*>(offsetof(ModelVertex, p)));
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride,
                        reinterpret_cast<const void*>(offsetof(ModelVertex, n)));
  glEnableVertexAttribArray(2);
  glVertexAttribPointer(2, 4, GL_UNSIGNED_BYTE, GL_TRUE, stride,
                        reinterpret_cast<const void*>(offsetof(ModelVertex, rgba)));
  glEnableVertexAttribArray(3);
  glVertexAttribIPointer(3, 1, GL_UNSIGNED_BYTE, stride,
                         reinterpret_cast<const void*>(offsetof(ModelVertex, material)));
  glGenBuffers(1, &g.ibo);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, g.ibo);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER,
               static_cast<GLsizeiptr>(m.indices.size() * sizeof(std::uint32_t)), m.indices.data(),
               GL_STATIC_DRAW);
  glBindVertexArray(0);
  return g;
}

Renderer::GpuMesh Renderer::UploadTerrain(const std::vector<TerrainVertex>& v,
                                          const std::vector<std::uint32_t>& i) {
  GpuMesh g;
  g.count = static_cast<std::int32_t>(i.size());
  glGenVertexArrays(1, &g.vao);
  glBindVertexArray(g.vao);
  glGenBuffers(1, &g.vbo);
  glBindBuffer(GL_ARRAY_BUFFER, g.vbo);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(v.size() * sizeof(TerrainVertex)), v.data(),
               GL_STATIC_DRAW);
  const auto stride = static_cast<GLsizei>(sizeof(TerrainVertex));
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride,
                        reinterpret_cast<const void*>(offsetof(TerrainVertex, p)));
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride,
                        reinterpret_cast<const void*>(offsetof(TerrainVertex, n)));
  glGenBuffers(1, &g.ibo);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, g.ibo);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(i.size() * sizeof(std::uint32_t)),
               i.data(), GL_STATIC_DRAW);
  glBindVertexArray(0);
  return g;
}

void Renderer::Free(GpuMesh& m) {
  if (m.vao != 0) glDeleteVertexArrays(1, &m.vao);
  if (m.vbo != 0) glDeleteBuffers(1, &m.vbo);
  if (m.ibo != 0) glDeleteBuffers(1, &m.ibo);
  m = GpuMesh{};
}

void Renderer::SetCarModel(std::shared_ptr<const ModelMesh> model) {
  Free(car_model_mesh_);
  car_model_ = std::move(model);
  if (car_model_) car_model_mesh_ = Upload(*car_model_);
}

const Renderer::GpuMesh& Renderer::BodyMesh(const BodyInstance& b) {
  if (car_model_) return car_model_mesh_;
  auto key = GeometryKey(b.geometry, b.coarse);
  auto it = bodies_.find(key);
  if (it == bodies_.end()) {
    if (bodies_.size() >= 64) {  // a bound on the cache: many geometries come and go rarely
      for (auto& [k, mesh] : bodies_) Free(mesh);
      bodies_.clear();
    }
    it = bodies_.emplace(std::move(key), Upload(BuildCarBody(b.geometry, b.coarse))).first;
  }
  return it->second;
}

Mat4 Renderer::BodyTransform(const BodyInstance& b) const {
  const Mat4 pose = FromPose(b.pose_WB);
  return car_model_ ? pose * FitModel(*car_model_, b.geometry, false) : pose;
}

void Renderer::ClearTerrain() {
  for (Terrain& t : terrain_meshes_) Free(t.mesh);
  terrain_meshes_.clear();
  Free(dressing_);
  dressing_chunks_.clear();
  terrain_triangles_ = 0;
}

void Renderer::SetTerrain(const TerrainData& t) {
  ClearTerrain();
  for (const TerrainMesh& tm : t.meshes) {
    Terrain m;
    m.style = tm.style;
    m.frame = tm.frame;
    m.chunks = tm.chunks;
    m.min_z = tm.min_W.z;
    m.max_z = tm.max_W.z;
    m.poster = tm.poster;
    // Low relief shaded steeper: rough ground (bumps of 0.3 m over metres), the washboard.
    if (tm.kind == pb::SURFACE_ROUGH) m.relief = 3.0;
    if (tm.kind == pb::SURFACE_OBSTACLE && tm.style == SurfaceStyle::kConcrete) m.relief = 4.0;
    m.translucent = tm.style == SurfaceStyle::kGlass;
    m.mesh = UploadTerrain(tm.vertices, tm.indices);
    terrain_meshes_.push_back(std::move(m));
  }
  // The grass beyond the world, to the horizon: a ring of four quads around the ground meshes'
  // bounds (inside, the world's own ground), at their lowest height.
  if (t.has_ground) {
    constexpr double kFar = 40000;
    const Vec3 lo = t.ground_min_W, hi = t.ground_max_W;
    const double z = lo.z - 0.01;
    std::vector<TerrainVertex> v;
    std::vector<std::uint32_t> idx;
    auto quad = [&](double x0, double y0, double x1, double y1) {
      const auto base = static_cast<std::uint32_t>(v.size());
      for (auto [x, y] : {std::pair{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}) {
        TerrainVertex tv{};
        tv.p[0] = static_cast<float>(x);
        tv.p[1] = static_cast<float>(y);
        tv.p[2] = static_cast<float>(z);
        tv.n[2] = 1.0f;
        v.push_back(tv);
      }
      for (std::uint32_t k : {0u, 1u, 2u, 0u, 2u, 3u}) idx.push_back(base + k);
    };
    quad(-kFar, -kFar, kFar, lo.y);  // south
    quad(-kFar, hi.y, kFar, kFar);   // north
    quad(-kFar, lo.y, lo.x, hi.y);   // west
    quad(hi.x, lo.y, kFar, hi.y);    // east
    Terrain m;
    m.style = SurfaceStyle::kGrass;
    TerrainChunk c;
    c.lods.fill({0, static_cast<std::uint32_t>(idx.size())});
    c.min_W = {-kFar, -kFar, z};
    c.max_W = {kFar, kFar, z};
    m.chunks = {c};
    m.mesh = UploadTerrain(v, idx);
    terrain_meshes_.push_back(std::move(m));
  }
  // What lies on the ground (road, bumps, rough patches) before the ground (drawn a little
  // further), so the depth test spares shading the grass under them; the grass beyond the world
  // after it; translucent meshes (the glass barrier) last.
  auto order = [](const Terrain& m) {
    if (m.translucent) return 3;
    if (m.style != SurfaceStyle::kGrass) return 0;
    return m.chunks.size() == 1 && m.chunks[0].max_W.x - m.chunks[0].min_W.x > 10000 ? 2 : 1;
  };
  std::stable_sort(terrain_meshes_.begin(), terrain_meshes_.end(),
                   [&](const Terrain& a, const Terrain& b) { return order(a) < order(b); });
  terrain_triangles_ = t.triangles;
  UploadDressing(MakeDressing(t, settings_.quality == Quality::kHigh));
}

void Renderer::UploadDressing(const Dressing& d) {
  if (d.list.vertices().empty()) return;
  dressing_.count = static_cast<std::int32_t>(d.list.vertices().size());
  glGenVertexArrays(1, &dressing_.vao);
  glBindVertexArray(dressing_.vao);
  glGenBuffers(1, &dressing_.vbo);
  glBindBuffer(GL_ARRAY_BUFFER, dressing_.vbo);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(d.list.vertices().size() * sizeof(Vertex)),
               d.list.vertices().data(), GL_STATIC_DRAW);
  VertexLayout();
  glBindVertexArray(0);
  dressing_chunks_ = d.chunks;
}

void Renderer::DrawDressing(const Mat4& view_proj) {
  if (dressing_chunks_.empty()) return;
  glUseProgram(list_->id);
  SetMat(list_->u.view_proj, view_proj);
  glUniform1f(list_->u.alpha, 1.0f);
  glBindVertexArray(dressing_.vao);
  for (const DressingChunk& c : dressing_chunks_) {
    const Vec3 centre = 0.5 * (c.min_W + c.max_W);
    if (!InFrustum(view_proj, centre, 0.5 * Norm(c.max_W - c.min_W))) continue;
    glDrawArrays(GL_TRIANGLES, static_cast<GLint>(c.first), static_cast<GLsizei>(c.count));
  }
  glBindVertexArray(0);
}

void Renderer::UseScene(const Program& p, const View& v, double fog_m) {
  glUseProgram(p.id);
  if (p.u.eye >= 0) SetVec3(p.u.eye, v.eye_W);
  if (p.u.fog >= 0) glUniform1f(p.u.fog, static_cast<float>(fog_m));
  if (settings_.shadows && p.u.shadow_mat >= 0) {
    SetMat(p.u.shadow_mat, shadow_mat_);
    const double r = settings_.shadow_radius_m;
    const double texel = 2 * r / settings_.shadow_map_px;
    // Not ready (no focus this frame): the box is empty, the sun reaches everything.
    glUniform4f(p.u.shadow_box, static_cast<float>(shadow_centre_W_.x),
                static_cast<float>(shadow_centre_W_.y),
                shadow_ready_ ? static_cast<float>(r) : -1.0f, static_cast<float>(texel));
    glUniform1f(p.u.shadow_texel, 1.0f / static_cast<float>(settings_.shadow_map_px));
  }
}

void Renderer::ShadowPass(const Vec3& focus, const FrameLists& lists) {
  const Vec3 L = SceneLighting().sun_W;
  const double r = settings_.shadow_radius_m;
  const int px = settings_.shadow_map_px;
  const double texel = 2 * r / px;
  // Looking down the sun's rays at the focus; the map's centre snapped to whole texels, so the
  // shadows do not crawl as the vehicle moves.
  constexpr double kBack = 200;
  Mat4 view = LookAt(focus + L * kBack, focus, {0, 0, 1});
  const Vec3 f_L = view.TransformPoint(focus);
  view(0, 3) -= std::round(f_L.x / texel) * texel;
  view(1, 3) -= std::round(f_L.y / texel) * texel;
  const Mat4 light = Orthographic(r, r, kBack - 150, kBack + 150) * view;
  Mat4 bias;
  bias(0, 0) = bias(1, 1) = bias(2, 2) = 0.5;
  bias(0, 3) = bias(1, 3) = bias(2, 3) = 0.5;
  shadow_mat_ = bias * light;
  shadow_centre_W_ = focus;
  shadow_ready_ = true;

  glBindFramebuffer(GL_FRAMEBUFFER, shadow_fbo_);
  glViewport(0, 0, px, px);
  glDepthMask(GL_TRUE);
  glClearDepth(1.0);
  glClear(GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);
  glEnable(GL_POLYGON_OFFSET_FILL);
  glPolygonOffset(1.5f, 3.0f);
  glUseProgram(depth_->id);
  SetMat(depth_->u.view_proj, light);
  SetMat(depth_->u.model, Mat4{});
  for (const Terrain& t : terrain_meshes_) {
    if (!CastsShadow(t.style)) continue;
    glBindVertexArray(t.mesh.vao);
    for (const TerrainChunk& c : t.chunks) {
      const Vec3 centre = 0.5 * (c.min_W + c.max_W);
      if (!InFrustum(light, centre, 0.5 * Norm(c.max_W - c.min_W))) continue;
      glDrawElements(
          GL_TRIANGLES, static_cast<GLsizei>(c.lods[0].count), GL_UNSIGNED_INT,
          reinterpret_cast<const void*>(static_cast<std::uintptr_t>(c.lods[0].first) * 4));
    }
  }
  for (const BodyInstance& b : lists.bodies) {
    if (!InFrustum(light, b.pose_WB.t, std::max(b.geometry.front, b.geometry.rear) + 1.0)) {
      continue;
    }
    const GpuMesh& m = BodyMesh(b);
    SetMat(depth_->u.model, BodyTransform(b));
    glBindVertexArray(m.vao);
    glDrawElements(GL_TRIANGLES, m.count, GL_UNSIGNED_INT, nullptr);
  }
  glBindVertexArray(wheel_coarse_.vao);  // the wheel's outline is all a shadow needs
  for (const WheelInstance& w : lists.wheels) {
    if (!InFrustum(light, w.centre_W, w.radius)) continue;
    SetMat(depth_->u.model, Scaled(w.R_WW, w.radius, w.centre_W));
    glDrawElements(GL_TRIANGLES, wheel_coarse_.count, GL_UNSIGNED_INT, nullptr);
  }
  glDisable(GL_POLYGON_OFFSET_FILL);
  glBindVertexArray(0);
}

const Renderer::Program& Renderer::TerrainProgram(SurfaceStyle style, bool grid, bool shadows) {
  shadows = shadows && settings_.shadows;
  const int key = static_cast<int>(style) * 4 + (grid ? 2 : 0) + (shadows ? 1 : 0);
  auto it = terrain_.find(key);
  if (it == terrain_.end()) {
    shaders::Options o;
    o.high = settings_.high_shading;
    o.shadows = shadows;
    o.clouds = settings_.clouds;
    o.grid = grid;
    o.style = static_cast<int>(style);
    it = terrain_
             .emplace(key, std::make_unique<Program>(shaders::VertexLit(o, shaders::kTerrainVs),
                                                     shaders::Fragment(o, shaders::kTerrainFs),
                                                     "terrain"))
             .first;
  }
  return *it->second;
}

void Renderer::DrawTerrain(const View& v, const Mat4& view_proj, double fog_m, bool translucent,
                           double grid_m) {
  glBindVertexArray(0);
  // A chunk is shaded with the shadow map only where the map's box reaches it.
  const double r = settings_.shadow_radius_m;
  auto in_shadow_box = [&](const TerrainChunk& c) {
    return shadow_ready_ && c.max_W.x >= shadow_centre_W_.x - r &&
           c.min_W.x <= shadow_centre_W_.x + r && c.max_W.y >= shadow_centre_W_.y - r &&
           c.min_W.y <= shadow_centre_W_.y + r;
  };
  for (const Terrain& t : terrain_meshes_) {
    if (t.translucent != translucent) continue;
    const Program* current = nullptr;
    // The ground a little further: where a road or a rough patch meets it at the same height,
    // they win (and an arrow lying on the road is hidden only by the road).
    if (t.style == SurfaceStyle::kGrass) {
      glEnable(GL_POLYGON_OFFSET_FILL);
      glPolygonOffset(1.0f, 2.0f);
    }
    glBindVertexArray(t.mesh.vao);
    for (const TerrainChunk& c : t.chunks) {
      const Vec3 centre = 0.5 * (c.min_W + c.max_W);
      if (!InFrustum(view_proj, centre, 0.5 * Norm(c.max_W - c.min_W))) continue;
      const Program& p =
          TerrainProgram(t.style, grid_m > 0 && t.style != SurfaceStyle::kGlass, in_shadow_box(c));
      if (&p != current) {
        UseScene(p, v, fog_m);
        SetMat(p.u.view_proj, view_proj);
        if (p.u.grid >= 0) glUniform1f(p.u.grid, static_cast<float>(grid_m));
        glUniform4f(p.u.frame, static_cast<float>(t.frame.centre_W.x),
                    static_cast<float>(t.frame.centre_W.y), static_cast<float>(t.frame.along_W.x),
                    static_cast<float>(t.frame.along_W.y));
        glUniform2f(p.u.half_size, static_cast<float>(t.frame.half_length_m),
                    static_cast<float>(t.frame.half_width_m));
        glUniform1f(p.u.strip, t.frame.strip ? 1.0f : 0.0f);
        if (p.u.relief >= 0) glUniform1f(p.u.relief, static_cast<float>(t.relief));
        if (p.u.z_range >= 0) {
          glUniform2f(p.u.z_range, static_cast<float>(t.min_z), static_cast<float>(t.max_z));
        }
        if (p.u.poster_a >= 0) {
          const PosterFace& f = t.poster;
          glUniform4f(p.u.poster_a, static_cast<float>(f.origin_W.x),
                      static_cast<float>(f.origin_W.y), static_cast<float>(f.origin_W.z),
                      static_cast<float>(f.width_m));
          glUniform4f(p.u.poster_b, static_cast<float>(f.right_W.x),
                      static_cast<float>(f.right_W.y), static_cast<float>(f.height_m),
                      f.present ? 1.0f : 0.0f);
        }
        current = &p;
      }
      // The level of detail by the distance from the eye to the chunk's box.
      const Vec3 near{std::clamp(v.eye_W.x, c.min_W.x, c.max_W.x),
                      std::clamp(v.eye_W.y, c.min_W.y, c.max_W.y),
                      std::clamp(v.eye_W.z, c.min_W.z, c.max_W.z)};
      const double d = Norm(near - v.eye_W);
      int lod = 0;
      while (lod + 1 < kTerrainLods && d >= kLodFromM[lod + 1]) ++lod;
      const TerrainChunk::Range& range = c.lods[static_cast<std::size_t>(lod)];
      glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(range.count), GL_UNSIGNED_INT,
                     reinterpret_cast<const void*>(static_cast<std::uintptr_t>(range.first) * 4));
    }
    glDisable(GL_POLYGON_OFFSET_FILL);
  }
  glBindVertexArray(0);
}

void Renderer::DrawModels(const Program& p, const FrameLists& lists, const Mat4& view_proj) {
  for (const BodyInstance& b : lists.bodies) {
    if (!InFrustum(
            view_proj, b.pose_WB.t,
            std::hypot(std::max(b.geometry.front, b.geometry.rear), b.geometry.half_width) + 0.5)) {
      continue;
    }
    const GpuMesh& m = BodyMesh(b);
    SetMat(p.u.model, BodyTransform(b));
    SetVec3(p.u.paint, Linear(b.paint));
    glUniform2f(p.u.lights, b.brake_lights ? 1.0f : 0.0f, b.reverse_lights ? 1.0f : 0.0f);
    if (b.from_inside) glEnable(GL_CULL_FACE);
    glBindVertexArray(m.vao);
    glDrawElements(GL_TRIANGLES, m.count, GL_UNSIGNED_INT, nullptr);
    glDisable(GL_CULL_FACE);
  }
  SetVec3(p.u.paint, {1, 1, 1});
  glUniform2f(p.u.lights, 0.0f, 0.0f);
  for (const WheelInstance& w : lists.wheels) {
    if (!InFrustum(view_proj, w.centre_W, w.radius)) continue;
    const GpuMesh& m = w.coarse ? wheel_coarse_ : wheel_fine_;
    SetMat(p.u.model, Scaled(w.R_WW, w.radius, w.centre_W));
    glBindVertexArray(m.vao);
    glDrawElements(GL_TRIANGLES, m.count, GL_UNSIGNED_INT, nullptr);
  }
  glBindVertexArray(0);
}

void Renderer::DrawContactShadows(const FrameLists& lists, const Mat4& view_proj) {
  if (lists.contact_shadows.empty()) return;
  std::vector<float> v;
  v.reserve(lists.contact_shadows.size() * 30);
  static constexpr float kUv[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
  for (const ContactShadow& s : lists.contact_shadows) {
    for (int k : {0, 1, 2, 0, 2, 3}) {
      const Vec3& p = s.corners_W[static_cast<std::size_t>(k)];
      v.insert(v.end(), {static_cast<float>(p.x), static_cast<float>(p.y),
                         static_cast<float>(p.z + 0.01), kUv[k][0], kUv[k][1]});
    }
  }
  glUseProgram(contact_->id);
  SetMat(contact_->u.view_proj, view_proj);
  glUniform1f(contact_->u.strength, 0.45f);
  glBindVertexArray(contact_vao_);
  glBindBuffer(GL_ARRAY_BUFFER, contact_vbo_);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(v.size() * sizeof(float)), v.data(),
               GL_STREAM_DRAW);
  glEnable(GL_BLEND);
  glBlendFunc(GL_ZERO, GL_SRC_COLOR);
  glDepthMask(GL_FALSE);
  glEnable(GL_POLYGON_OFFSET_FILL);
  glPolygonOffset(-2.0f, -4.0f);
  glDrawArrays(GL_TRIANGLES, 0, static_cast<GLsizei>(v.size() / 5));
  glDisable(GL_POLYGON_OFFSET_FILL);
  glDepthMask(GL_TRUE);
  glDisable(GL_BLEND);
  glBindVertexArray(0);
}

void Renderer::DrawList(const viewer::DrawList& list, Pass pass, const Mat4& view_proj) {
  if (list.vertices().empty()) return;
  glUseProgram(list_->id);
  SetMat(list_->u.view_proj, view_proj);
  glUniform1f(list_->u.alpha, pass == Pass::kGhost ? 0.35f : 1.0f);
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
  if (v.update_mirrors && !lists.mirrors.empty()) {
    GLint target_fbo = 0;
    GLint viewport[4] = {0, 0, 1, 1};
    glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &target_fbo);
    glGetIntegerv(GL_VIEWPORT, viewport);
    UpdateMirrors(v, lists);
    glBindFramebuffer(GL_FRAMEBUFFER, static_cast<GLuint>(target_fbo));
    glViewport(viewport[0], viewport[1], viewport[2], viewport[3]);
  }
  DrawScene(v, lists, false);
}

void Renderer::UpdateMirrors(const View& v, const FrameLists& lists) {
  const std::uint64_t frame = mirror_frames_++;
  const auto interval = static_cast<std::uint64_t>(std::max(settings_.mirror_interval, 1));
  const double far_m = std::min(FarOf(v.proj), 5000.0);
  for (const MirrorInstance& m : lists.mirrors) {
    const auto i = static_cast<std::size_t>(std::max(m.index, 0));
    if (mirror_targets_.size() <= i) mirror_targets_.resize(i + 1);
    // The rear-view mirror's image `mirror_px` wide, the side ones' half; their height by the
    // glass's aspect.
    const int w = std::max(i == 0 ? settings_.mirror_px : settings_.mirror_px / 2, 8);
    const int h = std::max(static_cast<int>(std::lround(w * m.tan_half_y / m.tan_half_x)), 8);
    auto& target = mirror_targets_[i];
    if (!target) target = std::make_unique<RenderTarget>();
    if (target->width() != w || target->height() != h) {
      target->Resize(w, h, 0);
    } else if ((frame + i) % interval != 0) {
      continue;  // not this one's turn
    }
    target->BeginScene();
    View mv;
    mv.eye_W = m.eye_W;
    mv.view = LookAt(m.eye_W, m.eye_W + m.look_W, m.up_W);
    mv.proj = Perspective(2 * std::atan(m.tan_half_y), m.tan_half_x / m.tan_half_y, 0.05, far_m);
    mv.haze = v.haze;
    DrawScene(mv, lists, true);
  }
}

void Renderer::DrawMirrorGlass(const FrameLists& lists, const Mat4& view_proj) {
  glUseProgram(mirror_->id);
  SetMat(mirror_->u.view_proj, view_proj);
  glBindVertexArray(contact_vao_);  // (the same layout: position, texture coordinates)
  glBindBuffer(GL_ARRAY_BUFFER, contact_vbo_);
  glActiveTexture(GL_TEXTURE0 + kMirrorUnit);
  for (const MirrorInstance& m : lists.mirrors) {
    const auto i = static_cast<std::size_t>(std::max(m.index, 0));
    if (i >= mirror_targets_.size() || !mirror_targets_[i]) continue;
    std::array<float, 30> v{};
    std::size_t n = 0;
    for (std::size_t k : {0, 1, 2, 0, 2, 3}) {
      const Vec3& p = m.glass_W[k];
      for (float f : {static_cast<float>(p.x), static_cast<float>(p.y), static_cast<float>(p.z),
                      m.uv[k][0], m.uv[k][1]}) {
        v[n++] = f;
      }
    }
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(sizeof v), v.data(), GL_STREAM_DRAW);
    glBindTexture(GL_TEXTURE_2D, mirror_targets_[i]->colour_texture());
    glDrawArrays(GL_TRIANGLES, 0, 6);
  }
  glBindTexture(GL_TEXTURE_2D, 0);
  glActiveTexture(GL_TEXTURE0);
  glBindVertexArray(0);
}

void Renderer::DrawScene(const View& v, const FrameLists& lists, bool in_mirror) {
  GLint target_fbo = 0;
  GLint viewport[4] = {0, 0, 1, 1};
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &target_fbo);
  glGetIntegerv(GL_VIEWPORT, viewport);
  glDisable(GL_CULL_FACE);
  glDisable(GL_SCISSOR_TEST);
  glDisable(GL_BLEND);
  const Mat4 view_proj = v.proj * v.view;
  const bool ortho = std::abs(v.proj(3, 3) - 1.0) < 1e-9;

  // The sun's shadow map around the focus: the followed vehicle, else where the view's centre
  // meets the ground (at most 30 m ahead).
  shadow_ready_ = false;
  if (settings_.shadows && !in_mirror) {
    Vec3 focus;
    if (v.focus_W) {
      focus = *v.focus_W;
    } else {
      const Mat4 inv = Inverse(view_proj);
      const Vec3 a = inv.TransformPoint({0, 0, -1}), b = inv.TransformPoint({0, 0, 1});
      const Vec3 d = Normalized(b - a);
      const double t = d.z < -1e-3 ? std::min(-(a.z) / d.z, 30.0) : 30.0;
      focus = a + d * t;
    }
    ShadowPass(focus, lists);
  }
  glBindFramebuffer(GL_FRAMEBUFFER, static_cast<GLuint>(target_fbo));
  glViewport(viewport[0], viewport[1], viewport[2], viewport[3]);

  // No colour clear: the sky, drawn at the far plane, covers every pixel nothing else does.
  glClearDepth(1.0);
  glDepthMask(GL_TRUE);
  glClearStencil(0);
  glStencilMask(0xFF);
  glClear(GL_DEPTH_BUFFER_BIT | GL_STENCIL_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D_ARRAY, surfaces_tex_);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, shadow_tex_);
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, clouds_tex_);
  glActiveTexture(GL_TEXTURE0);

  // Fog: thick at the far plane (it hides where the drawn world ends), at most 1.5 km deep.
  const double fog_m = v.haze && !ortho ? std::min(0.55 * FarOf(v.proj), 1500.0) : 0.0;
  const double grid_m = ortho ? v.grid_step_m : 0.0;
  for (const Program* p : {model_.get(), list_.get()}) {
    UseScene(*p, v, fog_m);
    SetMat(p->u.view_proj, view_proj);
  }

  // The terrain, the contact shadows on it, the landmarks; then the arrows, which the vehicles'
  // bodies never hide (the forces are what the viewer is for): they mark their pixels in the
  // stencil, where no body is drawn; the terrain hides them (a ghost shows where). The sky last of
  // what is opaque: only the pixels nothing covers are shaded (a software renderer pays for every
  // pixel).
  DrawTerrain(v, view_proj, fog_m, false, grid_m);
  DrawContactShadows(lists, view_proj);
  DrawList(lists.opaque, Pass::kOpaque, view_proj);
  DrawDressing(view_proj);
  glEnable(GL_STENCIL_TEST);
  // The cockpit marks its pixels (2): no arrow's ghost is drawn over it (an arrow of a car ahead
  // that the dashboard hides is simply hidden).
  glStencilFunc(GL_ALWAYS, 2, 0xFF);
  glStencilOp(GL_KEEP, GL_KEEP, GL_REPLACE);
  if (!in_mirror) {
    DrawList(lists.cockpit, Pass::kOpaque, view_proj);
    if (!lists.mirrors.empty()) DrawMirrorGlass(lists, view_proj);
  }
  glStencilFunc(GL_ALWAYS, 1, 0xFF);
  glStencilOp(GL_KEEP, GL_KEEP, GL_REPLACE);
  DrawList(lists.arrows, Pass::kOpaque, view_proj);
  glStencilFunc(GL_NOTEQUAL, 1, 0xFF);
  glStencilOp(GL_KEEP, GL_KEEP, GL_KEEP);
  glUseProgram(model_->id);
  DrawModels(*model_, lists, view_proj);
  glDisable(GL_STENCIL_TEST);
  if (!ortho) {
    glUseProgram(hills_->id);
    UseScene(*hills_, v, 0.0);
    SetMat(hills_->u.view_proj, view_proj);
    glUniform1f(hills_->u.radius, static_cast<float>(0.9 * std::min(FarOf(v.proj), 20000.0)));
    glBindVertexArray(hills_vao_);
    glDrawArrays(GL_TRIANGLE_STRIP, 0, hills_vertices_);
  }
  glUseProgram(sky_->id);
  UseScene(*sky_, v, 0.0);
  SetMat(sky_->u.inv_view_proj, Inverse(view_proj));
  glDepthMask(GL_FALSE);
  glBindVertexArray(sky_vao_);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  glDepthMask(GL_TRUE);

  glEnable(GL_BLEND);
  glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
  glDepthMask(GL_FALSE);
  DrawTerrain(v, view_proj, fog_m, true, 0.0);
  glDepthMask(GL_TRUE);
  glDisable(GL_BLEND);
  DrawList(lists.translucent, Pass::kTranslucent, view_proj);
  if (!in_mirror) {
    glEnable(GL_STENCIL_TEST);
    glStencilFunc(GL_NOTEQUAL, 2, 0xFF);
    glStencilOp(GL_KEEP, GL_KEEP, GL_KEEP);
    DrawList(lists.arrows, Pass::kGhost, view_proj);
    glDisable(GL_STENCIL_TEST);
  }
  glBindVertexArray(0);
  glUseProgram(0);
}

void Renderer::PresentToWindow(const RenderTarget& t, int window_width, int window_height) {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, t.resolve_framebuffer());
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, 0);
  glViewport(0, 0, window_width, window_height);
  // Fit the image into the window, keeping its aspect ratio; black bars where it does not fill
  // it (a clear of the whole window costs a software renderer half a millisecond).
  const double sx = static_cast<double>(window_width) / t.width();
  const double sy = static_cast<double>(window_height) / t.height();
  const double s = std::min(sx, sy);
  const int w = static_cast<int>(t.width() * s), h = static_cast<int>(t.height() * s);
  const int x0 = (window_width - w) / 2, y0 = (window_height - h) / 2;
  if (w != window_width || h != window_height) {
    glClearColor(0, 0, 0, 1);
    glClear(GL_COLOR_BUFFER_BIT);
  }
  // 1:1 (the usual case) by nearest texels: the same image, no filtering.
  glBlitFramebuffer(0, 0, t.width(), t.height(), x0, y0, x0 + w, y0 + h, GL_COLOR_BUFFER_BIT,
                    w == t.width() && h == t.height() ? GL_NEAREST : GL_LINEAR);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
}

}  // namespace vdyn::viewer

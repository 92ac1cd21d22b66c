// OpenGL 3.3 core drawing of the scene (through libepoxy): a sky, the terrain by surface kind with
// a grid and distance haze, the glass barrier translucent, and the frame's draw lists (vehicles,
// arrows, landmarks). It draws into a RenderTarget: an offscreen framebuffer (multisampled, then
// resolved into a colour texture) that the desktop window shows, a screenshot reads, and an
// OpenXR swapchain image receives. Needs a current GL 3.3 context; GL errors in construction
// throw std::runtime_error.
#pragma once

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "vdyn/viewer/draw_list.h"
#include "vdyn/viewer/math.h"
#include "vdyn/viewer/world_mesh.h"

namespace vdyn::viewer {

class GlError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// RGBA pixels, rows top to bottom.
struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgba;
};
// Writes a PNG (stb_image_write); false when the file cannot be written.
bool WritePng(const std::string& path, const Image& image);

class RenderTarget {
 public:
  RenderTarget() = default;
  ~RenderTarget();
  RenderTarget(const RenderTarget&) = delete;
  RenderTarget& operator=(const RenderTarget&) = delete;

  // (Re)creates the buffers for a size and sample count (clamped to what GL offers). With
  // `external_colour` the resolved image goes into that texture (an OpenXR swapchain image)
  // instead of one of its own; call SetExternalColour per acquired image.
  void Resize(int width, int height, int samples, bool external_colour = false);
  void SetExternalColour(std::uint32_t texture);
  // Binds the framebuffer the scene is drawn into, with its viewport.
  void BeginScene();
  // Resolves the multisampled scene into the colour texture and binds that framebuffer (for the
  // overlay drawn on top: the HUD).
  void Resolve();
  Image Read() const;  // the resolved colour
  std::uint32_t colour_texture() const { return external_ != 0 ? external_ : colour_tex_; }
  std::uint32_t resolve_framebuffer() const { return resolve_fbo_; }
  int width() const { return width_; }
  int height() const { return height_; }
  int samples() const { return samples_; }

 private:
  void Release();
  int width_ = 0, height_ = 0, samples_ = 0;
  std::uint32_t msaa_fbo_ = 0, msaa_colour_ = 0, msaa_depth_ = 0;
  std::uint32_t resolve_fbo_ = 0, colour_tex_ = 0, resolve_depth_ = 0;
  std::uint32_t external_ = 0;
  bool use_external_ = false;
};

// A landmark's post and its name.
struct LandmarkView {
  std::string name;
  Vec3 p_W;
};

class Renderer {
 public:
  Renderer();
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Uploads a world's terrain (replacing the one before); Clear draws none.
  void SetTerrain(const TerrainData& t);
  void ClearTerrain();
  std::size_t terrain_triangles() const { return terrain_triangles_; }

  struct View {
    Mat4 view, proj;
    Vec3 eye_W;
    double grid_step_m = 10;
    bool haze = true;
  };
  // Draws sky, terrain and the frame's lists into the bound target: opaque, then translucent,
  // then the arrows (full colour where seen, a faint ghost where hidden).
  void Draw(const View& v, const FrameLists& lists);

  // Blits a target's colour into the default framebuffer of a window (letterboxed, no scaling of
  // the aspect ratio).
  static void PresentToWindow(const RenderTarget& t, int window_width, int window_height);

 private:
  struct Mesh {
    std::uint32_t vao = 0, vbo = 0, ibo = 0;
    std::int32_t count = 0;
    SurfaceLook look;
  };
  enum class Pass { kOpaque, kTranslucent, kGhost };
  void DrawList(const viewer::DrawList& list, Pass pass, const View& v);
  std::uint32_t terrain_prog_ = 0, lit_prog_ = 0, sky_prog_ = 0;
  std::uint32_t sky_vao_ = 0;
  std::uint32_t dyn_vao_ = 0, dyn_vbo_ = 0;
  std::vector<Mesh> meshes_;
  std::size_t terrain_triangles_ = 0;
};

}  // namespace vdyn::viewer

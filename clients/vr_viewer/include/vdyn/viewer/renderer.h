// OpenGL 3.3 core drawing of the scene (through libepoxy), in linear light and encoded to sRGB at
// the end (lighting.h): a sky with the sun, far hills and clouds; the terrain by surface style
// with procedural textures (textures.h), road markings and kerbs, the grass carried on to the
// horizon and fogged towards it; the vehicles' bodies and wheels (car_model.h) with their contact
// shadows; the sun's shadow map fitted around the followed vehicle; the landmarks, and the force
// arrows in their exact colours (a faint ghost where something hides them).
//
// It draws into a RenderTarget: an offscreen framebuffer (multisampled, then resolved into a
// colour texture) that the desktop window shows, a screenshot reads, and an OpenXR swapchain image
// receives. Needs a current GL 3.3 context; GL errors in construction throw GlError.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "vdyn/viewer/car_model.h"
#include "vdyn/viewer/draw_list.h"
#include "vdyn/viewer/dressing.h"
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
  // The window's own back buffer (framebuffer 0, of that size, with a depth and stencil buffer)
  // as the target: the scene and the HUD are drawn where they are shown, without a copy of each
  // frame. No multisampling. Read() is valid only until the buffers are swapped.
  void UseWindow(int width, int height);
  bool in_window() const { return in_window_; }
  void SetExternalColour(std::uint32_t texture);
  // Binds the framebuffer the scene is drawn into, with its viewport.
  void BeginScene();
  // Resolves the multisampled scene into the colour texture and binds that framebuffer (for the
  // overlay drawn on top: the HUD).
  void Resolve();
  Image Read() const;  // the resolved colour (in the window: the back buffer, before the swap)
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
  bool in_window_ = false;
};

// Whether the current context's window (framebuffer 0) has the depth and stencil bits the scene
// needs, so that RenderTarget::UseWindow can draw into it.
bool WindowHasDepthStencil();

// A landmark's post and its name.
struct LandmarkView {
  std::string name;
  Vec3 p_W;
};

// Quality presets (`--quality`). Low draws no shadow map, no clouds, no glossy highlights and no
// large-scale variation of the grass, with smaller textures kept in linear light: on a software
// renderer it costs no more than the plain viewer before it. High is everything.
enum class Quality { kLow, kHigh };
std::string_view QualityName(Quality q);
std::optional<Quality> QualityFromName(std::string_view name);

struct RenderSettings {
  Quality quality = Quality::kHigh;
  bool shadows = true;          // the sun's shadow map
  int shadow_map_px = 1024;     // its size
  double shadow_radius_m = 20;  // half its side on the ground, around the followed vehicle
  bool clouds = true;
  bool high_shading = true;  // sun highlights, rough reflections, world specular; grass patches
  int texture_px = 512;      // surface textures' size
  // The surface textures stored as sRGB (decoded per texel when sampled) or already in linear
  // light (8 bits: coarser steps in the dark, unseen in the textures' grain; a software
  // renderer samples them faster).
  bool srgb_textures = true;
  // The cockpit's mirrors: the rear-view mirror's image this many pixels wide (the side mirrors'
  // half as wide), each drawn again every `mirror_interval` frames, the mirrors taking turns
  // (1: all every frame; 3: one a frame).
  int mirror_px = 256;
  int mirror_interval = 1;
};
RenderSettings SettingsFor(Quality q);

class Renderer {
 public:
  explicit Renderer(const RenderSettings& settings = SettingsFor(Quality::kHigh));
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  const RenderSettings& settings() const { return settings_; }
  // The body every vehicle gets instead of the built-in one (a file's model, LoadCarModel);
  // null: the built-in body.
  void SetCarModel(std::shared_ptr<const ModelMesh> model);

  // Uploads a world's terrain (replacing the one before); Clear draws none.
  void SetTerrain(const TerrainData& t);
  void ClearTerrain();
  std::size_t terrain_triangles() const { return terrain_triangles_; }
  // The dressing around the facility (dressing.h) made with the terrain: its triangles (0: none).
  std::size_t dressing_triangles() const { return dressing_.count / 3; }

  struct View {
    Mat4 view, proj;
    Vec3 eye_W;
    double grid_step_m = 10;  // on an orthographic view (the map): a grid on the ground
    bool haze = true;         // fog towards the horizon
    // The centre of the sun's shadow map (the followed vehicle); without it, where the view's
    // centre meets the ground, at most 30 m ahead.
    std::optional<Vec3> focus_W = std::nullopt;
    // The lists' mirrors drawn anew (due by the interval) before the view: false for a
    // headset's second eye (the first eye's images serve both).
    bool update_mirrors = true;
  };
  // Draws the sky, the terrain and the frame's lists into the bound target: the mirrors' images
  // and the shadow map first, then what is opaque, the sky, what is translucent, the arrows.
  void Draw(const View& v, const FrameLists& lists);

  // Blits a target's colour into the default framebuffer of a window (letterboxed, no scaling of
  // the aspect ratio).
  static void PresentToWindow(const RenderTarget& t, int window_width, int window_height);

 private:
  struct Program;
  struct GpuMesh {
    std::uint32_t vao = 0, vbo = 0, ibo = 0;
    std::int32_t count = 0;
  };
  struct Terrain {
    GpuMesh mesh;
    SurfaceStyle style = SurfaceStyle::kGrass;
    StripFrame frame;
    std::vector<TerrainChunk> chunks;
    double min_z = 0, max_z = 0;
    double relief = 1;  // its slopes shaded this much steeper
    PosterFace poster;
    bool translucent = false;
  };
  GpuMesh Upload(const ModelMesh& m);
  GpuMesh UploadTerrain(const std::vector<TerrainVertex>& v, const std::vector<std::uint32_t>& i);
  void UploadDressing(const Dressing& d);
  void Free(GpuMesh& m);
  const GpuMesh& BodyMesh(const BodyInstance& b);
  Mat4 BodyTransform(const BodyInstance& b) const;
  void ShadowPass(const Vec3& focus, const FrameLists& lists);
  const Program& TerrainProgram(SurfaceStyle style, bool grid, bool shadows);
  void DrawTerrain(const View& v, const Mat4& view_proj, double fog_m, bool translucent,
                   double grid_m);
  void DrawDressing(const Mat4& view_proj);
  void DrawModels(const Program& p, const FrameLists& lists, const Mat4& view_proj);
  void DrawContactShadows(const FrameLists& lists, const Mat4& view_proj);
  enum class Pass { kOpaque, kTranslucent, kGhost };
  void DrawList(const viewer::DrawList& list, Pass pass, const Mat4& view_proj);
  void UseScene(const Program& p, const View& v, double fog_m);
  // The scene of a view; `in_mirror`: a mirror's image (no shadow map, cockpit, mirrors or
  // arrows' ghosts).
  void DrawScene(const View& v, const FrameLists& lists, bool in_mirror);
  void UpdateMirrors(const View& v, const FrameLists& lists);
  void DrawMirrorGlass(const FrameLists& lists, const Mat4& view_proj);

  RenderSettings settings_;
  // By style, grid and shadows (chunks away from the shadow map's box go without), made when
  // first used.
  std::map<int, std::unique_ptr<Program>> terrain_;
  std::unique_ptr<Program> model_, list_, sky_, hills_, contact_, depth_, mirror_;
  std::vector<std::unique_ptr<RenderTarget>> mirror_targets_;  // by MirrorIndex
  std::uint64_t mirror_frames_ = 0;  // frames that drew the mirrors (whose turn it is)
  bool software_ = false;            // a software renderer (llvmpipe): no anisotropic filtering
  std::uint32_t sky_vao_ = 0;
  std::uint32_t hills_vao_ = 0, hills_vbo_ = 0;
  std::int32_t hills_vertices_ = 0;
  std::uint32_t dyn_vao_ = 0, dyn_vbo_ = 0;
  std::uint32_t contact_vao_ = 0, contact_vbo_ = 0;
  std::uint32_t surfaces_tex_ = 0, clouds_tex_ = 0;
  std::uint32_t shadow_fbo_ = 0, shadow_tex_ = 0;
  Mat4 shadow_mat_;  // world -> shadow map texture coordinates and depth
  Vec3 shadow_centre_W_;
  bool shadow_ready_ = false;
  std::vector<Terrain> terrain_meshes_;
  std::size_t terrain_triangles_ = 0;
  GpuMesh dressing_;  // vertices in the lists' layout, drawn by chunk (count: vertices)
  std::vector<DressingChunk> dressing_chunks_;
  GpuMesh wheel_fine_, wheel_coarse_;
  std::map<std::vector<std::int64_t>, GpuMesh> bodies_;  // built-in bodies by geometry
  std::shared_ptr<const ModelMesh> car_model_;
  GpuMesh car_model_mesh_;
};

}  // namespace vdyn::viewer

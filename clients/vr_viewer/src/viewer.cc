#include "vdyn/viewer/viewer.h"

#include <SDL.h>
#include <epoxy/gl.h>
#include <imgui.h>
#include <imgui_impl_opengl3.h>
#include <imgui_impl_sdl.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <stdexcept>

#include "vdyn/input.pb.h"
#include "vdyn/viewer/car_model.h"
#include "vdyn/viewer/cockpit.h"
#include "vdyn/viewer/params_editor.h"
#include "vdyn/viewer/world_mesh.h"
#include "vdyn/viewer/xr_session.h"

namespace vdyn::viewer {

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double rank = std::ceil(p / 100.0 * static_cast<double>(v.size()));
  const auto i = static_cast<std::size_t>(std::clamp(rank, 1.0, static_cast<double>(v.size())));
  return v[i - 1];
}

namespace {

constexpr std::size_t kMaxSamples = 1'000'000;  // frame and latency samples kept

ImU32 ImColour(Rgb8 c, int alpha = 255) {
  return IM_COL32(c.r, c.g, c.b, alpha);
}

std::string FormatSeconds(std::int64_t ns) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3f s", static_cast<double>(ns) * 1e-9);
  return b;
}

// printf into a string (the HUD's lines: drawn and kept for tests).
__attribute__((format(printf, 1, 2))) std::string Format(const char* fmt, ...) {
  char b[512];
  va_list args;
  va_start(args, fmt);
  std::vsnprintf(b, sizeof b, fmt, args);
  va_end(args);
  return b;
}

// A world that passed CheckWorld, with its extent.
struct AcceptedWorld {
  pb::WorldDescription desc;
  Vec3 min_W, max_W;
  std::uint64_t serial = 0;  // counts arrivals from its server
};

// The window's size in pixels (larger than its size in window units on a high-density screen):
// the size of the desktop target, which ImGui draws into at its framebuffer scale.
int DrawableWidth(SDL_Window* w) {
  int x = 0, y = 0;
  SDL_GL_GetDrawableSize(w, &x, &y);
  return std::max(x, 1);
}
int DrawableHeight(SDL_Window* w) {
  int x = 0, y = 0;
  SDL_GL_GetDrawableSize(w, &x, &y);
  return std::max(y, 1);
}

// A vehicle as received: its states (each passed CheckState), and what the frame shows of it.
// Without a state of the followed vehicle for this long its server is said to be silent, s.
constexpr double kSilenceS = 2.0;

struct Tracked {
  StateHistory history;
  std::uint64_t seen = 0;                // SessionView's count when last taken
  std::string server;                    // of its newest state
  pb::VehicleState drawn;                // at the frame's instant (interpolated)
  const pb::VehicleState* at = nullptr;  // the received state at or before the instant
  std::int64_t at_source_ns = 0;
  std::int64_t instant_ns = 0;       // the instant shown, publisher's clock
  std::int64_t last_instant_ns = 0;  // the previous frame's (latency counted when it moves)
  WheelSpin spin;                    // the wheels' turn, integrated frame by frame
  base::MonoTime arrived;            // when its newest state was taken here
};

// A key press held back until the frame's HUD has taken its input: keys typed into a text field
// never reach the hotkeys.
struct KeyPress {
  SDL_Keycode key;
  std::uint16_t mod;
};

// The headset's HUD panel in front of the head's reference pose (OpenXR axes), m: low and near
// (a dashboard) when seated, further when standing; it faces the eyes.
Pose HudPanel(bool seated) {
  const Vec3 at = seated ? Vec3{0, -0.32, -0.8} : Vec3{0, -0.5, -1.1};
  const Vec3 z = Normalized(-at);  // towards the eyes
  const Vec3 x = Normalized(Cross({0, 1, 0}, z), {1, 0, 0});
  Pose p;
  p.R.c[0] = x;
  p.R.c[1] = Cross(z, x);
  p.R.c[2] = z;
  p.t = at;
  return p;
}
// About 65 deg wide: the status panel's lines (some 55 characters) at a readable size.
constexpr double kHudWidthSeatedM = 1.1, kHudWidthStandingM = 1.5;
// The HUD's capital letters at least this tall as the eye sees them (about 0.8 deg reads well on
// headsets of 15-25 pixels per degree).
constexpr double kHudCapHeightDeg = 0.9;

}  // namespace

struct Viewer::Impl {
  Viewer& owner;
  transport::Participant participant;
  client::SessionView session;
  std::unique_ptr<ParamsEditor> params;
  SDL_Window* window = nullptr;
  SDL_GLContext gl = nullptr;
  bool imgui_ready = false;
  std::unique_ptr<Renderer> renderer;
  std::unique_ptr<RenderTarget> desktop;
  std::unique_ptr<Headset> xr;
  bool xr_ended = false;

  // Worlds that passed CheckWorld, by server; the one whose terrain is on the GPU.
  std::map<std::string, AcceptedWorld> worlds;
  std::string uploaded_server;
  std::uint64_t uploaded_serial = 0;
  bool uploaded = false;

  std::map<std::uint32_t, Tracked> tracked;
  // Each server's newest diagnostics seen (steps, sim time): a new one lists its vehicles.
  std::map<std::string, std::pair<std::uint64_t, std::int64_t>> diagnostics_seen;
  bool silence_said = false;  // "no states from server ..." logged for the followed vehicle
  std::map<std::string, ClockOffset> clocks;   // each publisher's clock, by server
  std::map<std::uint32_t, VehicleView> views;  // this frame's, for the followed server
  std::map<std::pair<std::uint32_t, std::string>, std::uint32_t> buttons;  // by vehicle, source
  FrameLists lists;

  bool show_params = false, legend_open = false, show_help = false;
  bool quit = false;
  bool dragging = false;
  base::MonoTime start = base::MonotonicNow();
  base::MonoTime next_frame = base::MonotonicNow();
  bool counting = false;
  Image last_image;
  bool have_image = false;   // the run's last frame is in last_image
  std::string f12_path;      // F12 asked for this frame's image, to be written there

  // The frame's display time (when it is expected on the screen), both clocks; the desktop's
  // lead from the scene to the screen (a running mean of the frames before).
  std::int64_t display_wall_ns = 0;
  base::MonoTime scene_at{0};
  double present_lead_ns = 0;

  // Keys of this frame (applied once the HUD has seen them), and whether an ImGui item (a text
  // field being typed into, a slider being dragged) had the input at the end of the last frame.
  std::vector<KeyPress> keys;
  bool item_active_before = false;

  // The HUD's lines and the labels, as last drawn (for tests).
  std::vector<std::string> hud_text;
  std::vector<ShownLabel> shown_labels;
  std::vector<LabelBox> hud_boxes;  // the HUD's panels and compass: no label under them

  // --follow of a vehicle that is not there (yet): when the first vehicle was seen, and what was
  // said about it.
  std::optional<base::MonoTime> first_vehicle_at;
  std::string missing_said;

  // Headset: where the head is taken to be in the reference space (the place's eye point goes
  // there); moved by recentring, back to the neutral head when the runtime recentres itself.
  Pose head_ref;
  std::uint64_t space_changes_seen = 0;
  bool recentre_pending = false;
  bool xr_waited = false;

  Impl(Viewer& v, const ViewerOptions& o)
      : owner(v), participant(o.domain), session(participant, Topics()) {}

  static client::SessionView::Topics Topics() {
    client::SessionView::Topics t;
    t.inputs = true;  // the paddle shifters turn the north camera
    return t;
  }

  const AcceptedWorld* WorldOf(const std::string& server) const {
    const auto it = worlds.find(server);
    return it == worlds.end() ? nullptr : &it->second;
  }

  // The server whose world is drawn: the followed vehicle's, else the first with a world.
  std::string CurrentServer() const {
    if (owner.followed_) {
      const auto it = tracked.find(*owner.followed_);
      if (it != tracked.end()) return it->second.server;
    }
    return worlds.empty() ? std::string() : worlds.begin()->first;
  }

  // The neutral head in the reference space: at the origin seated, standing at eye height.
  Pose NeutralHead() const {
    Pose p;
    if (xr && !owner.options_.xr_seated && !xr->standing_on_local()) {
      p.t.y = owner.options_.camera.eye_height;
    }
    return p;
  }

  // What the frame's stages share: the drawn server and world, the followed vehicle's view and
  // the camera. The camera's state is taken once, as the frame begins: a key that changes it
  // (applied after the HUD, ApplyKeys) counts from the next frame, so the HUD, the view and
  // what is left out of it (the own body from the driver's seat) always agree within a frame.
  struct FrameScene {
    std::string server;
    const AcceptedWorld* accepted = nullptr;
    const pb::WorldDescription* world = nullptr;
    const VehicleView* followed = nullptr;
    CameraState camera;
    CameraScene cs;
    CameraView cam;
  };

  // The stages of one frame, in order (Viewer::Frame).
  void HandleEvents();                                   // SDL: mouse, window; keys held back
  void WaitForDisplay();                                 // the display slot and its time
  void TakeSamples();                                    // DDS: states, worlds; followed vehicle
  FrameScene UpdateScene();                              // the vehicles at the display time
  void BuildHud(const FrameScene& f);                    // ImGui: panels, compass, labels
  void ApplyKeys();                                      // hotkeys the HUD did not take
  bool DrawHeadset(const FrameScene& f);                 // both eyes and the HUD panel
  void DrawDesktop(const FrameScene& f, bool xr_drawn);  // the window's target
  void SizeDesktop();                                    // the desktop's target, window's size
  bool CountFrame(const FrameScene& f, bool xr_drawn);   // counts it; true: it ends the run
  void Present(bool keep);                               // HUD on top, to the window
  void Account(base::MonoTime t0, bool xr_drawn);        // the frame's timing

  // Parts of the stages.
  void NoteMissingFollow();
  const pb::Diagnostics* PlayerOf(const std::string& server) const;
  void ForgetVehiclesGone();
  void NoteSilence();
  void HudStatus(const FrameScene& f, float right_px);  // its lines wrap before right_px
  void HudLabels(const FrameScene& f);
  void Line(const std::string& text, const ImVec4* colour = nullptr);
  void Occupied();

  // The draw lists for one view. `inside`: the followed vehicle seen from its own seat (its body
  // is left out). Vehicles out of sight are left out; far ones get fewer facets.
  void BuildLists(const FrameScene& f, const Mat4& view_proj, const Vec3& eye, bool ortho,
                  double metres_per_pixel, double fovy, int height_px, bool inside);
};

Viewer::Viewer(ViewerOptions options) : options_(std::move(options)) {
  if (options_.client_id.empty()) options_.client_id = "vdyn-viewer-" + std::to_string(getpid());
  impl_ = std::make_unique<Impl>(*this, options_);
  Impl& m = *impl_;
  m.session.on_world = [this](const pb::WorldDescription& w, const transport::SampleInfo&) {
    AcceptWorld(w);
  };
  m.session.on_state = [this](const pb::VehicleState& s, const transport::SampleInfo&) {
    const std::string why = CheckState(s);
    if (!why.empty()) {
      ++stats_.states_refused;
      stats_.last_refusal = why;
      impl_->session.drops().Count("state refused by the viewer", why);
    }
  };
  m.session.on_input = [this](const pb::DriverInput& in, const transport::SampleInfo&) {
    HandlePaddles(in);
  };
  OpenWindow();
  StartRenderer();
  StartImGui();
  m.params = std::make_unique<ParamsEditor>(m.participant, options_.client_id);
  StartHeadset();
}

void Viewer::AcceptWorld(const pb::WorldDescription& w) {
  Impl& im = *impl_;
  const std::string why = CheckWorld(w);
  if (!why.empty()) {
    ++stats_.worlds_refused;
    stats_.last_refusal = "world '" + w.name() + "' of server '" + w.server_id() + "': " + why;
    im.session.drops().Count("world refused by the viewer", why);
    spdlog::warn("vdyn-viewer: refused {}; keeping the world drawn before", stats_.last_refusal);
    return;
  }
  ++stats_.worlds_accepted;
  AcceptedWorld& a = im.worlds[w.server_id()];
  a.desc = w;
  ++a.serial;
  constexpr double kBig = 1e300;
  a.min_W = {kBig, kBig, kBig};
  a.max_W = {-kBig, -kBig, -kBig};
  std::size_t triangles = 0;
  for (const pb::Mesh& mesh : w.meshes()) {
    triangles += static_cast<std::size_t>(mesh.indices_size() / 3);
    for (int i = 0; i + 2 < mesh.vertices_size(); i += 3) {
      const Vec3 v{mesh.vertices(i), mesh.vertices(i + 1), mesh.vertices(i + 2)};
      a.min_W = {std::min(a.min_W.x, v.x), std::min(a.min_W.y, v.y), std::min(a.min_W.z, v.z)};
      a.max_W = {std::max(a.max_W.x, v.x), std::max(a.max_W.y, v.y), std::max(a.max_W.z, v.z)};
    }
  }
  spdlog::info("vdyn-viewer: world '{}' of server '{}': {} meshes, {} triangles, {} landmarks",
               w.name(), w.server_id(), w.meshes_size(), triangles, w.landmarks_size());
}

// LIVE or PLAYBACK: a player says what it is on vdyn/diagnostics (mode "playback", the recording,
// the servers it replays): the player of `server`'s vehicles, or none.
const pb::Diagnostics* Viewer::Impl::PlayerOf(const std::string& server) const {
  const pb::Diagnostics* player = nullptr;
  for (const auto& [id, d] : session.diagnostics()) {
    if (d.mode() != "playback") continue;
    const auto& rs = d.replayed_servers();
    if (id == server || rs.empty() || std::find(rs.begin(), rs.end(), server) != rs.end()) {
      player = &d;
    }
  }
  return player;
}

void Viewer::HandlePaddles(const pb::DriverInput& in) {
  Impl& im = *impl_;
  std::uint32_t& prev = im.buttons[{in.vehicle_id(), in.source_id()}];
  const std::uint32_t pressed = in.buttons() & ~prev;
  prev = in.buttons();
  // The paddles of the followed vehicle's driver (any vehicle's while none is followed).
  if (followed_ && *followed_ != in.vehicle_id()) return;
  // The wheel's camera button: the next camera, as C (it was sent and nothing read it).
  if (pressed & pb::BUTTON_CAMERA) {
    CameraState& c = options_.camera;
    c.mode = static_cast<CameraMode>((static_cast<int>(c.mode) + 1) % kCameraModes);
    ++stats_.camera_buttons;
    spdlog::info("vdyn-viewer: camera button from '{}': the {} camera", in.source_id(),
                 CameraName(c.mode));
  }
  // Live, a full-model car's paddles are its gearbox: a shift turned the map and north cameras.
  // They turn the camera in playback (the paper's use) and for a car without a gearbox (paper).
  const auto t = im.tracked.find(in.vehicle_id());
  const bool playback = options_.playback || (t != im.tracked.end() && im.PlayerOf(t->second.server));
  const bool gearbox = t != im.tracked.end() && !t->second.history.empty() &&
                       t->second.history.newest().model() != pb::VEHICLE_MODEL_PAPER;
  if (!playback && gearbox) return;
  int turn = 0;
  if (pressed & pb::BUTTON_PADDLE_LEFT) ++turn;
  if (pressed & pb::BUTTON_PADDLE_RIGHT) --turn;
  if (turn != 0) {
    TurnGeographic(options_.camera, turn);
    ++stats_.paddle_presses;
    spdlog::info("vdyn-viewer: paddle {} from '{}': the geographic camera turned {} (Q/E do the "
                 "same; N back to north)",
                 turn > 0 ? "left" : "right", in.source_id(),
                 turn > 0 ? "counter-clockwise" : "clockwise");
  }
}

void Viewer::OpenWindow() {
  Impl& m = *impl_;
  // Window and OpenGL 3.3 core.
  SDL_SetHint(SDL_HINT_VIDEO_X11_FORCE_EGL, "0");  // GLX: OpenXR's Xlib binding needs it
  if (std::getenv("WAYLAND_DISPLAY") == nullptr && std::getenv("XDG_RUNTIME_DIR") == nullptr) {
    // No Wayland compositor can be reached: SDL's Wayland driver would only print a stray
    // "XDG_RUNTIME_DIR is invalid or not set" before the offscreen fallback says what happened.
    SDL_SetHint(SDL_HINT_VIDEODRIVER, "x11,offscreen");
  }
  if (SDL_Init(SDL_INIT_VIDEO | SDL_INIT_EVENTS) != 0) {
    throw std::runtime_error(std::string("no display (SDL: ") + SDL_GetError() +
                             "); run it on a desktop, or headless under Xvfb (xvfb-run -s "
                             "'-screen 0 1280x720x24' vdyn-viewer ...)");
  }
  SDL_GL_SetAttribute(SDL_GL_CONTEXT_MAJOR_VERSION, 3);
  SDL_GL_SetAttribute(SDL_GL_CONTEXT_MINOR_VERSION, 3);
  SDL_GL_SetAttribute(SDL_GL_CONTEXT_PROFILE_MASK, SDL_GL_CONTEXT_PROFILE_CORE);
  SDL_GL_SetAttribute(SDL_GL_DOUBLEBUFFER, 1);
  // Drawn in the window, the scene needs the window's depth and stencil; else it has its own.
  const bool in_window = options_.in_window && !options_.hidden;
  SDL_GL_SetAttribute(SDL_GL_DEPTH_SIZE, in_window ? 24 : 0);
  SDL_GL_SetAttribute(SDL_GL_STENCIL_SIZE, in_window ? 8 : 0);
  Uint32 flags = SDL_WINDOW_OPENGL;
  if (!options_.xr) flags |= SDL_WINDOW_RESIZABLE;
  if (options_.hidden) flags |= SDL_WINDOW_HIDDEN;
  m.window = SDL_CreateWindow("vdyn-viewer", SDL_WINDOWPOS_CENTERED, SDL_WINDOWPOS_CENTERED,
                              options_.width, options_.height, flags);
  if (m.window == nullptr) {
    const std::string e = SDL_GetError();
    SDL_Quit();
    throw std::runtime_error("cannot open a window: " + e);
  }
  m.gl = SDL_GL_CreateContext(m.window);
  if (m.gl == nullptr) {
    const std::string e = SDL_GetError();
    SDL_DestroyWindow(m.window);
    SDL_Quit();
    throw std::runtime_error("no OpenGL 3.3 core context: " + e);
  }
  SDL_GL_MakeCurrent(m.window, m.gl);
  if (std::string(SDL_GetCurrentVideoDriver()) == "offscreen" && !options_.hidden) {
    spdlog::warn(
        "vdyn-viewer: no display (SDL fell back to its offscreen driver): drawing without "
        "a window; --screenshot writes what is drawn. Run it on a desktop, or under Xvfb "
        "(xvfb-run) for OpenXR");
  }
  SDL_GL_SetSwapInterval(0);  // the frame rate is paced here (--fps)
  stats_.renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  spdlog::info("vdyn-viewer: OpenGL {} on {} (SDL video: {})",
               reinterpret_cast<const char*>(glGetString(GL_VERSION)), stats_.renderer,
               SDL_GetCurrentVideoDriver());
}

void Viewer::StartRenderer() {
  Impl& m = *impl_;
  if (options_.samples < 0) {
    // Multisampling doubles the frame time of a software renderer: off there unless asked for.
    const bool software = stats_.renderer.find("llvmpipe") != std::string::npos ||
                          stats_.renderer.find("softpipe") != std::string::npos;
    options_.samples = software ? 0 : 4;
  }
  m.renderer = std::make_unique<Renderer>(SettingsFor(options_.quality));
  if (options_.car_model) m.renderer->SetCarModel(options_.car_model);
  {
    const RenderSettings& rs = m.renderer->settings();
    spdlog::info("vdyn-viewer: quality {} ({}, {}, {}); the {} car body", QualityName(rs.quality),
                 rs.shadows ? "sun shadows" : "no sun shadows", rs.clouds ? "clouds" : "no clouds",
                 rs.high_shading ? "glossy highlights" : "no glossy highlights",
                 options_.car_model ? "file's" : "built-in");
  }
  m.desktop = std::make_unique<RenderTarget>();
  m.SizeDesktop();
  spdlog::info("vdyn-viewer: the scene is drawn {}",
               m.desktop->in_window() ? "straight into the window"
                                      : "into a target of its own, copied to the window");
}

void Viewer::Impl::SizeDesktop() {
  const ViewerOptions& o = owner.options_;
  const int w = DrawableWidth(window), h = DrawableHeight(window);
  // Not in the offscreen driver's surface or a hidden window, whose pixels GL need not keep.
  if (o.in_window && !o.hidden && o.samples == 0 &&
      std::string(SDL_GetCurrentVideoDriver()) != "offscreen" && WindowHasDepthStencil()) {
    desktop->UseWindow(w, h);
  } else {
    desktop->Resize(w, h, o.samples);
  }
  owner.stats_.drawn_in_window = desktop->in_window();
}

void Viewer::StartImGui() {
  Impl& m = *impl_;
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGuiIO& io = ImGui::GetIO();
  io.IniFilename = nullptr;  // no imgui.ini in the working folder
  ImGui::StyleColorsDark();
  ImGui::GetStyle().WindowRounding = 4;
  ImGui::GetStyle().Alpha = 0.95f;
  ImGui_ImplSDL2_InitForOpenGL(m.window, m.gl);
  ImGui_ImplOpenGL3_Init("#version 330 core");
  m.imgui_ready = true;
}

void Viewer::StartHeadset() {
  Impl& m = *impl_;
  ImGuiIO& io = ImGui::GetIO();
  stats_.xr_status = "off";
  if (options_.xr) {
    XrOptions xo;
    xo.seated = options_.xr_seated;
    xo.hud = options_.hud;
    xo.hud_width = DrawableWidth(m.window);  // the HUD is drawn at the window's size
    xo.hud_height = DrawableHeight(m.window);
    xo.hud_width_m = options_.xr_seated ? kHudWidthSeatedM : kHudWidthStandingM;
    xo.samples = options_.samples;
    try {
      m.xr = std::make_unique<Headset>(xo);
      stats_.xr_status = "runtime '" + m.xr->runtime_name() + "'";
      m.head_ref = m.NeutralHead();
      // The HUD panel readable where it hangs: its text scaled so capitals subtend
      // kHudCapHeightDeg at the eyes (ImGui's font: 13 px, capitals 7.5 px).
      const double distance = Norm(HudPanel(options_.xr_seated).t);
      const double deg_per_px = Deg(xo.hud_width_m / xo.hud_width / distance);
      io.FontGlobalScale =
          static_cast<float>(std::clamp(kHudCapHeightDeg / (7.5 * deg_per_px), 1.0, 4.0));
      // In a headset the first camera is where the person is: at the driver's seat seated,
      // beside the vehicle standing (unless --camera chose).
      if (!options_.camera_chosen) {
        options_.camera.mode = options_.xr_seated ? CameraMode::kDriver : CameraMode::kBeside;
      }
    } catch (const XrError& e) {
      stats_.xr_status = std::string("desktop fallback: ") + e.what();
      spdlog::warn("vdyn-viewer: {}; showing the desktop window instead", e.what());
    }
  }
}

Viewer::~Viewer() {
  Impl& m = *impl_;
  if (m.xr) {
    // Leave the headset the way the runtime expects: request, then follow its events.
    try {
      m.xr->RequestExit();
      const auto deadline = base::MonotonicNow() + base::Seconds(5);
      while (m.xr->PollEvents() && base::MonotonicNow() < deadline) {
        if (m.xr->running()) {
          m.xr->EmptyFrame();  // frames go on, with nothing to show, until the runtime stops
        } else {
          SDL_Delay(5);
        }
      }
    } catch (const std::exception& e) {
      spdlog::warn("vdyn-viewer: OpenXR at exit: {}", e.what());
    }
    m.xr.reset();
  }
  m.params.reset();
  if (m.imgui_ready) {
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplSDL2_Shutdown();
    ImGui::DestroyContext();
  }
  m.renderer.reset();
  m.desktop.reset();  // GL objects go before their context
  if (m.gl != nullptr) SDL_GL_DeleteContext(m.gl);
  if (m.window != nullptr) SDL_DestroyWindow(m.window);
  SDL_Quit();
}

bool Viewer::xr_active() const {
  return impl_->xr != nullptr && !impl_->xr_ended;
}
ParamsEditor& Viewer::params_editor() {
  return *impl_->params;
}
client::SessionView& Viewer::session() {
  return impl_->session;
}

const VehicleView* Viewer::vehicle(std::uint32_t id) const {
  const auto it = impl_->views.find(id);
  return it == impl_->views.end() ? nullptr : &it->second;
}

bool Viewer::ready() const {
  if (!followed_) return false;
  const auto it = impl_->tracked.find(*followed_);
  return it != impl_->tracked.end() && impl_->WorldOf(it->second.server) != nullptr;
}

const pb::VehicleState* Viewer::shown_state(std::uint32_t id) const {
  const auto it = impl_->tracked.find(id);
  return it == impl_->tracked.end() ? nullptr : it->second.at;
}

const std::vector<std::string>& Viewer::hud_text() const {
  return impl_->hud_text;
}

const std::vector<Viewer::ShownLabel>& Viewer::labels() const {
  return impl_->shown_labels;
}

const std::vector<LabelBox>& Viewer::hud_boxes() const {
  return impl_->hud_boxes;
}

Image Viewer::Screenshot() const {
  if (impl_->have_image || impl_->desktop->in_window()) return impl_->last_image;
  return impl_->desktop->Read();
}

void Viewer::WriteStats(const std::string& path) const {
  std::ofstream out(path);
  const auto& s = stats_;
  double mean = 0;
  for (double f : s.frame_ms) mean += f / static_cast<double>(s.frame_ms.size());
  out << "frames " << s.frames << "\n"
      << "xr_frames " << s.xr_frames << "\n"
      << "frame_ms_mean " << mean << "\n"
      << "frame_ms_p50 " << Percentile(s.frame_ms, 50) << "\n"
      << "frame_ms_p99 " << Percentile(s.frame_ms, 99) << "\n"
      << "latency_samples " << s.latency_ms.size() << "\n"
      << "latency_ms_p50 " << Percentile(s.latency_ms, 50) << "\n"
      << "latency_ms_p99 " << Percentile(s.latency_ms, 99) << "\n"
      << "worlds_accepted " << s.worlds_accepted << "\n"
      << "worlds_refused " << s.worlds_refused << "\n"
      << "states_refused " << s.states_refused << "\n"
      << "paddle_presses " << s.paddle_presses << "\n"
      << "vehicles " << impl_->tracked.size() << "\n"
      << "last_display_mono_ns " << s.last_display_mono_ns << "\n"
      << "geo_turn_deg " << Deg(options_.camera.geo_turn) << "\n"
      << "drops_total " << impl_->session.drops().Total() << "\n";
  for (const auto& [kind, n] : impl_->session.drops().Snapshot()) {
    std::string k = kind;
    std::replace(k.begin(), k.end(), ' ', '_');
    out << "drop." << k << " " << n << "\n";
  }
  out << "renderer " << s.renderer << "\n"
      << "quality " << QualityName(options_.quality) << "\n"
      << "drawn_in_window " << (s.drawn_in_window ? 1 : 0) << "\n"
      << "xr " << s.xr_status << "\n";
}

int Viewer::Run() {
  while (Frame()) {
  }
  return Finish();
}

int Viewer::Finish() {
  int code = 0;
  if (!options_.screenshot.empty()) {
    if (WritePng(options_.screenshot, Screenshot())) {
      spdlog::info("vdyn-viewer: screenshot written to {}", options_.screenshot);
    } else {
      spdlog::error("vdyn-viewer: cannot write the screenshot {}", options_.screenshot);
      code = 1;
    }
  }
  if (!options_.stats_out.empty()) {
    WriteStats(options_.stats_out);
    if (!std::ifstream(options_.stats_out)) {
      spdlog::error("vdyn-viewer: cannot write {}", options_.stats_out);
      code = 1;
    }
  }
  return code;
}

namespace {

// Screen position (pixels, y down) of a world point, or false behind the camera.
bool Project(const CameraView& cam, int w, int h, const Vec3& p, ImVec2& out) {
  double clip_w = 0;
  const Vec3 c = (cam.proj * cam.view).TransformPoint(p, &clip_w);
  if (clip_w <= 1e-6) return false;
  const double x = c.x / clip_w, y = c.y / clip_w;
  if (std::abs(x) > 1.2 || std::abs(y) > 1.2) return false;
  out = ImVec2(static_cast<float>((x * 0.5 + 0.5) * w), static_cast<float>((0.5 - y * 0.5) * h));
  return true;
}

// The compass: a dial at the top right; the red needle points where north is, the letters turn
// with it. Drawn into the HUD so it shows in the headset too; its size follows the HUD's text.
void DrawCompass(ImDrawList* dl, ImVec2 centre, float radius, double north_angle,
                 double heading_deg) {
  const float s = radius / 55.0f;
  dl->AddCircleFilled(centre, radius, IM_COL32(20, 24, 32, 200), 48);
  dl->AddCircle(centre, radius, IM_COL32(230, 230, 230, 255), 48, 2.0f);
  auto dir = [&](double a) {  // counter-clockwise from up, screen y down
    return ImVec2(static_cast<float>(-std::sin(a)), static_cast<float>(-std::cos(a)));
  };
  const char* letters[] = {"N", "W", "S", "E"};
  for (int i = 0; i < 4; ++i) {
    const ImVec2 d = dir(north_angle + i * kPi / 2);
    const ImVec2 p(centre.x + d.x * radius * 0.78f - 4 * s,
                   centre.y + d.y * radius * 0.78f - 7 * s);
    dl->AddText(p, i == 0 ? IM_COL32(255, 90, 90, 255) : IM_COL32(220, 220, 220, 255), letters[i]);
  }
  const ImVec2 n = dir(north_angle), side = ImVec2(-n.y, n.x);
  const float len = radius * 0.55f, half = radius * 0.13f;
  const ImVec2 tip(centre.x + n.x * len, centre.y + n.y * len);
  const ImVec2 tail(centre.x - n.x * len, centre.y - n.y * len);
  const ImVec2 l(centre.x + side.x * half, centre.y + side.y * half);
  const ImVec2 r(centre.x - side.x * half, centre.y - side.y * half);
  dl->AddTriangleFilled(l, tip, r, IM_COL32(235, 40, 40, 255));
  dl->AddTriangleFilled(r, tail, l, IM_COL32(235, 235, 235, 255));
  char b[32];
  std::snprintf(b, sizeof b, "view %03.0f deg", heading_deg);
  dl->AddText(ImVec2(centre.x - 34 * s, centre.y + radius + 4 * s), IM_COL32(235, 235, 235, 255),
              b);
}

}  // namespace

// One frame, as its stages.
bool Viewer::Frame() {
  Impl& m = *impl_;
  const base::MonoTime t0 = base::MonotonicNow();
  m.HandleEvents();
  m.WaitForDisplay();
  m.TakeSamples();
  const Impl::FrameScene f = m.UpdateScene();
  m.BuildHud(f);
  m.ApplyKeys();
  const bool xr_drawn = m.DrawHeadset(f);
  m.DrawDesktop(f, xr_drawn);
  const bool last = m.CountFrame(f, xr_drawn);
  m.Present(last);
  m.Account(t0, xr_drawn);
  if (last) m.quit = true;
  return !m.quit;
}

void Viewer::Impl::HandleEvents() {
  ViewerOptions& o = owner.options_;
  ImGuiIO& io = ImGui::GetIO();
  keys.clear();
  SDL_Event ev;
  while (SDL_PollEvent(&ev)) {
    ImGui_ImplSDL2_ProcessEvent(&ev);
    switch (ev.type) {
      case SDL_QUIT:
        quit = true;
        break;
      case SDL_WINDOWEVENT:
        if (ev.window.event == SDL_WINDOWEVENT_CLOSE) quit = true;
        if (ev.window.event == SDL_WINDOWEVENT_SIZE_CHANGED && !o.xr) {
          o.width = std::max(ev.window.data1, 64);
          o.height = std::max(ev.window.data2, 64);
          SizeDesktop();
        }
        break;
      case SDL_KEYDOWN:
        // Held back: whether the HUD takes it (a field being typed into) is known once the HUD
        // has seen this frame's input (ApplyKeys).
        keys.push_back({ev.key.keysym.sym, ev.key.keysym.mod});
        break;
      case SDL_MOUSEBUTTONDOWN:
        if (!io.WantCaptureMouse) dragging = true;
        break;
      case SDL_MOUSEBUTTONUP:
        dragging = false;
        break;
      case SDL_MOUSEMOTION:
        if (dragging && !io.WantCaptureMouse) {
          CameraState& c = o.camera;
          if (c.mode != CameraMode::kOrbit && c.mode != CameraMode::kMap) {
            // Dragging starts orbiting from where the camera is.
            const VehicleView* fv = owner.followed_ ? owner.vehicle(*owner.followed_) : nullptr;
            const Vec3 d = owner.last_camera_.eye_W - (fv != nullptr ? fv->pose_WB.t : Vec3{});
            c.orbit_yaw = std::atan2(d.y, d.x);
            c.orbit_distance = std::clamp(Norm(d), 1.0, 2000.0);
            c.orbit_pitch = std::clamp(
                std::asin(std::clamp(d.z / std::max(Norm(d), 1e-9), -1.0, 1.0)), Rad(-5), Rad(89));
            c.mode = CameraMode::kOrbit;
          }
          if (c.mode == CameraMode::kOrbit) {
            c.orbit_yaw -= ev.motion.xrel * 0.006;
            c.orbit_pitch = std::clamp(c.orbit_pitch + ev.motion.yrel * 0.006, Rad(-5), Rad(89));
          }
        }
        break;
      case SDL_MOUSEWHEEL:
        if (!io.WantCaptureMouse) {
          CameraState& c = o.camera;
          const double factor = std::pow(0.9, ev.wheel.y);
          switch (c.mode) {
            case CameraMode::kMap:
              c.map_half_height = std::clamp(c.map_half_height * factor, 2.0, 5000.0);
              break;
            case CameraMode::kChase:
              c.chase_distance = std::clamp(c.chase_distance * factor, 2.0, 200.0);
              break;
            case CameraMode::kNorth:
              c.north_distance = std::clamp(c.north_distance * factor, 2.0, 500.0);
              break;
            case CameraMode::kBeside:
              c.beside_distance = std::clamp(c.beside_distance * factor, 1.0, 200.0);
              break;
            default:
              c.orbit_distance = std::clamp(c.orbit_distance * factor, 1.0, 2000.0);
              break;
          }
        }
        break;
      default:
        break;
    }
  }
}

void Viewer::Impl::WaitForDisplay() {
  const ViewerOptions& o = owner.options_;
  xr_waited = false;
  if (xr && !xr_ended) {
    try {
      if (!xr->PollEvents()) {
        // The headset session is over (the person left through the runtime): so is the viewer.
        xr_ended = true;
        spdlog::info("vdyn-viewer: the OpenXR session ended; closing");
        quit = true;
      } else if (xr->running()) {
        // The runtime paces the frames and predicts when this one will be seen.
        xr->WaitFrame();
        xr_waited = true;
        const base::MonoTime mono_now = base::MonotonicNow();
        scene_at = mono_now;
        display_wall_ns = base::WallNow().ns + (xr->display_mono_ns() - mono_now.ns);
        owner.stats_.last_display_mono_ns = xr->display_mono_ns();
        return;
      }
    } catch (const XrError& e) {
      spdlog::error("vdyn-viewer: OpenXR failed: {}; back to the desktop window", e.what());
      owner.stats_.xr_status = std::string("failed: ") + e.what();
      xr_ended = true;
    }
  }
  // The desktop: the frame-rate cap, then on the screen when this frame's work is done (as long
  // as the frames before took from here to the screen).
  if (o.fps > 0 && owner.stats_.frames > 0) {
    const base::Nanos period{static_cast<std::int64_t>(1e9 / o.fps)};
    next_frame = next_frame + period;
    const base::MonoTime now = base::MonotonicNow();
    if (next_frame < now) next_frame = now;  // late: no burst to catch up
    base::SleepUntil(next_frame);
  }
  scene_at = base::MonotonicNow();
  const auto lead = static_cast<std::int64_t>(present_lead_ns);
  display_wall_ns = base::WallNow().ns + lead;
  owner.stats_.last_display_mono_ns = scene_at.ns + lead;
}

void Viewer::Impl::TakeSamples() {
  session.Poll();
  const std::int64_t arrived = base::WallNow().ns;
  for (const auto& [id, v] : session.vehicles()) {
    if (v.states == 0) continue;
    if (tracked.count(id) == 0 && !CheckState(v.state).empty()) continue;  // only bad ones yet
    Tracked& t = tracked[id];
    if (t.seen == v.states) continue;
    t.seen = v.states;
    if (!CheckState(v.state).empty()) continue;  // refused (counted as it arrived)
    clocks[v.state.server_id()].Observe(v.source_timestamp_ns, arrived);
    t.history.Add(v.state, v.source_timestamp_ns, arrived);
    t.server = v.state.server_id();
    t.arrived = v.received;
  }
  ForgetVehiclesGone();
  // The followed vehicle: the chosen one when present, else the lowest id. One chosen but not
  // there is waited for (and said so), never swapped for another.
  const ViewerOptions& o = owner.options_;
  owner.followed_.reset();
  if (!tracked.empty() && !first_vehicle_at) first_vehicle_at = base::MonotonicNow();
  if (o.follow) {
    if (tracked.count(*o.follow) != 0) owner.followed_ = o.follow;
  } else if (!tracked.empty()) {
    owner.followed_ = tracked.begin()->first;
  }
  NoteMissingFollow();
  NoteSilence();
  // The followed server's terrain on the GPU.
  const std::string server = CurrentServer();
  const AcceptedWorld* accepted = WorldOf(server);
  if (accepted != nullptr) {
    const std::uint64_t serial = accepted->serial;
    if (!uploaded || uploaded_server != server || uploaded_serial != serial) {
      renderer->SetTerrain(TerrainFromWorld(accepted->desc));
      uploaded = true;
      uploaded_server = server;
      uploaded_serial = serial;
    }
  } else if (uploaded) {
    renderer->ClearTerrain();
    uploaded = false;
  }
}

// A vehicle its server no longer runs (removed, or the server started again without it) is
// forgotten: each new diagnostics message of a server lists the vehicles it runs, and one of its
// vehicles not among them, without a state for half a second, has left. (Before, it stayed on the
// screen, frozen, counted and reachable with Tab.) A server that stopped sends no diagnostics: its
// vehicles stay, and the HUD says how long no state has come.
void Viewer::Impl::ForgetVehiclesGone() {
  const base::MonoTime now = base::MonotonicNow();
  for (const auto& [server, d] : session.diagnostics()) {
    const std::pair<std::uint64_t, std::int64_t> key{d.steps(), d.sim_time_ns()};
    auto& seen = diagnostics_seen[server];
    if (seen == key) continue;
    seen = key;
    for (auto it = tracked.begin(); it != tracked.end();) {
      const auto& listed = d.vehicles();
      const bool runs =
          std::any_of(listed.begin(), listed.end(), [&](const pb::VehicleDiagnostics& v) {
            return v.vehicle_id() == it->first;
          });
      if (it->second.server != server || runs || now - it->second.arrived < base::Milliseconds(500)) {
        ++it;
        continue;
      }
      spdlog::info("vdyn-viewer: vehicle {} has left server '{}' (not among the vehicles it runs)",
                   it->first, server);
      session.Forget(it->first);
      it = tracked.erase(it);
    }
  }
}

// No state of the followed vehicle for 2 s (its server stopped, paused, or between lockstep
// steps): said in the log once, and again when states come back; the HUD says it too.
void Viewer::Impl::NoteSilence() {
  const auto it = owner.followed_ ? tracked.find(*owner.followed_) : tracked.end();
  if (it == tracked.end()) return;
  const double silent_s = (base::MonotonicNow() - it->second.arrived).seconds();
  if (silent_s >= kSilenceS && !silence_said) {
    spdlog::warn("vdyn-viewer: no state of vehicle {} from server '{}' for {:.0f} s (stopped, "
                 "paused, or a lockstep server between steps)",
                 it->first, it->second.server, silent_s);
    silence_said = true;
  } else if (silent_s < kSilenceS && silence_said) {
    spdlog::info("vdyn-viewer: states of vehicle {} from server '{}' again", it->first,
                 it->second.server);
    silence_said = false;
  }
}

// --follow ID of a vehicle that is not on the domain: said once the others have had a moment to
// arrive (with the ids that are there), again when that list changes, and when it comes.
void Viewer::Impl::NoteMissingFollow() {
  const ViewerOptions& o = owner.options_;
  if (!o.follow) return;
  if (owner.followed_) {
    if (!missing_said.empty()) {
      spdlog::info("vdyn-viewer: vehicle {} is here now: following it", *o.follow);
      missing_said.clear();
    }
    return;
  }
  if (!first_vehicle_at || base::MonotonicNow() - *first_vehicle_at < base::Seconds(1)) return;
  std::string there;
  for (const auto& [id, t] : tracked) there += (there.empty() ? "" : ", ") + std::to_string(id);
  if (there == missing_said) return;
  spdlog::warn(
      "vdyn-viewer: vehicle {} is not on domain {}; there: {} (Tab follows one); "
      "waiting for vehicle {}",
      *o.follow, o.domain, there, *o.follow);
  missing_said = there;
}

Viewer::Impl::FrameScene Viewer::Impl::UpdateScene() {
  const ViewerOptions& o = owner.options_;
  FrameScene f;
  f.server = CurrentServer();
  f.accepted = WorldOf(f.server);
  f.world = f.accepted != nullptr ? &f.accepted->desc : nullptr;
  // Each vehicle at the frame's instant: its display time less the presentation delay, on its
  // publisher's clock (motion.h).
  for (auto& [id, t] : tracked) {
    if (t.history.empty()) continue;
    StateHistory::Sample sample;
    if (o.delay_ns > 0) {
      const ClockOffset& clock = clocks[t.server];
      sample = t.history.At(display_wall_ns - clock.offset_ns() - o.delay_ns);
    } else {
      sample = t.history.At(t.history.newest_source_ns());
    }
    t.at = sample.a;
    t.at_source_ns = sample.a_source_ns;
    t.instant_ns = sample.source_ns;
    if (sample.b != nullptr) {
      InterpolateState(*sample.a, *sample.b, sample.u, t.drawn);
    } else {
      t.drawn.CopyFrom(*sample.a);
    }
    AdvanceWheelSpin(t.spin, t.drawn);
  }
  // The vehicles of the drawn world: those of its server, and those of other servers on the same
  // terrain (several servers of a lab on one world); another world's vehicles would float.
  views.clear();
  for (const auto& [id, t] : tracked) {
    if (t.at == nullptr) continue;
    const std::string& server_id = t.server;
    if (!f.server.empty() && server_id != f.server) {
      const AcceptedWorld* theirs = WorldOf(server_id);
      if (f.world == nullptr || theirs == nullptr || f.world->terrain_hash() == 0 ||
          theirs->desc.terrain_hash() != f.world->terrain_hash()) {
        continue;
      }
    }
    const auto* sv = session.vehicle(id);
    const pb::VehicleParams* vp = sv != nullptr && sv->params ? &*sv->params : nullptr;
    const AcceptedWorld* own_world = WorldOf(server_id);
    views.emplace(
        id, BuildVehicleView(t.drawn,
                             GeometryFor(id, own_world != nullptr ? &own_world->desc : f.world, vp),
                             &t.spin));
  }
  f.followed = owner.followed_ ? owner.vehicle(*owner.followed_) : nullptr;
  f.cs.followed = f.followed;
  if (f.accepted != nullptr) {
    const AcceptedWorld& a = *f.accepted;
    f.cs.north_yaw = f.world->north_yaw();
    const double span = std::max(a.max_W.x - a.min_W.x, a.max_W.y - a.min_W.y);
    f.cs.top_z = a.max_W.z;
    f.cs.far_m = std::clamp(2.0 * span, 500.0, 50000.0);
    f.cs.fallback_target_W = f.world->has_spawn()
                                 ? Vec3{f.world->spawn().x(), f.world->spawn().y(), 0}
                                 : 0.5 * (a.min_W + a.max_W);
  }
  f.camera = o.camera;
  f.cam = ComputeCamera(f.camera, f.cs, desktop->width(), desktop->height());
  owner.last_camera_ = f.cam;
  return f;
}

void Viewer::Impl::BuildLists(const FrameScene& f, const Mat4& view_proj, const Vec3& eye,
                              bool ortho, double metres_per_pixel, double fovy, int height_px,
                              bool inside) {
  const ViewerOptions& o = owner.options_;
  lists.Clear();
  // Arrows at least ~3 px thick wherever they are.
  auto radius_at = [&](const Vec3& p) {
    const double mpp = ortho ? metres_per_pixel
                             : 2.0 * Norm(p - eye) * std::tan(0.5 * fovy) / std::max(height_px, 1);
    return std::max(0.03, 1.6 * mpp);
  };
  // The cockpit's mirrors see what is behind: a vehicle is drawn when the view or a mirror sees
  // it.
  std::vector<Mat4> seen_by = {view_proj};
  if (inside && f.camera.cockpit && owner.followed_) {
    if (auto own = views.find(*owner.followed_); own != views.end()) {
      AppendMirrors(own->second, CabinFor(own->second.geometry).eyes_B, lists.mirrors);
      for (const MirrorInstance& m : lists.mirrors) {
        seen_by.push_back(MirrorViewProj(m, f.cs.far_m));
      }
    }
  }
  for (const auto& [id, v] : views) {
    // From the driver's seat the own vehicle is its cockpit and its bonnet (the body from
    // inside); its tyres and arrows are left out (they would fill the view of the road ahead),
    // its forces show in the other cameras.
    if (inside && owner.followed_ && id == *owner.followed_) {
      if (!f.camera.cockpit) continue;
      VehicleParts parts;
      parts.wheels = parts.arrows = false;
      AppendVehicle(v, o.arrows, radius_at, parts, false, lists);
      for (BodyInstance& b : lists.bodies) b.from_inside = b.vehicle_id == id;
      AppendCockpit(v, CabinFor(v.geometry).eyes_B, lists.cockpit);
      continue;
    }
    const double bound = BoundingRadius(v, o.arrows);
    const auto& at = v.pose_WB.t;  // a lambda may not capture a structured binding (clang 14)
    if (std::none_of(seen_by.begin(), seen_by.end(),
                     [&](const Mat4& vp) { return InFrustum(vp, at, bound); })) {
      continue;
    }
    const double px_per_m = 1.0 / std::max(radius_at(v.pose_WB.t) / 1.6, 1e-6);
    AppendVehicle(v, o.arrows, radius_at, true, px_per_m < 40.0, lists);
  }
  if (f.world != nullptr && o.landmarks) {
    // Landmarks: a small marker on the ground (their names are labels on the desktop).
    for (const pb::Landmark& l : f.world->landmarks()) {
      const Vec3 p{l.p_w().x(), l.p_w().y(), l.p_w().z()};
      const double r = std::max(0.2, 2.0 * radius_at(p));
      lists.opaque.Cone(p, p + Vec3{0, 0, 2 * r}, r, {255, 120, 40}, true, 10);
    }
  }
}

// The current ImGui window's rectangle: labels keep out of it.
void Viewer::Impl::Occupied() {
  const ImVec2 p = ImGui::GetWindowPos(), sz = ImGui::GetWindowSize();
  hud_boxes.push_back({p.x, p.y, p.x + sz.x, p.y + sz.y});
  // A window ImGui pushed past the top or left edge (the display shrank to a few pixels) comes
  // back by the next frame: it stayed clipped after the window grew again.
  if (p.x < 0 || p.y < 0) ImGui::SetWindowPos(ImVec2(std::max(p.x, 0.0f), std::max(p.y, 0.0f)));
}

// A line of the HUD: drawn, and kept for tests.
void Viewer::Impl::Line(const std::string& text, const ImVec4* colour) {
  if (colour != nullptr) {
    ImGui::TextColored(*colour, "%s", text.c_str());
  } else {
    ImGui::TextUnformatted(text.c_str());
  }
  hud_text.push_back(text);
}

void Viewer::Impl::BuildHud(const FrameScene& f) {
  ViewerOptions& o = owner.options_;
  const CameraView& cam = f.cam;
  ImGui_ImplOpenGL3_NewFrame();
  ImGui_ImplSDL2_NewFrame();
  ImGui::NewFrame();
  hud_text.clear();
  shown_labels.clear();
  hud_boxes.clear();
  const double heading_deg = std::fmod(Deg(f.cs.north_yaw - cam.heading) + 720.0, 360.0);
  const double north_angle = CompassNorthAngle(f.cs.north_yaw, cam.heading);
  const float scale = ImGui::GetIO().FontGlobalScale;
  const ImVec2 compass(static_cast<float>(o.width) - 75 * scale, 75 * scale);
  if (!o.hud) {
    DrawCompass(ImGui::GetForegroundDrawList(), compass, 55 * scale, north_angle, heading_deg);
    ImGui::Render();
    return;
  }
  HudStatus(f, compass.x - 60 * scale - 10);  // clear of the compass (a narrow window)
  // The forces legend, at the bottom left: collapsed to its title until L (or a click on its
  // arrow) opens it.
  ImGui::SetNextWindowPos(ImVec2(10, static_cast<float>(o.height) - 10), ImGuiCond_Always,
                          ImVec2(0, 1));
  ImGui::SetNextWindowBgAlpha(0.7f);
  ImGui::SetNextWindowCollapsed(!legend_open, ImGuiCond_Always);
  // Never narrower than its title: a display shrunk to a few pixels left it cut to "for" after.
  ImGui::SetNextWindowSizeConstraints(ImVec2(160.0f * scale, 0.0f), ImVec2(FLT_MAX, FLT_MAX));
  const bool expanded =
      ImGui::Begin("forces (L)", nullptr,
                   ImGuiWindowFlags_AlwaysAutoResize | ImGuiWindowFlags_NoFocusOnAppearing);
  legend_open = !ImGui::IsWindowCollapsed();
  if (expanded) {
    for (int k = 0; k < kForceKinds; ++k) {
      const auto kind = static_cast<ForceKind>(k);
      const Rgb8 c = ForceColour(kind);
      const ImVec2 p = ImGui::GetCursorScreenPos();
      ImGui::GetWindowDrawList()->AddRectFilled(ImVec2(p.x, p.y + 3), ImVec2(p.x + 22, p.y + 13),
                                                ImColour(c));
      ImGui::Dummy(ImVec2(26, 14));
      ImGui::SameLine();
      ImGui::Checkbox(std::string(ForceLabel(kind)).c_str(), &o.arrows.show[k]);
    }
    float kn = static_cast<float>(o.arrows.metres_per_newton * 1000.0);
    ImGui::SetNextItemWidth(140);
    if (ImGui::SliderFloat("m per kN (+/-)", &kn, 0.02f, 10.0f, "%.2f",
                           ImGuiSliderFlags_Logarithmic)) {
      o.arrows.metres_per_newton = static_cast<double>(kn) / 1000.0;
    }
  }
  Occupied();
  ImGui::End();
  if (show_params && owner.followed_) {
    ImGui::SetNextWindowPos(ImVec2(static_cast<float>(o.width) - 470, 160), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(460, 480), ImGuiCond_FirstUseEver);
    ImGui::Begin("parameters", &show_params);
    const std::uint32_t id = *owner.followed_;
    const auto* sv = session.vehicle(id);
    ImGui::Text("vehicle %u (P to close)", id);
    params->Draw(id, f.server, sv != nullptr && sv->params ? &*sv->params : nullptr);
    Occupied();
    ImGui::End();
  }
  if (show_help) {
    ImGui::SetNextWindowPos(ImVec2(static_cast<float>(o.width) * 0.5f - 220, 80),
                            ImGuiCond_FirstUseEver);
    ImGui::Begin("keys", &show_help, ImGuiWindowFlags_AlwaysAutoResize);
    ImGui::TextUnformatted(
        "1-6  chase, driver, orbit, map, north, beside camera   C  next camera\n"
        "K    horizon level / with the body (chase, orbit)     R  recentre the headset\n"
        "I    the cockpit in the driver's seat on / off\n"
        "Q/E  turn the geographic cameras left/right    N  back to north\n"
        "     (the wheel's paddle shifters do the same)\n"
        "Tab  next vehicle (Shift: previous)\n"
        "+/-  arrow scale     L forces legend   P parameters   H HUD\n"
        "M    landmarks (the world's named points) on / off\n"
        "drag orbit   wheel zoom   F12 screenshot   Esc quit");
    Occupied();
    ImGui::End();
  }
  DrawCompass(ImGui::GetForegroundDrawList(), compass, 55 * scale, north_angle, heading_deg);
  hud_boxes.push_back({compass.x - 60 * scale, compass.y - 60 * scale, compass.x + 60 * scale,
                       compass.y + 85 * scale});
  if (!owner.xr_active()) HudLabels(f);
  ImGui::Render();
}

// The HUD's status panel, its lines wrapped before right_px.
void Viewer::Impl::HudStatus(const FrameScene& f, float right_px) {
  const ViewerOptions& o = owner.options_;
  const ViewerStats& stats = owner.stats_;
  ImGui::SetNextWindowPos(ImVec2(10, 10), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowBgAlpha(0.7f);
  ImGui::Begin("vdyn-viewer", nullptr,
               ImGuiWindowFlags_AlwaysAutoResize | ImGuiWindowFlags_NoFocusOnAppearing);
  ImGui::PushTextWrapPos(
      std::max(right_px - ImGui::GetWindowPos().x - ImGui::GetStyle().WindowPadding.x, 200.0f));
  const pb::Diagnostics* player = PlayerOf(f.server);
  // Before any server is heard: said so, in amber (it read "LIVE server ''  world '(waiting)'").
  const bool none = f.server.empty() && player == nullptr;
  std::string mode = none                             ? "WAITING"
                     : o.playback || player != nullptr ? "PLAYBACK"
                                                       : "LIVE";
  std::string source = none ? "no server yet on domain " + std::to_string(o.domain)
                            : "server '" + f.server + "'";
  if (player != nullptr) {
    source = "recording '" + player->recording() + "' (player '" + player->server_id() +
             "', server '" + f.server + "')";
  } else if (const auto d = session.diagnostics().find(f.server);
             d != session.diagnostics().end() && !d->second.mode().empty()) {
    source += " " + d->second.mode();
  }
  const ImVec4 green(0.4f, 1, 0.4f, 1), amber(1, 0.8f, 0.3f, 1), red(1, 0.35f, 0.3f, 1);
  ImGui::TextColored(mode == "LIVE" ? green : amber, "%s", mode.c_str());
  ImGui::SameLine();
  const std::string where =
      none ? source
           : source + "  world '" + (f.world != nullptr ? f.world->name() : "(waiting)") + "'";
  ImGui::TextUnformatted(where.c_str());
  hud_text.push_back(mode + "  " + where);

  const auto it = owner.followed_ ? tracked.find(*owner.followed_) : tracked.end();
  if (o.follow && !owner.followed_) {
    std::string there;
    for (const auto& [id, t] : tracked) there += (there.empty() ? "" : ", ") + std::to_string(id);
    Line(Format("waiting for vehicle %u (--follow): not on domain %u", *o.follow, o.domain),
         &amber);
    Line(there.empty() ? "no vehicle on the domain yet"
                       : "on the domain: " + there + "  (Tab follows one)");
  } else if (it != tracked.end() && it->second.at != nullptr) {
    const pb::VehicleState& s = *it->second.at;
    Line(Format("vehicle %u  (%zu on the domain, Tab: next)", s.vehicle_id(), tracked.size()));
    if (const double silent_s = (base::MonotonicNow() - it->second.arrived).seconds();
        silent_s >= kSilenceS) {
      Line(Format("NO STATE from server '%s' for %.0f s: stopped, paused, or between lockstep steps",
                  it->second.server.c_str(), silent_s),
           &red);
    }
    // The vehicle's time and step always agree: its time is its steps (since its first spawn;
    // a restore continues a recording's); the server's clock is shown too where it differs
    // (a vehicle spawned later, or restored into another session).
    const std::int64_t vehicle_ns =
        s.step_ns() > 0 ? static_cast<std::int64_t>(s.step()) * s.step_ns() : s.sim_time_ns();
    std::string time =
        Format("speed %6.1f km/h   sim time %s   step %llu", it->second.drawn.speed_kmh(),
               FormatSeconds(vehicle_ns).c_str(), static_cast<unsigned long long>(s.step()));
    if (s.sim_time_ns() != vehicle_ns) {
      time += "   server clock " + FormatSeconds(s.sim_time_ns());
    }
    Line(time);
    const std::string& src = s.input().source_id();
    const std::string input = "input from " + (src.empty() ? "(none)" : "'" + src + "'");
    ImGui::TextUnformatted(input.c_str());
    ImGui::SameLine();
    const bool safe = s.control().watchdog_safe_state();
    const std::string watchdog = safe ? "WATCHDOG: safe state (no live input)" : "watchdog ok";
    ImGui::TextColored(safe ? red : ImVec4(0.5f, 0.9f, 0.5f, 1), "%s", watchdog.c_str());
    hud_text.push_back(input + "  " + watchdog);
    const double age_ms = static_cast<double>(base::WallNow().ns - it->second.at_source_ns) * 1e-6;
    Line(Format("state age %.1f ms   steer %.1f deg  throttle %.2f  brake %.2f", age_ms,
                Deg(s.control().gamma()), s.control().throttle(), s.control().brake()));
  } else {
    Line(Format("no vehicle on domain %u yet", o.domain));
  }
  const double frame_ms = stats.frame_ms.empty() ? 0.0 : stats.frame_ms.back();
  const CameraMode cm = f.camera.mode;
  const bool lockable = cm == CameraMode::kChase || cm == CameraMode::kOrbit;
  Line(Format(
      "camera %s%s (1-6, C)   frame %.1f ms", std::string(CameraName(cm)).c_str(),
      lockable ? (f.camera.horizon_locked ? ", horizon level (K)" : ", with the body (K)") : "",
      frame_ms));
  if (xr) {
    Line(Format("OpenXR: %s, %s  (R: recentre)", xr->runtime_name().c_str(),
                xr->state_name().c_str()));
  }
  const std::uint64_t drops = session.drops().Total();
  if (drops > 0) {
    const ImVec4 orange(1, 0.6f, 0.3f, 1);
    Line(Format("refused or dropped: %llu", static_cast<unsigned long long>(drops)), &orange);
    if (ImGui::IsItemHovered()) {
      ImGui::BeginTooltip();
      for (const auto& [kind, n] : session.drops().Snapshot())
        ImGui::Text("%s: %llu", kind.c_str(), static_cast<unsigned long long>(n));
      if (!stats.last_refusal.empty()) ImGui::TextWrapped("last: %s", stats.last_refusal.c_str());
      ImGui::EndTooltip();
    }
  }
  ImGui::PopTextWrapPos();
  Occupied();
  ImGui::End();
}

// Landmark names and vehicle numbers beside what they name, never overlapping (labels.h).
void Viewer::Impl::HudLabels(const FrameScene& f) {
  const ViewerOptions& o = owner.options_;
  const CameraView& cam = f.cam;
  std::vector<LabelRequest> requests;
  std::vector<ImU32> colours;
  auto ask = [&](const std::string& text, const Vec3& at, int priority, ImU32 colour) {
    ImVec2 p;
    if (!Project(cam, o.width, o.height, at, p)) return;
    const ImVec2 size = ImGui::CalcTextSize(text.c_str());
    requests.push_back(
        {text, p.x, p.y, size.x, size.y, cam.orthographic ? 0.0 : Norm(at - cam.eye_W), priority});
    colours.push_back(colour);
  };
  for (const auto& [id, v] : views) {
    const bool own = owner.followed_ && id == *owner.followed_;
    if (own && f.camera.mode == CameraMode::kDriver) continue;  // not drawn from its own seat
    ask(Format("#%u", id), v.pose_WB * Vec3{0, 0, 1.6}, own ? 2 : 1, ImColour(VehicleColour(id)));
  }
  if (f.world != nullptr && o.landmarks) {
    for (const pb::Landmark& l : f.world->landmarks()) {
      ask(l.name(), {l.p_w().x(), l.p_w().y(), l.p_w().z() + 1.0}, 0, IM_COL32(255, 255, 255, 255));
    }
  }
  ImDrawList* fg = ImGui::GetForegroundDrawList();
  LabelStyle style;
  for (const PlacedLabel& p : LayoutLabels(requests, static_cast<float>(o.width),
                                           static_cast<float>(o.height), hud_boxes, style)) {
    const LabelRequest& r = requests[p.request];
    const ImU32 c = colours[p.request];
    const auto alpha = static_cast<int>(std::lround(p.alpha * ((c >> IM_COL32_A_SHIFT) & 0xFF)));
    const ImU32 faded = (c & ~IM_COL32_A_MASK) | (static_cast<ImU32>(alpha) << IM_COL32_A_SHIFT);
    fg->AddText(ImVec2(p.box.x0 + style.padding_px, p.box.y0 + style.padding_px), faded,
                r.text.c_str());
    shown_labels.push_back({r.text, p.box, p.alpha});
  }
}

// The frame's key presses, unless the HUD took them: an ImGui item (a text field, a slider) had
// the input when this frame began, has it now, or the frame's input went to one (the keys typed
// right after a click into a field arrive with that click).
void Viewer::Impl::ApplyKeys() {
  ViewerOptions& o = owner.options_;
  const bool active_now = ImGui::IsAnyItemActive();
  const bool taken = item_active_before || active_now || ImGui::GetIO().WantTextInput;
  item_active_before = active_now;
  if (taken) return;
  bool tab_pressed = false;  // a Tab earlier in this frame's keys
  for (const KeyPress& kp : keys) {
    const SDL_Keycode k = kp.key;
    CameraState& c = o.camera;
    if (k == SDLK_ESCAPE) quit = true;
    if (k >= SDLK_1 && k <= SDLK_6) c.mode = static_cast<CameraMode>(k - SDLK_1);
    if (k == SDLK_c)
      c.mode = static_cast<CameraMode>((static_cast<int>(c.mode) + 1) % kCameraModes);
    if (k == SDLK_k) c.horizon_locked = !c.horizon_locked;
    if (k == SDLK_i) c.cockpit = !c.cockpit;
    if (k == SDLK_r) recentre_pending = true;
    if (k == SDLK_q) TurnGeographic(c, +1);
    if (k == SDLK_e) TurnGeographic(c, -1);
    if (k == SDLK_n) c.geo_turn = 0;
    if (k == SDLK_PLUS || k == SDLK_EQUALS || k == SDLK_KP_PLUS) o.arrows.metres_per_newton *= 1.25;
    if (k == SDLK_MINUS || k == SDLK_KP_MINUS) o.arrows.metres_per_newton /= 1.25;
    if (k == SDLK_h) o.hud = !o.hud;
    if (k == SDLK_m) o.landmarks = !o.landmarks;
    if (k == SDLK_p) show_params = !show_params;
    if (k == SDLK_l) legend_open = !legend_open;
    if (k == SDLK_F1) show_help = !show_help;
    if (k == SDLK_TAB && !tracked.empty()) {
      // Next (Shift: previous) vehicle of the domain; the first (last) when none is followed.
      std::vector<std::uint32_t> ids;
      for (const auto& [id, t] : tracked) ids.push_back(id);
      const bool back = (kp.mod & KMOD_SHIFT) != 0;
      // From the one a Tab earlier in this frame chose (the followed one changes next frame:
      // three quick presses in one frame moved one place before).
      const std::optional<std::uint32_t> from = tab_pressed ? o.follow : owner.followed_;
      tab_pressed = true;
      const auto it = from ? std::find(ids.begin(), ids.end(), *from) : ids.end();
      std::size_t i = 0;
      if (it == ids.end()) {
        i = back ? ids.size() - 1 : 0;
      } else {
        const auto at = static_cast<std::size_t>(it - ids.begin());
        i = back ? (at + ids.size() - 1) % ids.size() : (at + 1) % ids.size();
      }
      o.follow = ids[i];
    }
    if (k == SDLK_F12) {  // this frame's image, read before it is shown (Present)
      f12_path = "vdyn-viewer-" + std::to_string(base::WallNow().ns / 1'000'000) + ".png";
    }
  }
}

bool Viewer::Impl::DrawHeadset(const FrameScene& f) {
  if (!xr_waited) return false;
  xr_waited = false;
  const ViewerOptions& o = owner.options_;
  bool drawn = false;
  try {
    // Recentring: the head's place and heading now become the place's eye point (on the floor
    // it stays on the floor). The runtime recentring its space itself starts over.
    if (xr->space_changes() != space_changes_seen) {
      space_changes_seen = xr->space_changes();
      head_ref = NeutralHead();
    }
    Pose head;
    if (recentre_pending && xr->head_in_space(&head)) {
      const Vec3 forward = -head.R.c[2];
      head_ref.R = RotationAxisAngle({0, 1, 0}, std::atan2(-forward.x, -forward.z));
      head_ref.t = head.t;
      spdlog::info(
          "vdyn-viewer: headset recentred (head at {:.2f} {:.2f} {:.2f} m, turned "
          "{:.0f} deg)",
          head.t.x, head.t.y, head.t.z, Deg(std::atan2(-forward.x, -forward.z)));
    }
    recentre_pending = false;
    // The reference space's origin in the world: the camera's place (its eye point, level, or
    // turning with the body), the floor under it when standing.
    Pose place = XrPlace(f.camera, f.cs);
    const Pose neutral = NeutralHead();
    Pose ref = head_ref;
    ref.t.y -= neutral.t.y;  // standing on STAGE: the head's height stays the runtime's
    place.t = place.t - place.R.c[1] * neutral.t.y;
    const Pose world_from_space = place * ref.Inverse();
    // The HUD: a panel below and ahead of the (recentred) head, fixed in the space.
    const Pose hud_in_space = head_ref * HudPanel(o.xr_seated);
    xr->Frame(
        world_from_space, hud_in_space, 0.05, f.cs.far_m,
        [&](const XrEye& eye) {
          BuildLists(f, eye.proj * eye.view, eye.eye_W, false, 0, Rad(90), eye.target->height(),
                     f.camera.mode == CameraMode::kDriver);
          eye.target->BeginScene();
          Renderer::View rv{eye.view, eye.proj, eye.eye_W};
          if (f.followed != nullptr) rv.focus_W = f.followed->pose_WB.t;  // the sun's shadow map
          rv.update_mirrors = eye.index == 0;  // the left eye's mirror images serve both
          renderer->Draw(rv, lists);
          eye.target->Resolve();
        },
        [&](RenderTarget& hud) {
          glBindFramebuffer(GL_FRAMEBUFFER, hud.resolve_framebuffer());
          glViewport(0, 0, hud.width(), hud.height());
          glClearColor(0, 0, 0, 0);
          glClear(GL_COLOR_BUFFER_BIT);
          ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
        });
    ++owner.stats_.xr_frames;
    drawn = true;
  } catch (const XrError& e) {
    spdlog::error("vdyn-viewer: OpenXR failed: {}; back to the desktop window", e.what());
    owner.stats_.xr_status = std::string("failed: ") + e.what();
    xr_ended = true;
  }
  return drawn;
}

void Viewer::Impl::DrawDesktop(const FrameScene& f, bool xr_drawn) {
  const ViewerOptions& o = owner.options_;
  RenderTarget& target = *desktop;
  if (xr_drawn) {
    // The window mirrors the left eye, with the HUD.
    glBindFramebuffer(GL_FRAMEBUFFER, target.resolve_framebuffer());
    glViewport(0, 0, target.width(), target.height());
    glClearColor(0, 0, 0, 1);
    glClear(GL_COLOR_BUFFER_BIT);
    const RenderTarget& mirror = xr->mirror();
    glBindFramebuffer(GL_READ_FRAMEBUFFER, mirror.resolve_framebuffer());
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, target.resolve_framebuffer());
    const double s = std::min(static_cast<double>(o.width) / mirror.width(),
                              static_cast<double>(o.height) / mirror.height());
    const int w = static_cast<int>(mirror.width() * s), h = static_cast<int>(mirror.height() * s);
    const int x0 = (o.width - w) / 2, y0 = (o.height - h) / 2;
    glBlitFramebuffer(0, 0, mirror.width(), mirror.height(), x0, y0, x0 + w, y0 + h,
                      GL_COLOR_BUFFER_BIT, GL_LINEAR);
    glBindFramebuffer(GL_FRAMEBUFFER, target.resolve_framebuffer());
    return;
  }
  const CameraView& cam = f.cam;
  BuildLists(f, cam.proj * cam.view, cam.eye_W, cam.orthographic, cam.metres_per_pixel, cam.fovy,
             target.height(), f.camera.mode == CameraMode::kDriver);
  target.BeginScene();
  Renderer::View rv{cam.view, cam.proj, cam.eye_W};
  rv.haze = !cam.orthographic;
  if (f.followed != nullptr) rv.focus_W = f.followed->pose_WB.t;  // the sun's shadow map
  renderer->Draw(rv, lists);
  target.Resolve();
}

// Whether this frame counts towards --frames (once the world and the vehicle are there, or the
// wait has passed; with a headset, only frames it was given) and is the last.
bool Viewer::Impl::CountFrame(const FrameScene& f, bool xr_drawn) {
  const ViewerOptions& o = owner.options_;
  ViewerStats& stats = owner.stats_;
  if (!counting) {
    const bool waited = (base::MonotonicNow() - start).seconds() >= o.wait_s;
    if (owner.ready() || waited) {
      if (!owner.ready() && o.frames > 0) {
        spdlog::warn("vdyn-viewer: no {} after {:.0f} s; drawing what there is",
                     f.world == nullptr ? "world" : "vehicle", o.wait_s);
      }
      counting = true;
    }
  }
  const bool xr_pending = xr != nullptr && !xr_ended;
  if (counting && (!xr_pending || xr_drawn)) ++stats.counted_frames;
  return o.frames > 0 && stats.counted_frames >= o.frames;
}

// The image is read before the swap (after it, a window's back buffer holds nothing defined):
// the run's last frame and the one F12 asked for are kept.
void Viewer::Impl::Present(bool keep) {
  ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
  if ((keep && !have_image) || !f12_path.empty()) {
    last_image = desktop->Read();
    have_image = keep || have_image;
    if (!f12_path.empty()) {
      if (WritePng(f12_path, last_image)) spdlog::info("vdyn-viewer: screenshot {}", f12_path);
      f12_path.clear();
    }
  }
  if (!desktop->in_window()) {
    int ww = 0, wh = 0;
    SDL_GL_GetDrawableSize(window, &ww, &wh);
    Renderer::PresentToWindow(*desktop, ww, wh);
  }
  SDL_GL_SwapWindow(window);
  glFinish();
}

void Viewer::Impl::Account(base::MonoTime t0, bool xr_drawn) {
  ViewerStats& stats = owner.stats_;
  // What the frame showed is on the screen now: the latency of each vehicle whose instant moved.
  const base::WallTime shown = base::WallNow();
  for (auto& [id, t] : tracked) {
    if (t.at == nullptr || t.instant_ns == t.last_instant_ns) continue;
    t.last_instant_ns = t.instant_ns;
    if (views.count(id) == 0 || t.instant_ns <= 0) continue;
    if (stats.latency_ms.size() < kMaxSamples) {
      stats.latency_ms.push_back(static_cast<double>(shown.ns - t.instant_ns) * 1e-6);
    }
  }
  ++stats.frames;
  const base::MonoTime t1 = base::MonotonicNow();
  if (stats.frame_ms.size() < kMaxSamples) stats.frame_ms.push_back((t1 - t0).millis());
  // The desktop's lead from the scene to the screen, for the next frame's display time.
  if (!xr_drawn) {
    const auto lead = static_cast<double>((t1 - scene_at).ns);
    // (The first frames, with their shaders compiled and buffers filled, do not count.)
    if (stats.frames > 3) {
      present_lead_ns = present_lead_ns == 0 ? lead : 0.75 * present_lead_ns + 0.25 * lead;
    }
  }
}

}  // namespace vdyn::viewer

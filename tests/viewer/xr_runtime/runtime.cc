// A headless OpenXR runtime for tests: a shared library the real OpenXR loader loads through
// XR_RUNTIME_JSON (it exports only xrNegotiateLoaderRuntimeInterface and is never linked to the
// loader). It offers one stereo headset with XR_KHR_opengl_enable, drives the session through
// its states the way the specification orders them, checks every call an application makes
// against that order (graphics requirements before the session, the current GLX context in the
// binding, wait/begin/end frame pairs, acquire/wait/release of swapchain images, the layers
// submitted), reads back the images of each submitted frame on the application's thread and
// context, and writes a report and the last frame's images (left.png, right.png, hud.png) to
// $VDYN_XR_TEST_OUT when the instance is destroyed.
#include <epoxy/gl.h>
#include <epoxy/glx.h>
#define XR_USE_PLATFORM_XLIB
#define XR_USE_GRAPHICS_API_OPENGL
#define XR_USE_TIMESPEC
#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>
#include <stb_image_write.h>
#include <time.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "test_runtime.h"

// The loader's negotiation structures (Debian's OpenXR headers do not ship loader_interfaces.h).
extern "C" {
enum XrLoaderInterfaceStructs {
  XR_LOADER_INTERFACE_STRUCT_UNINTIALIZED = 0,
  XR_LOADER_INTERFACE_STRUCT_LOADER_INFO,
  XR_LOADER_INTERFACE_STRUCT_API_LAYER_REQUEST,
  XR_LOADER_INTERFACE_STRUCT_RUNTIME_REQUEST,
  XR_LOADER_INTERFACE_STRUCT_API_LAYER_CREATE_INFO,
  XR_LOADER_INTERFACE_STRUCT_API_LAYER_NEXT_INFO,
};
struct XrNegotiateLoaderInfo {
  XrLoaderInterfaceStructs structType;
  std::uint32_t structVersion;
  std::size_t structSize;
  std::uint32_t minInterfaceVersion;
  std::uint32_t maxInterfaceVersion;
  XrVersion minApiVersion;
  XrVersion maxApiVersion;
};
struct XrNegotiateRuntimeRequest {
  XrLoaderInterfaceStructs structType;
  std::uint32_t structVersion;
  std::size_t structSize;
  std::uint32_t runtimeInterfaceVersion;
  XrVersion runtimeApiVersion;
  PFN_xrGetInstanceProcAddr getInstanceProcAddr;
};
__attribute__((visibility("default"))) XrResult xrNegotiateLoaderRuntimeInterface(
    const XrNegotiateLoaderInfo* loaderInfo, XrNegotiateRuntimeRequest* runtimeRequest);
}

namespace {

using namespace vdyn::xrtest;

constexpr std::int64_t kGlRgba8 = 0x8058, kGlSrgb8Alpha8 = 0x8C43, kGlRgba16 = 0x805B,
                       kGlRgba16f = 0x881A, kGlRgb10A2 = 0x8059;
// The formats it can offer, by the names kEnvFormats lists them with; by default in the order
// Monado 25.1 offers its OpenGL swapchains (NOTES.md): a viewer that takes the first, or RGBA8,
// gets a linear one.
struct NamedFormat {
  const char* name;
  std::int64_t format;
};
constexpr NamedFormat kFormatNames[] = {{"RGBA16", kGlRgba16},
                                        {"RGBA16F", kGlRgba16f},
                                        {"SRGB8_ALPHA8", kGlSrgb8Alpha8},
                                        {"RGBA8", kGlRgba8},
                                        {"RGB10_A2", kGlRgb10A2}};
constexpr std::int64_t kFormats[] = {kGlRgba16, kGlRgba16f, kGlSrgb8Alpha8, kGlRgba8};
bool IsSrgb(std::int64_t format) {
  return format == kGlSrgb8Alpha8;
}
constexpr XrTime kPeriodNs = 11'111'111;  // 90 Hz

XrTime Now() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<XrTime>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgba;  // rows top down
};

struct Swapchain {
  int width = 0, height = 0;
  std::int64_t format = 0;
  std::vector<GLuint> textures;
  int next = 0;              // next image to acquire
  std::deque<int> acquired;  // acquired, not yet released
  bool waited = false;       // the oldest acquired one has been waited for
  int last_released = -1;
};

struct Space {
  XrReferenceSpaceType type = XR_REFERENCE_SPACE_TYPE_LOCAL;
  XrPosef pose{};
};

// Everything the runtime knows, one instance at a time (tests start one viewer per process).
struct State {
  bool instance = false, session = false;
  bool requirements_asked = false;
  bool running = false;  // between xrBeginSession and xrEndSession
  XrSessionState state = XR_SESSION_STATE_UNKNOWN;
  std::deque<XrSessionState> events;
  std::vector<std::string> polled;  // session states in the order the application received them
  bool frame_waited = false, frame_begun = false;
  XrTime predicted = 0;
  XrTime last_drawn_display = 0;  // the display time of the last frame with a projection layer
  bool timespec_enabled = false;
  std::array<double, 4> head{0, 0, 0, 0};  // kEnvHead: x, y, z, yaw (rad)
  std::uint64_t frames_ended = 0, frames_projection = 0, frames_quad = 0;
  std::uint64_t exit_after = 0;
  bool stage = true;
  bool requested_exit = false, runtime_exit = false;
  bool binding_context_current = false;
  std::string first_violation;
  std::map<std::uintptr_t, std::unique_ptr<Swapchain>> swapchains;
  std::map<std::uintptr_t, std::unique_ptr<Space>> spaces;
  std::uintptr_t next_handle = 0x1000;
  Image left, right, hud;
  double quad_width_m = 0, quad_height_m = 0;
  XrReferenceSpaceType projection_space = XR_REFERENCE_SPACE_TYPE_MAX_ENUM;
  XrReferenceSpaceType quad_space = XR_REFERENCE_SPACE_TYPE_MAX_ENUM;
  XrPosef quad_pose{};
  std::string out_dir;
  std::vector<std::int64_t> formats{std::begin(kFormats), std::end(kFormats)};  // as offered
  std::string swapchain_formats;  // of the swapchains created, by name, in order
};

// One lock for every call (applications may call from several threads).
std::mutex g_mu;
std::unique_ptr<State> g_state = std::make_unique<State>();
State& S() {
  return *g_state;
}

void Violation(const std::string& what) {
  State& s = S();
  if (s.first_violation.empty()) s.first_violation = what;
}

const char* StateName(XrSessionState st) {
  switch (st) {
    case XR_SESSION_STATE_IDLE:
      return "idle";
    case XR_SESSION_STATE_READY:
      return "ready";
    case XR_SESSION_STATE_SYNCHRONIZED:
      return "synchronized";
    case XR_SESSION_STATE_VISIBLE:
      return "visible";
    case XR_SESSION_STATE_FOCUSED:
      return "focused";
    case XR_SESSION_STATE_STOPPING:
      return "stopping";
    case XR_SESSION_STATE_EXITING:
      return "exiting";
    default:
      return "other";
  }
}

template <class H>
std::uintptr_t Id(H h) {
  return reinterpret_cast<std::uintptr_t>(h);
}

// What a compositor shows of a swapchain image: an sRGB format's bytes as they are; a linear
// format's values (OpenXR: every non-sRGB format holds linear light) encoded to sRGB for the
// display, from the texture's own precision. A viewer that writes sRGB-encoded values into a
// linear format is shown washed out here, as in a real headset. Read back on the application's
// thread and context, restoring the state it touches.
Image Displayed(GLuint tex, int width, int height, std::int64_t format) {
  GLint prev_tex = 0, prev_pack = 0, prev_buf = 0;
  glGetIntegerv(GL_TEXTURE_BINDING_2D, &prev_tex);
  glGetIntegerv(GL_PACK_ALIGNMENT, &prev_pack);
  glGetIntegerv(GL_PIXEL_PACK_BUFFER_BINDING, &prev_buf);
  glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glBindTexture(GL_TEXTURE_2D, tex);
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 4;
  std::vector<std::uint8_t> bottom_up(n);
  if (IsSrgb(format)) {
    glGetTexImage(GL_TEXTURE_2D, 0, GL_RGBA, GL_UNSIGNED_BYTE, bottom_up.data());
  } else {
    std::vector<float> linear(n);
    glGetTexImage(GL_TEXTURE_2D, 0, GL_RGBA, GL_FLOAT, linear.data());
    for (std::size_t i = 0; i < n; ++i) {
      const double c = std::clamp(static_cast<double>(linear[i]), 0.0, 1.0);
      const double e = i % 4 == 3       ? c
                       : c <= 0.0031308 ? 12.92 * c
                                        : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
      bottom_up[i] = static_cast<std::uint8_t>(std::lround(255.0 * e));
    }
  }
  glBindTexture(GL_TEXTURE_2D, static_cast<GLuint>(prev_tex));
  glPixelStorei(GL_PACK_ALIGNMENT, prev_pack);
  glBindBuffer(GL_PIXEL_PACK_BUFFER, static_cast<GLuint>(prev_buf));
  Image img;
  img.width = width;
  img.height = height;
  img.rgba.resize(n);
  const std::size_t row = static_cast<std::size_t>(width) * 4;
  for (int y = 0; y < height; ++y) {
    std::memcpy(img.rgba.data() + static_cast<std::size_t>(y) * row,
                bottom_up.data() + static_cast<std::size_t>(height - 1 - y) * row, row);
  }
  return img;
}

void WriteReport() {
  State& s = S();
  if (s.out_dir.empty()) return;
  std::ofstream out(s.out_dir + "/report.txt");
  out << "lifecycle " << (s.first_violation.empty() ? "ok" : "FAIL: " + s.first_violation) << "\n";
  out << "states";
  for (const auto& p : s.polled) out << " " << p;
  out << "\n";
  out << "requirements_before_session " << (s.requirements_asked ? 1 : 0) << "\n"
      << "binding_context_current " << (s.binding_context_current ? 1 : 0) << "\n"
      << "frames_ended " << s.frames_ended << "\n"
      << "frames_with_projection " << s.frames_projection << "\n"
      << "frames_with_quad " << s.frames_quad << "\n"
      << "requested_exit " << (s.requested_exit ? 1 : 0) << "\n"
      << "runtime_exit " << (s.runtime_exit ? 1 : 0) << "\n"
      << "projection_space " << static_cast<int>(s.projection_space) << "\n"
      << "quad_space " << static_cast<int>(s.quad_space) << "\n"
      << "quad_size_m " << s.quad_width_m << " " << s.quad_height_m << "\n"
      << "quad_pose " << s.quad_pose.position.x << " " << s.quad_pose.position.y << " "
      << s.quad_pose.position.z << " " << s.quad_pose.orientation.x << " "
      << s.quad_pose.orientation.y << " " << s.quad_pose.orientation.z << " "
      << s.quad_pose.orientation.w << "\n"
      << "last_drawn_display_ns " << s.last_drawn_display << "\n"
      << "session_open " << (s.session ? 1 : 0) << "\n"
      << "swapchain_formats" << s.swapchain_formats << "\n";
  auto png = [&](const char* name, const Image& img) {
    if (img.width > 0) {
      stbi_write_png((s.out_dir + "/" + name).c_str(), img.width, img.height, 4, img.rgba.data(),
                     img.width * 4);
    }
  };
  png("left.png", s.left);
  png("right.png", s.right);
  png("hud.png", s.hud);
}

// --- instance --------------------------------------------------------------------------------

XrResult EnumerateInstanceExtensionProperties(const char* layer, std::uint32_t capacity,
                                              std::uint32_t* count, XrExtensionProperties* props) {
  if (layer != nullptr) return XR_ERROR_API_LAYER_NOT_PRESENT;
  *count = 2;
  if (capacity == 0) return XR_SUCCESS;
  if (props == nullptr) return XR_ERROR_VALIDATION_FAILURE;
  if (capacity < 2) return XR_ERROR_SIZE_INSUFFICIENT;
  std::strncpy(props[0].extensionName, XR_KHR_OPENGL_ENABLE_EXTENSION_NAME,
               XR_MAX_EXTENSION_NAME_SIZE - 1);
  props[0].extensionVersion = XR_KHR_opengl_enable_SPEC_VERSION;
  std::strncpy(props[1].extensionName, XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME,
               XR_MAX_EXTENSION_NAME_SIZE - 1);
  props[1].extensionVersion = XR_KHR_convert_timespec_time_SPEC_VERSION;
  return XR_SUCCESS;
}

XrResult CreateInstance(const XrInstanceCreateInfo* info, XrInstance* instance) {
  std::lock_guard<std::mutex> lock(g_mu);
  if (S().instance) return XR_ERROR_LIMIT_REACHED;
  if (info == nullptr || info->type != XR_TYPE_INSTANCE_CREATE_INFO)
    return XR_ERROR_VALIDATION_FAILURE;
  if (XR_VERSION_MAJOR(info->applicationInfo.apiVersion) != 1)
    return XR_ERROR_API_VERSION_UNSUPPORTED;
  bool gl = false, timespec_time = false;
  for (std::uint32_t i = 0; i < info->enabledExtensionCount; ++i) {
    if (std::strcmp(info->enabledExtensionNames[i], XR_KHR_OPENGL_ENABLE_EXTENSION_NAME) == 0) {
      gl = true;
    } else if (std::strcmp(info->enabledExtensionNames[i],
                           XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME) == 0) {
      timespec_time = true;
    } else {
      return XR_ERROR_EXTENSION_NOT_PRESENT;
    }
  }
  g_state = std::make_unique<State>();  // a fresh instance
  State& fresh = S();
  if (!gl) Violation("instance created without XR_KHR_opengl_enable");
  fresh.instance = true;
  fresh.timespec_enabled = timespec_time;
  if (const char* h = std::getenv(kEnvHead)) {
    double v[4] = {0, 0, 0, 0};
    if (std::sscanf(h, "%lf %lf %lf %lf", &v[0], &v[1], &v[2], &v[3]) == 4) {
      fresh.head = {v[0], v[1], v[2], v[3] * 3.14159265358979323846 / 180.0};
    } else {
      Violation(std::string(kEnvHead) + " is not 'x y z yaw_deg'");
    }
  }
  if (const char* d = std::getenv(kEnvOut)) fresh.out_dir = d;
  if (const char* e = std::getenv(kEnvExitAfter)) fresh.exit_after = std::strtoull(e, nullptr, 10);
  if (const char* st = std::getenv(kEnvStage)) fresh.stage = std::string(st) != "0";
  if (const char* f = std::getenv(kEnvFormats)) {
    fresh.formats.clear();
    std::istringstream names(f);
    for (std::string name; names >> name;) {
      const auto* it = std::find_if(std::begin(kFormatNames), std::end(kFormatNames),
                                    [&](const NamedFormat& n) { return name == n.name; });
      if (it == std::end(kFormatNames)) {
        Violation(std::string(kEnvFormats) + " names an unknown format '" + name + "'");
      } else {
        fresh.formats.push_back(it->format);
      }
    }
  }
  *instance = reinterpret_cast<XrInstance>(0x1);
  return XR_SUCCESS;
}

XrResult DestroyInstance(XrInstance) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (s.session) Violation("instance destroyed with its session still open");
  WriteReport();
  s.instance = false;
  return XR_SUCCESS;
}

XrResult GetInstanceProperties(XrInstance, XrInstanceProperties* p) {
  p->runtimeVersion = XR_MAKE_VERSION(0, 1, 0);
  std::strncpy(p->runtimeName, "vdyn test runtime", XR_MAX_RUNTIME_NAME_SIZE - 1);
  return XR_SUCCESS;
}

XrResult ResultToString(XrInstance, XrResult r, char buffer[XR_MAX_RESULT_STRING_SIZE]) {
  std::snprintf(buffer, XR_MAX_RESULT_STRING_SIZE, "XR_RESULT_%d", static_cast<int>(r));
  return XR_SUCCESS;
}

XrResult StructureTypeToString(XrInstance, XrStructureType t,
                               char buffer[XR_MAX_STRUCTURE_NAME_SIZE]) {
  std::snprintf(buffer, XR_MAX_STRUCTURE_NAME_SIZE, "XR_TYPE_%d", static_cast<int>(t));
  return XR_SUCCESS;
}

XrResult GetSystem(XrInstance, const XrSystemGetInfo* info, XrSystemId* id) {
  if (info->formFactor != XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY)
    return XR_ERROR_FORM_FACTOR_UNSUPPORTED;
  *id = 1;
  return XR_SUCCESS;
}

XrResult GetSystemProperties(XrInstance, XrSystemId, XrSystemProperties* p) {
  p->systemId = 1;
  p->vendorId = 0;
  std::strncpy(p->systemName, "vdyn test headset", XR_MAX_SYSTEM_NAME_SIZE - 1);
  p->graphicsProperties.maxSwapchainImageWidth = 4096;
  p->graphicsProperties.maxSwapchainImageHeight = 4096;
  p->graphicsProperties.maxLayerCount = 16;
  p->trackingProperties.orientationTracking = XR_TRUE;
  p->trackingProperties.positionTracking = XR_TRUE;
  return XR_SUCCESS;
}

XrResult GetOpenGLGraphicsRequirements(XrInstance, XrSystemId, XrGraphicsRequirementsOpenGLKHR* r) {
  std::lock_guard<std::mutex> lock(g_mu);
  S().requirements_asked = true;
  r->minApiVersionSupported = XR_MAKE_VERSION(3, 3, 0);
  r->maxApiVersionSupported = XR_MAKE_VERSION(4, 6, 0);
  return XR_SUCCESS;
}

XrResult EnumerateViewConfigurations(XrInstance, XrSystemId, std::uint32_t capacity,
                                     std::uint32_t* count, XrViewConfigurationType* types) {
  *count = 1;
  if (capacity > 0) types[0] = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  return XR_SUCCESS;
}

XrResult EnumerateViewConfigurationViews(XrInstance, XrSystemId, XrViewConfigurationType type,
                                         std::uint32_t capacity, std::uint32_t* count,
                                         XrViewConfigurationView* views) {
  if (type != XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO)
    return XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
  *count = 2;
  if (capacity == 0) return XR_SUCCESS;
  if (capacity < 2) return XR_ERROR_SIZE_INSUFFICIENT;
  for (int i = 0; i < 2; ++i) {
    views[i].recommendedImageRectWidth = kEyeWidth;
    views[i].recommendedImageRectHeight = kEyeHeight;
    views[i].maxImageRectWidth = 4096;
    views[i].maxImageRectHeight = 4096;
    views[i].recommendedSwapchainSampleCount = 1;
    views[i].maxSwapchainSampleCount = 1;
  }
  return XR_SUCCESS;
}

XrResult EnumerateEnvironmentBlendModes(XrInstance, XrSystemId, XrViewConfigurationType,
                                        std::uint32_t capacity, std::uint32_t* count,
                                        XrEnvironmentBlendMode* modes) {
  *count = 1;
  if (capacity > 0) modes[0] = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
  return XR_SUCCESS;
}

// --- session ---------------------------------------------------------------------------------

XrResult CreateSession(XrInstance, const XrSessionCreateInfo* info, XrSession* session) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (!s.requirements_asked) {
    Violation("xrCreateSession before xrGetOpenGLGraphicsRequirementsKHR");
    return XR_ERROR_GRAPHICS_REQUIREMENTS_CALL_MISSING;
  }
  if (s.session) return XR_ERROR_LIMIT_REACHED;
  const auto* b = static_cast<const XrGraphicsBindingOpenGLXlibKHR*>(info->next);
  if (b == nullptr || b->type != XR_TYPE_GRAPHICS_BINDING_OPENGL_XLIB_KHR) {
    Violation("xrCreateSession without an Xlib OpenGL binding");
    return XR_ERROR_GRAPHICS_DEVICE_INVALID;
  }
  s.binding_context_current = b->xDisplay != nullptr && b->glxContext != nullptr &&
                              b->glxContext == glXGetCurrentContext() && b->glxDrawable != 0;
  if (!s.binding_context_current) Violation("the binding's GLX context is not the current one");
  s.session = true;
  s.state = XR_SESSION_STATE_IDLE;
  s.events.push_back(XR_SESSION_STATE_IDLE);
  s.events.push_back(XR_SESSION_STATE_READY);
  *session = reinterpret_cast<XrSession>(0x2);
  return XR_SUCCESS;
}

XrResult DestroySession(XrSession) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (s.running) Violation("xrDestroySession while running (no xrEndSession)");
  for (auto& [id, sc] : s.swapchains) {
    (void)id;
    Violation("xrDestroySession with a swapchain left");
    break;
  }
  s.session = false;
  return XR_SUCCESS;
}

XrResult PollEvent(XrInstance, XrEventDataBuffer* buffer) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (s.events.empty()) return XR_EVENT_UNAVAILABLE;
  const XrSessionState st = s.events.front();
  s.events.pop_front();
  s.state = st;
  s.polled.push_back(StateName(st));
  auto* e = reinterpret_cast<XrEventDataSessionStateChanged*>(buffer);
  e->type = XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED;
  e->next = nullptr;
  e->session = reinterpret_cast<XrSession>(0x2);
  e->state = st;
  e->time = Now();
  return XR_SUCCESS;
}

XrResult BeginSession(XrSession, const XrSessionBeginInfo* info) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (s.state != XR_SESSION_STATE_READY) {
    Violation(std::string("xrBeginSession in state ") + StateName(s.state));
    return XR_ERROR_SESSION_NOT_READY;
  }
  if (info->primaryViewConfigurationType != XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO) {
    return XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED;
  }
  s.running = true;
  return XR_SUCCESS;
}

XrResult EndSession(XrSession) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (s.state != XR_SESSION_STATE_STOPPING) {
    Violation(std::string("xrEndSession in state ") + StateName(s.state));
    return XR_ERROR_SESSION_NOT_STOPPING;
  }
  s.running = false;
  s.events.push_back(XR_SESSION_STATE_IDLE);
  s.events.push_back(XR_SESSION_STATE_EXITING);
  return XR_SUCCESS;
}

XrResult RequestExitSession(XrSession) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (!s.running) {
    Violation("xrRequestExitSession on a session that is not running");
    return XR_ERROR_SESSION_NOT_RUNNING;
  }
  s.requested_exit = true;
  s.events.push_back(XR_SESSION_STATE_STOPPING);
  return XR_SUCCESS;
}

// --- spaces and views ------------------------------------------------------------------------

XrResult EnumerateReferenceSpaces(XrSession, std::uint32_t capacity, std::uint32_t* count,
                                  XrReferenceSpaceType* spaces) {
  std::lock_guard<std::mutex> lock(g_mu);
  const bool stage = S().stage;
  *count = stage ? 3 : 2;
  if (capacity == 0) return XR_SUCCESS;
  if (capacity < *count) return XR_ERROR_SIZE_INSUFFICIENT;
  spaces[0] = XR_REFERENCE_SPACE_TYPE_VIEW;
  spaces[1] = XR_REFERENCE_SPACE_TYPE_LOCAL;
  if (stage) spaces[2] = XR_REFERENCE_SPACE_TYPE_STAGE;
  return XR_SUCCESS;
}

XrResult CreateReferenceSpace(XrSession, const XrReferenceSpaceCreateInfo* info, XrSpace* space) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (info->referenceSpaceType == XR_REFERENCE_SPACE_TYPE_STAGE && !s.stage) {
    return XR_ERROR_REFERENCE_SPACE_UNSUPPORTED;
  }
  auto sp = std::make_unique<Space>();
  sp->type = info->referenceSpaceType;
  sp->pose = info->poseInReferenceSpace;
  const std::uintptr_t id = s.next_handle++;
  s.spaces[id] = std::move(sp);
  *space = reinterpret_cast<XrSpace>(id);
  return XR_SUCCESS;
}

XrResult DestroySpace(XrSpace space) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  return s.spaces.erase(Id(space)) == 1 ? XR_SUCCESS : XR_ERROR_HANDLE_INVALID;
}

XrResult LocateViews(XrSession, const XrViewLocateInfo* info, XrViewState* state,
                     std::uint32_t capacity, std::uint32_t* count, XrView* views) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  *count = 2;
  if (capacity == 0) return XR_SUCCESS;
  if (capacity < 2) return XR_ERROR_SIZE_INSUFFICIENT;
  const auto it = s.spaces.find(Id(info->space));
  if (it == s.spaces.end()) return XR_ERROR_HANDLE_INVALID;
  const Space& sp = *it->second;
  // The head in the base space, looking along -Z; then into the space's own pose (translation
  // only: the tests create spaces with identity orientation, which this checks).
  double head_y = sp.type == XR_REFERENCE_SPACE_TYPE_STAGE ? kStageHeadHeight : 0.0;
  if (sp.pose.orientation.w != 1.0f)
    Violation("reference space with a rotated pose (not supported here)");
  state->viewStateFlags = XR_VIEW_STATE_ORIENTATION_VALID_BIT | XR_VIEW_STATE_POSITION_VALID_BIT |
                          XR_VIEW_STATE_ORIENTATION_TRACKED_BIT |
                          XR_VIEW_STATE_POSITION_TRACKED_BIT;
  // The head moved and turned by kEnvHead (yaw about +Y); each eye half the IPD along its X.
  const double yaw = s.head[3];
  const double c = std::cos(yaw), sn = std::sin(yaw);
  for (int e = 0; e < 2; ++e) {
    XrView& v = views[e];
    v.pose.orientation = {0, static_cast<float>(std::sin(0.5 * yaw)), 0,
                          static_cast<float>(std::cos(0.5 * yaw))};
    const double px = sp.pose.position.x, py = sp.pose.position.y, pz = sp.pose.position.z;
    const double side = (e == 0 ? -0.5 : 0.5) * kIpd;  // along the head's X: (cos, 0, -sin)
    v.pose.position = {static_cast<float>(s.head[0] + side * c - px),
                       static_cast<float>(head_y + s.head[1] - py),
                       static_cast<float>(s.head[2] - side * sn - pz)};
    if (e == 0) {
      v.fov = {static_cast<float>(kAngleOuter), static_cast<float>(kAngleInner),
               static_cast<float>(kAngleUp), static_cast<float>(kAngleDown)};
    } else {
      v.fov = {static_cast<float>(-kAngleInner), static_cast<float>(-kAngleOuter),
               static_cast<float>(kAngleUp), static_cast<float>(kAngleDown)};
    }
  }
  return XR_SUCCESS;
}

// --- swapchains ------------------------------------------------------------------------------

XrResult EnumerateSwapchainFormats(XrSession, std::uint32_t capacity, std::uint32_t* count,
                                   std::int64_t* formats) {
  std::lock_guard<std::mutex> lock(g_mu);
  const std::vector<std::int64_t>& offered = S().formats;
  const auto n = static_cast<std::uint32_t>(offered.size());
  *count = n;
  if (capacity == 0) return XR_SUCCESS;
  if (capacity < n) return XR_ERROR_SIZE_INSUFFICIENT;
  std::copy(offered.begin(), offered.end(), formats);
  return XR_SUCCESS;
}

XrResult CreateSwapchain(XrSession, const XrSwapchainCreateInfo* info, XrSwapchain* swapchain) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (std::find(s.formats.begin(), s.formats.end(), info->format) == s.formats.end())
    return XR_ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED;
  if (info->width == 0 || info->height == 0 || info->arraySize != 1 || info->faceCount != 1) {
    return XR_ERROR_VALIDATION_FAILURE;
  }
  if (glXGetCurrentContext() == nullptr) {
    Violation("xrCreateSwapchain without a current OpenGL context");
    return XR_ERROR_GRAPHICS_DEVICE_INVALID;
  }
  auto sc = std::make_unique<Swapchain>();
  sc->width = static_cast<int>(info->width);
  sc->height = static_cast<int>(info->height);
  sc->format = info->format;
  for (const NamedFormat& n : kFormatNames) {
    if (n.format == info->format) s.swapchain_formats += std::string(" ") + n.name;
  }
  sc->textures.resize(3);
  GLint prev = 0;
  glGetIntegerv(GL_TEXTURE_BINDING_2D, &prev);
  glGenTextures(3, sc->textures.data());
  for (GLuint t : sc->textures) {
    glBindTexture(GL_TEXTURE_2D, t);
    glTexStorage2D(GL_TEXTURE_2D, 1, static_cast<GLenum>(info->format), sc->width, sc->height);
  }
  glBindTexture(GL_TEXTURE_2D, static_cast<GLuint>(prev));
  const std::uintptr_t id = s.next_handle++;
  s.swapchains[id] = std::move(sc);
  *swapchain = reinterpret_cast<XrSwapchain>(id);
  return XR_SUCCESS;
}

XrResult DestroySwapchain(XrSwapchain swapchain) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  const auto it = s.swapchains.find(Id(swapchain));
  if (it == s.swapchains.end()) return XR_ERROR_HANDLE_INVALID;
  glDeleteTextures(static_cast<GLsizei>(it->second->textures.size()), it->second->textures.data());
  s.swapchains.erase(it);
  return XR_SUCCESS;
}

XrResult EnumerateSwapchainImages(XrSwapchain swapchain, std::uint32_t capacity,
                                  std::uint32_t* count, XrSwapchainImageBaseHeader* images) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  const auto it = s.swapchains.find(Id(swapchain));
  if (it == s.swapchains.end()) return XR_ERROR_HANDLE_INVALID;
  *count = static_cast<std::uint32_t>(it->second->textures.size());
  if (capacity == 0) return XR_SUCCESS;
  if (capacity < *count) return XR_ERROR_SIZE_INSUFFICIENT;
  auto* gl = reinterpret_cast<XrSwapchainImageOpenGLKHR*>(images);
  for (std::uint32_t i = 0; i < *count; ++i) {
    if (gl[i].type != XR_TYPE_SWAPCHAIN_IMAGE_OPENGL_KHR) return XR_ERROR_VALIDATION_FAILURE;
    gl[i].image = it->second->textures[i];
  }
  return XR_SUCCESS;
}

XrResult AcquireSwapchainImage(XrSwapchain swapchain, const XrSwapchainImageAcquireInfo*,
                               std::uint32_t* index) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  const auto it = s.swapchains.find(Id(swapchain));
  if (it == s.swapchains.end()) return XR_ERROR_HANDLE_INVALID;
  Swapchain& sc = *it->second;
  if (!sc.acquired.empty()) {
    Violation("a second image acquired before the first was released");
    return XR_ERROR_CALL_ORDER_INVALID;
  }
  *index = static_cast<std::uint32_t>(sc.next);
  sc.acquired.push_back(sc.next);
  sc.next = (sc.next + 1) % static_cast<int>(sc.textures.size());
  sc.waited = false;
  return XR_SUCCESS;
}

XrResult WaitSwapchainImage(XrSwapchain swapchain, const XrSwapchainImageWaitInfo*) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  const auto it = s.swapchains.find(Id(swapchain));
  if (it == s.swapchains.end()) return XR_ERROR_HANDLE_INVALID;
  if (it->second->acquired.empty()) {
    Violation("xrWaitSwapchainImage with no image acquired");
    return XR_ERROR_CALL_ORDER_INVALID;
  }
  it->second->waited = true;
  return XR_SUCCESS;
}

XrResult ReleaseSwapchainImage(XrSwapchain swapchain, const XrSwapchainImageReleaseInfo*) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  const auto it = s.swapchains.find(Id(swapchain));
  if (it == s.swapchains.end()) return XR_ERROR_HANDLE_INVALID;
  Swapchain& sc = *it->second;
  if (sc.acquired.empty() || !sc.waited) {
    Violation("xrReleaseSwapchainImage of an image not acquired and waited for");
    return XR_ERROR_CALL_ORDER_INVALID;
  }
  sc.last_released = sc.acquired.front();
  sc.acquired.pop_front();
  return XR_SUCCESS;
}

// --- frames ----------------------------------------------------------------------------------

XrResult WaitFrame(XrSession, const XrFrameWaitInfo*, XrFrameState* fs) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (!s.running) {
    Violation("xrWaitFrame on a session that is not running");
    return XR_ERROR_SESSION_NOT_RUNNING;
  }
  s.frame_waited = true;
  s.predicted = Now() + kPeriodNs;
  fs->predictedDisplayTime = s.predicted;
  fs->predictedDisplayPeriod = kPeriodNs;
  // Frames are to be drawn once the session is visible; the first ones (synchronizing) too here.
  fs->shouldRender = s.state == XR_SESSION_STATE_STOPPING ? XR_FALSE : XR_TRUE;
  return XR_SUCCESS;
}

XrResult BeginFrame(XrSession, const XrFrameBeginInfo*) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (!s.frame_waited) {
    Violation("xrBeginFrame without xrWaitFrame");
    return XR_ERROR_CALL_ORDER_INVALID;
  }
  s.frame_waited = false;
  s.frame_begun = true;
  return XR_SUCCESS;
}

XrResult EndFrame(XrSession, const XrFrameEndInfo* info) {
  State& s = S();
  std::lock_guard<std::mutex> lock(g_mu);
  if (!s.frame_begun) {
    Violation("xrEndFrame without xrBeginFrame");
    return XR_ERROR_CALL_ORDER_INVALID;
  }
  s.frame_begun = false;
  if (info->displayTime != s.predicted) Violation("xrEndFrame with a display time not predicted");
  if (info->environmentBlendMode != XR_ENVIRONMENT_BLEND_MODE_OPAQUE) {
    return XR_ERROR_ENVIRONMENT_BLEND_MODE_UNSUPPORTED;
  }
  auto released = [&](XrSwapchain h, const XrRect2Di& rect, Swapchain** out) {
    const auto it = s.swapchains.find(Id(h));
    if (it == s.swapchains.end()) {
      Violation("a layer names an unknown swapchain");
      return false;
    }
    Swapchain& sc = *it->second;
    if (sc.last_released < 0 || !sc.acquired.empty()) {
      Violation("a layer's swapchain image was not released before xrEndFrame");
      return false;
    }
    if (rect.offset.x < 0 || rect.offset.y < 0 || rect.extent.width <= 0 ||
        rect.offset.x + rect.extent.width > sc.width ||
        rect.offset.y + rect.extent.height > sc.height) {
      Violation("a layer's image rectangle is outside its swapchain");
      return false;
    }
    *out = &sc;
    return true;
  };
  bool projection = false, quad = false;
  for (std::uint32_t i = 0; i < info->layerCount; ++i) {
    const XrCompositionLayerBaseHeader* l = info->layers[i];
    const auto space = s.spaces.find(Id(l->space));
    if (space == s.spaces.end()) {
      Violation("a layer in an unknown space");
      continue;
    }
    if (l->type == XR_TYPE_COMPOSITION_LAYER_PROJECTION) {
      const auto* p = reinterpret_cast<const XrCompositionLayerProjection*>(l);
      if (p->viewCount != 2) {
        Violation("a projection layer without exactly two views");
        continue;
      }
      s.projection_space = space->second->type;
      for (int e = 0; e < 2; ++e) {
        Swapchain* sc = nullptr;
        if (!released(p->views[e].subImage.swapchain, p->views[e].subImage.imageRect, &sc))
          continue;
        Image img = Displayed(sc->textures[static_cast<std::size_t>(sc->last_released)], sc->width,
                              sc->height, sc->format);
        (e == 0 ? s.left : s.right) = std::move(img);
      }
      projection = true;
    } else if (l->type == XR_TYPE_COMPOSITION_LAYER_QUAD) {
      const auto* q = reinterpret_cast<const XrCompositionLayerQuad*>(l);
      Swapchain* sc = nullptr;
      if (!released(q->subImage.swapchain, q->subImage.imageRect, &sc)) continue;
      if (!(q->size.width > 0 && q->size.height > 0)) Violation("a quad layer of no size");
      s.quad_space = space->second->type;
      s.quad_pose = q->pose;
      s.quad_width_m = q->size.width;
      s.quad_height_m = q->size.height;
      s.hud = Displayed(sc->textures[static_cast<std::size_t>(sc->last_released)], sc->width,
                        sc->height, sc->format);
      quad = true;
    } else {
      Violation("a layer of a type this runtime does not compose");
    }
  }
  ++s.frames_ended;
  if (projection) {
    ++s.frames_projection;
    s.last_drawn_display = info->displayTime;
  }
  if (quad) ++s.frames_quad;
  if (s.frames_ended == 1) {
    // Synchronized with the application's frames: visible, then focused.
    s.events.push_back(XR_SESSION_STATE_SYNCHRONIZED);
    s.events.push_back(XR_SESSION_STATE_VISIBLE);
    s.events.push_back(XR_SESSION_STATE_FOCUSED);
  }
  if (s.exit_after > 0 && s.frames_ended == s.exit_after && !s.requested_exit) {
    s.runtime_exit = true;  // the user left through the runtime
    s.events.push_back(XR_SESSION_STATE_STOPPING);
  }
  return XR_SUCCESS;
}

// --- time (XR_KHR_convert_timespec_time): XrTime is CLOCK_MONOTONIC in ns here --------------

XrResult ConvertTimeToTimespecTime(XrInstance, XrTime time, timespec* out) {
  std::lock_guard<std::mutex> lock(g_mu);
  if (!S().timespec_enabled) {
    Violation("xrConvertTimeToTimespecTimeKHR without its extension enabled");
    return XR_ERROR_FUNCTION_UNSUPPORTED;
  }
  if (time <= 0 || out == nullptr) return XR_ERROR_TIME_INVALID;
  out->tv_sec = static_cast<time_t>(time / 1'000'000'000);
  out->tv_nsec = static_cast<long>(time % 1'000'000'000);
  return XR_SUCCESS;
}

XrResult ConvertTimespecTimeToTime(XrInstance, const timespec* in, XrTime* out) {
  std::lock_guard<std::mutex> lock(g_mu);
  if (!S().timespec_enabled) return XR_ERROR_FUNCTION_UNSUPPORTED;
  *out = static_cast<XrTime>(in->tv_sec) * 1'000'000'000 + in->tv_nsec;
  return XR_SUCCESS;
}

// --- dispatch --------------------------------------------------------------------------------

XrResult GetInstanceProcAddr(XrInstance instance, const char* name, PFN_xrVoidFunction* fn) {
  struct Entry {
    const char* name;
    PFN_xrVoidFunction fn;
    bool without_instance;
  };
#define VDYN_XR_ENTRY(api, impl, pre) \
  { api, reinterpret_cast<PFN_xrVoidFunction>(&impl), pre }
  static const Entry kEntries[] = {
      VDYN_XR_ENTRY("xrGetInstanceProcAddr", GetInstanceProcAddr, true),
      VDYN_XR_ENTRY("xrEnumerateInstanceExtensionProperties", EnumerateInstanceExtensionProperties,
                    true),
      VDYN_XR_ENTRY("xrCreateInstance", CreateInstance, true),
      VDYN_XR_ENTRY("xrDestroyInstance", DestroyInstance, false),
      VDYN_XR_ENTRY("xrGetInstanceProperties", GetInstanceProperties, false),
      VDYN_XR_ENTRY("xrResultToString", ResultToString, false),
      VDYN_XR_ENTRY("xrStructureTypeToString", StructureTypeToString, false),
      VDYN_XR_ENTRY("xrGetSystem", GetSystem, false),
      VDYN_XR_ENTRY("xrGetSystemProperties", GetSystemProperties, false),
      VDYN_XR_ENTRY("xrGetOpenGLGraphicsRequirementsKHR", GetOpenGLGraphicsRequirements, false),
      VDYN_XR_ENTRY("xrEnumerateViewConfigurations", EnumerateViewConfigurations, false),
      VDYN_XR_ENTRY("xrEnumerateViewConfigurationViews", EnumerateViewConfigurationViews, false),
      VDYN_XR_ENTRY("xrEnumerateEnvironmentBlendModes", EnumerateEnvironmentBlendModes, false),
      VDYN_XR_ENTRY("xrCreateSession", CreateSession, false),
      VDYN_XR_ENTRY("xrDestroySession", DestroySession, false),
      VDYN_XR_ENTRY("xrPollEvent", PollEvent, false),
      VDYN_XR_ENTRY("xrBeginSession", BeginSession, false),
      VDYN_XR_ENTRY("xrEndSession", EndSession, false),
      VDYN_XR_ENTRY("xrRequestExitSession", RequestExitSession, false),
      VDYN_XR_ENTRY("xrEnumerateReferenceSpaces", EnumerateReferenceSpaces, false),
      VDYN_XR_ENTRY("xrCreateReferenceSpace", CreateReferenceSpace, false),
      VDYN_XR_ENTRY("xrDestroySpace", DestroySpace, false),
      VDYN_XR_ENTRY("xrLocateViews", LocateViews, false),
      VDYN_XR_ENTRY("xrEnumerateSwapchainFormats", EnumerateSwapchainFormats, false),
      VDYN_XR_ENTRY("xrCreateSwapchain", CreateSwapchain, false),
      VDYN_XR_ENTRY("xrDestroySwapchain", DestroySwapchain, false),
      VDYN_XR_ENTRY("xrEnumerateSwapchainImages", EnumerateSwapchainImages, false),
      VDYN_XR_ENTRY("xrAcquireSwapchainImage", AcquireSwapchainImage, false),
      VDYN_XR_ENTRY("xrWaitSwapchainImage", WaitSwapchainImage, false),
      VDYN_XR_ENTRY("xrReleaseSwapchainImage", ReleaseSwapchainImage, false),
      VDYN_XR_ENTRY("xrWaitFrame", WaitFrame, false),
      VDYN_XR_ENTRY("xrBeginFrame", BeginFrame, false),
      VDYN_XR_ENTRY("xrEndFrame", EndFrame, false),
      VDYN_XR_ENTRY("xrConvertTimeToTimespecTimeKHR", ConvertTimeToTimespecTime, false),
      VDYN_XR_ENTRY("xrConvertTimespecTimeToTimeKHR", ConvertTimespecTimeToTime, false),
  };
#undef VDYN_XR_ENTRY
  if (name == nullptr || fn == nullptr) return XR_ERROR_VALIDATION_FAILURE;
  for (const Entry& e : kEntries) {
    if (std::strcmp(e.name, name) != 0) continue;
    if (instance == XR_NULL_HANDLE && !e.without_instance) break;
    *fn = e.fn;
    return XR_SUCCESS;
  }
  *fn = nullptr;
  return instance == XR_NULL_HANDLE ? XR_ERROR_HANDLE_INVALID : XR_ERROR_FUNCTION_UNSUPPORTED;
}

}  // namespace

extern "C" XrResult xrNegotiateLoaderRuntimeInterface(const XrNegotiateLoaderInfo* loader,
                                                      XrNegotiateRuntimeRequest* request) {
  if (loader == nullptr || request == nullptr ||
      loader->structType != XR_LOADER_INTERFACE_STRUCT_LOADER_INFO ||
      loader->structSize != sizeof(XrNegotiateLoaderInfo) ||
      request->structType != XR_LOADER_INTERFACE_STRUCT_RUNTIME_REQUEST ||
      request->structSize != sizeof(XrNegotiateRuntimeRequest) || loader->minInterfaceVersion > 1 ||
      loader->maxInterfaceVersion < 1) {
    return XR_ERROR_INITIALIZATION_FAILED;
  }
  request->runtimeInterfaceVersion = 1;
  request->runtimeApiVersion = XR_CURRENT_API_VERSION;
  request->getInstanceProcAddr = &GetInstanceProcAddr;
  return XR_SUCCESS;
}

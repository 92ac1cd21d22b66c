#include "vdyn/viewer/xr_session.h"

#include <time.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include <spdlog/spdlog.h>

#include "gl_program.h"

// X11 and GLX last: their macros (None, Status, Bool...) must not reach other headers.
#include <epoxy/gl.h>
#include <epoxy/glx.h>
#define XR_USE_PLATFORM_XLIB
#define XR_USE_GRAPHICS_API_OPENGL
#define XR_USE_TIMESPEC
#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>

namespace vdyn::viewer {

namespace {

// A zeroed OpenXR structure of its type.
template <class T>
T XrStruct(XrStructureType type) {
  T v{};
  v.type = type;
  return v;
}

constexpr std::int64_t kGlRgba8 = 0x8058;        // GL_RGBA8
constexpr std::int64_t kGlRgba16 = 0x805B;       // GL_RGBA16
constexpr std::int64_t kGlRgba16f = 0x881A;      // GL_RGBA16F
constexpr std::int64_t kGlSrgb8Alpha8 = 0x8C43;  // GL_SRGB8_ALPHA8

// The swapchain formats this viewer draws into, best first. An sRGB one takes the renderer's
// sRGB-encoded bytes as they are. A linear one gets them decoded to linear light (LinearCopy):
// 16-bit float keeps the darks' steps as fine as the 8-bit sRGB image has them (8-bit linear
// merges the darkest: sRGB levels 0..6 all become 0, 7..17 all one level shown as 13, 18..25 one
// shown as 22), so it comes before the 16-bit normalised and the 8-bit one.
struct FormatChoice {
  std::int64_t format;
  const char* name;
  bool srgb;
};
constexpr FormatChoice kChoices[] = {{kGlSrgb8Alpha8, "GL_SRGB8_ALPHA8", true},
                                     {kGlRgba16f, "GL_RGBA16F", false},
                                     {kGlRgba16, "GL_RGBA16", false},
                                     {kGlRgba8, "GL_RGBA8", false}};

// A format's GL name where it is a common colour format, else its number.
std::string FormatName(std::int64_t f) {
  for (const FormatChoice& c : kChoices) {
    if (c.format == f) return c.name;
  }
  switch (f) {
    case 0x8059:
      return "GL_RGB10_A2";
    case 0x8C3A:
      return "GL_R11F_G11F_B10F";
    case 0x8814:
      return "GL_RGBA32F";
    case 0x8C41:
      return "GL_SRGB8";
    default: {
      char buf[32];
      std::snprintf(buf, sizeof buf, "0x%llX", static_cast<unsigned long long>(f));
      return buf;
    }
  }
}

// Copies the renderer's image (sRGB-encoded, 8 bits) into a linear swapchain image, decoding
// each texel to linear light (IEC 61966-2-1) in a full-screen triangle: what OpenXR's
// compositor expects of a non-sRGB format, which it encodes again for the display.
class LinearCopy {
 public:
  LinearCopy() {
    static const char* kVs = R"(#version 330 core
void main() {
  vec2 p = vec2(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0);
  gl_Position = vec4(p, 0.0, 1.0);
})";
    static const char* kFs = R"(#version 330 core
uniform sampler2D u_image;
out vec4 o_colour;
void main() {
  vec4 c = texelFetch(u_image, ivec2(gl_FragCoord.xy), 0);
  vec3 lo = c.rgb / 12.92, hi = pow((c.rgb + 0.055) / 1.055, vec3(2.4));
  o_colour = vec4(mix(lo, hi, step(vec3(0.04045), c.rgb)), c.a);
})";
    try {
      program_ = LinkProgram(kVs, kFs, "the headset's sRGB-to-linear copy");
    } catch (const GlError& e) {
      throw XrError(std::string("OpenXR: ") + e.what());
    }
    image_ = glGetUniformLocation(program_, "u_image");
    glGenVertexArrays(1, &vao_);
    glGenFramebuffers(1, &fbo_);
  }
  ~LinearCopy() {
    glDeleteFramebuffers(1, &fbo_);
    glDeleteVertexArrays(1, &vao_);
    glDeleteProgram(program_);
  }
  LinearCopy(const LinearCopy&) = delete;
  LinearCopy& operator=(const LinearCopy&) = delete;

  // Draws `source` (a texture of width x height) decoded into the texture `dest`; the GL state
  // it touches is put back.
  void Copy(GLuint source, GLuint dest, int width, int height) {
    GLint prev_program = 0, prev_vao = 0, prev_tex = 0, prev_active = 0, prev_fbo = 0;
    GLint viewport[4] = {};
    glGetIntegerv(GL_CURRENT_PROGRAM, &prev_program);
    glGetIntegerv(GL_VERTEX_ARRAY_BINDING, &prev_vao);
    glGetIntegerv(GL_ACTIVE_TEXTURE, &prev_active);
    glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &prev_fbo);
    glGetIntegerv(GL_VIEWPORT, viewport);
    const GLenum caps[] = {GL_DEPTH_TEST, GL_BLEND, GL_CULL_FACE, GL_SCISSOR_TEST,
                           GL_FRAMEBUFFER_SRGB};
    std::array<GLboolean, std::size(caps)> enabled{};
    for (std::size_t i = 0; i < std::size(caps); ++i) {
      enabled[i] = glIsEnabled(caps[i]);
      glDisable(caps[i]);
    }
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo_);
    glFramebufferTexture2D(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, dest, 0);
    if (glCheckFramebufferStatus(GL_DRAW_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
      throw XrError("OpenXR: a swapchain image cannot be drawn into");
    glViewport(0, 0, width, height);
    glUseProgram(program_);
    glActiveTexture(GL_TEXTURE0);
    glGetIntegerv(GL_TEXTURE_BINDING_2D, &prev_tex);
    glBindTexture(GL_TEXTURE_2D, source);
    glUniform1i(image_, 0);
    glBindVertexArray(vao_);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glFramebufferTexture2D(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, 0, 0);
    glBindVertexArray(static_cast<GLuint>(prev_vao));
    glBindTexture(GL_TEXTURE_2D, static_cast<GLuint>(prev_tex));
    glActiveTexture(static_cast<GLenum>(prev_active));
    glUseProgram(static_cast<GLuint>(prev_program));
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, static_cast<GLuint>(prev_fbo));
    glViewport(viewport[0], viewport[1], viewport[2], viewport[3]);
    for (std::size_t i = 0; i < std::size(caps); ++i) {
      if (enabled[i]) glEnable(caps[i]);
    }
  }

 private:
  GLuint program_ = 0, vao_ = 0, fbo_ = 0;
  GLint image_ = -1;
};

std::string ResultName(XrInstance instance, XrResult r) {
  char buf[XR_MAX_RESULT_STRING_SIZE] = {};
  if (instance != XR_NULL_HANDLE && xrResultToString(instance, r, buf) == XR_SUCCESS) {
    return std::string(buf) + " (" + std::to_string(r) + ")";
  }
  switch (r) {
    case XR_ERROR_RUNTIME_UNAVAILABLE:
      return "XR_ERROR_RUNTIME_UNAVAILABLE (-51)";
    case XR_ERROR_RUNTIME_FAILURE:
      return "XR_ERROR_RUNTIME_FAILURE (-2)";
    case XR_ERROR_EXTENSION_NOT_PRESENT:
      return "XR_ERROR_EXTENSION_NOT_PRESENT (-9)";
    case XR_ERROR_FORM_FACTOR_UNAVAILABLE:
      return "XR_ERROR_FORM_FACTOR_UNAVAILABLE (-35)";
    default:
      return "XrResult " + std::to_string(r);
  }
}

Pose PoseOf(const XrPosef& p) {
  return {RotationFromQuat(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z),
          {p.position.x, p.position.y, p.position.z}};
}

// A rotation matrix as a unit quaternion (Shepperd's method), with the pose's position.
XrPosef XrPoseOf(const Pose& p) {
  const Mat3& R = p.R;
  const double m00 = R.c[0].x, m11 = R.c[1].y, m22 = R.c[2].z;
  const double m01 = R.c[1].x, m10 = R.c[0].y, m02 = R.c[2].x, m20 = R.c[0].z;
  const double m12 = R.c[2].y, m21 = R.c[1].z;
  double w, qx, qy, qz;
  const double tr = m00 + m11 + m22;
  if (tr > 0) {
    const double s = std::sqrt(tr + 1.0) * 2;
    w = 0.25 * s, qx = (m21 - m12) / s, qy = (m02 - m20) / s, qz = (m10 - m01) / s;
  } else if (m00 > m11 && m00 > m22) {
    const double s = std::sqrt(1.0 + m00 - m11 - m22) * 2;
    w = (m21 - m12) / s, qx = 0.25 * s, qy = (m01 + m10) / s, qz = (m02 + m20) / s;
  } else if (m11 > m22) {
    const double s = std::sqrt(1.0 + m11 - m00 - m22) * 2;
    w = (m02 - m20) / s, qx = (m01 + m10) / s, qy = 0.25 * s, qz = (m12 + m21) / s;
  } else {
    const double s = std::sqrt(1.0 + m22 - m00 - m11) * 2;
    w = (m10 - m01) / s, qx = (m02 + m20) / s, qy = (m12 + m21) / s, qz = 0.25 * s;
  }
  XrPosef out{};
  out.orientation = {static_cast<float>(qx), static_cast<float>(qy), static_cast<float>(qz),
                     static_cast<float>(w)};
  out.position = {static_cast<float>(p.t.x), static_cast<float>(p.t.y), static_cast<float>(p.t.z)};
  return out;
}

const char* StateName(XrSessionState s) {
  switch (s) {
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
    case XR_SESSION_STATE_LOSS_PENDING:
      return "loss pending";
    case XR_SESSION_STATE_EXITING:
      return "exiting";
    default:
      return "unknown";
  }
}

struct Swapchain {
  XrSwapchain handle = XR_NULL_HANDLE;
  int width = 0, height = 0;
  std::vector<XrSwapchainImageOpenGLKHR> images;
  RenderTarget target;
  std::uint32_t acquired = 0;  // the acquired image's index
};

}  // namespace

struct Headset::Impl {
  XrOptions options;
  XrInstance instance = XR_NULL_HANDLE;
  XrSystemId system = XR_NULL_SYSTEM_ID;
  XrSession session = XR_NULL_HANDLE;
  XrSpace space = XR_NULL_HANDLE;
  XrSpace view_space = XR_NULL_HANDLE;
  XrSessionState state = XR_SESSION_STATE_UNKNOWN;
  bool running = false;
  bool ended = false;
  bool exit_requested = false;
  bool standing_on_local = false;
  std::string runtime;
  std::int64_t format = kGlSrgb8Alpha8;
  // A linear format: the eyes and the HUD are drawn into targets of their own (sRGB-encoded, as
  // on the desktop) and copied, decoded, into the swapchain images.
  std::unique_ptr<LinearCopy> linear;
  std::array<Swapchain, 2> eyes;
  Swapchain hud;
  std::array<XrViewConfigurationView, 2> config_views{};
  std::uint64_t frames = 0;
  RenderTarget mirror;
  // The waited frame.
  XrFrameState frame_state{};
  bool frame_waited = false;
  std::int64_t display_mono_ns = 0;
  PFN_xrConvertTimeToTimespecTimeKHR to_timespec = nullptr;
  // The head at the last tracked frame.
  Pose head;
  bool head_known = false;
  std::uint64_t space_changes = 0;

  // The constructor's stages, in order.
  void CreateInstance();      // an instance with OpenGL, on the runtime's headset system
  void CheckOpenGlVersion();  // the runtime's OpenGL requirements against this context
  void CreateSession();       // the session on the current GLX context
  void CreateSpaces();        // the place's reference space (seated or standing) and the head's
  void ReadViews();           // the two eyes' recommended sizes
  void ChooseFormat();        // an sRGB swapchain format, else the best linear one
  void CreateSwapchains();    // the eyes', the HUD's and the desktop mirror's

  void Check(XrResult r, const char* what) const {
    if (XR_FAILED(r)) throw XrError(std::string("OpenXR ") + what + ": " + ResultName(instance, r));
  }

  void CreateSwapchain(Swapchain& s, int width, int height, std::uint32_t samples,
                       int render_samples) {
    auto ci = XrStruct<XrSwapchainCreateInfo>(XR_TYPE_SWAPCHAIN_CREATE_INFO);
    ci.usageFlags = XR_SWAPCHAIN_USAGE_COLOR_ATTACHMENT_BIT | XR_SWAPCHAIN_USAGE_SAMPLED_BIT;
    ci.format = format;
    ci.sampleCount = samples;
    ci.width = static_cast<std::uint32_t>(width);
    ci.height = static_cast<std::uint32_t>(height);
    ci.faceCount = 1;
    ci.arraySize = 1;
    ci.mipCount = 1;
    Check(xrCreateSwapchain(session, &ci, &s.handle), "xrCreateSwapchain");
    std::uint32_t n = 0;
    Check(xrEnumerateSwapchainImages(s.handle, 0, &n, nullptr), "xrEnumerateSwapchainImages");
    s.images.assign(n, XrStruct<XrSwapchainImageOpenGLKHR>(XR_TYPE_SWAPCHAIN_IMAGE_OPENGL_KHR));
    Check(xrEnumerateSwapchainImages(
              s.handle, n, &n, reinterpret_cast<XrSwapchainImageBaseHeader*>(s.images.data())),
          "xrEnumerateSwapchainImages");
    s.width = width;
    s.height = height;
    // A linear format: the target keeps a colour texture of its own, copied in at Release.
    s.target.Resize(width, height, render_samples, linear == nullptr);
  }

  // Acquires and waits for an image of `s` and points its target at it.
  void Acquire(Swapchain& s) {
    std::uint32_t index = 0;
    auto ai = XrStruct<XrSwapchainImageAcquireInfo>(XR_TYPE_SWAPCHAIN_IMAGE_ACQUIRE_INFO);
    Check(xrAcquireSwapchainImage(s.handle, &ai, &index), "xrAcquireSwapchainImage");
    auto wi = XrStruct<XrSwapchainImageWaitInfo>(XR_TYPE_SWAPCHAIN_IMAGE_WAIT_INFO);
    wi.timeout = 1'000'000'000;  // 1 s
    Check(xrWaitSwapchainImage(s.handle, &wi), "xrWaitSwapchainImage");
    if (index >= s.images.size())
      throw XrError("OpenXR runtime gave a swapchain image index past the end");
    s.acquired = index;
    if (linear == nullptr) s.target.SetExternalColour(s.images[index].image);
  }

  // Releases the acquired image, with the target's picture copied into it decoded to linear
  // light first when the format is linear.
  void Release(Swapchain& s) {
    if (linear != nullptr) {
      linear->Copy(s.target.colour_texture(), s.images[s.acquired].image, s.width, s.height);
    }
    auto ri = XrStruct<XrSwapchainImageReleaseInfo>(XR_TYPE_SWAPCHAIN_IMAGE_RELEASE_INFO);
    Check(xrReleaseSwapchainImage(s.handle, &ri), "xrReleaseSwapchainImage");
  }

  void Destroy() {
    for (Swapchain& s : eyes) {
      if (s.handle != XR_NULL_HANDLE) xrDestroySwapchain(s.handle);
      s.handle = XR_NULL_HANDLE;
    }
    if (hud.handle != XR_NULL_HANDLE) xrDestroySwapchain(hud.handle);
    hud.handle = XR_NULL_HANDLE;
    if (space != XR_NULL_HANDLE) xrDestroySpace(space);
    if (view_space != XR_NULL_HANDLE) xrDestroySpace(view_space);
    space = view_space = XR_NULL_HANDLE;
    if (session != XR_NULL_HANDLE) xrDestroySession(session);
    session = XR_NULL_HANDLE;
    linear.reset();
    if (instance != XR_NULL_HANDLE) xrDestroyInstance(instance);
    instance = XR_NULL_HANDLE;
  }
};

void Headset::Impl::CreateInstance() {
  // The runtime must offer OpenGL.
  std::uint32_t n = 0;
  XrResult r = xrEnumerateInstanceExtensionProperties(nullptr, 0, &n, nullptr);
  if (XR_FAILED(r)) {
    throw XrError("no OpenXR runtime (" + ResultName(XR_NULL_HANDLE, r) +
                  "): install one (Monado, SteamVR) or point XR_RUNTIME_JSON at its manifest");
  }
  std::vector<XrExtensionProperties> exts(
      n, XrStruct<XrExtensionProperties>(XR_TYPE_EXTENSION_PROPERTIES));
  Check(xrEnumerateInstanceExtensionProperties(nullptr, n, &n, exts.data()),
        "xrEnumerateInstanceExtensionProperties");
  bool has_gl = false, has_timespec = false;
  for (const auto& e : exts) {
    has_gl |= std::strcmp(e.extensionName, XR_KHR_OPENGL_ENABLE_EXTENSION_NAME) == 0;
    has_timespec |= std::strcmp(e.extensionName, XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME) == 0;
  }
  if (!has_gl) throw XrError("the OpenXR runtime does not offer XR_KHR_opengl_enable");

  auto ici = XrStruct<XrInstanceCreateInfo>(XR_TYPE_INSTANCE_CREATE_INFO);
  std::strncpy(ici.applicationInfo.applicationName, "vdyn-viewer",
               XR_MAX_APPLICATION_NAME_SIZE - 1);
  ici.applicationInfo.applicationVersion = 1;
  std::strncpy(ici.applicationInfo.engineName, "vdyn", XR_MAX_ENGINE_NAME_SIZE - 1);
  ici.applicationInfo.apiVersion = XR_CURRENT_API_VERSION;
  // The display time of a frame in this machine's clock (for drawing the scene at that instant).
  const char* enabled[] = {XR_KHR_OPENGL_ENABLE_EXTENSION_NAME,
                           XR_KHR_CONVERT_TIMESPEC_TIME_EXTENSION_NAME};
  ici.enabledExtensionCount = has_timespec ? 2 : 1;
  ici.enabledExtensionNames = enabled;
  r = xrCreateInstance(&ici, &instance);
  if (XR_FAILED(r)) {
    throw XrError("no OpenXR runtime (" + ResultName(XR_NULL_HANDLE, r) +
                  "): install one (Monado, SteamVR) or point XR_RUNTIME_JSON at its manifest");
  }
  if (has_timespec) {
    Check(xrGetInstanceProcAddr(instance, "xrConvertTimeToTimespecTimeKHR",
                                reinterpret_cast<PFN_xrVoidFunction*>(&to_timespec)),
          "xrGetInstanceProcAddr(xrConvertTimeToTimespecTimeKHR)");
  }
  auto ip = XrStruct<XrInstanceProperties>(XR_TYPE_INSTANCE_PROPERTIES);
  Check(xrGetInstanceProperties(instance, &ip), "xrGetInstanceProperties");
  runtime = ip.runtimeName;

  auto sgi = XrStruct<XrSystemGetInfo>(XR_TYPE_SYSTEM_GET_INFO);
  sgi.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  r = xrGetSystem(instance, &sgi, &system);
  if (XR_FAILED(r)) {
    throw XrError("OpenXR runtime '" + runtime + "' has no headset (" + ResultName(instance, r) +
                  "): is one connected?");
  }
}

void Headset::Impl::CheckOpenGlVersion() {
  // The runtime's OpenGL requirements, which must be asked before the session is created.
  PFN_xrGetOpenGLGraphicsRequirementsKHR get_reqs = nullptr;
  Check(xrGetInstanceProcAddr(instance, "xrGetOpenGLGraphicsRequirementsKHR",
                              reinterpret_cast<PFN_xrVoidFunction*>(&get_reqs)),
        "xrGetInstanceProcAddr(xrGetOpenGLGraphicsRequirementsKHR)");
  auto reqs = XrStruct<XrGraphicsRequirementsOpenGLKHR>(XR_TYPE_GRAPHICS_REQUIREMENTS_OPENGL_KHR);
  Check(get_reqs(instance, system, &reqs), "xrGetOpenGLGraphicsRequirementsKHR");
  const int gl_version = epoxy_gl_version();  // e.g. 45
  const XrVersion have = XR_MAKE_VERSION(gl_version / 10, gl_version % 10, 0);
  if (have < reqs.minApiVersionSupported) {
    throw XrError("OpenXR runtime needs OpenGL " +
                  std::to_string(XR_VERSION_MAJOR(reqs.minApiVersionSupported)) + "." +
                  std::to_string(XR_VERSION_MINOR(reqs.minApiVersionSupported)) +
                  ", this context has " + std::to_string(gl_version / 10) + "." +
                  std::to_string(gl_version % 10));
  }
}

void Headset::Impl::CreateSession() {
  // The Xlib binding of the current GLX context.
  auto binding = XrStruct<XrGraphicsBindingOpenGLXlibKHR>(XR_TYPE_GRAPHICS_BINDING_OPENGL_XLIB_KHR);
  binding.xDisplay = glXGetCurrentDisplay();
  binding.glxContext = glXGetCurrentContext();
  binding.glxDrawable = glXGetCurrentDrawable();
  if (binding.xDisplay == nullptr || binding.glxContext == nullptr) {
    throw XrError("no current GLX context for OpenXR (the window does not use GLX)");
  }
  int fb_id = 0;
  glXQueryContext(binding.xDisplay, binding.glxContext, GLX_FBCONFIG_ID, &fb_id);
  const int attribs[] = {GLX_FBCONFIG_ID, fb_id, 0};
  int count = 0;
  GLXFBConfig* configs =
      glXChooseFBConfig(binding.xDisplay, DefaultScreen(binding.xDisplay), attribs, &count);
  if (configs != nullptr && count > 0) {
    binding.glxFBConfig = configs[0];
    if (XVisualInfo* vi = glXGetVisualFromFBConfig(binding.xDisplay, configs[0])) {
      binding.visualid = static_cast<std::uint32_t>(vi->visualid);
      XFree(vi);
    }
  }
  if (configs != nullptr) XFree(configs);

  auto sci = XrStruct<XrSessionCreateInfo>(XR_TYPE_SESSION_CREATE_INFO);
  sci.next = &binding;
  sci.systemId = system;
  Check(xrCreateSession(instance, &sci, &session), "xrCreateSession");
}

void Headset::Impl::CreateSpaces() {
  // Reference spaces.
  std::uint32_t ns = 0;
  Check(xrEnumerateReferenceSpaces(session, 0, &ns, nullptr), "xrEnumerateReferenceSpaces");
  std::vector<XrReferenceSpaceType> spaces(ns);
  Check(xrEnumerateReferenceSpaces(session, ns, &ns, spaces.data()), "xrEnumerateReferenceSpaces");
  XrReferenceSpaceType type = XR_REFERENCE_SPACE_TYPE_LOCAL;
  if (!options.seated) {
    bool stage = false;
    for (auto s : spaces) stage |= s == XR_REFERENCE_SPACE_TYPE_STAGE;
    if (stage) {
      type = XR_REFERENCE_SPACE_TYPE_STAGE;
    } else {
      standing_on_local = true;
    }
  }
  auto rci = XrStruct<XrReferenceSpaceCreateInfo>(XR_TYPE_REFERENCE_SPACE_CREATE_INFO);
  rci.referenceSpaceType = type;
  rci.poseInReferenceSpace.orientation.w = 1;
  Check(xrCreateReferenceSpace(session, &rci, &space), "xrCreateReferenceSpace");
  rci.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_VIEW;
  Check(xrCreateReferenceSpace(session, &rci, &view_space), "xrCreateReferenceSpace(VIEW)");
}

void Headset::Impl::ReadViews() {
  // Stereo views and their swapchains.
  std::uint32_t nv = 0;
  Check(xrEnumerateViewConfigurationViews(
            instance, system, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO, 0, &nv, nullptr),
        "xrEnumerateViewConfigurationViews");
  if (nv != 2)
    throw XrError("OpenXR runtime offers " + std::to_string(nv) + " stereo views, not 2");
  config_views.fill(XrStruct<XrViewConfigurationView>(XR_TYPE_VIEW_CONFIGURATION_VIEW));
  Check(
      xrEnumerateViewConfigurationViews(instance, system, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO,
                                        2, &nv, config_views.data()),
      "xrEnumerateViewConfigurationViews");
}

void Headset::Impl::ChooseFormat() {
  std::uint32_t nf = 0;
  Check(xrEnumerateSwapchainFormats(session, 0, &nf, nullptr), "xrEnumerateSwapchainFormats");
  std::vector<std::int64_t> formats(nf);
  Check(xrEnumerateSwapchainFormats(session, nf, &nf, formats.data()),
        "xrEnumerateSwapchainFormats");
  formats.resize(nf);
  // The renderer writes sRGB-encoded colour (its shaders encode; GL_FRAMEBUFFER_SRGB stays
  // off, so the bytes are stored as written). OpenXR treats every non-sRGB format as linear
  // and the compositor encodes it again (issue 35: washed out on Monado, the road's median 142
  // against 69): an sRGB format takes the bytes as they are, a linear one gets them decoded.
  const auto offered = [&](std::int64_t f) {
    return std::find(formats.begin(), formats.end(), f) != formats.end();
  };
  const FormatChoice* chosen = nullptr;
  for (const FormatChoice& c : kChoices) {
    if (offered(c.format)) {
      chosen = &c;
      break;
    }
  }
  if (chosen == nullptr) {
    std::string list;
    for (std::int64_t f : formats) list += (list.empty() ? "" : ", ") + FormatName(f);
    throw XrError("OpenXR runtime '" + runtime +
                  "' offers no swapchain format this viewer draws into (GL_SRGB8_ALPHA8, "
                  "GL_RGBA16F, GL_RGBA16 or GL_RGBA8); it offers: " +
                  (list.empty() ? std::string("none") : list));
  }
  format = chosen->format;
  if (chosen->srgb) {
    spdlog::info("OpenXR: swapchain format {} (sRGB: the renderer's colour as it is)",
                 chosen->name);
  } else {
    linear = std::make_unique<LinearCopy>();
    spdlog::info(
        "OpenXR: swapchain format {} (the runtime offers no sRGB format: the colour is "
        "decoded to linear light for it)",
        chosen->name);
  }
}

void Headset::Impl::CreateSwapchains() {
  for (int e = 0; e < 2; ++e) {
    const auto& cv = config_views[static_cast<std::size_t>(e)];
    CreateSwapchain(eyes[static_cast<std::size_t>(e)],
                    static_cast<int>(cv.recommendedImageRectWidth),
                    static_cast<int>(cv.recommendedImageRectHeight), 1, options.samples);
  }
  if (options.hud) CreateSwapchain(hud, options.hud_width, options.hud_height, 1, 0);
  mirror.Resize(eyes[0].width, eyes[0].height, 0);
  spdlog::info("OpenXR: runtime '{}', {}x{} per eye, {} space{}", runtime, eyes[0].width,
               eyes[0].height, options.seated ? "seated (LOCAL)" : "standing",
               standing_on_local ? " on LOCAL (the runtime has no STAGE)" : "");
}

Headset::Headset(const XrOptions& options) : impl_(std::make_unique<Impl>()) {
  Impl& x = *impl_;
  x.options = options;
  // The loader writes its own error lines to stderr (five of them when there is no runtime) before
  // it returns the error this viewer explains in one sentence; XR_LOADER_DEBUG set by the person
  // (e.g. to "error" or "all") brings them back.
  setenv("XR_LOADER_DEBUG", "none", 0);
  try {
    x.CreateInstance();
    x.CheckOpenGlVersion();
    x.CreateSession();
    x.CreateSpaces();
    x.ReadViews();
    x.ChooseFormat();
    x.CreateSwapchains();
  } catch (...) {
    x.Destroy();
    throw;
  }
}

Headset::~Headset() {
  if (impl_->running && impl_->session != XR_NULL_HANDLE) xrEndSession(impl_->session);
  impl_->Destroy();
}

bool Headset::PollEvents() {
  Impl& x = *impl_;
  if (x.ended) return false;
  for (int i = 0; i < 64; ++i) {  // bounded: the rest waits for the next frame
    auto ev = XrStruct<XrEventDataBuffer>(XR_TYPE_EVENT_DATA_BUFFER);
    const XrResult r = xrPollEvent(x.instance, &ev);
    if (r == XR_EVENT_UNAVAILABLE) break;
    x.Check(r, "xrPollEvent");
    switch (ev.type) {
      case XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED: {
        const auto& e = *reinterpret_cast<const XrEventDataSessionStateChanged*>(&ev);
        x.state = e.state;
        spdlog::info("OpenXR: session {}", StateName(e.state));
        if (e.state == XR_SESSION_STATE_READY) {
          auto bi = XrStruct<XrSessionBeginInfo>(XR_TYPE_SESSION_BEGIN_INFO);
          bi.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
          x.Check(xrBeginSession(x.session, &bi), "xrBeginSession");
          x.running = true;
        } else if (e.state == XR_SESSION_STATE_STOPPING) {
          x.Check(xrEndSession(x.session), "xrEndSession");
          x.running = false;
        } else if (e.state == XR_SESSION_STATE_EXITING ||
                   e.state == XR_SESSION_STATE_LOSS_PENDING) {
          x.running = false;
          x.ended = true;
        }
        break;
      }
      case XR_TYPE_EVENT_DATA_REFERENCE_SPACE_CHANGE_PENDING:
        ++x.space_changes;  // the runtime recentred: the caller's own recentring starts over
        break;
      case XR_TYPE_EVENT_DATA_INSTANCE_LOSS_PENDING:
        spdlog::warn("OpenXR: instance loss pending; leaving the headset");
        x.running = false;
        x.ended = true;
        break;
      default:
        break;
    }
  }
  return !x.ended;
}

bool Headset::running() const {
  return impl_->running;
}

void Headset::WaitFrame() {
  Impl& x = *impl_;
  if (x.frame_waited) throw XrError("OpenXR: a frame waited for twice without being drawn");
  auto wi = XrStruct<XrFrameWaitInfo>(XR_TYPE_FRAME_WAIT_INFO);
  x.frame_state = XrStruct<XrFrameState>(XR_TYPE_FRAME_STATE);
  x.Check(xrWaitFrame(x.session, &wi, &x.frame_state), "xrWaitFrame");
  x.frame_waited = true;
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  x.display_mono_ns = static_cast<std::int64_t>(now.tv_sec) * 1'000'000'000 + now.tv_nsec +
                      x.frame_state.predictedDisplayPeriod;
  if (x.to_timespec != nullptr) {
    timespec t{};
    if (XR_SUCCEEDED(x.to_timespec(x.instance, x.frame_state.predictedDisplayTime, &t))) {
      x.display_mono_ns = static_cast<std::int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
    }
  }
}

std::int64_t Headset::display_mono_ns() const {
  return impl_->display_mono_ns;
}

bool Headset::Frame(const Pose& world_from_space, const Pose& hud_in_space, double near_m,
                    double far_m, const std::function<void(const XrEye&)>& draw_eye,
                    const std::function<void(RenderTarget&)>& draw_hud) {
  Impl& x = *impl_;
  if (!x.frame_waited) throw XrError("OpenXR: a frame drawn without waiting for it");
  x.frame_waited = false;
  const XrFrameState& fs = x.frame_state;
  auto bi = XrStruct<XrFrameBeginInfo>(XR_TYPE_FRAME_BEGIN_INFO);
  x.Check(xrBeginFrame(x.session, &bi), "xrBeginFrame");

  std::array<XrCompositionLayerProjectionView, 2> pviews{};
  auto projection = XrStruct<XrCompositionLayerProjection>(XR_TYPE_COMPOSITION_LAYER_PROJECTION);
  auto quad = XrStruct<XrCompositionLayerQuad>(XR_TYPE_COMPOSITION_LAYER_QUAD);
  std::vector<const XrCompositionLayerBaseHeader*> layers;
  bool drawn = false;
  if (fs.shouldRender) {
    auto li = XrStruct<XrViewLocateInfo>(XR_TYPE_VIEW_LOCATE_INFO);
    li.viewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
    li.displayTime = fs.predictedDisplayTime;
    li.space = x.space;
    auto vs = XrStruct<XrViewState>(XR_TYPE_VIEW_STATE);
    std::array<XrView, 2> views{XrStruct<XrView>(XR_TYPE_VIEW), XrStruct<XrView>(XR_TYPE_VIEW)};
    std::uint32_t nv = 0;
    x.Check(xrLocateViews(x.session, &li, &vs, 2, &nv, views.data()), "xrLocateViews");
    const bool tracked = (vs.viewStateFlags & XR_VIEW_STATE_POSITION_VALID_BIT) != 0 &&
                         (vs.viewStateFlags & XR_VIEW_STATE_ORIENTATION_VALID_BIT) != 0;
    if (nv == 2 && tracked) {
      // The head: between the eyes, looking as they do.
      const Pose l = PoseOf(views[0].pose), r = PoseOf(views[1].pose);
      x.head = {l.R, 0.5 * (l.t + r.t)};
      x.head_known = true;
      for (int e = 0; e < 2; ++e) {
        const auto ei = static_cast<std::size_t>(e);
        Swapchain& sc = x.eyes[ei];
        x.Acquire(sc);
        const Pose world_from_eye = world_from_space * PoseOf(views[ei].pose);
        XrEye eye;
        eye.index = e;
        eye.view = FromPose(world_from_eye.Inverse());
        const XrFovf& f = views[ei].fov;
        eye.proj = PerspectiveFov(f.angleLeft, f.angleRight, f.angleUp, f.angleDown, near_m, far_m);
        eye.eye_W = world_from_eye.t;
        eye.target = &sc.target;
        draw_eye(eye);
        if (e == 0) {
          // The desktop window mirrors the left eye.
          glBindFramebuffer(GL_READ_FRAMEBUFFER, sc.target.resolve_framebuffer());
          glBindFramebuffer(GL_DRAW_FRAMEBUFFER, x.mirror.resolve_framebuffer());
          glBlitFramebuffer(0, 0, sc.width, sc.height, 0, 0, sc.width, sc.height,
                            GL_COLOR_BUFFER_BIT, GL_NEAREST);
          glBindFramebuffer(GL_FRAMEBUFFER, 0);
        }
        x.Release(sc);
        auto& pv = pviews[ei];
        pv.type = XR_TYPE_COMPOSITION_LAYER_PROJECTION_VIEW;
        pv.pose = views[ei].pose;
        pv.fov = views[ei].fov;
        pv.subImage.swapchain = sc.handle;
        pv.subImage.imageRect.offset = {0, 0};
        pv.subImage.imageRect.extent = {sc.width, sc.height};
        pv.subImage.imageArrayIndex = 0;
      }
      projection.space = x.space;
      projection.viewCount = 2;
      projection.views = pviews.data();
      layers.push_back(reinterpret_cast<const XrCompositionLayerBaseHeader*>(&projection));
      if (x.options.hud && draw_hud) {
        x.Acquire(x.hud);
        draw_hud(x.hud.target);
        x.Release(x.hud);
        quad.layerFlags = XR_COMPOSITION_LAYER_BLEND_TEXTURE_SOURCE_ALPHA_BIT;
        quad.space = x.space;  // fixed where it is put, not to the head
        quad.eyeVisibility = XR_EYE_VISIBILITY_BOTH;
        quad.subImage.swapchain = x.hud.handle;
        quad.subImage.imageRect.extent = {x.hud.width, x.hud.height};
        quad.pose = XrPoseOf(hud_in_space);
        quad.size.width = static_cast<float>(x.options.hud_width_m);
        quad.size.height =
            static_cast<float>(x.options.hud_width_m * x.hud.height / std::max(x.hud.width, 1));
        layers.push_back(reinterpret_cast<const XrCompositionLayerBaseHeader*>(&quad));
      }
      drawn = true;
    }
  }
  auto ei = XrStruct<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
  ei.displayTime = fs.predictedDisplayTime;
  ei.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
  ei.layerCount = static_cast<std::uint32_t>(layers.size());
  ei.layers = layers.data();
  x.Check(xrEndFrame(x.session, &ei), "xrEndFrame");
  ++x.frames;
  return drawn;
}

void Headset::EmptyFrame() {
  Impl& x = *impl_;
  if (!x.frame_waited) WaitFrame();  // (a frame waited for and not drawn is ended here)
  x.frame_waited = false;
  const XrFrameState& fs = x.frame_state;
  auto bi = XrStruct<XrFrameBeginInfo>(XR_TYPE_FRAME_BEGIN_INFO);
  x.Check(xrBeginFrame(x.session, &bi), "xrBeginFrame");
  auto ei = XrStruct<XrFrameEndInfo>(XR_TYPE_FRAME_END_INFO);
  ei.displayTime = fs.predictedDisplayTime;
  ei.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
  x.Check(xrEndFrame(x.session, &ei), "xrEndFrame");
}

void Headset::RequestExit() {
  Impl& x = *impl_;
  if (x.exit_requested || x.ended) return;
  x.exit_requested = true;
  if (x.running) {
    x.Check(xrRequestExitSession(x.session), "xrRequestExitSession");
  } else {
    x.ended = true;  // never began: nothing to end
  }
}

bool Headset::exit_requested() const {
  return impl_->exit_requested;
}
std::string Headset::runtime_name() const {
  return impl_->runtime;
}
std::string Headset::state_name() const {
  return StateName(impl_->state);
}
int Headset::eye_width() const {
  return impl_->eyes[0].width;
}
int Headset::eye_height() const {
  return impl_->eyes[0].height;
}
std::uint64_t Headset::frames_submitted() const {
  return impl_->frames;
}
const RenderTarget& Headset::mirror() const {
  return impl_->mirror;
}
bool Headset::standing_on_local() const {
  return impl_->standing_on_local;
}
bool Headset::head_in_space(Pose* out) const {
  if (!impl_->head_known) return false;
  *out = impl_->head;
  return true;
}
std::uint64_t Headset::space_changes() const {
  return impl_->space_changes;
}

}  // namespace vdyn::viewer

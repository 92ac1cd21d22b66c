// The test OpenXR runtime's fixed headset, shared by the runtime and the tests that check what the
// viewer drew into it: eye image size, the eyes' field of view (asymmetric, as real headsets are)
// and their offset, and where the head is in each reference space.
#pragma once

namespace vdyn::xrtest {

inline constexpr int kEyeWidth = 512;
inline constexpr int kEyeHeight = 512;
inline constexpr double kIpd = 0.064;  // m: the eyes at x = -kIpd/2 (left) and +kIpd/2 (right)
// Half-angles of each eye's view, rad (left and down negative). The right eye mirrors the left.
inline constexpr double kAngleOuter = -0.80;  // left eye's left edge
inline constexpr double kAngleInner = 0.70;   // left eye's right edge
inline constexpr double kAngleUp = 0.75;
inline constexpr double kAngleDown = -0.85;
// Head position in the reference spaces (OpenXR axes: X right, Y up, -Z forward), m; the head
// looks along -Z.
inline constexpr double kStageHeadHeight = 1.6;  // STAGE: origin on the floor
// LOCAL and VIEW: the head at the origin.

// Environment of the runtime: where it writes its report and the last frame's images
// (left.png, right.png, hud.png), after how many frames it ends the session itself (0: never),
// and whether it offers a STAGE space ("0" to leave it out).
inline constexpr const char* kEnvOut = "VDYN_XR_TEST_OUT";
inline constexpr const char* kEnvExitAfter = "VDYN_XR_TEST_EXIT_AFTER";
inline constexpr const char* kEnvStage = "VDYN_XR_TEST_STAGE";
// Where the head is, moved from its place above and turned about the vertical: "x y z yaw_deg"
// (OpenXR axes of the base space, m; yaw positive to the left), e.g. a person sitting off-centre.
inline constexpr const char* kEnvHead = "VDYN_XR_TEST_HEAD";
// The swapchain formats it offers, in order: names among RGBA16, RGBA16F, SRGB8_ALPHA8, RGBA8
// and RGB10_A2, separated by spaces (unset: Monado 25.1's order, "RGBA16 RGBA16F SRGB8_ALPHA8
// RGBA8"). It shows a linear format's values encoded to sRGB, as a compositor does.
inline constexpr const char* kEnvFormats = "VDYN_XR_TEST_FORMATS";

}  // namespace vdyn::xrtest

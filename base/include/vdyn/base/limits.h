// The one table of limits: every driver input, request, message, parameter and command-line
// limit of vdyn, in one place. The physics validates parameters against it, the server checks
// inputs and requests against it, the clients clamp to it, and every program checks its numeric
// options with it (docs/topics.md and docs/formats.md quote it).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

namespace vdyn::limits {

// A closed, open or half-open interval of finite numbers, with what the number is (and its unit)
// for messages: "vehicle mass, kg must be in (0, 100000], got -5".
struct Range {
  double lo;
  double hi;
  bool lo_open = false;
  bool hi_open = false;
  std::string_view what = "";
};

// Empty when v is finite and inside r; else the reason, e.g. "throttle must be in [-1, 1], got 5"
// or "throttle must be a finite number, got nan". Numbers are printed as a person writes them.
std::string Check(const Range& r, double v);
// Clamps into [lo, hi]; a non-finite value becomes `fallback`.
double Clamp(const Range& r, double v, double fallback = 0.0);
// "[lo, hi]" or "(lo, hi]" etc.
std::string Describe(const Range& r);

// --- Driver input (vdyn.pb.DriverInput) ------------------------------------------------------
inline constexpr Range kSteer{-1.5, 1.5, false, false, "steer (front road-wheel angle, rad)"};
inline constexpr Range kThrottle{-1.0, 1.0, false, false, "throttle"};
inline constexpr Range kBrake{0.0, 1.0, false, false, "brake"};
inline constexpr Range kCruiseSetKmh{0.0, 400.0, false, false, "cruise_set_kmh"};
// The hand-wheel angle (steer_mode STEER_HAND_WHEEL): three turns each way covers every rig.
inline constexpr Range kHandWheel{-6.0 * 3.141592653589793, 6.0 * 3.141592653589793, false, false,
                                  "steer (hand-wheel angle, rad)"};
inline constexpr Range kClutch{0.0, 1.0, false, false, "clutch"};
inline constexpr Range kHandbrake{0.0, 1.0, false, false, "handbrake"};
inline constexpr Range kGear{-1.0, 10.0, false, false, "gear"};

// --- Control requests (vdyn.pb.ControlRequest) -----------------------------------------------
// A vehicle's id: 0 is no vehicle in a message (a request for the whole server, a lockstep step
// with no input), so ids start at 1 (every program's --vehicle-id, --vehicle-ids, --vehicle,
// --follow, --as; spawn and restore requests; the Python client).
inline constexpr Range kVehicleId{1.0, 4294967295.0, false, false, "vehicle id"};
inline constexpr Range kPoseXY{-1e7, 1e7, false, false, "pose position, m"};
inline constexpr Range kPoseYaw{-1e3, 1e3, false, false, "pose yaw, rad"};
inline constexpr Range kSpawnSpeed{0.0, 110.0, false, false, "speed, m/s"};
// Steps one request may ask for: 10 simulated minutes at 1 kHz.
inline constexpr std::uint32_t kMaxStepsPerRequest = 600'000;
// Requests the server applies at one step boundary; more wait in the queue.
inline constexpr int kMaxRequestsPerBoundary = 16;
// Frames of the server's state outbox (runtime/state_outbox.h: 64 steps of its vehicles, never
// fewer than this): a lockstep client that waits for a request's states before the next asks for
// at most half as many states a request (clients/python), so the outbox never overflows.
inline constexpr std::size_t kMinStateOutboxFrames = 512;
// The input watchdog's default (vdyn-server --watchdog-ms): a vehicle without live input this long
// goes to its safe state; a lockstep client repeats a held input more often than this.
inline constexpr double kDefaultWatchdogMs = 100.0;

// --- Messages -------------------------------------------------------------------------------
// Every string field of every message (ids, names, reasons).
inline constexpr std::size_t kMaxIdBytes = 64;        // client_id, source_id, server_id
inline constexpr std::size_t kMaxReasonBytes = 1024;  // a reply's reason
inline constexpr std::size_t kMaxNameBytes = 256;     // mesh, landmark and world names
// Serialised payload sizes per topic, bytes (a larger sample is refused and counted).
inline constexpr std::size_t kMaxStateBytes = 64 * 1024;
// A step's states of many vehicles (vdyn/states): 256 vehicles of the largest state (~2.2 KB)
// fit; a writer with more splits them over several samples.
inline constexpr std::size_t kMaxStatesBytes = 1024 * 1024;
inline constexpr std::size_t kMaxInputBytes = 4 * 1024;
inline constexpr std::size_t kMaxControlBytes = 64 * 1024;
inline constexpr std::size_t kMaxReplyBytes = 16 * 1024;
inline constexpr std::size_t kMaxParamsBytes = 64 * 1024;
inline constexpr std::size_t kMaxWorldBytes = 512ull * 1024 * 1024;
inline constexpr std::size_t kMaxEventBytes = 1024 * 1024;
inline constexpr std::size_t kMaxDiagnosticsBytes = 1024 * 1024;
// A terrain vertex's coordinate (a world description's meshes, a world file): the terrain drops
// every triangle with a vertex beyond it, and the world description leaves it out; a viewer
// refuses a description holding one (floats hold it; a grid cell index of it fits 64 bits).
inline constexpr Range kWorldCoordinateM{-1e9, 1e9, true, true, "terrain vertex coordinate, m"};

// --- Files -----------------------------------------------------------------------------------
// A maneuver (CSV, docs/formats.md): a million rows is 1000 s at a row a millisecond (rows are
// interpolated, so a drive rarely needs more than a row per change). A larger file is refused
// before it is read; a row beyond the limit where it starts. Rows are 48 bytes in memory.
inline constexpr std::size_t kMaxManeuverBytes = 64u << 20;
inline constexpr std::size_t kMaxManeuverRows = 1'000'000;
// A vehicle parameter file or a wheel mapping (text or JSON): far more than any holds.
inline constexpr std::size_t kMaxTextFileBytes = 4u << 20;

// --- Vehicle parameters (vdyn.pb.VehicleParams), by field path -------------------------------
struct ParamLimit {
  std::string_view path;  // "mass", "lf.free_length" (wheel fields are given as "wheel.<name>")
  Range range;
};
std::span<const ParamLimit> VehicleParamLimits();
std::span<const ParamLimit> WheelParamLimits();  // per wheel, path without the wheel prefix
// The limit of a field path ("mass", "lf.radius"); nullptr for a path with no limit.
const Range* ParamRange(std::string_view path);
// The fields that are not numbers with a limit: choices (enums) and the per-wheel groups, named.
struct ParamChoice {
  std::string_view path;  // "model", "lf"
  std::string_view what;  // "vehicle model (the equations)"
};
// What every field of vdyn.pb.VehicleParams is, in words with its unit ("vehicle mass, kg";
// "lf.radius": "wheel radius, m"): the `what` of its limit above, or of its choice. Empty for a
// path that names no field. The viewer's parameters panel labels its fields with it, and
// docs/formats.md's table of the parameters is checked against it (tests/test_base.cc).
std::string_view ParamWords(std::string_view path);

// --- Driving rigs (vdyn-input: wheel mapping files and force feedback options) -------------
// SDL's raw axis values.
inline constexpr Range kRawAxis{-32768.0, 32767.0, false, false, "raw axis value"};
inline constexpr Range kAxisIndex{0.0, 63.0, false, false, "axis index"};
inline constexpr Range kButtonIndex{0.0, 255.0, false, false, "button index"};
inline constexpr Range kWheelRangeDeg{90.0, 3600.0, false, false, "wheel rotation range, degree"};
inline constexpr Range kDeadZone{0.0, 0.5, false, false, "dead zone (fraction of the travel)"};
inline constexpr Range kPedalGamma{0.2, 5.0, false, false, "pedal curve exponent"};
// Peak torque of a device and the user's cap; no wheel base reaches 50 N*m.
inline constexpr Range kTorqueNm{0.0, 50.0, false, false, "hand-wheel torque, N*m"};
inline constexpr Range kFfbGain{0.0, 4.0, false, false, "force feedback gain"};
inline constexpr Range kFfbRateHz{10.0, 1000.0, false, false, "force feedback update rate, Hz"};
inline constexpr Range kFfbSlewNmPerS{1.0, 10000.0, false, false, "torque slew limit, N*m/s"};
inline constexpr Range kFfbFilterHz{1.0, 500.0, false, false, "torque filter cut-off, Hz"};
inline constexpr Range kFfbEffectMs{10.0, 1000.0, false, false, "effect length, ms"};
inline constexpr Range kFfbDamper{0.0, 1.0, false, false, "damper (fraction of the device's)"};
inline constexpr Range kGears{1.0, 10.0, false, false, "forward gears"};
inline constexpr Range kKeyRatePerS{0.1, 100.0, false, false, "keyboard ramp, full travel per s"};

// --- Command-line options -------------------------------------------------------------------
inline constexpr Range kDomainId{0, 232, false, false, "DDS domain id"};
// Vehicles one server runs (vdyn-server --max-vehicles): 256 at 1 kHz on two cores (bench/).
inline constexpr Range kMaxVehicles{1, 256, false, false, "vehicles per server"};
// Threads that step a server's vehicles (vdyn-server --step-threads; runtime/step_pool.h).
inline constexpr Range kStepThreads{1, 16, false, false, "stepping threads"};
inline constexpr Range kStepMs{0.01, 100.0, false, false, "integration step, ms"};
inline constexpr Range kWatchdogMs{1.0, 60000.0, false, false, "watchdog, ms"};
inline constexpr Range kLockstepTimeoutS{0.1, 86400.0, false, false, "lockstep timeout, s"};
inline constexpr Range kDurationS{0.0, 1e7, true, false, "duration, s"};
inline constexpr Range kSpeedKmh{0.0, 400.0, false, false, "speed, km/h"};
inline constexpr Range kRateHz{1.0, 2000.0, false, false, "rate, Hz"};
inline constexpr Range kWaitS{0.0, 3600.0, false, false, "wait, s"};
inline constexpr Range kWorldScale{0.0, 1e6, true, false, "terrain scale, m per file unit"};
inline constexpr Range kHeightmapCell{0.0, 1e4, true, false, "height-map cell, m"};
inline constexpr Range kHeightmapHeight{0.0, 1e5, true, false, "height-map height, m"};
inline constexpr Range kStrength{0, 1e6, false, false, "ownership strength"};
// The viewer (vdyn-viewer).
inline constexpr Range kWindowPixels{64, 16384, false, false, "window size, pixels"};
inline constexpr Range kFrames{0, 1e9, false, false, "frames"};
inline constexpr Range kViewerFps{0, 1000, false, false, "frame rate cap, Hz (0: none)"};
inline constexpr Range kSamples{0, 16, false, false, "multisampling, samples"};
inline constexpr Range kArrowScale{0.001, 100, false, false, "arrow scale, m per kN"};
inline constexpr Range kPaddleStepDeg{1, 180, false, false, "paddle step, deg"};
inline constexpr Range kMapHalfHeight{1, 10000, false, false, "map half height, m"};
inline constexpr Range kFovDeg{10, 150, false, false, "field of view, deg"};
inline constexpr Range kCameraDistance{0.5, 5000, false, false, "camera distance, m"};
inline constexpr Range kAngleDeg{-360, 360, false, false, "angle, deg"};
inline constexpr Range kPresentationDelayMs{0, 1000, false, false, "presentation delay, ms"};

// --- Recordings (vdyn-recorder) ---------------------------------------------------------------
// A recorder's reader history per instance on keep-last topics (vdyn/state: one second of a
// vehicle at 1 kHz), so a recorder that takes a little late loses nothing; bounded, so one that
// stops taking cannot grow without end.
inline constexpr int kRecorderHistoryDepth = 1000;
// The receive buffer a recorder asks of its sockets: a session's start (the world, every vehicle's
// parameters and events, discovery) arrives in a burst on top of the states; 64 vehicles at 1 kHz
// are ~95 MB/s, so the default 1 MiB is ~10 ms of them. The kernel caps it at net.core.rmem_max.
inline constexpr std::size_t kRecorderReceiveBufferBytes = 16u << 20;
inline constexpr Range kRecorderQueueMb{1.0, 65536.0, false, false, "recorder queue, MiB"};
inline constexpr Range kPlaybackRate{0.01, 1000.0, false, false, "playback rate"};
inline constexpr Range kSplitMb{1.0, 1e7, false, false, "split size, MiB"};
inline constexpr Range kSplitS{1.0, 1e7, false, false, "split duration, s"};
inline constexpr Range kChunkKb{1.0, 65536.0, false, false, "chunk size, KiB"};
inline constexpr Range kRecordingTimeS{0.0, 1e9, false, false, "time from the recording's start, s"};

// vdyn-telemetry: packet rates (LFS itself sends at most 100 per second; a motion platform may
// take more, and states come at 1 kHz), the age after which a state is too old to send, and the
// optional packet ID (LFS's "OutSim ID"/"OutGauge ID": not zero when present).
inline constexpr Range kTelemetryRateHz{1.0, 1000.0, false, false, "telemetry packet rate, Hz"};
inline constexpr Range kStaleMs{10.0, 60000.0, false, false, "stale-state limit, ms"};
inline constexpr Range kTelemetryId{1.0, 2147483647.0, false, false, "telemetry packet ID"};

// vdyn-foxglove: the state channels' rate (0: every state), the scene's and transforms' rate, a
// client's send queue (its data bound in KiB and ms: past either the oldest goes), the TCP port
// (0: any free one), the clients at once, and how long a vehicle may send nothing before its
// channels are unadvertised.
inline constexpr Range kFoxgloveStateHz{0.0, 100000.0, false, false,
                                        "state channel rate, Hz (0: every state)"};
inline constexpr Range kFoxgloveSceneHz{1.0, 1000.0, false, false, "scene rate, Hz"};
inline constexpr Range kFoxgloveQueueKb{16.0, 1048576.0, false, false, "client send queue, KiB"};
inline constexpr Range kFoxgloveQueueMs{10.0, 60000.0, false, false, "client send queue age, ms"};
inline constexpr Range kPort{0.0, 65535.0, false, false, "TCP port"};
inline constexpr Range kFoxgloveClients{1.0, 1024.0, false, false, "clients"};
inline constexpr Range kVehicleTimeoutS{0.1, 3600.0, false, false, "vehicle timeout, s"};

}  // namespace vdyn::limits

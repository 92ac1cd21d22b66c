// Live for Speed's UDP telemetry packets, OutSim (motion platforms) and OutGauge (dashboards), as
// LFS's docs/InSim.txt defines them (OutSim with "OutSim Opts 0"); BeamNG.drive sends the same
// layouts, and SimHub, SimTools and the like read them. All multi-byte fields are little-endian
// ("PC style - lowest byte first"), packed, with no header: the datagram is the struct. The
// optional trailing int ID is sent only when an ID is configured (LFS: "OutSim ID" / "OutGauge
// ID" not zero). docs/formats.md has both layouts with their byte offsets.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

namespace vdyn::telemetry {

static_assert(std::endian::native == std::endian::little,
              "the packets are written as their in-memory image: a little-endian host");

#pragma pack(push, 1)
struct OutSimPack {
  std::uint32_t time_ms = 0;                          // Time: ms, to check order
  float ang_vel_x = 0, ang_vel_y = 0, ang_vel_z = 0;  // AngVel: rad/s, world axes
  float heading = 0;  // rad, anticlockwise from above (Z); 0 = forward along world +Y
  float pitch = 0;    // rad, anticlockwise from the right (X): nose up positive
  float roll = 0;     // rad, anticlockwise from the front (Y): right side down positive
  float accel_x = 0, accel_y = 0, accel_z = 0;   // Accel: m/s^2, world axes
  float vel_x = 0, vel_y = 0, vel_z = 0;         // Vel: m/s, world axes
  std::int32_t pos_x = 0, pos_y = 0, pos_z = 0;  // Pos: 1 m = 65536, world axes
  std::int32_t id = 0;                           // only on the wire when an ID is configured
};

struct OutGaugePack {
  std::uint32_t time_ms = 0;      // Time: ms
  char car[4] = {};               // Car name
  std::uint16_t flags = 0;        // OG_x
  std::uint8_t gear = 0;          // reverse 0, neutral 1, first 2, ...
  std::uint8_t plid = 0;          // unique id of the viewed player (0 = none)
  float speed = 0;                // m/s
  float rpm = 0;                  // rpm
  float turbo = 0;                // bar
  float eng_temp = 0;             // C
  float fuel = 0;                 // 0 to 1
  float oil_pressure = 0;         // bar
  float oil_temp = 0;             // C
  std::uint32_t dash_lights = 0;  // DL_x bits: lights the car has
  std::uint32_t show_lights = 0;  // DL_x bits: lights switched on
  float throttle = 0;             // 0 to 1
  float brake = 0;                // 0 to 1
  float clutch = 0;               // 0 to 1
  char display1[16] = {};         // usually fuel
  char display2[16] = {};         // usually settings
  std::int32_t id = 0;            // only on the wire when an ID is configured
};
#pragma pack(pop)

// The published sizes and offsets (InSim.txt): the struct is the wire image.
inline constexpr std::size_t kOutSimSize = 64;
inline constexpr std::size_t kOutGaugeSize = 92;
inline constexpr std::size_t kIdSize = 4;
static_assert(sizeof(OutSimPack) == kOutSimSize + kIdSize);
static_assert(offsetof(OutSimPack, heading) == 16 && offsetof(OutSimPack, accel_x) == 28 &&
              offsetof(OutSimPack, vel_x) == 40 && offsetof(OutSimPack, pos_x) == 52 &&
              offsetof(OutSimPack, id) == 64);
static_assert(sizeof(OutGaugePack) == kOutGaugeSize + kIdSize);
static_assert(offsetof(OutGaugePack, flags) == 8 && offsetof(OutGaugePack, gear) == 10 &&
              offsetof(OutGaugePack, speed) == 12 && offsetof(OutGaugePack, dash_lights) == 40 &&
              offsetof(OutGaugePack, throttle) == 48 && offsetof(OutGaugePack, display1) == 60 &&
              offsetof(OutGaugePack, display2) == 76 && offsetof(OutGaugePack, id) == 92);

// OG_x: bits of OutGaugePack::flags.
inline constexpr std::uint16_t kOgShift = 1;     // key
inline constexpr std::uint16_t kOgCtrl = 2;      // key
inline constexpr std::uint16_t kOgTurbo = 8192;  // show the turbo gauge
inline constexpr std::uint16_t kOgKm = 16384;    // the user prefers km (else miles)
inline constexpr std::uint16_t kOgBar = 32768;   // the user prefers bar (else psi)

// DL_x: bit numbers of OutGaugePack::dash_lights and show_lights.
enum DashLight : std::uint32_t {
  kDlShift = 0,  // shift light
  kDlFullBeam = 1,
  kDlHandbrake = 2,
  kDlPitSpeed = 3,
  kDlTc = 4,  // traction control active or switched off
  kDlSignalL = 5,
  kDlSignalR = 6,
  kDlSignalAny = 7,
  kDlOilWarn = 8,
  kDlBattery = 9,
  kDlAbs = 10,  // ABS active or switched off
  kDlEngine = 11,
  kDlFogRear = 12,
  kDlFogFront = 13,
  kDlDipped = 14,
  kDlFuelWarn = 15,
  kDlSidelights = 16,
  kDlNeutral = 17,
};
constexpr std::uint32_t Bit(DashLight l) {
  return 1u << l;
}

// OutGauge gears.
inline constexpr std::uint8_t kGaugeGearReverse = 0;
inline constexpr std::uint8_t kGaugeGearNeutral = 1;
inline constexpr std::uint8_t kGaugeGearFirst = 2;

// The datagram: 64 bytes, or 68 with the ID (`id` set). Returns the bytes written into `out`
// (which must hold 68).
std::size_t Encode(const OutSimPack& p, bool with_id, std::span<std::uint8_t> out);
// 92 bytes, or 96 with the ID.
std::size_t Encode(const OutGaugePack& p, bool with_id, std::span<std::uint8_t> out);

// Copies text into a fixed char field, zero-padded; at most n - 1 characters when `terminate`
// (Display1/2 are C strings), else up to n (Car: 4 characters, e.g. "beam").
void SetText(char* field, std::size_t n, const char* text, bool terminate);

}  // namespace vdyn::telemetry

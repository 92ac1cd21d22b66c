// vdyn-telemetry (issue 12, "Telemetry for dashboards and motion platforms"): the OutSim and
// OutGauge packets against the byte offsets Live for Speed's docs/InSim.txt publishes, the frame
// mapping against geometry, and the bridge as a process between vdyn-server and UDP sockets this
// test binds on loopback.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <initializer_list>
#include <map>
#include <numbers>
#include <stdexcept>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "process.h"
#include "test_support.h"
#include "vdyn/base/deadline.h"
#include "vdyn/telemetry/convert.h"
#include "vdyn/telemetry/packets.h"
#include "vdyn/telemetry/udp.h"
#include "vdyn/transport/dds.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;
using namespace std::chrono_literals;
using namespace telemetry;
constexpr double kPi = std::numbers::pi;

// --- Little-endian bytes at the spec's offsets, written and read without our structs ----------

void PutU32(std::vector<std::uint8_t>& b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}
void PutF32(std::vector<std::uint8_t>& b, std::size_t at, float v) {
  PutU32(b, at, std::bit_cast<std::uint32_t>(v));
}
std::uint32_t GetU32(const std::vector<std::uint8_t>& b, std::size_t at) {
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= static_cast<std::uint32_t>(b[at + i]) << (8 * i);
  return v;
}
std::int32_t GetI32(const std::vector<std::uint8_t>& b, std::size_t at) {
  return static_cast<std::int32_t>(GetU32(b, at));
}
double GetF32(const std::vector<std::uint8_t>& b, std::size_t at) {
  return static_cast<double>(std::bit_cast<float>(GetU32(b, at)));
}

// OutSimPack (InSim.txt): unsigned Time; Vector AngVel; float Heading, Pitch, Roll; Vector Accel;
// Vector Vel; Vec Pos (3 ints); [int ID]. Vector = 3 floats, Vec = 3 ints, 4 bytes each.
namespace os {
[[maybe_unused]] constexpr std::size_t kTime = 0, kAngVel = 4, kHeading = 16, kPitch = 20, kRoll = 24, kAccel = 28,
                      kVel = 40, kPos = 52, kId = 64;
}
// OutGaugePack: unsigned Time; char Car[4]; word Flags; byte Gear; byte PLID; float Speed, RPM,
// Turbo, EngTemp, Fuel, OilPressure, OilTemp; unsigned DashLights, ShowLights; float Throttle,
// Brake, Clutch; char Display1[16], Display2[16]; [int ID].
namespace og {
constexpr std::size_t kTime = 0, kCar = 4, kFlags = 8, kGear = 10, kPlid = 11, kSpeed = 12,
                      kRpm = 16, kTurbo = 20, kEngTemp = 24, kFuel = 28, kOilPressure = 32,
                      kOilTemp = 36, kDashLights = 40, kShowLights = 44, kThrottle = 48,
                      kBrake = 52, kClutch = 56, kDisplay1 = 60, kDisplay2 = 76, kId = 92;
}

std::vector<std::uint8_t> Encoded(const OutSimPack& p, bool id) {
  std::vector<std::uint8_t> b(128, 0xee);
  b.resize(Encode(p, id, b));
  return b;
}
std::vector<std::uint8_t> Encoded(const OutGaugePack& p, bool id) {
  std::vector<std::uint8_t> b(128, 0xee);
  b.resize(Encode(p, id, b));
  return b;
}

TEST(TelemetryPackets, OutSimMatchesThePublishedLayoutByteForByte) {
  OutSimPack p;
  p.time_ms = 0x01020304;
  p.ang_vel_x = 0.5f, p.ang_vel_y = -1.25f, p.ang_vel_z = 2.0f;
  p.heading = 1.5f, p.pitch = -0.25f, p.roll = 0.125f;
  p.accel_x = 9.5f, p.accel_y = -3.0f, p.accel_z = 0.75f;
  p.vel_x = 20.0f, p.vel_y = -0.5f, p.vel_z = 0.0625f;
  p.pos_x = 65536, p.pos_y = -131072, p.pos_z = 0x7fffffff;
  p.id = -7;

  std::vector<std::uint8_t> want(68, 0);
  PutU32(want, os::kTime, 0x01020304);
  const float floats[] = {0.5f, -1.25f, 2.0f,  1.5f,  -0.25f, 0.125f,
                          9.5f, -3.0f,  0.75f, 20.0f, -0.5f,  0.0625f};
  for (int i = 0; i < 12; ++i) PutF32(want, os::kAngVel + 4 * i, floats[i]);
  PutU32(want, os::kPos + 0, 65536);
  PutU32(want, os::kPos + 4, static_cast<std::uint32_t>(-131072));
  PutU32(want, os::kPos + 8, 0x7fffffff);
  PutU32(want, os::kId, static_cast<std::uint32_t>(-7));

  const auto with_id = Encoded(p, true);
  ASSERT_EQ(with_id.size(), 68u);
  EXPECT_EQ(with_id, want);
  const auto without = Encoded(p, false);
  ASSERT_EQ(without.size(), 64u);
  EXPECT_EQ(without, std::vector<std::uint8_t>(want.begin(), want.begin() + 64));
  // Little-endian spot checks, written out: Time 0x01020304 is 04 03 02 01; Heading 1.5f is
  // 0x3fc00000; Pos.X 65536 (one metre) is 00 00 01 00.
  EXPECT_EQ(with_id[0], 0x04);
  EXPECT_EQ(with_id[3], 0x01);
  EXPECT_EQ(with_id[os::kHeading + 3], 0x3f);
  EXPECT_EQ(with_id[os::kHeading + 2], 0xc0);
  EXPECT_EQ(with_id[os::kPos + 2], 0x01);
}

TEST(TelemetryPackets, OutGaugeMatchesThePublishedLayoutByteForByte) {
  OutGaugePack p;
  p.time_ms = 123456;
  SetText(p.car, sizeof p.car, "beam", false);
  p.flags = kOgKm | kOgBar;
  p.gear = 4;
  p.plid = 3;
  p.speed = 27.5f, p.rpm = 6500.0f, p.turbo = 0.5f, p.eng_temp = 90.0f, p.fuel = 1.0f;
  p.oil_pressure = 4.0f, p.oil_temp = 100.0f;
  p.dash_lights = Bit(kDlHandbrake) | Bit(kDlAbs) | Bit(kDlNeutral);
  p.show_lights = Bit(kDlAbs);
  p.throttle = 0.25f, p.brake = 0.75f, p.clutch = 1.0f;
  SetText(p.display1, sizeof p.display1, "full auto", true);
  SetText(p.display2, sizeof p.display2, "a text longer than sixteen", true);
  p.id = 42;

  std::vector<std::uint8_t> want(96, 0);
  PutU32(want, og::kTime, 123456);
  std::memcpy(&want[og::kCar], "beam", 4);
  want[og::kFlags] = 0x00;  // OG_KM 16384 | OG_BAR 32768 = 0xc000, low byte first
  want[og::kFlags + 1] = 0xc0;
  want[og::kGear] = 4;
  want[og::kPlid] = 3;
  PutF32(want, og::kSpeed, 27.5f);
  PutF32(want, og::kRpm, 6500.0f);
  PutF32(want, og::kTurbo, 0.5f);
  PutF32(want, og::kEngTemp, 90.0f);
  PutF32(want, og::kFuel, 1.0f);
  PutF32(want, og::kOilPressure, 4.0f);
  PutF32(want, og::kOilTemp, 100.0f);
  // DL_HANDBRAKE is bit 2, DL_ABS bit 10, DL_NEUTRAL bit 17 (InSim.txt's DL_x enum).
  PutU32(want, og::kDashLights, (1u << 2) | (1u << 10) | (1u << 17));
  PutU32(want, og::kShowLights, 1u << 10);
  PutF32(want, og::kThrottle, 0.25f);
  PutF32(want, og::kBrake, 0.75f);
  PutF32(want, og::kClutch, 1.0f);
  std::memcpy(&want[og::kDisplay1], "full auto", 9);
  std::memcpy(&want[og::kDisplay2], "a text longer t", 15);  // 15 characters and a zero
  PutU32(want, og::kId, 42);

  const auto with_id = Encoded(p, true);
  ASSERT_EQ(with_id.size(), 96u);
  EXPECT_EQ(with_id, want);
  const auto without = Encoded(p, false);
  ASSERT_EQ(without.size(), 92u);
  EXPECT_EQ(without, std::vector<std::uint8_t>(want.begin(), want.begin() + 92));
}

// --- The frame mapping, checked against geometry ----------------------------------------------

pb::Quat QuatZyx(double yaw, double pitch, double roll) {
  // q = qz(yaw) qy(pitch) qx(roll): R_WB = Rz Ry Rx (docs/model.md).
  const double cy = std::cos(yaw / 2), sy = std::sin(yaw / 2), cp = std::cos(pitch / 2),
               sp = std::sin(pitch / 2), cr = std::cos(roll / 2), sr = std::sin(roll / 2);
  pb::Quat q;
  q.set_w(cy * cp * cr + sy * sp * sr);
  q.set_x(cy * cp * sr - sy * sp * cr);
  q.set_y(cy * sp * cr + sy * cp * sr);
  q.set_z(sy * cp * cr - cy * sp * sr);
  return q;
}

pb::VehicleState Posed(double yaw, double pitch, double roll) {
  pb::VehicleState s;
  s.set_model(pb::VEHICLE_MODEL_FULL);
  *s.mutable_q_wb() = QuatZyx(yaw, pitch, roll);
  s.mutable_rpy()->set_x(roll);
  s.mutable_rpy()->set_y(pitch);
  s.mutable_rpy()->set_z(yaw);
  return s;
}

TEST(TelemetryFrames, HeadingPointsTheForwardAxisAsLfsDefinesIt) {
  // LFS: heading 0 is the world's +Y direction, anticlockwise from above, so the forward axis
  // is (-sin H, cos H). vdyn's forward axis at yaw psi is (cos psi, sin psi).
  for (double yaw : {0.0, 0.3, kPi / 2, 2.5, kPi, -kPi, -2.0, 7.0, -9.0}) {
    const double h = HeadingFromYaw(yaw);
    EXPECT_GE(h, -kPi);
    EXPECT_LT(h, kPi);
    EXPECT_NEAR(-std::sin(h), std::cos(yaw), 1e-12) << yaw;
    EXPECT_NEAR(std::cos(h), std::sin(yaw), 1e-12) << yaw;
  }
  EXPECT_NEAR(HeadingFromYaw(kPi / 2), 0.0, 1e-15);  // facing north
}

TEST(TelemetryFrames, PitchAndRollFollowTheCarsAxes) {
  // Nose up by 0.1 rad: vdyn's pitch is -0.1 (nose down positive); the forward axis rises, so
  // LFS's pitch (anticlockwise seen from the right) is +0.1. Right side down by 0.2 rad: the right
  // axis falls; LFS's roll (anticlockwise seen from the front) is +0.2.
  const OutSimPack p = MakeOutSim(Posed(0.4, -0.1, 0.2));
  EXPECT_NEAR(p.pitch, 0.1, 1e-7);
  EXPECT_NEAR(p.roll, 0.2, 1e-7);
  EXPECT_NEAR(p.heading, 0.4 - kPi / 2, 1e-6);
  // With heading, then pitch, then roll: forward.z = sin(P), right.z = -sin(R) cos(P).
  const pb::Quat q = QuatZyx(0.4, -0.1, 0.2);
  const double fz = 2 * (q.x() * q.z() - q.w() * q.y());      // R_WB (1,0,0), z
  const double left_z = 2 * (q.y() * q.z() + q.w() * q.x());  // R_WB (0,1,0), z
  EXPECT_NEAR(std::sin(p.pitch), fz, 1e-6);
  EXPECT_NEAR(-std::sin(p.roll) * std::cos(p.pitch), -left_z, 1e-6);
}

TEST(TelemetryFrames, AngularVelocityIsSentInWorldAxes) {
  // Pitched nose down by 0.5 rad, spinning about the body's Z at 1 rad/s: in the world the axis
  // leans forward, (sin 0.5, 0, cos 0.5) at yaw 0.
  pb::VehicleState s = Posed(0.0, 0.5, 0.0);
  s.mutable_w_wb_b()->set_z(1.0);
  OutSimPack p = MakeOutSim(s);
  EXPECT_NEAR(p.ang_vel_x, std::sin(0.5), 1e-6);
  EXPECT_NEAR(p.ang_vel_y, 0.0, 1e-6);
  EXPECT_NEAR(p.ang_vel_z, std::cos(0.5), 1e-6);
  // Yawed by 90 degrees, a roll rate about the body's X is about the world's Y.
  s = Posed(kPi / 2, 0.0, 0.0);
  s.mutable_w_wb_b()->set_x(2.0);
  p = MakeOutSim(s);
  EXPECT_NEAR(p.ang_vel_x, 0.0, 1e-6);
  EXPECT_NEAR(p.ang_vel_y, 2.0, 1e-6);
}

TEST(TelemetryFrames, PositionsAreInSixtyFourThousandthsOfAMetreAndSaturate) {
  EXPECT_EQ(PositionUnits(1.0), 65536);
  EXPECT_EQ(PositionUnits(-2.5), -163840);
  EXPECT_EQ(PositionUnits(1.0 / 65536.0 * 0.6), 1);  // rounded
  EXPECT_EQ(PositionUnits(1e6), 2147483647);
  EXPECT_EQ(PositionUnits(-1e6), -2147483647 - 1);
  EXPECT_EQ(PositionUnits(std::nan("")), 0);
  EXPECT_EQ(TimeMs(1'234'999'999), 1234u);
  EXPECT_EQ(TimeMs((std::int64_t{1} << 32) * 1'000'000 + 5'000'000), 5u);  // wraps
}

TEST(TelemetryGauge, GearsSpeedPedalsAndLights) {
  pb::VehicleState s;
  s.set_model(pb::VEHICLE_MODEL_FULL);
  s.set_vehicle_id(3);
  s.mutable_v_wt_w()->set_x(3.0);
  s.mutable_v_wt_w()->set_y(4.0);
  s.mutable_v_wt_w()->set_z(12.0);
  for (auto [g, want] : {std::pair{-1, 0}, {0, 1}, {1, 2}, {6, 7}}) {
    s.mutable_drivetrain()->set_gear(g);
    EXPECT_EQ(GaugeGear(s), want) << g;
  }
  s.mutable_drivetrain()->set_gear(0);
  s.mutable_drivetrain()->set_engine_rpm(6500);
  s.mutable_drivetrain()->set_tc_factor(1.0);
  s.mutable_drivetrain()->set_automatic(true);
  s.mutable_control()->set_throttle(0.6);
  s.mutable_control()->set_brake(0.2);
  s.mutable_input()->set_clutch(0.3);
  s.mutable_input()->set_handbrake(1.0);
  for (double f : {1.0, 0.7, 1.0, 1.0}) s.add_wheels()->set_abs_factor(f);
  pb::VehicleParams params;
  params.set_abs(true);
  params.set_traction_control(true);
  params.set_shift_up_rpm(6000);

  OutGaugePack p = MakeOutGauge(s, &params, {});
  EXPECT_FLOAT_EQ(p.speed, 13.0f);  // |(3, 4, 12)|
  EXPECT_EQ(p.gear, kGaugeGearNeutral);
  EXPECT_EQ(p.plid, 3);
  EXPECT_FLOAT_EQ(p.rpm, 6500.0f);
  EXPECT_FLOAT_EQ(p.throttle, 0.6f);
  EXPECT_FLOAT_EQ(p.brake, 0.2f);
  EXPECT_FLOAT_EQ(p.clutch, 0.3f);
  EXPECT_EQ(p.flags, kOgKm | kOgBar);
  EXPECT_EQ(std::string(p.car, 4), "VDYN");
  EXPECT_STREQ(p.display1, "full auto");
  const std::uint32_t all =
      Bit(kDlShift) | Bit(kDlHandbrake) | Bit(kDlTc) | Bit(kDlAbs) | Bit(kDlNeutral);
  EXPECT_EQ(p.dash_lights, all);
  // Handbrake up, neutral, past the shift point, ABS working on one wheel; TC on and idle.
  EXPECT_EQ(p.show_lights, all & ~Bit(kDlTc));
  // Traction control switched off: its light stays on (LFS: "active or switched off").
  params.set_traction_control(false);
  EXPECT_NE(MakeOutGauge(s, &params, {}).show_lights & Bit(kDlTc), 0u);
  // Without parameters the lights that depend on them are not claimed.
  EXPECT_EQ(MakeOutGauge(s, nullptr, {}).dash_lights, Bit(kDlHandbrake) | Bit(kDlNeutral));

  // The paper's model: no gearbox, no engine; reverse while the throttle drives backwards.
  s.set_model(pb::VEHICLE_MODEL_PAPER);
  s.mutable_control()->set_throttle(-0.5);
  p = MakeOutGauge(s, &params, {});
  EXPECT_EQ(p.gear, kGaugeGearReverse);
  EXPECT_FLOAT_EQ(p.throttle, 0.5f);
  EXPECT_EQ(p.rpm, 0.0f);
  EXPECT_EQ(p.dash_lights, 0u);
  EXPECT_STREQ(p.display1, "paper");
  s.mutable_control()->set_throttle(0.5);
  EXPECT_EQ(GaugeGear(s), kGaugeGearFirst);
}

// --- The bridge as a process between the server and UDP sockets -------------------------------

class UdpSocket {
 public:
  UdpSocket() {
    fd_ = socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd_ < 0) throw std::runtime_error("cannot open a UDP socket");
    // A free port below 7400: the kernel's own choice (port 0) lands in the ephemeral range,
    // where Cyclone DDS's ports for domains 100..229 are too (7400 + 250 * domain + ...), and
    // its unicast discovery, with multicast off on loopback, reaches every one of them.
    static std::atomic<int> next{2000 + static_cast<int>(getpid() % 4000)};
    for (int tries = 0; tries < 5000 && port_ == 0; ++tries) {
      const int port = 1024 + (next++ - 1024) % (7400 - 1024);
      sockaddr_in a{};
      a.sin_family = AF_INET;
      a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      a.sin_port = htons(static_cast<std::uint16_t>(port));
      if (bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0) {
        port_ = static_cast<std::uint16_t>(port);
      }
    }
    if (port_ == 0) throw std::runtime_error("no free UDP port in 1024..7399 on 127.0.0.1");
  }
  ~UdpSocket() { close(fd_); }
  std::uint16_t port() const { return port_; }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }

  struct Packet {
    std::vector<std::uint8_t> bytes;
    std::chrono::steady_clock::time_point at;
  };
  // Takes every datagram waiting.
  int Drain() {
    int n = 0;
    std::uint8_t buf[512];
    for (;;) {
      const ssize_t r = recv(fd_, buf, sizeof buf, 0);
      if (r < 0) return n;
      packets.push_back(
          {std::vector<std::uint8_t>(buf, buf + r), std::chrono::steady_clock::now()});
      ++n;
    }
  }
  // Blocks until one of `sockets` has a datagram waiting or the timeout passes.
  static void WaitAny(std::initializer_list<const UdpSocket*> sockets, base::Nanos timeout) {
    std::vector<pollfd> fds;
    for (const UdpSocket* s : sockets) fds.push_back({s->fd_, POLLIN, 0});
    const auto ms = (timeout.ns + 999'999) / 1'000'000;  // rounded up: never a busy loop
    (void)poll(fds.data(), fds.size(), static_cast<int>(std::min<std::int64_t>(ms, 60'000)));
  }
  std::vector<Packet> packets;

 private:
  int fd_ = -1;
  std::uint16_t port_ = 0;
};

TEST(TelemetryUdp, DestinationsAreCheckedAndEverySendIsCounted) {
  std::string error;
  const auto local = ResolveEndpoint("localhost:4444", error);
  ASSERT_TRUE(local.has_value()) << error;
  EXPECT_EQ(ntohl(local->addr.sin_addr.s_addr), INADDR_LOOPBACK);
  EXPECT_EQ(ntohs(local->addr.sin_port), 4444);
  EXPECT_FALSE(ResolveEndpoint("10.0.0.300:4444", error).has_value());
  EXPECT_THAT(error, HasSubstr("'10.0.0.300' is not an IPv4 address"));
  EXPECT_FALSE(ResolveEndpoint(":4444", error).has_value());
  EXPECT_THAT(error, HasSubstr("no host"));

  UdpSocket a, b;
  std::string e1, e2;
  UdpSender sender({*ResolveEndpoint(a.address(), e1), *ResolveEndpoint(b.address(), e2)});
  const std::vector<std::uint8_t> datagram(92, 0x5a);
  EXPECT_EQ(sender.Send(datagram), 2);
  EXPECT_EQ(sender.sent(), 2u);
  EXPECT_EQ(sender.errors(), 0u);
  (void)base::PollUntil(
      base::Deadline::After(base::Seconds(10)), base::Milliseconds(100),
      [&] {
        a.Drain();
        b.Drain();
        return !a.packets.empty() && !b.packets.empty();
      },
      [&](base::Nanos slice) {
        UdpSocket::WaitAny({&a, &b}, slice);
      });
  ASSERT_EQ(a.packets.size(), 1u);
  EXPECT_EQ(a.packets[0].bytes, datagram);
  ASSERT_EQ(b.packets.size(), 1u);
  // A datagram the network refuses (larger than UDP allows) is an error per destination, counted
  // and described, and nothing stops.
  EXPECT_EQ(sender.Send(std::vector<std::uint8_t>(70000, 0)), 0);
  EXPECT_EQ(sender.errors(), 2u);
  EXPECT_THAT(sender.last_error(), HasSubstr(b.address()));
  EXPECT_EQ(sender.Send(datagram), 2);
  EXPECT_EQ(sender.sent(), 4u);
}

std::string TelemetryBinary() {
  return VDYN_TELEMETRY_BINARY;
}

class TelemetryNet : public ::testing::Test {
 protected:
  void SetUp() override {
    testing::UseLoopbackDds();
    domain_ = testing::FreshDomain();
  }
  std::unique_ptr<testing::Process> Start(std::vector<std::string> argv, const std::string& log) {
    return std::make_unique<testing::Process>(std::move(argv), dir_ / log);
  }
  std::uint32_t domain_ = 0;
  testing::TempDir dir_;
};

TEST_F(TelemetryNet, PacketsCarryTheStatesAtTheirRatesAndStopWhenStatesGoStale) {
  auto server = Start({testing::ServerBinary(), "--domain", std::to_string(domain_), "--no-status",
                       "--world", "flat"},
                      "server.log");
  UdpSocket sim, gauge, gauge2, sim_id, gauge_id;
  constexpr double kSimHz = 50, kGaugeHz = 25;
  // Bridge 1: no IDs, two dashboards (one by host name). Bridge 2: both IDs.
  auto bridge = Start(
      {TelemetryBinary(), "--domain", std::to_string(domain_), "--outsim", sim.address(),
       "--outgauge", gauge.address(), "--outgauge", "localhost:" + std::to_string(gauge2.port()),
       "--outsim-hz", "50", "--outgauge-hz", "25", "--stale-ms", "400"},
      "telemetry.log");
  auto bridge_ids = Start(
      {TelemetryBinary(), "--domain", std::to_string(domain_), "--outsim", sim_id.address(),
       "--outsim-id", "7", "--outgauge", gauge_id.address(), "--outgauge-id", "9", "--no-status"},
      "telemetry_ids.log");
  auto drain = [&] {
    for (UdpSocket* s : {&sim, &gauge, &gauge2, &sim_id, &gauge_id}) s->Drain();
  };

  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Writer<pb::DriverInput> input(p, transport::TopicId::kInput, 10);
  transport::Reader<pb::VehicleState> states(p, transport::TopicId::kState, &drops);
  std::map<std::uint32_t, pb::VehicleState> by_ms;  // every state seen, by its packets' Time
  pb::VehicleState last;
  auto take_states = [&] {
    (void)states.Take([&](const pb::VehicleState& s, const transport::SampleInfo&) {
      if (s.vehicle_id() != 1) return;
      by_ms[TimeMs(s.sim_time_ns())] = s;
      last = s;
    });
  };
  auto drive = [&](double throttle, double brake, double handbrake) {
    pb::DriverInput in;
    in.set_vehicle_id(1);
    in.set_source_id("test-rig");
    in.set_throttle(throttle);
    in.set_brake(brake);
    in.set_handbrake(handbrake);
    EXPECT_TRUE(input.Write(1, in)) << input.last_error();
  };

  // Takes what came until `done` (the packets follow the states: a state wakes it), for at most
  // `seconds`; `between` runs before each wait.
  auto take_until = [&](
                        std::int64_t seconds, const std::function<bool()>& done,
                        const std::function<void()>& between = [] {}) {
    return base::PollUntil(
        base::Deadline::After(base::Seconds(seconds)), base::Milliseconds(10),
        [&] {
          take_states();
          drain();
          return done();
        },
        [&](base::Nanos slice) {
          between();
          (void)states.Wait(base::Chrono(slice));
        });
  };
  // Until packets flow (the server and both bridges are up).
  (void)take_until(60, [&] {
    return !sim.packets.empty() && !gauge.packets.empty() && !sim_id.packets.empty() &&
           !gauge_id.packets.empty();
  });
  ASSERT_FALSE(sim.packets.empty()) << server->Log() << bridge->Log();
  ASSERT_FALSE(gauge_id.packets.empty()) << bridge_ids->Log();

  // Full throttle to 12 m/s, then brake with the handbrake up to below 3 m/s.
  const auto window_start = std::chrono::steady_clock::now();
  const std::size_t sim_before = sim.packets.size(), gauge_before = gauge.packets.size();
  (void)take_until(
      60, [&] { return last.speed_kmh() > 12 * 3.6; }, [&] { drive(1.0, 0.0, 0.0); });
  ASSERT_GT(last.speed_kmh(), 12 * 3.6) << server->Log();
  (void)take_until(
      60, [&] { return last.speed_kmh() < 3 * 3.6; }, [&] { drive(0.0, 1.0, 1.0); });
  ASSERT_LT(last.speed_kmh(), 3 * 3.6);
  drain();
  const double window_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - window_start).count();

  // Sizes: 64 and 92 without IDs, 68 and 96 with them, the IDs last.
  for (const auto& pk : sim.packets) ASSERT_EQ(pk.bytes.size(), 64u);
  for (const auto* s : {&gauge, &gauge2}) {
    for (const auto& pk : s->packets) ASSERT_EQ(pk.bytes.size(), 92u);
  }
  for (const auto& pk : sim_id.packets) {
    ASSERT_EQ(pk.bytes.size(), 68u);
    EXPECT_EQ(GetI32(pk.bytes, os::kId), 7);
  }
  for (const auto& pk : gauge_id.packets) {
    ASSERT_EQ(pk.bytes.size(), 96u);
    EXPECT_EQ(GetI32(pk.bytes, og::kId), 9);
  }

  // Rates, over the driving window's wall time, generously: a fixed rate, not one packet per
  // state (1000 a second) and not starved.
  const double sim_rate = static_cast<double>(sim.packets.size() - sim_before) / window_s;
  const double gauge_rate = static_cast<double>(gauge.packets.size() - gauge_before) / window_s;
  std::printf(
      "  telemetry: OutSim %.1f packets/s (asked %.0f), OutGauge %.1f/s (asked %.0f) over "
      "%.1f s of driving\n",
      sim_rate, kSimHz, gauge_rate, kGaugeHz, window_s);
  EXPECT_GT(sim_rate, 0.3 * kSimHz);
  EXPECT_LT(sim_rate, 1.2 * kSimHz + 2.0 / window_s);
  EXPECT_GT(gauge_rate, 0.3 * kGaugeHz);
  EXPECT_LT(gauge_rate, 1.2 * kGaugeHz + 2.0 / window_s);
  // Both dashboards get every packet (loopback loses none at this rate).
  EXPECT_NEAR(static_cast<double>(gauge2.packets.size()), static_cast<double>(gauge.packets.size()),
              3.0);

  // OutSim against the state of the same simulation time.
  int sim_matched = 0, accel_fwd = 0, accel_back = 0;
  double pitch_accel = 0, pitch_brake = 0;
  int n_pitch_accel = 0, n_pitch_brake = 0;
  for (const auto& pk : sim.packets) {
    const auto& b = pk.bytes;
    const auto it = by_ms.find(GetU32(b, os::kTime));
    if (it == by_ms.end()) continue;
    const pb::VehicleState& s = it->second;
    ++sim_matched;
    const double u = 1.0 / 65536.0;
    EXPECT_NEAR(GetI32(b, os::kPos + 0) * u, s.p_wt_w().x(), u);
    EXPECT_NEAR(GetI32(b, os::kPos + 4) * u, s.p_wt_w().y(), u);
    EXPECT_NEAR(GetI32(b, os::kPos + 8) * u, s.p_wt_w().z(), u);
    EXPECT_FLOAT_EQ(GetF32(b, os::kVel + 0), static_cast<float>(s.v_wt_w().x()));
    EXPECT_FLOAT_EQ(GetF32(b, os::kVel + 4), static_cast<float>(s.v_wt_w().y()));
    EXPECT_FLOAT_EQ(GetF32(b, os::kVel + 8), static_cast<float>(s.v_wt_w().z()));
    EXPECT_FLOAT_EQ(GetF32(b, os::kAccel + 0), static_cast<float>(s.a_wt_w().x()));
    EXPECT_FLOAT_EQ(GetF32(b, os::kAccel + 4), static_cast<float>(s.a_wt_w().y()));
    EXPECT_FLOAT_EQ(GetF32(b, os::kAccel + 8), static_cast<float>(s.a_wt_w().z()));
    // Orientation against the state's quaternion: LFS's forward axis (-sin H, cos H) and
    // forward.z = sin(Pitch) are vdyn's R_WB (1, 0, 0).
    const auto& q = s.q_wb();
    const double fx = 1 - 2 * (q.y() * q.y() + q.z() * q.z());
    const double fy = 2 * (q.x() * q.y() + q.w() * q.z());
    const double fz = 2 * (q.x() * q.z() - q.w() * q.y());
    const double h = GetF32(b, os::kHeading), pitch = GetF32(b, os::kPitch);
    const double fh = std::hypot(fx, fy);
    EXPECT_NEAR(-std::sin(h), fx / fh, 1e-5);
    EXPECT_NEAR(std::cos(h), fy / fh, 1e-5);
    EXPECT_NEAR(std::sin(pitch), fz, 1e-5);
    // Physics, in the packet's own terms: the car speeds up along its forward axis under
    // throttle and slows under the brakes; it squats (nose up) under throttle and dives under
    // the brakes.
    const double a_fwd =
        GetF32(b, os::kAccel + 0) * -std::sin(h) + GetF32(b, os::kAccel + 4) * std::cos(h);
    const double speed = std::hypot(GetF32(b, os::kVel + 0), GetF32(b, os::kVel + 4));
    if (s.control().throttle() == 1.0 && speed > 1.0) {
      accel_fwd += a_fwd > 0.5;
      pitch_accel += pitch;
      ++n_pitch_accel;
    }
    if (s.control().brake() == 1.0 && speed > 4.0) {
      accel_back += a_fwd < -0.5;
      pitch_brake += pitch;
      ++n_pitch_brake;
    }
  }
  EXPECT_GT(sim_matched, 20);
  ASSERT_GT(n_pitch_accel, 5);
  ASSERT_GT(n_pitch_brake, 3);
  EXPECT_GE(accel_fwd, n_pitch_accel * 9 / 10);
  EXPECT_GE(accel_back, n_pitch_brake * 9 / 10);
  EXPECT_GT(pitch_accel / n_pitch_accel, pitch_brake / n_pitch_brake);

  // OutGauge against the state of the same simulation time.
  int gauge_matched = 0, handbrake_on = 0, handbrake_off = 0, driving_in_gear = 0;
  for (const auto& pk : gauge.packets) {
    const auto& b = pk.bytes;
    const auto it = by_ms.find(GetU32(b, og::kTime));
    if (it == by_ms.end()) continue;
    const pb::VehicleState& s = it->second;
    ++gauge_matched;
    const auto& v = s.v_wt_w();
    EXPECT_NEAR(GetF32(b, og::kSpeed), std::sqrt(v.x() * v.x() + v.y() * v.y() + v.z() * v.z()),
                1e-5 * (1 + s.speed_kmh()));
    EXPECT_NEAR(GetF32(b, og::kSpeed) * 3.6, s.speed_kmh(), 1e-4 * (1 + s.speed_kmh()));
    EXPECT_EQ(b[og::kGear], s.drivetrain().gear() + 1);  // R 0, N 1, first 2
    EXPECT_FLOAT_EQ(GetF32(b, og::kRpm), static_cast<float>(s.drivetrain().engine_rpm()));
    EXPECT_FLOAT_EQ(GetF32(b, og::kThrottle), static_cast<float>(s.control().throttle()));
    EXPECT_FLOAT_EQ(GetF32(b, og::kBrake), static_cast<float>(s.control().brake()));
    EXPECT_EQ(b[og::kPlid], 1);
    EXPECT_EQ(GetU32(b, og::kFlags) & 0xffffu, 16384u | 32768u);  // OG_KM | OG_BAR
    const std::uint32_t dash = GetU32(b, og::kDashLights), show = GetU32(b, og::kShowLights);
    EXPECT_NE(dash & (1u << 2), 0u);  // the car has a handbrake light
    EXPECT_EQ(show & ~dash, 0u);      // never a light the car does not have
    const bool hb = (show & (1u << 2)) != 0;
    EXPECT_EQ(hb, s.input().handbrake() > 0) << s.step();
    handbrake_on += hb;
    handbrake_off += !hb;
    if (s.control().throttle() == 1.0 && s.speed_kmh() > 20) driving_in_gear += b[og::kGear] >= 2;
  }
  EXPECT_GT(gauge_matched, 10);
  EXPECT_GT(handbrake_on, 0);
  EXPECT_GT(handbrake_off, 0);
  EXPECT_GT(driving_in_gear, 0);

  // The server stops: within the stale limit (400 ms) the stream stops, and the bridge says so.
  server->Signal(SIGTERM);
  ASSERT_TRUE(server->Wait(20s).has_value());
  drain();
  std::size_t count = sim.packets.size() + gauge.packets.size();
  auto quiet_since = std::chrono::steady_clock::now();
  bool quiet = false;
  // A loop of its own: it ends on a quiet spell, not on something that arrives.
  for (const base::Deadline deadline = base::Deadline::After(base::Seconds(20));
       !deadline.Passed();) {
    UdpSocket::WaitAny({&sim, &gauge}, std::min(base::Milliseconds(100), deadline.Left()));
    drain();
    const std::size_t now_count = sim.packets.size() + gauge.packets.size();
    if (now_count != count) {
      count = now_count;
      quiet_since = std::chrono::steady_clock::now();
    } else if (std::chrono::steady_clock::now() - quiet_since > 1500ms) {
      quiet = true;
      break;
    }
  }
  EXPECT_TRUE(quiet) << "packets kept coming after the server stopped";
  EXPECT_TRUE(bridge->running());
  EXPECT_THAT(bridge->Log(), HasSubstr("sending paused"));

  // A server comes back: the packets resume, and the bridge says so.
  server = Start({testing::ServerBinary(), "--domain", std::to_string(domain_), "--no-status",
                  "--world", "flat"},
                 "server2.log");
  const std::size_t before_restart = sim.packets.size();
  (void)take_until(60, [&] { return sim.packets.size() >= before_restart + 5; });
  EXPECT_GE(sim.packets.size(), before_restart + 5) << server->Log();
  EXPECT_THAT(bridge->Log(), HasSubstr("sending resumed"));

  // A clean exit on SIGINT with the counts.
  bridge->Signal(SIGINT);
  const auto rc = bridge->Wait(20s);
  ASSERT_TRUE(rc.has_value());
  EXPECT_EQ(*rc, 0) << bridge->Log();
  EXPECT_THAT(bridge->Log(), HasSubstr("send errors"));
  bridge_ids->Signal(SIGTERM);
  EXPECT_EQ(bridge_ids->Wait(20s).value_or(-1), 0) << bridge_ids->Log();
}

TEST_F(TelemetryNet, BadOptionsExitWithTwoAndSayWhy) {
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"--outsim", "127.0.0.1:4123", "--outsim-hz", "nan"}, "not a finite number"},
      {{"--outgauge", "127.0.0.1:4444", "--outgauge-hz", "0"}, "telemetry packet rate"},
      {{"--outsim", "127.0.0.1:4123", "--stale-ms", "-1"}, "stale-state limit"},
      {{"--outsim", "999.1.1.1:4123"}, "is not an IPv4 address"},
      {{"--outsim", "127.0.0.1"}, "expected HOST:PORT"},
      {{"--outgauge", "127.0.0.1:70000"}, "not in 1 to 65535"},
      {{"--outgauge", "127.0.0.1:port"}, "not a port number"},
      {{"--outsim", "127.0.0.1:4123", "--outsim-id", "0"}, "telemetry packet ID"},
      {{"--outgauge", "127.0.0.1:4444", "--car", "TOOLONG"}, "1 to 4"},
      {{}, "give at least one destination"},
  };
  int i = 0;
  for (const auto& [args, why] : cases) {
    std::vector<std::string> argv = {TelemetryBinary(), "--domain", std::to_string(domain_)};
    argv.insert(argv.end(), args.begin(), args.end());
    auto proc = Start(argv, "bad" + std::to_string(i++) + ".log");
    const auto rc = proc->Wait(20s);
    ASSERT_TRUE(rc.has_value());
    EXPECT_EQ(*rc, 2) << proc->Log();
    EXPECT_THAT(proc->Log(), HasSubstr(why));
  }
}

}  // namespace
}  // namespace vdyn

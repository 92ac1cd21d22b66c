// DDS Security (issue: the lab, "Only permitted participants drive"): the server and its clients
// as real processes over loopback DDS with Cyclone's security plugins and the material
// scripts/lab-pki.sh makes. Each participant's identity is its process's CYCLONEDDS_URI; this
// test process watches with an observer identity of its own. Every wait is bounded.
#include <chrono>
#include <cstdlib>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "dds_wait.h"
#include "process.h"
#include "test_support.h"
#include "vdyn/diagnostics.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/security_log.h"
#include "vdyn/vehicle_params.pb.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;
using namespace std::chrono_literals;
using testing::Process;
using transport::TopicId;

const std::string kLoopback =
    "<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces></General>"
    "<Discovery><MaxAutoParticipantIndex>120</MaxAutoParticipantIndex></Discovery>";

// Runs scripts/lab-pki.sh with the arguments; its output.
std::string LabPki(const std::vector<std::string>& args, const std::filesystem::path& log) {
  std::vector<std::string> argv = {"/bin/bash", VDYN_LAB_PKI_SCRIPT};
  argv.insert(argv.end(), args.begin(), args.end());
  Process p(argv, log);
  const auto rc = p.Wait(120s);
  EXPECT_EQ(rc, std::optional<int>(0)) << p.Log();
  return p.Log();
}

std::string OneLine(std::string s) {
  std::erase(s, '\n');
  return s;
}

// The rest of the first line of `log` that starts with `prefix`.
std::optional<std::string> Fact(const std::string& log, const std::string& prefix) {
  std::istringstream in(log);
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(prefix, 0) == 0) return line.substr(prefix.size());
  }
  return std::nullopt;
}

long Count(const std::string& log, const std::string& prefix) {
  const auto f = Fact(log, prefix);
  return f ? std::atol(f->c_str()) : -1;
}

using testing::ReadUntil;

class Security : public ::testing::Test {
 protected:
  // The lab's material, and a second "lab" whose CA nobody here trusts: made once for the suite.
  static void SetUpTestSuite() {
    root_ = new testing::TempDir;  // one per process: both labs live in it
    lab_ = new std::filesystem::path(root_->path() / "lab");
    rogue_ = new std::filesystem::path(root_->path() / "rogue");
    LabPki({lab_->string(), "server:server", "rig:rig", "operator:operator",
            "observer:observer", "watch:observer"},
           root_->path() / "lab-pki.log");
    // An intruder with its own CA; and an observer of our lab that signed itself permissions to
    // do everything a rig does, with a CA of its own (its certificate is genuine).
    LabPki({rogue_->string(), "intruder:rig", "observer:rig"}, root_->path() / "rogue-pki.log");
  }
  static void TearDownTestSuite() {
    delete lab_;
    delete rogue_;
    delete root_;
  }

  void SetUp() override {
    domain_ = testing::FreshDomain();
    // This process's participant: the observer `watch` (set before the domain is created).
    setenv("CYCLONEDDS_URI", Uri(*lab_, "watch").c_str(), 1);
  }

  // CYCLONEDDS_URI for identity `name` of the material in `dir` (lab-pki.sh --config).
  static std::string Uri(const std::filesystem::path& dir, const std::string& name) {
    return kLoopback + OneLine(LabPki({"--config", dir.string(), name},
                                      dir / ("config-" + name + ".log")));
  }
  // Our lab's observer certificate with permissions signed by the rogue CA (and that CA as its
  // permissions CA, so its own checks pass).
  static std::string ForgedObserverUri() {
    const auto l = lab_->string(), r = rogue_->string();
    const std::string plugins = "/usr/lib/x86_64-linux-gnu/libddsc0debian/";
    return kLoopback + "<Security><Authentication><Library initFunction=\"init_authentication\" "
           "finalizeFunction=\"finalize_authentication\" path=\"" + plugins +
           "libdds_security_auth.so\"/><IdentityCA>file:" + l + "/ca.pem</IdentityCA>"
           "<IdentityCertificate>file:" + l + "/observer.pem</IdentityCertificate>"
           "<PrivateKey>file:" + l + "/observer.key</PrivateKey></Authentication>"
           "<Cryptographic><Library initFunction=\"init_crypto\" finalizeFunction=\"finalize_crypto\" "
           "path=\"" + plugins + "libdds_security_crypto.so\"/></Cryptographic>"
           "<AccessControl><Library initFunction=\"init_access_control\" "
           "finalizeFunction=\"finalize_access_control\" path=\"" + plugins +
           "libdds_security_ac.so\"/><PermissionsCA>file:" + r + "/ca.pem</PermissionsCA>"
           "<Governance>file:" + r + "/governance.p7s</Governance>"
           "<Permissions>file:" + r + "/observer.permissions.p7s</Permissions></AccessControl>"
           "</Security>";
  }

  std::unique_ptr<Process> Start(const std::string& uri, std::vector<std::string> argv,
                                 const std::string& log) {
    argv.insert(argv.begin(), {"/usr/bin/env", "CYCLONEDDS_URI=" + uri});
    return std::make_unique<Process>(argv, dir_ / log);
  }
  std::unique_ptr<Process> StartServer() {
    return Start(Uri(*lab_, "server"),
                 {testing::ServerBinary(), "--domain", std::to_string(domain_), "--no-status",
                  "--world", "flat"},
                 "server.log");
  }
  // security_peer: tries to set vehicle 1's mass and to drive it as `source` for `seconds`.
  std::unique_ptr<Process> StartPeer(const std::string& uri, const std::string& source,
                                     int seconds, double mass) {
    return Start(uri, {VDYN_SECURITY_PEER_BINARY, std::to_string(domain_),
                       std::to_string(seconds), source, std::to_string(mass)},
                 source + ".log");
  }
  static std::string Finish(Process& p) {
    const auto rc = p.Wait(60s);
    EXPECT_EQ(rc, std::optional<int>(0)) << p.Log();
    return p.Log();
  }

  static testing::TempDir* root_;
  static std::filesystem::path* lab_;
  static std::filesystem::path* rogue_;
  std::uint32_t domain_ = 0;
  testing::TempDir dir_;
};
testing::TempDir* Security::root_ = nullptr;
std::filesystem::path* Security::lab_ = nullptr;
std::filesystem::path* Security::rogue_ = nullptr;

// Waits until the server runs (this observer reads its states); the first state.
pb::VehicleState WaitForServer(transport::Reader<pb::VehicleState>& states, Process& server) {
  pb::VehicleState first;
  bool got = false;
  EXPECT_TRUE(ReadUntil<pb::VehicleState>(states, 30s, [&](const auto& s) { first = s; got = true; },
                                          [&] { return got; }))
      << server.Log();
  return first;
}

TEST_F(Security, APermittedRigDrivesAndAnObserverOnlyWatches) {
  auto server = StartServer();
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  WaitForServer(states, *server);

  // The rig drives: its states name it.
  auto rig = Start(Uri(*lab_, "rig"),
                   {testing::InputBinary(), "--domain", std::to_string(domain_), "--source-id",
                    "rig-a", "play", "demo"},
                   "rig.log");
  bool driven = false;
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(states, 30s, [&](const auto& s) {
    driven = driven || s.input().source_id() == "rig-a";
  }, [&] { return driven; })) << rig->Log() << server->Log();

  // An observer may not even create a writer of input or requests; it reads the states.
  auto observer = StartPeer(Uri(*lab_, "observer"), "observer-x", 4, 1900.0);
  long foreign = 0;
  ReadUntil<pb::VehicleState>(states, 5s, [&](const auto& s) {
    foreign += s.input().source_id() == "observer-x";
  }, [&] { return !observer->running(); });
  const std::string log = Finish(*observer);
  EXPECT_THAT(Fact(log, "control writer refused: ").value_or("(none)"),
              HasSubstr("Not Allowed By Security"));
  EXPECT_THAT(Fact(log, "input writer refused: ").value_or("(none)"),
              HasSubstr("Not Allowed By Security"));
  EXPECT_GT(Count(log, "states received "), 0) << log;
  EXPECT_EQ(foreign, 0);
  // The rig still drives.
  driven = false;
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(states, 10s, [&](const auto& s) {
    driven = s.input().source_id() == "rig-a";
  }, [&] { return driven; }));
}

TEST_F(Security, AnOperatorChangesParametersAndCannotDrive) {
  auto server = StartServer();
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  transport::Reader<pb::VehicleParams> params(p, TopicId::kParams, &drops);
  WaitForServer(states, *server);
  double mass = 0;
  ASSERT_TRUE(ReadUntil<pb::VehicleParams>(params, 10s, [&](const auto& m) { mass = m.mass(); },
                                           [&] { return mass > 0; }));
  ASSERT_NE(mass, 1850.0);

  auto op = StartPeer(Uri(*lab_, "operator"), "operator-a", 10, 1850.0);
  const std::string log = Finish(*op);
  EXPECT_TRUE(Fact(log, "reply accepted").has_value()) << log;
  EXPECT_THAT(Fact(log, "input writer refused: ").value_or("(none)"),
              HasSubstr("Not Allowed By Security"));
  EXPECT_TRUE(ReadUntil<pb::VehicleParams>(params, 10s, [&](const auto& m) { mass = m.mass(); },
                                           [&] { return mass == 1850.0; }))
      << "mass " << mass << "\n" << server->Log();
}

TEST_F(Security, ForgedPermissionsAndAForeignCaCannotDriveOrChangeParametersAndAreCounted) {
  auto server = StartServer();
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  transport::Reader<pb::VehicleParams> params(p, TopicId::kParams, &drops);
  transport::Reader<pb::Diagnostics> diag(p, TopicId::kDiagnostics, &drops);
  WaitForServer(states, *server);
  double mass = 0;
  ASSERT_TRUE(ReadUntil<pb::VehicleParams>(params, 10s, [&](const auto& m) { mass = m.mass(); },
                                           [&] { return mass > 0; }));

  // Both pass their own checks, so both create their writers and write; the server refuses them.
  auto forged = StartPeer(ForgedObserverUri(), "forged", 6, 2345.0);
  auto intruder = StartPeer(Uri(*rogue_, "intruder"), "intruder", 6, 2345.0);
  long foreign = 0, seen = 0;
  ReadUntil<pb::VehicleState>(states, 30s, [&](const auto& s) {
    ++seen;
    foreign += s.input().source_id() == "forged" || s.input().source_id() == "intruder";
  }, [&] { return !forged->running() && !intruder->running(); });
  EXPECT_GT(seen, 0);
  EXPECT_EQ(foreign, 0);
  (void)params.Take([&](const pb::VehicleParams& m, const transport::SampleInfo&) {
    EXPECT_NE(m.mass(), 2345.0);
  });
  for (auto* peer : {forged.get(), intruder.get()}) {
    const std::string log = Finish(*peer);
    EXPECT_THAT(Fact(log, "no reply: ").value_or("(none)"), Not(StartsWith("(none)"))) << log;
    EXPECT_EQ(Count(log, "input matched readers "), 0) << log;
    EXPECT_EQ(Count(log, "states received "), 0) << log;
  }

  // The server's diagnostics count both refusals (Cyclone logs them; transport/security_log.h).
  std::map<std::string, std::uint64_t> counts;
  ASSERT_TRUE(ReadUntil<pb::Diagnostics>(diag, 15s, [&](const auto& d) {
    for (const auto& dc : d.drops()) counts[dc.kind()] = dc.count();
  }, [&] {
    return counts["DDS Security: remote identity refused"] > 0 &&
           counts["DDS Security: remote permissions refused"] > 0;
  })) << server->Log();
  // And its log says whom (the counters log each kind with its last detail).
  // The server logs its counters once a second, with its diagnostics: each wakes the wait.
  (void)ReadUntil(
      diag, 15s, [](const pb::Diagnostics&) {},
      [&] { return server->Log().find("CN=intruder") != std::string::npos; });
  EXPECT_THAT(server->Log(), HasSubstr("dropped: DDS Security: remote identity refused"));
  EXPECT_THAT(server->Log(), HasSubstr("CN=intruder"));
}

TEST_F(Security, AParticipantWithoutSecuritySeesNothingAndDrivesNothing) {
  auto server = StartServer();
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  transport::Reader<pb::VehicleParams> params(p, TopicId::kParams, &drops);
  WaitForServer(states, *server);

  auto plain = StartPeer(kLoopback, "plain", 5, 2345.0);
  long foreign = 0, seen = 0;
  ReadUntil<pb::VehicleState>(states, 30s, [&](const auto& s) {
    ++seen;
    foreign += s.input().source_id() == "plain";
  }, [&] { return !plain->running(); });
  EXPECT_GT(seen, 0);
  EXPECT_EQ(foreign, 0);
  (void)params.Take([&](const pb::VehicleParams& m, const transport::SampleInfo&) {
    EXPECT_NE(m.mass(), 2345.0);
  });
  const std::string log = Finish(*plain);
  EXPECT_TRUE(Fact(log, "no reply: ").has_value()) << log;
  EXPECT_EQ(Count(log, "input matched readers "), 0) << log;
  EXPECT_EQ(Count(log, "states received "), 0) << log;
}

// Cyclone DDS 0.10.2's own lines, as the server received them in this suite's refusals.
TEST(SecurityLog, RecognisesCyclonesRefusalLines) {
  const auto identity = transport::ClassifySecurityLogLine(
      "Begin handshake reply failed: Certificate not valid: error: certificate signature "
      "failure; subject: /O=vdyn lab/CN=intruder(code: 200)");
  ASSERT_TRUE(identity.has_value());
  EXPECT_EQ(identity->kind, "DDS Security: remote identity refused");
  EXPECT_EQ(identity->detail, "subject: /O=vdyn lab/CN=intruder(code: 200)");
  const auto permissions = transport::ClassifySecurityLogLine(
      "Could not get remote participant f9611d4d:96e6b695:6fb08b3b:1c1 permissions from plugin: "
      "Failed to parse PKCS7 SMIME document: C0A63FA2C87F0000:error:1C880004:Provider "
      "routines:rsa_verify:RSA lib:../providers/implementations/signature/rsa_sig.c:769:\n"
      "C0A63FA2C87F0000:error:06880006:asn1 encoding routines\n(code: 127)");
  ASSERT_TRUE(permissions.has_value());
  EXPECT_EQ(permissions->kind, "DDS Security: remote permissions refused");
  EXPECT_THAT(permissions->detail, StartsWith("permissions from plugin: Failed to parse PKCS7"));
  EXPECT_EQ(permissions->detail.find('\n'), std::string::npos);
  EXPECT_FALSE(transport::ClassifySecurityLogLine(
      "selected interface \"lo\" is not multicast-capable: disabling multicast").has_value());
}

}  // namespace
}  // namespace vdyn

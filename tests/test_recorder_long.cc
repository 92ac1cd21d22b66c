// A live session at 1 kHz recorded on loopback with nothing lost: every step of the vehicle in the
// file, no gap, no drop counted by the recorder, and the recording re-simulates bit for bit. Real
// time, so it takes as long as the session: VDYN_SOAK_SECONDS (tests/CMakeLists.txt registers it
// twice: a one-minute soak in the default run, the ten-minute one behind the label "full").
// Release build only (the sanitizer build runs the same recorder code in test_recorder's shorter
// sessions).
#include <signal.h>

#include <cstdio>
#include <cstdlib>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "process.h"
#include "vdyn/recorder/capture.h"
#include "test_support.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;
using namespace std::chrono_literals;
using testing::Process;

// The session's length in seconds, from the environment (ctest sets it), 600 when unset.
int SoakSeconds() {
  const char* text = std::getenv("VDYN_SOAK_SECONDS");
  const int seconds = text != nullptr ? std::atoi(text) : 600;
  return seconds >= 10 ? seconds : 600;
}

TEST(RecorderLong, ASessionAt1kHzWithNothingLostOnLoopback) {
  // Nothing lost needs room for a burst: behind Debian's 208 KiB cap a recorder descheduled for
  // 0.2 s loses best-effort states, whatever it does (scripts/test.sh raises the cap as root).
  if (const std::uint64_t cap = recorder::KernelReceiveBufferMax(); cap < 16u << 20) {
    GTEST_SKIP() << "net.core.rmem_max is " << cap
                 << " bytes: nothing lost needs the recorder's socket buffer of 16 MiB or more "
                    "(as root: sysctl -w net.core.rmem_max=16777216)";
  }
  const int seconds = SoakSeconds();
  std::fprintf(stderr, "soak: a %d s session\n", seconds);
  testing::UseLoopbackDds();
  const std::uint32_t domain = testing::FreshDomain();
  testing::TempDir dir;
  const auto file = dir / "soak.mcap";
  Process recorder({testing::RecorderBinary(), "record", file.string(), "--domain", std::to_string(domain), "--status"},
                   dir / "rec.log");
  Process server({testing::ServerBinary(), "--domain", std::to_string(domain), "--world", "facility", "--duration",
                  std::to_string(seconds), "--no-status", "--stats-out", (dir / "stats.txt").string()},
                 dir / "server.log");
  Process input({testing::InputBinary(), "--domain", std::to_string(domain), "--maneuver", "demo", "--loop",
                 "--wait", "60"},
                dir / "input.log");
  ASSERT_EQ(server.Wait(std::chrono::seconds(seconds + 300)), 0) << server.Log();
  input.Signal(SIGTERM);
  recorder.Signal(SIGINT);
  ASSERT_EQ(recorder.Wait(120s), 0) << recorder.Log();
  const std::string summary = recorder.Log();
  EXPECT_THAT(summary, HasSubstr("lost 0, dropped 0")) << summary;

  auto run = [&](const std::vector<std::string>& args, const std::string& log) {
    std::vector<std::string> argv = {testing::RecorderBinary()};
    argv.insert(argv.end(), args.begin(), args.end());
    Process p(argv, dir / log);
    const auto code = p.Wait(600s);
    return std::make_pair(code.value_or(-1), p.Log());
  };
  auto [icode, info] = run({"info", file.string()}, "info.log");
  ASSERT_EQ(icode, 0) << info;
  // "  1         steps 0..599999 (...), 600000 states, 0 missing" (ten minutes)
  std::uint64_t first = 0, last = 0, states = 0, missing = 0;
  const std::size_t at = info.find("steps ");
  ASSERT_NE(at, std::string::npos) << info;
  const std::size_t paren = info.find("), ", at);
  ASSERT_NE(paren, std::string::npos) << info;
  ASSERT_EQ(std::sscanf(info.c_str() + at, "steps %lu..%lu", &first, &last), 2) << info;
  ASSERT_EQ(std::sscanf(info.c_str() + paren, "), %lu states, %lu missing", &states, &missing), 2) << info;
  EXPECT_EQ(missing, 0u) << info;
  EXPECT_EQ(states, last - first + 1) << info;
  // The recorder joins before the server and so has every state from the first; a second of
  // margin for a slow start of the server's writer.
  EXPECT_GE(states, static_cast<std::uint64_t>(seconds - 1) * 1000u) << info;
  EXPECT_THAT(info, HasSubstr("gaps        none")) << info;
  auto [vcode, verify] = run({"verify", file.string()}, "verify.log");
  EXPECT_EQ(vcode, 0) << verify;
  EXPECT_THAT(verify, HasSubstr("bit-exact over")) << verify;
}

}  // namespace
}  // namespace vdyn

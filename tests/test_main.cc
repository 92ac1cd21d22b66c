// Test main: a test that logs a warning or an error it did not expect fails (STYLE.md, MuJoCo's
// habit). A test that expects one wraps the code in vdyn::testing::ExpectLogs.
#include <atomic>
#include <mutex>

#include <gtest/gtest.h>
#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>

#include "test_support.h"

namespace vdyn::testing {
namespace {

std::atomic<int> g_expected_depth{0};
std::atomic<int> g_unexpected{0};
std::atomic<int> g_seen{0};

class FailOnWarningSink : public spdlog::sinks::base_sink<std::mutex> {
 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    if (msg.level < spdlog::level::warn) return;
    g_seen.fetch_add(1);
    if (g_expected_depth.load() == 0) {
      g_unexpected.fetch_add(1);
      ADD_FAILURE() << "unexpected log at level " << spdlog::level::to_string_view(msg.level).data()
                    << ": " << std::string(msg.payload.data(), msg.payload.size());
    }
  }
  void flush_() override {}
};

}  // namespace

ExpectLogs::ExpectLogs() : before_(g_seen.load()) { g_expected_depth.fetch_add(1); }
ExpectLogs::~ExpectLogs() { g_expected_depth.fetch_sub(1); }
int ExpectLogs::count() const { return g_seen.load() - before_; }

}  // namespace vdyn::testing

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  auto logger = std::make_shared<spdlog::logger>(
      "vdyn-test", std::make_shared<vdyn::testing::FailOnWarningSink>());
  logger->set_level(spdlog::level::trace);
  spdlog::set_default_logger(logger);
  return RUN_ALL_TESTS();
}

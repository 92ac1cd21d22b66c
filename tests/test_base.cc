// The bottom layer: the one hash against answers computed independently from its specification
// (docs/hash.md's Python reference, and FNV's published test vectors), the table of limits, and
// numbers as a person reads and writes them.
#include <cmath>
#include <limits>
#include <memory>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "vdyn/base/hash.h"
#include "vdyn/base/limits.h"
#include "vdyn/base/spsc_queue.h"
#include "vdyn/base/text.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;

TEST(Hash, Fnv1a64MatchesThePublishedTestVectors) {
  EXPECT_EQ(base::Fnv1a64(""), 0xcbf29ce484222325ull);
  EXPECT_EQ(base::Fnv1a64("a"), 0xaf63dc4c8601ec8cull);
  EXPECT_EQ(base::Fnv1a64("foobar"), 0x85944171f73967e8ull);
}

// Expected values from the reference implementation in docs/hash.md (Python), not from this code.
TEST(Hash, WordHashMatchesTheReferenceImplementation) {
  EXPECT_EQ(base::WordHash().Final(), 0xefd01f60ba992926ull);
  base::WordHash h;
  h.Word(1);
  h.Word(2);
  h.Word(3);
  EXPECT_EQ(h.Final(), 0xfd97a838d02d3759ull);
  base::WordHash d;
  d.Double(1.0);
  d.Double(-0.0);  // its own bits: -0 and +0 hash differently
  d.Int(-7);       // two's complement, sign-extended
  EXPECT_EQ(d.Final(), 0x7074e1174e45c72bull);
  base::WordHash z;
  z.Double(1.0);
  z.Double(0.0);
  z.Int(-7);
  EXPECT_NE(z.Final(), d.Final());
}

TEST(Hash, ServerKeyFoldsFnv1aOfTheId) {
  EXPECT_EQ(base::ServerKey("vdyn"), 0x68ea826du);
  EXPECT_EQ(base::ServerKey("lab-a"), 0xb611de42u);
}

TEST(Limits, CheckNamesTheQuantityTheRangeAndTheValue) {
  EXPECT_EQ(limits::Check(limits::kThrottle, 0.5), "");
  EXPECT_EQ(limits::Check(limits::kThrottle, 5.0), "throttle must be in [-1, 1], got 5");
  EXPECT_THAT(limits::Check(limits::kThrottle, std::nan("")), HasSubstr("finite number, got nan"));
  const limits::Range* mass = limits::ParamRange("mass");
  ASSERT_NE(mass, nullptr);
  EXPECT_EQ(limits::Check(*mass, 0.0), "vehicle mass, kg must be in (0, 100000], got 0");
  ASSERT_NE(limits::ParamRange("rr.radius"), nullptr);
  EXPECT_EQ(limits::ParamRange("wings"), nullptr);
  // Clamp keeps the range and maps non-finite values to the fallback.
  EXPECT_EQ(limits::Clamp(limits::kBrake, 3.0), 1.0);
  EXPECT_EQ(limits::Clamp(limits::kBrake, std::numeric_limits<double>::infinity(), 0.25), 0.25);
}

TEST(Text, NumbersReadAsAPersonWritesThem) {
  EXPECT_EQ(base::ParseNumber(" 1.5 "), 1.5);
  EXPECT_EQ(base::ParseNumber("+2"), 2.0);
  EXPECT_EQ(base::ParseNumber("1e-400"), 0.0);  // underflows to zero, as on paper
  EXPECT_EQ(base::ParseNumber("-1e-400"), -0.0);
  EXPECT_FALSE(base::ParseNumber("nan"));
  EXPECT_FALSE(base::ParseNumber("inf"));
  EXPECT_FALSE(base::ParseNumber("1e400"));
  EXPECT_FALSE(base::ParseNumber("1.5x"));
  EXPECT_FALSE(base::ParseNumber(""));
  EXPECT_FALSE(base::ParseNumber("--1"));
}

TEST(Text, NumbersPrintedWithoutNoise) {
  EXPECT_EQ(base::FormatNumber(100000), "100000");
  EXPECT_EQ(base::FormatNumber(0.1), "0.1");
  EXPECT_EQ(base::FormatNumber(1e9), "1e9");
  EXPECT_EQ(base::FormatNumber(1.5e-7), "1.5e-7");
  EXPECT_EQ(base::FormatNumber(1e300), "1e300");
  EXPECT_EQ(base::FormatNumber(-3), "-3");
}

TEST(Text, ComputedQuantitiesToAFewDigits) {
  EXPECT_EQ(base::FormatApprox(14094.827586206897), "14095");
  EXPECT_EQ(base::FormatApprox(3.086419753086419e-7), "3.086e-7");
  EXPECT_EQ(base::FormatApprox(4.087499999999999e303), "4.087e303");
  EXPECT_EQ(base::FormatApprox(0.29), "0.29");
  EXPECT_EQ(base::FormatApprox(0.034641016151377546, 3), "0.0346");
}

TEST(Text, QuoteCutsAndEscapesUntrustedText) {
  EXPECT_EQ(base::Quote("ok"), "ok");
  EXPECT_EQ(base::Quote(std::string("a\nb\x01", 4)), "a\\nb\\x01");
  const std::string big(10'000'000, 'x');
  const std::string q = base::Quote(big, 16);
  EXPECT_EQ(q, "xxxxxxxxxxxxxxxx... (10000000 bytes)");
  EXPECT_EQ(base::StripBom("\xEF\xBB\xBFt_s"), "t_s");
}

TEST(SpscQueue, KeepsOrderRefusesWhenFullAndMovesOwnership) {
  base::SpscQueue<std::unique_ptr<int>> q(4);
  EXPECT_EQ(q.capacity(), 4u);
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(q.TryPush(std::make_unique<int>(i)));
  auto extra = std::make_unique<int>(99);
  EXPECT_FALSE(q.TryPush(std::move(extra)));
  ASSERT_TRUE(extra);  // a refused push leaves the item with the caller
  std::unique_ptr<int> out;
  for (int i = 0; i < 4; ++i) {
    ASSERT_TRUE(q.TryPop(out));
    EXPECT_EQ(*out, i);
  }
  EXPECT_FALSE(q.TryPop(out));
}

TEST(SpscQueue, TwoThreadsPassEveryItemInOrder) {
  base::SpscQueue<int> q(64);
  constexpr int kN = 200'000;
  std::thread producer([&] {
    for (int i = 0; i < kN;) {
      int v = i;
      if (q.TryPush(std::move(v))) ++i;
    }
  });
  int expected = 0;
  while (expected < kN) {
    int v = -1;
    if (q.TryPop(v)) {
      ASSERT_EQ(v, expected);
      ++expected;
    }
  }
  producer.join();
}

}  // namespace
}  // namespace vdyn

#include "vdyn/control.pb.h"
#include "vdyn/messages/checks.h"
#include "vdyn/state.pb.h"

namespace vdyn {
namespace {

TEST(Messages, EveryFieldIsCheckedNestedAndRepeated) {
  pb::VehicleState s;
  s.add_wheels()->set_fp(1.0);
  s.add_wheels()->mutable_f_w()->set_y(std::numeric_limits<double>::infinity());
  messages::Finding f = messages::CheckMessage(s);
  EXPECT_EQ(f.problem, messages::Problem::kNonFinite);
  EXPECT_EQ(f.field, "wheels[1].f_w.y");
  pb::ControlRequest r;
  r.set_client_id(std::string(64, 'c'));
  EXPECT_EQ(messages::CheckMessage(r).problem, messages::Problem::kNone);
  r.set_client_id(std::string(65, 'c'));
  f = messages::CheckMessage(r);
  EXPECT_EQ(f.problem, messages::Problem::kStringTooLong);
  EXPECT_EQ(f.field, "client_id");
  r.set_client_id("ok");
  r.mutable_teleport()->mutable_pose()->set_yaw(std::nan(""));
  f = messages::CheckMessage(r);
  EXPECT_EQ(f.problem, messages::Problem::kNonFinite);
  EXPECT_EQ(f.field, "teleport.pose.yaw");
  EXPECT_EQ(messages::MaxStringBytes("reason"), limits::kMaxReasonBytes);
  EXPECT_EQ(messages::MaxStringBytes("server_id"), limits::kMaxIdBytes);
  EXPECT_EQ(messages::MaxStringBytes("name"), limits::kMaxNameBytes);
}

}  // namespace
}  // namespace vdyn

// The bottom layer: the one hash against answers computed independently from its specification
// (docs/hash.md's Python reference, and FNV's published test vectors), the table of limits, and
// numbers as a person reads and writes them.
#include <sys/resource.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "vdyn/base/deadline.h"
#include "vdyn/base/file.h"
#include "vdyn/base/gearbox.h"
#include "vdyn/base/hash.h"
#include "vdyn/base/limits.h"
#include "vdyn/base/memory.h"
#include "vdyn/base/spsc_queue.h"
#include "vdyn/base/text.h"
#include "vdyn/base/time.h"
#include "vdyn/vehicle_params.pb.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;

// After KeepFreedMemory a large block freed and allocated again keeps its pages: no page faults
// the second time (glibc's default maps such a block afresh, or trims it off the heap, and the
// next one faults every page in again). The sanitizers' allocator ignores mallopt: skipped there.
TEST(Memory, AFreedLargeBlockComesBackWithoutFaultingItsPagesAgain) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "AddressSanitizer's allocator ignores mallopt";
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
  GTEST_SKIP() << "AddressSanitizer's allocator ignores mallopt";
#endif
#endif
  ASSERT_TRUE(base::KeepFreedMemory());
  constexpr std::size_t kBytes = std::size_t{8} << 20;
  auto faults = [] {
    rusage u{};
    getrusage(RUSAGE_THREAD, &u);
    return u.ru_minflt + u.ru_majflt;
  };
  auto touch_and_free = [&] {
    auto* p = static_cast<volatile char*>(std::malloc(kBytes));
    if (p == nullptr) return -1L;
    const long before = faults();
    for (std::size_t i = 0; i < kBytes; i += 4096) p[i] = 1;
    const long n = faults() - before;
    std::free(const_cast<char*>(p));
    return n;
  };
  const long first = touch_and_free();
  const long second = touch_and_free();
  EXPECT_GT(first, 0) << "the first block's pages were new";
  EXPECT_LT(second, 64) << "faults the second time, of " << kBytes / 4096 << " pages";
}

// A deadline from a timeout of any size: 1e10 s from now is past the int64 nanoseconds' end (the
// sum wrapped round into the past, and a Python call with timeout=1e10 failed at once: "no server
// answered"); it and every longer time never pass. Shorter ones pass when they are due.
TEST(Deadline, ATimeoutBeyondTheClocksRangeNeverPassesInsteadOfWrapping) {
  const base::MonoTime now = base::MonotonicNow();
  for (const double s : {1e10, 3e11, 1e300, std::numeric_limits<double>::infinity()}) {
    const base::Deadline d = base::Deadline::AfterSeconds(s, now);
    EXPECT_TRUE(d.never()) << s;
    EXPECT_FALSE(d.Passed(now + base::Seconds(1'000'000'000))) << s;
    EXPECT_GT(d.Left(now).seconds(), 1e9) << s;
  }
  EXPECT_TRUE(
      base::Deadline::After(base::Nanos{std::numeric_limits<std::int64_t>::max()}, now).never());
  const base::Deadline d = base::Deadline::AfterSeconds(2.5, now);
  EXPECT_FALSE(d.never());
  EXPECT_FALSE(d.Passed(now + base::Milliseconds(2499)));
  EXPECT_TRUE(d.Passed(now + base::Milliseconds(2500)));
  EXPECT_EQ(d.Left(now + base::Seconds(1)).ns, 1'500'000'000);
  EXPECT_EQ(d.Left(now + base::Seconds(9)).ns, 0);
  for (const double s : {0.0, -1.0, std::nan("")}) {
    EXPECT_TRUE(base::Deadline::AfterSeconds(s, now).Passed(now)) << s;
  }
}

// PollUntil: looks once more after its last wait (what arrived in the last slice counts), waits
// at most the time left, and ends false when the deadline passes.
TEST(Deadline, PollUntilLooksAfterItsLastWaitAndNeverWaitsPastTheDeadline) {
  int looks = 0;
  std::vector<base::Nanos> waits;
  const base::Deadline d = base::Deadline::After(base::Milliseconds(30));
  const bool got = base::PollUntil(
      d, base::Milliseconds(20), [&] { return ++looks == 3; },
      [&](base::Nanos slice) {
        waits.push_back(slice);
        std::this_thread::sleep_for(base::Chrono(slice));
      });
  // Two waits: 20 ms, then at most the 10 ms left; the third look, after the second wait, succeeds
  // (or the deadline passed first on a machine too loaded to wake within 30 ms).
  ASSERT_GE(waits.size(), 1u);
  EXPECT_EQ(waits[0].ns, 20'000'000);
  for (const base::Nanos w : waits) EXPECT_LE(w.ns, 20'000'000);
  if (waits.size() == 2) {
    EXPECT_TRUE(got);
    EXPECT_EQ(looks, 3);
  }
  looks = 0;
  EXPECT_FALSE(base::PollUntil(
      base::Deadline::After(base::Milliseconds(5)), base::Milliseconds(1),
      [&] { return ++looks < 0; },
      [](base::Nanos slice) { std::this_thread::sleep_for(base::Chrono(slice)); }));
  EXPECT_GE(looks, 2);
}

// The gearbox's ratios against their closed form (docs/model.md, section 8): geometric from the
// first to the top gear, each step the same ratio, the top gear exactly as given.
TEST(Gearbox, RatiosRunInGeometricProgressionFromFirstToTop) {
  const double first = 3.5, top = 0.8;
  const int n = 6;
  const double q = std::pow(top / first, 1.0 / 5.0);
  EXPECT_DOUBLE_EQ(base::GearRatioStep(first, top, n), q);
  EXPECT_DOUBLE_EQ(base::ForwardGearRatio(first, top, n, 1), 3.5);
  EXPECT_DOUBLE_EQ(base::ForwardGearRatio(first, top, n, 3), 3.5 * q * q);
  EXPECT_EQ(base::ForwardGearRatio(first, top, n, 6), 0.8);
  for (int g = 2; g <= n; ++g) {
    EXPECT_NEAR(
        base::ForwardGearRatio(first, top, n, g) / base::ForwardGearRatio(first, top, n, g - 1), q,
        1e-12);
  }
  EXPECT_EQ(base::GearRatioStep(first, top, 1), 1.0);
  EXPECT_EQ(base::ForwardGearRatio(first, top, 1, 1), top);
}

// A time typed as decimal seconds names a nanosecond exactly: every one of these, written with
// nine decimals and read back as a command line reads it (strtod), is that nanosecond; a cast that
// truncates gets about one in forty-five of them (2,211 of these 100,000) a nanosecond early.
TEST(Time, DecimalSecondsComeBackAsTheNanosecondWritten) {
  std::uint64_t x = 0x9e3779b97f4a7c15ull;
  int truncated_wrong = 0;
  for (int i = 0; i < 100000; ++i) {
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    const std::int64_t ns = static_cast<std::int64_t>(x % 100'000'000'000'000ull);  // < 28 h
    char text[40];
    std::snprintf(text, sizeof text, "%lld.%09lld", static_cast<long long>(ns / 1'000'000'000),
                  static_cast<long long>(ns % 1'000'000'000));
    const double s = std::strtod(text, nullptr);
    ASSERT_EQ(base::FromSeconds(s).ns, ns) << text;
    if (static_cast<std::int64_t>(s * 1e9) != ns) ++truncated_wrong;
  }
  EXPECT_GT(truncated_wrong, 1000);  // the bug this guards against is real for these values
  EXPECT_EQ(base::FromSeconds(0.0).ns, 0);
  EXPECT_EQ(base::FromSeconds(1.5).ns, 1'500'000'000);
}

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

// docs/formats.md's table of every vehicle parameter ("### Every field"): field -> (words, range).
std::map<std::string, std::pair<std::string, std::string>> DocumentedParams() {
  std::ifstream in(std::string(VDYN_SOURCE_DIR) + "/docs/formats.md");
  std::map<std::string, std::pair<std::string, std::string>> rows;
  bool in_section = false;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("### Every field", 0) == 0) in_section = true;
    if (!in_section) continue;
    if (line.rfind("## ", 0) == 0) break;
    if (line.rfind("| `", 0) != 0) continue;
    std::vector<std::string> cells;
    std::stringstream ss(line.substr(1));
    for (std::string c; std::getline(ss, c, '|');) {
      const auto b = c.find_first_not_of(' '), e = c.find_last_not_of(' ');
      cells.push_back(b == std::string::npos ? "" : c.substr(b, e - b + 1));
    }
    if (cells.size() < 3) continue;
    rows[cells[0].substr(1, cells[0].size() - 2)] = {cells[1], cells[2]};
  }
  return rows;
}

TEST(Limits, EveryVehicleParameterIsNamedInWordsAndTheDocumentationSaysTheSame) {
  const auto doc = DocumentedParams();
  ASSERT_FALSE(doc.empty()) << "no table of the parameters in docs/formats.md";
  namespace gp = google::protobuf;
  std::size_t expected = 0;
  auto check = [&](const std::string& row, const std::string& path, const gp::FieldDescriptor* f) {
    SCOPED_TRACE(row);
    ++expected;
    const std::string_view words = limits::ParamWords(path);
    ASSERT_FALSE(words.empty()) << "the table of limits does not name " << path;
    ASSERT_EQ(doc.count(row), 1u) << "docs/formats.md does not list " << row;
    EXPECT_EQ(doc.at(row).first, words);
    if (f->type() == gp::FieldDescriptor::TYPE_BOOL) {
      EXPECT_EQ(doc.at(row).second, "`true`, `false`");  // a switch, not a number
    } else if (const limits::Range* r = limits::ParamRange(path)) {
      EXPECT_EQ(doc.at(row).second, limits::Describe(*r));
    } else if (f->enum_type() != nullptr) {
      std::string choices;
      for (int i = 1; i < f->enum_type()->value_count(); ++i) {
        choices += (i > 1 ? ", `" : "`") + f->enum_type()->value(i)->name() + "`";
      }
      EXPECT_EQ(doc.at(row).second, choices);
    }
  };
  const gp::Descriptor* d = pb::VehicleParams::descriptor();
  for (int i = 0; i < d->field_count(); ++i)
    check(d->field(i)->name(), d->field(i)->name(), d->field(i));
  const gp::Descriptor* w = pb::WheelParams::descriptor();
  for (int i = 0; i < w->field_count(); ++i) {
    check("<wheel>." + w->field(i)->name(), "rr." + w->field(i)->name(), w->field(i));
  }
  EXPECT_EQ(doc.size(), expected) << "docs/formats.md lists fields the message does not have";
  // The words say what a field is and its unit, not its name.
  EXPECT_EQ(limits::ParamWords("b"), "distance T to front axle, m");
  EXPECT_EQ(limits::ParamWords("lf.radius"), "wheel radius, m");
  EXPECT_EQ(limits::ParamWords("wings"), "");
}

// A file is read whole up to its bound and refused past it, also one that cannot be sized
// beforehand (a device, a pipe: /dev/zero never ends).
TEST(File, ReadsAWholeFileWithinItsBoundAndRefusesOneBeyondIt) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("vdyn-file-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string text(100000, 'x');  // more than one block of the reader
  std::ofstream(dir / "f.txt", std::ios::binary) << text;
  const base::FileText whole = base::ReadFileBounded(dir / "f.txt", text.size(), "test file");
  EXPECT_EQ(whole.error, "");
  EXPECT_EQ(whole.text, text);
  const base::FileText over = base::ReadFileBounded(dir / "f.txt", text.size() - 1, "test file");
  EXPECT_EQ(over.error, "more than 99999 bytes, more than a test file may have");
  EXPECT_EQ(over.text, "");
  const base::FileText zero = base::ReadFileBounded("/dev/zero", 1 << 20, "test file");
  EXPECT_EQ(zero.error, "more than 1048576 bytes, more than a test file may have");
  const base::FileText none = base::ReadFileBounded(dir / "none.txt", 10, "test file");
  EXPECT_EQ(none.error, "cannot open the test file (No such file or directory)");
  std::filesystem::remove_all(dir);
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
  EXPECT_EQ(base::FormatNumber(2147483647), "2147483647");  // shorter than 2.147483647e9
  EXPECT_EQ(base::FormatNumber(-12345678), "-12345678");
  EXPECT_EQ(base::FormatNumber(1e7), "1e7");
}

TEST(Text, ComputedQuantitiesToAFewDigits) {
  EXPECT_EQ(base::FormatApprox(14094.827586206897), "14095");
  EXPECT_EQ(base::FormatApprox(3.086419753086419e-7), "3.086e-7");
  EXPECT_EQ(base::FormatApprox(4.087499999999999e303), "4.087e303");
  EXPECT_EQ(base::FormatApprox(0.29), "0.29");
  EXPECT_EQ(base::FormatApprox(0.034641016151377546, 3), "0.0346");
}

// A display's reading: a value that rounds to zero from below is "0.0", never "-0.0".
TEST(Text, FixedReadingsNeverShowMinusZero) {
  EXPECT_EQ(base::FormatFixed(-0.04, 1), "0.0");
  EXPECT_EQ(base::FormatFixed(-0.0, 1), "0.0");
  EXPECT_EQ(base::FormatFixed(-0.4, 0), "0");
  EXPECT_EQ(base::FormatFixed(-0.04, 1, true), "+0.0");
  EXPECT_EQ(base::FormatFixed(-0.06, 1), "-0.1");
  EXPECT_EQ(base::FormatFixed(-70.0, 1), "-70.0");
  EXPECT_EQ(base::FormatFixed(2.5, 2, true), "+2.50");
  EXPECT_EQ(base::FormatFixed(0.0, 1, true), "+0.0");
}

// Hashes and CRCs quoted one way: "0x", zero-padded to the width asked, every digit kept.
TEST(Text, HexadecimalIsPaddedToItsWidthAndNeverCut) {
  EXPECT_EQ(base::FormatHex(0xbeef, 8), "0x0000beef");
  EXPECT_EQ(base::FormatHex(0x0f, 2), "0x0f");
  EXPECT_EQ(base::FormatHex(0xcbf29ce484222325ull, 16), "0xcbf29ce484222325");
  EXPECT_EQ(base::FormatHex(1, 16), "0x0000000000000001");
  EXPECT_EQ(base::FormatHex(0x1234, 2), "0x1234");  // wider than asked: all of it
  EXPECT_EQ(base::FormatHex(~0ull, 99), "0xffffffffffffffff");
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
#include "vdyn/messages/control_reply.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/world.pb.h"

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

// A reply (the server's and the recorder's player's, one form) answers its request by its ids and
// is one every receiver takes: an id or a reason too long for a reply is cut to its limit, never
// sent as a reply that the client's reader drops (CheckMessage).
TEST(Messages, AControlReplyEchoesItsRequestAndPassesTheReceiversChecks) {
  pb::ControlRequest r;
  r.set_request_id(41);
  r.set_vehicle_id(7);
  r.set_client_id(std::string(200, 'c'));
  pb::ControlReply reply = messages::ReplyTo(&r, "vdyn");
  EXPECT_EQ(reply.request_id(), 41u);
  EXPECT_EQ(reply.vehicle_id(), 7u);
  EXPECT_EQ(reply.server_id(), "vdyn");
  EXPECT_EQ(reply.client_id(), std::string(limits::kMaxIdBytes, 'c'));
  EXPECT_EQ(base::CutUtf8("a\xc2\xb0", 2), "a");  // not inside the character
  EXPECT_TRUE(reply.accepted());
  EXPECT_EQ(messages::CheckMessage(reply).problem, messages::Problem::kNone);
  messages::Refuse(reply, std::string(5000, 'x'));
  EXPECT_FALSE(reply.accepted());
  EXPECT_EQ(reply.reason().size(), limits::kMaxReasonBytes);
  EXPECT_TRUE(reply.reason().ends_with("x ..."));  // said to be cut
  // A cut inside a character (here each is 2 bytes, odd offset) would leave invalid UTF-8, which
  // a receiver's parse refuses: cut where one starts.
  std::string degrees;
  for (int i = 0; i < 1000; ++i) degrees += "\xc2\xb0";
  messages::Refuse(reply, "x" + degrees);
  EXPECT_LE(reply.reason().size(), limits::kMaxReasonBytes);
  std::string bytes;
  ASSERT_TRUE(reply.SerializeToString(&bytes));
  pb::ControlReply back;
  EXPECT_TRUE(back.ParseFromString(bytes));
  EXPECT_TRUE(back.reason().ends_with("\xc2\xb0 ..."));
  EXPECT_EQ(base::CutText("short", 10), "short");
  EXPECT_EQ(messages::CheckMessage(reply).problem, messages::Problem::kNone)
      << messages::CheckMessage(reply).field;
  EXPECT_EQ(messages::ReplyTo(nullptr, "vdyn").client_id(), "");  // to no request
}

// The check on the serialised bytes agrees with the reflective one: clean means clean, and
// anything to report is left to CheckMessage (which names the field).
TEST(Messages, TheWireCheckPassesCleanMessagesAndLeavesEveryProblemToTheReflectiveOne) {
  auto bytes = [](const google::protobuf::Message& m) {
    const std::string s = m.SerializeAsString();
    return std::vector<std::uint8_t>(s.begin(), s.end());
  };
  auto clean = [&](const google::protobuf::Message& m) {
    const auto b = bytes(m);
    return messages::WireClean(*m.GetDescriptor(), b);
  };
  pb::VehicleState s;
  s.set_vehicle_id(3);
  s.set_step(12345);
  for (int i = 0; i < 4; ++i) {
    pb::WheelState* w = s.add_wheels();
    w->set_fp(1000.0 + i);
    w->mutable_f_w()->set_y(-2.5 * i);
  }
  s.mutable_input()->set_source_id(std::string(limits::kMaxIdBytes, 'x'));
  EXPECT_TRUE(clean(s));
  s.mutable_wheels(2)->mutable_f_w()->set_y(std::nan(""));
  EXPECT_FALSE(clean(s));
  EXPECT_EQ(messages::CheckMessage(s).field, "wheels[2].f_w.y");
  s.mutable_wheels(2)->mutable_f_w()->set_y(0.5);
  s.mutable_input()->set_source_id(std::string(limits::kMaxIdBytes + 1, 'x'));
  EXPECT_FALSE(clean(s));
  s.mutable_input()->set_source_id("rig");
  EXPECT_TRUE(clean(s));
  // A field numbered 16 and above has a two-byte tag.
  s.mutable_f_wall_w()->set_z(std::numeric_limits<double>::infinity());
  EXPECT_FALSE(clean(s));
  EXPECT_EQ(messages::CheckMessage(s).field, "f_wall_w.z");
  s.mutable_f_wall_w()->set_z(-1.0);
  EXPECT_TRUE(clean(s));
  // Cut anywhere inside, the bytes are not a message: not sure.
  const auto whole = bytes(s);
  for (std::size_t cut = 1; cut < whole.size(); ++cut) {
    pb::VehicleState cut_state;
    const std::vector<std::uint8_t> head(whole.begin(), whole.begin() + static_cast<long>(cut));
    if (!cut_state.ParseFromArray(head.data(), static_cast<int>(head.size()))) {
      EXPECT_FALSE(messages::WireClean(*pb::VehicleState::descriptor(), head)) << cut;
    }
  }
  // A group (wire type 3) is not proto3: not sure.
  std::vector<std::uint8_t> group = whole;
  group.push_back((2 << 3) | 3);
  EXPECT_FALSE(messages::WireClean(*pb::VehicleState::descriptor(), group));

  // Packed repeated doubles: every value is looked at.
  pb::Mesh mesh;
  for (int i = 0; i < 300; ++i) mesh.add_vertices(0.25 * i);
  EXPECT_TRUE(clean(mesh));
  mesh.set_vertices(299, -std::numeric_limits<double>::infinity());
  EXPECT_FALSE(clean(mesh));
  EXPECT_EQ(messages::CheckMessage(mesh).field, "vertices[299]");
  // Unpacked occurrences of a repeated double (a parser accepts both).
  std::vector<std::uint8_t> unpacked;
  for (double v : {1.0, std::nan("")}) {
    unpacked.push_back((3 << 3) | 1);
    std::uint64_t u;
    std::memcpy(&u, &v, 8);
    for (int k = 0; k < 8; ++k) unpacked.push_back(static_cast<std::uint8_t>(u >> (8 * k)));
  }
  EXPECT_FALSE(messages::WireClean(*pb::Mesh::descriptor(), unpacked));

  // A bad value that a later occurrence of the field replaces: not sure on the wire, clean once
  // parsed, and DecodeEnvelope takes it.
  pb::VehicleState bad;
  bad.set_steering_torque(std::nan(""));
  pb::VehicleState good;
  good.set_steering_torque(2.0);
  std::vector<std::uint8_t> both = bytes(bad);
  const auto tail = bytes(good);
  both.insert(both.end(), tail.begin(), tail.end());
  EXPECT_FALSE(messages::WireClean(*pb::VehicleState::descriptor(), both));
  pb::VehicleState parsed;
  EXPECT_EQ(
      transport::DecodeEnvelope(transport::TopicId::kState, "vdyn.pb.VehicleState", both, parsed)
          .outcome,
      transport::Decoded::Outcome::kOk);
  EXPECT_EQ(parsed.steering_torque(), 2.0);
  // And one it does not replace is refused with the field's name.
  std::vector<std::uint8_t> nan_last = tail;
  const auto b = bytes(bad);
  nan_last.insert(nan_last.end(), b.begin(), b.end());
  const transport::Decoded d = transport::DecodeEnvelope(transport::TopicId::kState,
                                                         "vdyn.pb.VehicleState", nan_last, parsed);
  EXPECT_EQ(d.outcome, transport::Decoded::Outcome::kNonFinite);
  EXPECT_EQ(d.field, "steering_torque");
  // Not protobuf: not sure.
  const std::vector<std::uint8_t> junk = {0xff, 0xff, 0xff};
  EXPECT_FALSE(messages::WireClean(*pb::VehicleState::descriptor(), junk));
}

}  // namespace
}  // namespace vdyn

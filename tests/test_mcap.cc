// The recorder's MCAP files without the network: the layout the spec prescribes (magic, header,
// data end, summary, footer), every message back in order, compression, the schema as a
// FileDescriptorSet that decodes a payload by itself, and bad files - truncated at every kind of
// place, corrupted, empty, foreign - refused with the file, offset and reason; recover salvages.
#include <fcntl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/un.h>
#include <unistd.h>

#include <cstring>
#include <fstream>
#include <functional>
#include <random>
#include <set>
#include <sstream>
#include <thread>

#include <gmock/gmock.h>
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/dynamic_message.h>
#include <gtest/gtest.h>

#include "test_support.h"
#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/mcap.h"
#include "vdyn/recorder/output_file.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/session.pb.h"
#include "vdyn/state.pb.h"

namespace vdyn {
namespace {

using recorder::FileDescriptorSetOf;
using ::testing::HasSubstr;
namespace mc = mcap;

std::vector<std::uint8_t> ReadBytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}
void WriteBytes(const std::filesystem::path& p, const std::vector<std::uint8_t>& b) {
  std::ofstream out(p, std::ios::binary);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}
std::uint64_t Le64(const std::vector<std::uint8_t>& b, std::size_t at) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i)
    v |= static_cast<std::uint64_t>(b[at + static_cast<std::size_t>(i)]) << (8 * i);
  return v;
}

// Where a chunk record keeps its uncompressed size: opcode (1), length (8), message start and
// end times (8 + 8), then the size (8), little-endian.
std::size_t UncompressedSizeAt(const mc::ChunkIndex& chunk) {
  return chunk.chunk_start_offset + 1 + 8 + 16;
}
void PutLe64(std::vector<std::uint8_t>& b, std::size_t at, std::uint64_t v) {
  for (int i = 0; i < 8; ++i)
    b[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (8 * i));
}

pb::VehicleState StateAt(std::uint64_t step) {
  pb::VehicleState s;
  s.set_vehicle_id(1);
  s.set_server_id("test");
  s.set_step(step);
  s.set_step_ns(1'000'000);
  s.mutable_p_wt_w()->set_x(0.001 * static_cast<double>(step));
  s.mutable_p_wt_w()->set_y(std::sin(0.01 * static_cast<double>(step)));
  s.set_speed_kmh(3.6 * 0.001 * static_cast<double>(step));
  s.set_state_hash(0x9e3779b97f4a7c15ull * (step + 1));
  for (int w = 0; w < 4; ++w)
    s.add_wheels()->set_fp(3000.0 + w + 0.5 * static_cast<double>(step % 17));
  return s;
}

struct Written {
  std::vector<std::string> payloads;
  std::vector<std::uint64_t> times;
};

// The states of the small recordings the damage tests damage byte by byte (McapRecover): in chunks
// of 512 bytes: at least eight chunks.
constexpr int kSmallStates = 40;
constexpr std::size_t kSmallChunkBytes = 512;

// A file of `n` state messages at 1 kHz of log time, written with the given compression (and
// chunk CRCs unless `chunk_crc` is false).
// `small_schema`: a placeholder of a few bytes for the FileDescriptorSet (7 KB), for tests that
// go through a file byte by byte.
Written WriteStates(const std::filesystem::path& path, int n, mc::Compression c,
                    std::size_t chunk_bytes = 64 * 1024, bool chunk_crc = true,
                    bool small_schema = false) {
  mc::WriterOptions o;
  o.compression = c;
  o.chunk_bytes = chunk_bytes;
  mc::Writer w(path, o);
  w.SetChunkCrc(chunk_crc);
  const auto* d = pb::VehicleState::descriptor();
  const std::uint16_t schema =
      w.AddSchema(d->full_name(), "protobuf", small_schema ? "fds" : FileDescriptorSetOf(d));
  const std::uint16_t ch = w.AddChannel(schema, "vdyn/state/1", "protobuf",
                                        recorder::ChannelMetadata(transport::TopicId::kState, 1));
  w.WriteMetadata("vdyn.recording", {{"format", recorder::kFormatVersion}, {"domain", "7"}});
  Written out;
  for (int i = 0; i < n; ++i) {
    const std::string bytes = StateAt(static_cast<std::uint64_t>(i)).SerializeAsString();
    const std::uint64_t t =
        1'700'000'000'000'000'000ull + static_cast<std::uint64_t>(i) * 1'000'000;
    w.WriteMessage(ch, static_cast<std::uint32_t>(i), t, t - 50'000,
                   {reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()});
    out.payloads.push_back(bytes);
    out.times.push_back(t);
  }
  w.Close();
  return out;
}

std::vector<std::string> ReadAll(const std::filesystem::path& path,
                                 mc::ScanResult* result = nullptr, bool lenient = false) {
  mc::Reader r(path);
  std::vector<std::string> got;
  mc::Visitor v;
  v.on_message = [&](const mc::Message& m, std::uint64_t) {
    got.emplace_back(reinterpret_cast<const char*>(m.data.data()), m.data.size());
  };
  const mc::ScanResult res = r.Scan(v, lenient);
  if (result != nullptr) *result = res;
  return got;
}

class Mcap : public ::testing::TestWithParam<mc::Compression> {
 protected:
  testing::TempDir dir_;
};

TEST_P(Mcap, EveryMessageComesBackInOrderWithItsTimesAndTheSummaryCountsThem) {
  const auto path = dir_ / "a.mcap";
  const Written w = WriteStates(path, 5000, GetParam());
  mc::ScanResult res;
  std::vector<std::uint64_t> log_times, publish_times;
  mc::Reader r(path);
  std::vector<std::string> got;
  mc::Visitor v;
  v.on_message = [&](const mc::Message& m, std::uint64_t) {
    got.emplace_back(reinterpret_cast<const char*>(m.data.data()), m.data.size());
    log_times.push_back(m.log_time);
    publish_times.push_back(m.publish_time);
  };
  res = r.Scan(v);
  EXPECT_TRUE(res.complete);
  ASSERT_EQ(got, w.payloads);
  EXPECT_EQ(log_times, w.times);
  for (std::size_t i = 0; i < w.times.size(); ++i) ASSERT_EQ(publish_times[i], w.times[i] - 50'000);
  ASSERT_TRUE(res.statistics.has_value());
  EXPECT_EQ(res.statistics->message_count, 5000u);
  EXPECT_EQ(res.statistics->message_start_time, w.times.front());
  EXPECT_EQ(res.statistics->message_end_time, w.times.back());
  EXPECT_EQ(res.statistics->channel_message_counts.at(1), 5000u);
  EXPECT_GT(res.chunks, 5u);  // small chunks
  const auto summary = r.ReadSummary();
  ASSERT_TRUE(summary.has_value());
  EXPECT_EQ(summary->chunk_indexes.size(), res.chunks);
  ASSERT_EQ(summary->channels.size(), 1u);
  EXPECT_EQ(summary->channels[0].topic, "vdyn/state/1");
  EXPECT_EQ(summary->channels[0].message_encoding, "protobuf");
  for (const mc::ChunkIndex& ci : summary->chunk_indexes) {
    EXPECT_EQ(ci.compression, std::string(mc::CompressionName(GetParam())));
  }
  // Random access: each chunk alone gives its messages.
  std::size_t n = 0;
  std::vector<std::uint8_t> scratch;
  for (const mc::ChunkIndex& ci : r.Chunks()) {
    r.ReadChunk(
        ci,
        [&](const mc::Message& m) {
          ASSERT_LT(n, w.payloads.size());
          EXPECT_EQ(std::string(reinterpret_cast<const char*>(m.data.data()), m.data.size()),
                    w.payloads[n++]);
        },
        scratch);
  }
  EXPECT_EQ(n, w.payloads.size());
}

INSTANTIATE_TEST_SUITE_P(Compression, Mcap,
                         ::testing::Values(mc::Compression::kZstd, mc::Compression::kLz4,
                                           mc::Compression::kNone));

TEST(McapLayout, FollowsTheSpecFromMagicToFooter) {
  testing::TempDir dir;
  const auto path = dir / "a.mcap";
  WriteStates(path, 300, mc::Compression::kZstd);
  const std::vector<std::uint8_t> b = ReadBytes(path);
  const std::uint8_t magic[8] = {0x89, 'M', 'C', 'A', 'P', 0x30, '\r', '\n'};
  ASSERT_GT(b.size(), 64u);
  EXPECT_TRUE(std::equal(magic, magic + 8, b.begin()));
  EXPECT_TRUE(std::equal(magic, magic + 8, b.end() - 8));
  EXPECT_EQ(b[8], 0x01);  // the header record comes first
  // Footer: opcode 0x02, length 20, then summary_start, summary_offset_start, summary_crc.
  const std::size_t footer = b.size() - 8 - 29;
  EXPECT_EQ(b[footer], 0x02);
  EXPECT_EQ(Le64(b, footer + 1), 20u);
  const std::uint64_t summary_start = Le64(b, footer + 9);
  const std::uint64_t summary_offset_start = Le64(b, footer + 17);
  ASSERT_GT(summary_start, 8u);
  ASSERT_LT(summary_start, summary_offset_start);
  // Just before the summary: the data end record (opcode 0x0f, 4 bytes of CRC of all before it).
  EXPECT_EQ(b[summary_start - 13], 0x0f);
  EXPECT_EQ(Le64(b, summary_start - 12), 4u);
  // Walk the whole file as opcode + length records: they tile it exactly.
  std::size_t pos = 8;
  std::set<int> ops;
  while (pos < b.size() - 8) {
    ops.insert(b[pos]);
    pos += 9 + Le64(b, pos + 1);
  }
  EXPECT_EQ(pos, b.size() - 8);
  // Header, schema, channel, chunk, message index, chunk index, statistics, metadata (+ index),
  // summary offset, data end, footer.
  for (int op : {0x01, 0x02, 0x03, 0x04, 0x06, 0x07, 0x08, 0x0b, 0x0c, 0x0d, 0x0e, 0x0f}) {
    EXPECT_EQ(ops.count(op), 1u) << "no record of opcode " << op;
  }
  EXPECT_EQ(ops.count(0x05), 0u);  // every message is inside a chunk
}

// The summary's statistics must describe the data section: `info` and `verify` passed a file whose
// statistics said 999999 messages (its summary CRC written anew, or zero), while a reader that
// trusts the summary (Foxglove seeks by it) shows another file.
TEST(McapBadFiles, StatisticsThatDoNotCountTheDataSectionAreRefused) {
  testing::TempDir dir;
  const auto path = dir / "a.mcap";
  WriteStates(path, 300, mc::Compression::kNone);
  const std::vector<std::uint8_t> b = ReadBytes(path);
  const std::size_t footer = b.size() - 8 - 29;
  const std::uint64_t summary_start = Le64(b, footer + 9);
  std::size_t stats = 0;
  for (std::size_t pos = summary_start; pos < footer; pos += 9 + Le64(b, pos + 1)) {
    if (b[pos] == 0x0b) stats = pos;
  }
  ASSERT_NE(stats, 0u);
  struct Edit {
    std::size_t at;  // in the statistics record's content
    const char* says;
  };
  // message_count at 0; channel 1's count after the fixed fields (8 + 2 + 4 * 4 + 8 + 8), the
  // map's byte length (4) and the channel id (2).
  for (const Edit e : {Edit{0, "the statistics count 999999 messages; the data section holds 300"},
                       Edit{48, "the statistics count 999999 messages on channel 1; the data "
                                "section holds 300"}}) {
    std::vector<std::uint8_t> bad = b;
    PutLe64(bad, stats + 9 + e.at, 999999);
    std::fill_n(bad.begin() + static_cast<std::ptrdiff_t>(footer + 25), 4, 0);  // summary_crc 0
    WriteBytes(dir / "bad.mcap", bad);
    try {
      ReadAll(dir / "bad.mcap");
      ADD_FAILURE() << e.says;
    } catch (const mc::McapError& err) {
      EXPECT_THAT(err.what(), HasSubstr(e.says));
      EXPECT_THAT(err.what(), HasSubstr("(in the summary)"));
    }
  }
  EXPECT_EQ(ReadAll(path).size(), 300u);  // the file as written reads
}

TEST(McapSchema, TheFileDescriptorSetAloneDecodesAPayload) {
  const std::string fds = FileDescriptorSetOf(pb::VehicleState::descriptor());
  google::protobuf::FileDescriptorSet set;
  ASSERT_TRUE(set.ParseFromString(fds));
  std::vector<std::string> files;
  for (const auto& f : set.file()) files.push_back(f.name());
  // The file and its imports (state.proto imports common, input and vehicle_params), each after
  // what it imports.
  EXPECT_THAT(files, ::testing::ElementsAre("vdyn/common.proto", "vdyn/input.proto",
                                            "vdyn/vehicle_params.proto", "vdyn/state.proto"));
  // A pool built from the set alone (not the compiled-in descriptors) parses a payload.
  google::protobuf::DescriptorPool pool;
  for (const auto& f : set.file()) ASSERT_NE(pool.BuildFile(f), nullptr) << f.name();
  const auto* d = pool.FindMessageTypeByName("vdyn.pb.VehicleState");
  ASSERT_NE(d, nullptr);
  google::protobuf::DynamicMessageFactory factory(&pool);
  std::unique_ptr<google::protobuf::Message> m(factory.GetPrototype(d)->New());
  ASSERT_TRUE(m->ParseFromString(StateAt(1234).SerializeAsString()));
  EXPECT_EQ(m->GetReflection()->GetUInt64(*m, d->FindFieldByName("step")), 1234u);
  const auto& p = m->GetReflection()->GetMessage(*m, d->FindFieldByName("p_wt_w"));
  EXPECT_EQ(p.GetReflection()->GetDouble(p, p.GetDescriptor()->FindFieldByName("x")), 1.234);
}

TEST(McapWire, TopLevelFieldsWithoutParsing) {
  const std::string bytes = StateAt(987654).SerializeAsString();
  const std::span<const std::uint8_t> p(reinterpret_cast<const std::uint8_t*>(bytes.data()),
                                        bytes.size());
  EXPECT_EQ(recorder::wire::Number(p, 3), 987654u);                          // step, a varint
  EXPECT_EQ(recorder::wire::Number(p, 21), 0x9e3779b97f4a7c15ull * 987655);  // state_hash, fixed64
  EXPECT_EQ(recorder::wire::Bytes(p, 2), "test");
  EXPECT_FALSE(recorder::wire::Number(p, 99).has_value());
  const std::span<const std::uint8_t> cut = p.first(p.size() - 3);
  EXPECT_FALSE(recorder::wire::ForEachField(cut, [](const auto&) { return true; }));
  const std::uint8_t bad[] = {0x0f, 0x01};  // wire type 7 does not exist
  EXPECT_FALSE(recorder::wire::ForEachField(bad, [](const auto&) { return true; }));
}

// Written the other way: states appended as elements of VehicleStates (field 1) parse back
// with protobuf as the same states, and the sizes foretold are the sizes written.
TEST(McapWire, StatesAppendedAsFieldsParseAsVehicleStates) {
  std::vector<std::uint8_t> out;
  std::size_t foretold = 0;
  std::vector<std::string> states;
  for (std::uint64_t step : {1ull, 300ull, 70000ull}) {
    pb::VehicleState s = StateAt(step);
    for (std::uint64_t k = 0; k < step / 10; ++k) s.add_wheels()->set_fp(1.0 * k);  // longer ones
    states.push_back(s.SerializeAsString());
    const auto& b = states.back();
    foretold += recorder::wire::BytesFieldSize(1, b.size());
    recorder::wire::AppendBytesField(out, 1,
                                     {reinterpret_cast<const std::uint8_t*>(b.data()), b.size()});
  }
  EXPECT_EQ(out.size(), foretold);
  EXPECT_GT(states.back().size(), 16384u);  // a three-byte length
  pb::VehicleStates batch;
  ASSERT_TRUE(batch.ParseFromArray(out.data(), static_cast<int>(out.size())));
  ASSERT_EQ(batch.states_size(), 3);
  for (int i = 0; i < 3; ++i)
    EXPECT_EQ(batch.states(i).SerializeAsString(), states[static_cast<std::size_t>(i)]);
  EXPECT_EQ(recorder::wire::BytesFieldSize(1, 127), 129u);
  EXPECT_EQ(recorder::wire::BytesFieldSize(1, 128), 131u);
  EXPECT_EQ(recorder::wire::BytesFieldSize(16, 0), 3u);  // field 16: a two-byte tag
}

// --- bad files ---------------------------------------------------------------------------------

TEST(McapBadFiles, EmptyForeignAndMissingFilesAreRefusedWithTheReason) {
  testing::TempDir dir;
  testing::WriteFile(dir / "empty.mcap", "");
  testing::WriteFile(dir / "notes.mcap", "t_s,steer_deg\n0,0\n");
  try {
    mc::Reader r(dir / "empty.mcap");
    FAIL() << "an empty file was accepted";
  } catch (const mc::McapError& e) {
    EXPECT_EQ(e.offset(), 0u);
    EXPECT_THAT(e.what(), HasSubstr("empty.mcap: offset 0: empty file"));
  }
  try {
    mc::Reader r(dir / "notes.mcap");
    FAIL() << "a CSV file was accepted";
  } catch (const mc::McapError& e) {
    EXPECT_EQ(e.offset(), 0u);
    EXPECT_THAT(e.what(), HasSubstr("not an MCAP file: it starts with bytes 74 5f 73 2c"));
  }
  EXPECT_THROW(mc::Reader(dir / "missing.mcap"), mc::McapError);
  EXPECT_THROW(mc::Reader(dir.path()), mc::McapError);
}

TEST(McapBadFiles, ATruncatedFileIsRefusedAtTheOffsetWhereItEndsAndRecoverKeepsEveryWholeChunk) {
  testing::TempDir dir;
  const auto path = dir / "a.mcap";
  const Written w = WriteStates(path, 4000, mc::Compression::kZstd, 16 * 1024);
  const std::vector<std::uint8_t> whole = ReadBytes(path);
  const mc::ChunkIndex first_chunk = mc::Reader(path).Chunks().at(0);
  const std::size_t first_chunk_end = first_chunk.chunk_start_offset + first_chunk.chunk_length;
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 40; ++trial) {
    // Cuts everywhere: inside the magic, a record header, a chunk, the summary, the footer.
    std::size_t cut =
        trial < 6 ? std::vector<std::size_t>{3,
                                             12,
                                             30,
                                             whole.size() - 4,
                                             whole.size() - 30,
                                             whole.size() / 2}[static_cast<std::size_t>(trial)]
                  : 9 + rng() % (whole.size() - 10);
    std::vector<std::uint8_t> part(whole.begin(), whole.begin() + static_cast<std::ptrdiff_t>(cut));
    const auto cut_path = dir / ("cut" + std::to_string(trial) + ".mcap");
    WriteBytes(cut_path, part);
    try {
      ReadAll(cut_path);
      FAIL() << "a file cut at " << cut << " of " << whole.size() << " bytes was accepted";
    } catch (const mc::McapError& e) {
      EXPECT_LE(e.offset(), cut);
      EXPECT_THAT(e.reason(),
                  ::testing::AnyOf(HasSubstr("truncated"), HasSubstr("ends without a data end"),
                                   HasSubstr("ends inside the MCAP magic")))
          << e.what();
      // Past the magic, wherever the cut fell (a killed recorder's chunk half written too), the
      // reason says what to do.
      if (cut >= 8) {
        EXPECT_THAT(e.reason(), HasSubstr("`vdyn-recorder recover`")) << e.what();
      }
    }
    if (cut < 8) continue;
    // Recover: a closed, indexed file with a prefix of the messages, every one intact; before the
    // first chunk is whole there is no message to recover, said so, and no copy is written.
    std::ostringstream log;
    recorder::RecoverOptions ro;
    ro.file = cut_path;
    ro.out = dir / ("rec" + std::to_string(trial) + ".mcap");
    if (cut < first_chunk_end) {
      try {
        recorder::RunRecover(ro, log);
        ADD_FAILURE() << "a file cut at " << cut << " before its first chunk's end was recovered";
      } catch (const mc::McapError& e) {
        EXPECT_THAT(e.reason(), HasSubstr("nothing to recover")) << cut;
      }
      EXPECT_FALSE(std::filesystem::exists(ro.out)) << cut;
      continue;
    }
    ASSERT_EQ(recorder::RunRecover(ro, log), 0) << log.str();
    mc::ScanResult res;
    const std::vector<std::string> got = ReadAll(ro.out, &res);
    EXPECT_TRUE(res.complete);
    ASSERT_LE(got.size(), w.payloads.size());
    for (std::size_t i = 0; i < got.size(); ++i)
      ASSERT_EQ(got[i], w.payloads[i]) << "message " << i;
    // A cut in the data section loses at most the chunk it fell into (16 KiB of records,
    // about 180 messages); a cut after the data section loses nothing.
    EXPECT_GE(got.size() + 400,
              w.payloads.size() * std::min<std::size_t>(cut, whole.size()) / whole.size())
        << "cut at " << cut;
  }
}

// A damaged length in a closed file is not a truncation: said as corruption, with the record
// whose length it is (it was "truncated ... the recorder was stopped before it closed the file?"
// at an offset far from the damage).
TEST(McapBadFiles, ADamagedLengthInAClosedFileIsCorruptionNotATruncation) {
  testing::TempDir dir;
  const auto path = dir / "a.mcap";
  WriteStates(path, 3000, mc::Compression::kNone, 16 * 1024);
  const std::vector<mc::ChunkIndex> chunks = mc::Reader(path).Chunks();
  ASSERT_GT(chunks.size(), 4u);
  const std::vector<std::uint8_t> whole = ReadBytes(path);
  const std::uint64_t index = chunks[1].message_index_offsets.begin()->second;
  ASSERT_EQ(whole[index], 0x07);  // a message index record
  // Its own length far past the end: the record itself is named.
  std::vector<std::uint8_t> b = whole;
  b[index + 1 + 6] ^= 0x01;  // + 2^48 bytes
  WriteBytes(dir / "own.mcap", b);
  try {
    ReadAll(dir / "own.mcap");
    FAIL() << "accepted";
  } catch (const mc::McapError& e) {
    EXPECT_EQ(e.offset(), index);
    EXPECT_THAT(e.reason(), HasSubstr("corrupted: a message index record at offset " +
                                      std::to_string(index) +
                                      " claims more bytes than the data section holds"));
    EXPECT_THAT(e.reason(), ::testing::Not(HasSubstr("stopped before it closed")));
  }
  // A length that lands inside the file on bytes that are no record: the record before is named.
  b = whole;
  std::uint64_t len = 0;
  for (int i = 0; i < 8; ++i) len |= std::uint64_t{whole[index + 1 + i]} << (8 * i);
  const std::uint64_t to = chunks[3].chunk_start_offset + 9 + 40;  // inside a chunk's records
  const std::uint64_t bad = to - index - 9;
  for (int i = 0; i < 8; ++i) b[index + 1 + i] = static_cast<std::uint8_t>(bad >> (8 * i));
  ASSERT_NE(bad, len);
  WriteBytes(dir / "before.mcap", b);
  try {
    ReadAll(dir / "before.mcap");
    FAIL() << "accepted";
  } catch (const mc::McapError& e) {
    const std::string why = e.reason();
    if (why.find("do not read as a record") != std::string::npos) {
      EXPECT_THAT(why, HasSubstr("the record before, a message index at offset " +
                                 std::to_string(index)));
    } else {
      // The bytes there read as some record's header whose content does not: said so, never as
      // a truncation of a closed file.
      EXPECT_THAT(why, ::testing::Not(HasSubstr("stopped before it closed"))) << why;
    }
  }
}

TEST(McapBadFiles, AFlippedBitIsACrcMismatchAndRecoverDropsOnlyThatChunk) {
  testing::TempDir dir;
  const auto path = dir / "a.mcap";
  const Written w = WriteStates(path, 3000, mc::Compression::kNone, 16 * 1024);
  mc::Reader r(path);
  const std::vector<mc::ChunkIndex> chunks = r.Chunks();
  ASSERT_GT(chunks.size(), 4u);
  std::vector<std::uint8_t> b = ReadBytes(path);
  // One bit in the middle of the third chunk's records (uncompressed: a payload byte).
  const std::size_t at = chunks[2].chunk_start_offset + chunks[2].chunk_length / 2;
  b[at] ^= 0x10;
  WriteBytes(dir / "flipped.mcap", b);
  try {
    ReadAll(dir / "flipped.mcap");
    FAIL() << "a corrupted chunk was accepted";
  } catch (const mc::McapError& e) {
    EXPECT_EQ(e.offset(), chunks[2].chunk_start_offset);
    EXPECT_THAT(e.reason(), HasSubstr("chunk CRC mismatch"));
  }
  std::ostringstream log;
  recorder::RecoverOptions ro;
  ro.file = dir / "flipped.mcap";
  ASSERT_EQ(recorder::RunRecover(ro, log), 0);
  EXPECT_THAT(log.str(), HasSubstr("1 damaged chunk dropped"));
  EXPECT_THAT(log.str(), HasSubstr("messages (log time"));
  // The chunks it says the copy holds are those `info` counts in the copy.
  EXPECT_THAT(log.str(),
              HasSubstr(", written in " +
                        std::to_string(mc::Reader(dir / "flipped-recovered.mcap").Chunks().size()) +
                        " chunks"));
  mc::ScanResult res;
  const std::vector<std::string> got = ReadAll(dir / "flipped-recovered.mcap", &res);
  EXPECT_TRUE(res.complete);
  std::uint64_t in_chunk = 0;
  std::vector<std::uint8_t> scratch;
  r.ReadChunk(
      chunks[2], [&](const mc::Message&) { ++in_chunk; }, scratch);
  EXPECT_EQ(got.size(), w.payloads.size() - in_chunk);

  EXPECT_THAT(log.str(), HasSubstr("chunk CRC mismatch"));
  // A flipped bit in the summary: the footer's CRC catches it.
  std::vector<std::uint8_t> s = ReadBytes(path);
  const std::size_t footer = s.size() - 8 - 29;
  s[(Le64(s, footer + 9) + footer) / 2] ^= 0x01;
  WriteBytes(dir / "summary.mcap", s);
  try {
    ReadAll(dir / "summary.mcap");
    FAIL() << "a corrupted summary was accepted";
  } catch (const mc::McapError& e) {
    EXPECT_THAT(e.reason(), HasSubstr("CRC mismatch"));
  }
}

// A chunk whose size field claims far more than its records hold (a corrupted field, or a file
// made to exhaust a reader's memory) is refused with the sizes, and the reader never allocates
// what the chunk claims: its buffer follows what the decompressor yields.
TEST(McapBadFiles, AChunkThatClaimsMoreThanItHoldsIsRefusedWithoutAllocatingTheClaim) {
  testing::TempDir dir;
  constexpr std::uint64_t kClaim = 900ull << 20;  // under the reader's 1 GiB limit
  struct Case {
    mc::Compression compression;
    const char* name;
    const char* reason;
  };
  for (const Case& c : {Case{mc::Compression::kZstd, "zstd", "zstd: the frames hold"},
                        Case{mc::Compression::kLz4, "lz4", "lz4 gave"},
                        Case{mc::Compression::kNone, "none", "an uncompressed chunk of"}}) {
    SCOPED_TRACE(c.name);
    const auto path = dir / (std::string(c.name) + ".mcap");
    WriteStates(path, 2000, c.compression, 16 * 1024);
    const std::vector<mc::ChunkIndex> chunks = mc::Reader(path).Chunks();
    ASSERT_GT(chunks.size(), 2u);
    ASSERT_EQ(chunks[1].compression, c.compression == mc::Compression::kNone ? "" : c.name);
    std::vector<std::uint8_t> b = ReadBytes(path);
    ASSERT_EQ(Le64(b, UncompressedSizeAt(chunks[1])), chunks[1].uncompressed_size);
    PutLe64(b, UncompressedSizeAt(chunks[1]), kClaim);
    const auto bad = dir / (std::string(c.name) + "-claims.mcap");
    WriteBytes(bad, b);
    // The chunk's own read (what `export` and `verify` use through the chunk index).
    mc::Reader r(bad);
    std::vector<std::uint8_t> scratch;
    try {
      r.ReadChunk(
          chunks[1], [](const mc::Message&) {}, scratch);
      FAIL() << "a chunk claiming " << kClaim << " bytes was read";
    } catch (const mc::McapError& e) {
      EXPECT_EQ(e.offset(), chunks[1].chunk_start_offset);
      EXPECT_THAT(e.reason(), HasSubstr(c.reason));
      EXPECT_THAT(e.reason(), HasSubstr("claims " + std::to_string(kClaim)));
    }
    EXPECT_LT(scratch.capacity(), std::size_t{16} << 20)
        << "the reader allocated what the chunk claims";
    // A scan refuses the file at that chunk; a lenient one skips only it.
    try {
      ReadAll(bad);
      FAIL() << "a chunk claiming " << kClaim << " bytes was scanned";
    } catch (const mc::McapError& e) {
      EXPECT_EQ(e.offset(), chunks[1].chunk_start_offset);
    }
    mc::ScanResult res;
    ReadAll(bad, &res, /*lenient=*/true);
    EXPECT_EQ(res.chunks_skipped, 1u);
  }
  // Beyond the limit, refused before any decompression.
  std::vector<std::uint8_t> b = ReadBytes(dir / "zstd.mcap");
  const std::vector<mc::ChunkIndex> chunks = mc::Reader(dir / "zstd.mcap").Chunks();
  PutLe64(b, UncompressedSizeAt(chunks[0]), 3ull << 30);
  WriteBytes(dir / "huge.mcap", b);
  try {
    ReadAll(dir / "huge.mcap");
    FAIL() << "a chunk claiming 3 GiB was read";
  } catch (const mc::McapError& e) {
    EXPECT_THAT(e.reason(), HasSubstr("more than this reader accepts"));
  }
}

// --- outputs: never over an input, never in place
// ---------------------------------------------------

namespace fs = std::filesystem;

std::set<std::string> Names(const fs::path& dir) {
  std::set<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) out.insert(e.path().filename().string());
  return out;
}

// `export run.mcap --csv run.mcap` used to truncate the recording it was reading (a bus error and
// a file of 0 bytes). Every spelling of the same file is refused before anything is written.
TEST(RecorderOutputs, AnOutputThatIsAnInputIsRefusedWhateverItsSpelling) {
  testing::TempDir dir;
  const fs::path path = dir / "run.mcap";
  WriteStates(path, 2000, mc::Compression::kZstd);
  const std::vector<std::uint8_t> before = ReadBytes(path);
  fs::create_directories(dir / "sub");
  fs::create_symlink(path, dir / "link.mcap");
  fs::create_hard_link(path, dir / "hard.mcap");
  const std::vector<fs::path> spellings = {path,
                                           dir.path() / "." / "run.mcap",
                                           dir.path() / "sub" / ".." / "run.mcap",
                                           fs::relative(path),
                                           dir / "link.mcap",
                                           dir / "hard.mcap"};
  const std::set<std::string> names = Names(dir.path());
  for (const fs::path& same : spellings) {
    SCOPED_TRACE(same.string());
    std::ostringstream log;
    recorder::ExportOptions eo;
    eo.file = path;
    eo.csv = same;
    try {
      recorder::RunExport(eo, log);
      ADD_FAILURE() << "export wrote over its input";
    } catch (const recorder::OutputError& e) {
      EXPECT_THAT(e.what(), HasSubstr("is the input"));
      EXPECT_THAT(e.what(), HasSubstr("nothing was written"));
    }
    recorder::RecoverOptions ro;
    ro.file = same;
    ro.out = path;
    EXPECT_THROW(recorder::RunRecover(ro, log), recorder::OutputError);
    ro.file = path;
    ro.out = same;
    EXPECT_THROW(recorder::RunRecover(ro, log), recorder::OutputError);
    mc::WriterOptions wo;
    wo.inputs = {path};
    EXPECT_THROW(mc::Writer(same, wo), recorder::OutputError);
    wo.live = true;
    EXPECT_THROW(mc::Writer(same, wo), recorder::OutputError);
    EXPECT_EQ(ReadBytes(path), before);
    EXPECT_EQ(Names(dir.path()), names) << "a file was left behind";
  }
  // Another output is fine, and lands where it was asked to.
  recorder::ExportOptions eo;
  eo.file = path;
  eo.csv = dir / "run.csv";
  std::ostringstream log;
  EXPECT_EQ(recorder::RunExport(eo, log), 0) << log.str();
  EXPECT_THAT(testing::ReadFile(dir / "run.csv"), HasSubstr("t_s,step,"));
}

// An output is written beside its destination and renamed when whole: an error (or a crash)
// leaves the destination as it was and no half file under its name.
TEST(RecorderOutputs, AnOutputTakesItsNameOnlyWhenWhole) {
  testing::TempDir dir;
  const fs::path dest = dir / "out.csv";
  testing::WriteFile(dest, "yesterday's export\n");
  {
    recorder::OutputFile f(dest, {});
    ASSERT_EQ(f.temp().parent_path(), dest.parent_path());
    ASSERT_EQ(::write(f.fd(), "half", 4), 4);
    EXPECT_EQ(testing::ReadFile(dest), "yesterday's export\n");
    EXPECT_TRUE(fs::exists(f.temp()));
  }  // not committed: an error happened
  EXPECT_EQ(testing::ReadFile(dest), "yesterday's export\n");
  EXPECT_EQ(Names(dir.path()), std::set<std::string>{"out.csv"});
  {
    recorder::OutputFile f(dest, {});
    ASSERT_EQ(::write(f.fd(), "whole\n", 6), 6);
    f.Commit();
  }
  EXPECT_EQ(testing::ReadFile(dest), "whole\n");
  EXPECT_EQ(Names(dir.path()), std::set<std::string>{"out.csv"});
  // A symlink keeps pointing where it did; its target gets the new file.
  fs::create_directories(dir / "real");
  testing::WriteFile(dir / "real" / "data.csv", "old\n");
  fs::create_symlink(fs::path("real") / "data.csv", dir / "alias.csv");
  {
    recorder::OutputFile f(dir / "alias.csv", {});
    ASSERT_EQ(::write(f.fd(), "new\n", 4), 4);
    f.Commit();
  }
  EXPECT_TRUE(fs::is_symlink(dir / "alias.csv"));
  EXPECT_EQ(testing::ReadFile(dir / "real" / "data.csv"), "new\n");

  // A recording abandoned by an error leaves nothing under its name.
  try {
    mc::Writer w(dir / "rec.mcap", {});
    w.WriteMetadata("x", {{"a", "b"}});
    throw std::runtime_error("the work failed");
  } catch (const std::runtime_error&) {
  }
  EXPECT_FALSE(fs::exists(dir / "rec.mcap"));
  // A live recording of a new file is under its name from its first byte (a killed recorder
  // leaves it for recover); one over an existing file replaces it only when it closes.
  mc::WriterOptions live;
  live.live = true;
  {
    mc::Writer w(dir / "new.mcap", live);
    EXPECT_EQ(w.writing_to(), dir / "new.mcap");
    EXPECT_TRUE(fs::exists(dir / "new.mcap"));
  }
  WriteStates(dir / "old.mcap", 50, mc::Compression::kZstd);
  const std::vector<std::uint8_t> old = ReadBytes(dir / "old.mcap");
  {
    mc::Writer w(dir / "old.mcap", live);
    EXPECT_NE(w.writing_to(), dir / "old.mcap");
    w.Flush();
    EXPECT_EQ(ReadBytes(dir / "old.mcap"), old);
    w.Close();
    EXPECT_NE(ReadBytes(dir / "old.mcap"), old);
  }
  EXPECT_EQ(Names(dir.path()),
            (std::set<std::string>{"out.csv", "real", "alias.csv", "new.mcap", "old.mcap"}));
}

// Issue 33, item 2: an output that is not a regular file is never unlinked or replaced. A FIFO,
// a character device and a descriptor (/dev/fd/N, as /dev/stdout) are written into as a stream
// (a recording through a FIFO reads back whole); a block device and a socket are refused, left
// as they were; a name ending with a slash is refused and creates no folder; a finished file is
// not moved over a FIFO.
std::string Drain(int fd) {
  std::string got;
  char b[65536];
  for (ssize_t n; (n = ::read(fd, b, sizeof b)) > 0;) got.append(b, static_cast<std::size_t>(n));
  ::close(fd);
  return got;
}

TEST(RecorderOutputs, AnOutputThatIsNotARegularFileIsWrittenAsAStreamOrRefusedNeverReplaced) {
  testing::TempDir dir;
  auto kind = [](const fs::path& p) { return fs::symlink_status(p).type(); };
  const fs::path fifo = dir / "pipe.mcap";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  fs::create_symlink("pipe.mcap", dir / "to-pipe.csv");
  // A second name of the FIFO: should a writer replace "pipe.mcap" with a file, the reader
  // waiting on the FIFO is let go through it (the test fails instead of waiting forever).
  ASSERT_EQ(::link(fifo.c_str(), (dir / "keep").c_str()), 0);
  auto let_go = [&] {
    const int fd = ::open((dir / "keep").c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd >= 0) ::close(fd);
  };
  // A recording (not live, live) and a CSV into the FIFO, directly and through a symlink.
  for (const fs::path& dest : {fifo, dir / "to-pipe.csv"}) {
    for (const bool live : {false, true}) {
      SCOPED_TRACE(dest.string() + (live ? " live" : ""));
      std::string got;
      std::thread reader([&] { got = Drain(::open(fifo.c_str(), O_RDONLY | O_CLOEXEC)); });
      {
        mc::WriterOptions o;
        o.live = live;
        mc::Writer w(dest, o);
        EXPECT_EQ(w.writing_to(), dest);
        w.WriteMetadata("x", {{"a", "b"}});
        w.Close();
      }
      let_go();
      reader.join();
      testing::WriteFile(dir / "copy.mcap", got);
      EXPECT_NO_THROW(ReadAll(dir / "copy.mcap")) << got.size() << " bytes through the FIFO";
      EXPECT_EQ(kind(fifo), fs::file_type::fifo);
    }
  }
  {
    std::string got;
    std::thread reader([&] { got = Drain(::open(fifo.c_str(), O_RDONLY | O_CLOEXEC)); });
    {
      recorder::OutputFile f(dir / "to-pipe.csv", {});
      EXPECT_EQ(::write(f.fd(), "a,b\n", 4), 4);
      f.Commit();
    }
    let_go();
    reader.join();
    EXPECT_EQ(got, "a,b\n");
  }
  EXPECT_EQ(kind(fifo), fs::file_type::fifo);
  EXPECT_TRUE(fs::is_symlink(dir / "to-pipe.csv"));
  // A character device: written into, still a device. A null device's node of its own (never
  // the system's /dev/null, which a regression here would replace), where this user may make
  // one.
  const fs::path null = dir / "null.mcap";
  if (::mknod(null.c_str(), S_IFCHR | 0600, ::makedev(1, 3)) == 0) {
    {
      mc::Writer w(null, {});
      w.Close();
    }
    {
      mc::WriterOptions o;
      o.live = true;
      mc::Writer w(null, o);
      w.Close();
    }
    EXPECT_EQ(kind(null), fs::file_type::character);
  }
  // A descriptor named as a file (what /dev/stdout is): written through, at its offset.
  int fds[2];
  ASSERT_EQ(::pipe2(fds, O_CLOEXEC), 0);
  {
    recorder::OutputFile f("/dev/fd/" + std::to_string(fds[1]), {});
    EXPECT_EQ(::write(f.fd(), "through\n", 8), 8);
    f.Commit();
  }
  ::close(fds[1]);
  EXPECT_EQ(Drain(fds[0]), "through\n");
  // Refused, and left as they were: a socket, a block device (where this user may make one).
  // (A socket's path must be short: beside the folder, not in it.)
  const fs::path sock = "/tmp/vdyn-sock-" + std::to_string(::getpid()) + ".mcap";
  fs::remove(sock);
  const int sfd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  ASSERT_LT(sock.string().size(), sizeof addr.sun_path);
  std::strcpy(addr.sun_path, sock.c_str());
  ASSERT_EQ(::bind(sfd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr), 0);
  std::vector<std::pair<fs::path, std::string>> refused = {{sock, "is a socket"}};
  const fs::path blk = dir / "disk.mcap";
  if (::mknod(blk.c_str(), S_IFBLK | 0600, ::makedev(7, 250)) == 0) {
    refused.push_back({blk, "is a block device"});
  }
  for (const auto& [dest, says] : refused) {
    SCOPED_TRACE(dest.string());
    const fs::file_type before = kind(dest);
    for (const bool live : {false, true}) {
      mc::WriterOptions o;
      o.live = live;
      try {
        mc::Writer w(dest, o);
        ADD_FAILURE() << "written";
      } catch (const recorder::OutputError& e) {
        EXPECT_THAT(e.what(), HasSubstr(says));
        EXPECT_THAT(e.what(), HasSubstr("nothing was written"));
      }
    }
    EXPECT_THROW(recorder::OutputFile(dest, {}), recorder::OutputError);
    EXPECT_EQ(kind(dest), before);
  }
  ::close(sfd);
  fs::remove(sock);
  // A finished file is not moved over a FIFO (plot's figures).
  testing::WriteFile(dir / "done.png", "png");
  EXPECT_THROW(recorder::MoveInto(dir / "done.png", fifo, {}), recorder::OutputError);
  EXPECT_EQ(kind(fifo), fs::file_type::fifo);
  // A name ending with a slash: refused, and no folder of that name is left behind.
  for (const bool live : {false, true}) {
    mc::WriterOptions o;
    o.live = live;
    try {
      mc::Writer w(dir.path().string() + "/new.mcap/", o);
      ADD_FAILURE() << "written";
    } catch (const recorder::OutputError& e) {
      EXPECT_THAT(e.what(), HasSubstr("ends with a slash"));
    }
    EXPECT_FALSE(fs::exists(dir / "new.mcap"));
  }
}

// Issue 33, item 3: another program truncates the file while it is read (mapped): at every
// chunk and at every 5th message of a scan, strict (info, export, verify) and lenient
// (recover), and at every chunk read by ReadChunk (play), cut to nothing, to the chunk being
// read, to half, to one byte short. Each read ends with McapError naming the file (and, where
// the bytes are gone, "changed while it was read"), never a SIGBUS.
TEST(McapBadFiles, AFileTruncatedWhileItIsReadIsAnErrorNeverASignal) {
  testing::TempDir dir;
  const fs::path source = dir / "source.mcap", path = dir / "read.mcap";
  WriteStates(source, 3000, mc::Compression::kZstd, 16 * 1024);
  const std::uint64_t size = fs::file_size(source);
  const std::vector<mc::ChunkIndex> chunks = mc::Reader(source).Chunks();
  ASSERT_GT(chunks.size(), 8u);
  int errors = 0, changed = 0;
  auto expect_error = [&](const std::function<void()>& read, const std::string& what) {
    try {
      read();
      ADD_FAILURE() << what << ": read to the end of a truncated file without an error";
    } catch (const mc::McapError& e) {
      ++errors;
      EXPECT_EQ(e.file(), path) << what;
      if (std::string(e.what()).find("changed while it was read") != std::string::npos) ++changed;
    }
  };
  auto cut_at = [&](std::uint64_t chunk_start) {
    return std::vector<std::uint64_t>{0, chunk_start, size / 2, size - 1};
  };
  for (const bool lenient : {false, true}) {
    for (std::size_t k = 0; k < chunks.size(); ++k) {
      for (const std::uint64_t cut : cut_at(chunks[k].chunk_start_offset)) {
        fs::copy_file(source, path, fs::copy_options::overwrite_existing);
        const mc::Reader r(path);
        std::size_t seen = 0;
        mc::Visitor v;
        v.on_chunk = [&](const mc::ChunkIndex&) {
          if (seen++ == k) fs::resize_file(path, cut);
          return true;
        };
        expect_error(
            [&] {
              const mc::ScanResult res = r.Scan(v, lenient);
              // A lenient scan reports instead of throwing where the bytes read as damage.
              if (lenient && !res.complete)
                throw mc::McapError(path, res.problem_offset, res.problem);
            },
            (lenient ? "lenient scan, chunk " : "scan, chunk ") + std::to_string(k) + ", cut to " +
                std::to_string(cut));
      }
    }
  }
  for (std::size_t m = 0; m < 3000; m += 5 * 37) {
    fs::copy_file(source, path, fs::copy_options::overwrite_existing);
    const mc::Reader r(path);
    std::size_t seen = 0;
    mc::Visitor v;
    v.on_message = [&](const mc::Message& msg, std::uint64_t) {
      if (seen++ == m) fs::resize_file(path, 0);
      // The payload is read after the cut (zeroes at most: the scan says so after the call).
      volatile std::uint8_t sink = 0;
      for (const std::uint8_t b : msg.data) sink = static_cast<std::uint8_t>(sink + b);
    };
    expect_error([&] { r.Scan(v); }, "scan, message " + std::to_string(m));
  }
  for (std::size_t k = 0; k < chunks.size(); ++k) {
    fs::copy_file(source, path, fs::copy_options::overwrite_existing);
    const mc::Reader r(path);
    std::vector<std::uint8_t> scratch;
    fs::resize_file(path, chunks[k].chunk_start_offset + chunks[k].chunk_length / 2);
    expect_error(
        [&] {
          for (std::size_t j = k; j < chunks.size(); ++j) {
            r.ReadChunk(
                chunks[j], [](const mc::Message&) {}, scratch);
          }
        },
        "ReadChunk " + std::to_string(k));
  }
  EXPECT_GT(errors, 100);
  EXPECT_GT(changed, errors / 2);  // most cuts take pages a read still needed
}

// --- recover: what is damaged, and only that
// ----------------------------------------------------------

std::pair<int, std::string> Recover(const fs::path& in, const fs::path& out) {
  std::ostringstream log;
  recorder::RecoverOptions ro;
  ro.file = in;
  ro.out = out;
  const int code = recorder::RunRecover(ro, log);
  return {code, log.str()};
}

std::string Info(const fs::path& file) {
  std::ostringstream out;
  recorder::RunInfo(file, out);
  return out.str();
}

struct Layout {
  std::uint64_t footer = 0, summary_start = 0, data_end = 0;
  std::vector<mc::ChunkIndex> chunks;
};
Layout LayoutOf(const fs::path& path) {
  const std::vector<std::uint8_t> b = ReadBytes(path);
  Layout l;
  l.footer = b.size() - 8 - 29;
  l.summary_start = Le64(b, l.footer + 9);
  l.data_end = l.summary_start - 13;
  l.chunks = mc::Reader(path).Chunks();
  return l;
}

// One flipped bit in the summary or in the footer's summary offset, or a chunk written twice:
// the file is refused (its summary or data-section CRC), but every chunk is intact, and recover,
// which reads the data section only, keeps every message, once.
TEST(McapRecover, DoesNotDependOnTheSummaryOrTheFooter) {
  testing::TempDir dir;
  const fs::path path = dir / "a.mcap";
  const Written w = WriteStates(path, 3000, mc::Compression::kNone, 16 * 1024);
  const std::vector<std::uint8_t> whole = ReadBytes(path);
  const Layout l = LayoutOf(path);
  ASSERT_GT(l.chunks.size(), 4u);
  struct Case {
    const char* name;
    std::vector<std::uint8_t> bytes;
    const char* says;
  };
  std::vector<Case> cases;
  cases.push_back({"summary", whole, "summary is damaged"});
  cases.back().bytes[(l.summary_start + l.footer) / 2] ^= 0x01;
  cases.push_back({"footer", whole, "summary is damaged"});
  cases.back().bytes[l.footer + 9] ^= 0x04;  // the summary's offset
  cases.push_back({"duplicate", {}, "an exact copy of the chunk at offset"});
  {
    // The third chunk, with its message indexes, written twice in a row.
    const auto from = whole.begin() + static_cast<std::ptrdiff_t>(l.chunks[2].chunk_start_offset);
    const auto to = from + static_cast<std::ptrdiff_t>(l.chunks[2].chunk_length +
                                                       l.chunks[2].message_index_length);
    std::vector<std::uint8_t>& b = cases.back().bytes;
    b.assign(whole.begin(), to);
    b.insert(b.end(), from, to);
    b.insert(b.end(), to, whole.end());
  }
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const fs::path bad = dir / (std::string(c.name) + ".mcap");
    WriteBytes(bad, c.bytes);
    EXPECT_THROW(ReadAll(bad), mc::McapError) << "the damaged file was accepted";
    const auto [code, log] = Recover(bad, dir / (std::string(c.name) + "-recovered.mcap"));
    ASSERT_EQ(code, 0) << log;
    EXPECT_THAT(log, HasSubstr(c.says));
    EXPECT_THAT(log, ::testing::Not(HasSubstr("damaged chunks dropped")));
    mc::ScanResult res;
    const std::vector<std::string> got =
        ReadAll(dir / (std::string(c.name) + "-recovered.mcap"), &res);
    EXPECT_TRUE(res.complete);
    EXPECT_EQ(got, w.payloads);
  }
}

// One flipped bit in a string's length inside the header, the first schema or the first metadata
// record leaves its record's frame whole: recover leaves out that record, says so, and keeps every
// message (a lost schema comes back from the summary's copy, or - the summary gone too - from this
// build's descriptor of the topic's type). A damaged record length: recover resynchronises on
// the next valid record and loses only what lay in between.
TEST(McapRecover, SkipsADamagedRecordResynchronisesAndKeepsTheRest) {
  testing::TempDir dir;
  const fs::path path = dir / "a.mcap";
  const Written w = WriteStates(path, 3000, mc::Compression::kZstd, 16 * 1024);
  const std::vector<std::uint8_t> whole = ReadBytes(path);
  const Layout l = LayoutOf(path);
  // Magic, then the header, the schema, the channel and the metadata, each opcode + length.
  std::vector<std::uint64_t> record = {8};
  for (int i = 0; i < 4; ++i) record.push_back(record.back() + 9 + Le64(whole, record.back() + 1));
  ASSERT_EQ(whole[record[0]], mc::kHeader);
  ASSERT_EQ(whole[record[1]], mc::kSchema);
  ASSERT_EQ(whole[record[2]], mc::kChannel);
  ASSERT_EQ(whole[record[3]], mc::kMetadata);
  struct Case {
    std::string name;
    std::size_t at;  // the byte whose bit 7 flips: the third byte of a length (+ 8 MiB)
    const char* says;
    bool cut_summary = false;
  };
  const std::vector<Case> cases = {
      {"header", record[0] + 9 + 4 + 2, "a malformed header record"},  // the library's length
      {"schema", record[1] + 9 + 2 + 2, "a malformed schema record"},  // the name's length
      {"schema-no-summary", record[1] + 9 + 2 + 2,
       "rebuilt from this build's descriptor of vdyn.pb.VehicleState", true},
      {"metadata", record[3] + 9 + 2, "a malformed metadata record"},  // the name's length
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    std::vector<std::uint8_t> b = whole;
    b[c.at] ^= 0x80;
    if (c.cut_summary) b.resize(l.data_end);  // killed before it closed: no summary to help
    const fs::path bad = dir / (c.name + ".mcap");
    WriteBytes(bad, b);
    EXPECT_THROW(ReadAll(bad), mc::McapError);
    const fs::path out = dir / (c.name + "-recovered.mcap");
    const auto [code, log] = Recover(bad, out);
    ASSERT_EQ(code, 0) << log;
    EXPECT_THAT(log, HasSubstr(c.says)) << log;
    EXPECT_THAT(log, HasSubstr("skipped")) << log;
    mc::ScanResult res;
    EXPECT_EQ(ReadAll(out, &res), w.payloads) << log;
    EXPECT_TRUE(res.complete);
    // The copy's states are still vdyn states (its schema is the type's, whatever happened).
    const std::string info = Info(out);
    EXPECT_THAT(info, HasSubstr("vdyn/state/1")) << info;
    EXPECT_THAT(info, HasSubstr("3000 states, 0 missing")) << info;
    EXPECT_THAT(info,
                HasSubstr("damaged   offset " + std::to_string(c.name == "header"     ? record[0]
                                                               : c.name == "metadata" ? record[3]
                                                                                      : record[1])))
        << info;
  }
  // A bit flipped in a chunk's record length: the scan resynchronises on the next valid record;
  // only that chunk is lost.
  std::vector<std::uint8_t> b = whole;
  b[l.chunks[3].chunk_start_offset + 1 + 2] ^= 0x80;
  WriteBytes(dir / "length.mcap", b);
  const auto [code, log] = Recover(dir / "length.mcap", dir / "length-recovered.mcap");
  ASSERT_EQ(code, 0) << log;
  EXPECT_THAT(log, HasSubstr("bytes to the next valid record"));
  const std::vector<std::string> got = ReadAll(dir / "length-recovered.mcap");
  std::uint64_t in_chunk = 0;
  std::vector<std::uint8_t> scratch;
  mc::Reader(path).ReadChunk(
      l.chunks[3], [&](const mc::Message&) { ++in_chunk; }, scratch);
  EXPECT_EQ(got.size(), w.payloads.size() - in_chunk);
  // The copy's info says what was lost, and when.
  const std::string info = Info(dir / "length-recovered.mcap");
  EXPECT_THAT(info, HasSubstr("recovered   from length.mcap"));
  EXPECT_THAT(info, HasSubstr(std::to_string(in_chunk) + " states missing"));
  EXPECT_THAT(info, HasSubstr("bytes to the next valid record"));
}

// Every record boundary of a small recording: its offset, opcode and length (magic first).
std::vector<std::uint64_t> RecordOffsets(const std::vector<std::uint8_t>& b) {
  std::vector<std::uint64_t> at;
  for (std::uint64_t p = 8; p + 9 <= b.size() - 8; p += 9 + Le64(b, p + 1)) at.push_back(p);
  return at;
}

std::string Damages(const mc::ScanResult& r) {
  std::string s;
  for (const mc::Damage& d : r.damage) {
    s += "\n  offset " + std::to_string(d.offset) + ", " + std::to_string(d.length) +
         " bytes: " + d.what;
  }
  return s;
}

// The messages of each chunk of `path` (payloads), with the chunk's byte range.
struct ChunkHolds {
  std::uint64_t begin = 0, end = 0;
  std::vector<std::string> payloads;
};
std::vector<ChunkHolds> ChunksOf(const fs::path& path) {
  std::vector<ChunkHolds> out;
  const mc::Reader r(path);
  std::vector<std::uint8_t> scratch;
  for (const mc::ChunkIndex& c : r.Chunks()) {
    ChunkHolds h{c.chunk_start_offset, c.chunk_start_offset + c.chunk_length, {}};
    r.ReadChunk(
        c,
        [&](const mc::Message& m) {
          h.payloads.emplace_back(reinterpret_cast<const char*>(m.data.data()), m.data.size());
        },
        scratch);
    out.push_back(std::move(h));
  }
  return out;
}

// Issue 33, item 1: every single-bit flip and every single-byte damage (zeroed, all ones, the
// complement) anywhere in a small recording - magic, header, schema, channel, metadata, chunks,
// message indexes, data end, summary, footer. The lenient scan `recover` reads with keeps every
// message of every chunk the damage did not touch, and delivers as checked no message that was
// not written. (Before: an opcode flipped into a summary opcode ended the data section, a message
// index flipped to a data end was taken for one, a grown length swallowed the records behind it.)
// The recording holds every kind of record with at least eight chunks and no more: the cases grow
// with its size and each case reads all of it.
TEST(McapRecover, EveryChunkTheDamageMissesIsKeptWhateverSingleByteIsDamaged) {
  testing::TempDir dir;
  const fs::path path = dir / "small.mcap";
  const Written w =
      WriteStates(path, kSmallStates, mc::Compression::kZstd, kSmallChunkBytes, true, true);
  const std::vector<std::uint8_t> whole = ReadBytes(path);
  const std::vector<ChunkHolds> chunks = ChunksOf(path);
  ASSERT_GE(chunks.size(), 8u);
  const std::set<std::string> written(w.payloads.begin(), w.payloads.end());
  std::vector<std::uint8_t> b = whole;
  std::size_t cases = 0;
  auto check = [&](std::size_t at, const char* how) {
    ++cases;
    std::multiset<std::string> got, checked;
    mc::Visitor v;
    v.on_message = [&](const mc::Message& m, std::uint64_t) {
      got.emplace(reinterpret_cast<const char*>(m.data.data()), m.data.size());
      if (!m.unchecked)
        checked.emplace(reinterpret_cast<const char*>(m.data.data()), m.data.size());
    };
    mc::ScanResult res;
    try {
      const mc::Reader r("damaged.mcap", b, mc::Reader::Open::kSalvage);
      res = r.Scan(v, /*lenient=*/true);
    } catch (const mc::McapError& e) {
      ADD_FAILURE() << how << " at byte " << at << ": the damaged file was refused: " << e.what();
      return false;
    }
    for (const ChunkHolds& c : chunks) {
      if (at >= c.begin && at < c.end) continue;  // the damaged chunk may go
      for (const std::string& p : c.payloads) {
        if (got.count(p) != 1) {
          ADD_FAILURE() << how << " at byte " << at << " (" << int{whole[at]} << " -> "
                        << int{b[at]} << "): the intact chunk at offset " << c.begin
                        << " was not kept once; " << Damages(res);
          return false;
        }
      }
    }
    // A loose message outside any chunk (another record whose opcode now says message) is
    // delivered as unchecked, which `recover` keeps apart and says so; a checked one is real.
    for (const std::string& p : checked) {
      if (written.count(p) == 0) {
        ADD_FAILURE() << how << " at byte " << at << " (" << int{whole[at]} << " -> " << int{b[at]}
                      << "): a message that was never written (" << p.size() << " bytes); "
                      << Damages(res);
        return false;
      }
    }
    return true;
  };
  for (std::size_t at = 0; at < whole.size(); ++at) {
    bool ok = true;
    for (int bit = 0; bit < 8 && ok; ++bit) {
      b[at] = static_cast<std::uint8_t>(whole[at] ^ (1u << bit));
      ok = check(at, "a flipped bit");
    }
    for (const std::uint8_t to :
         {std::uint8_t{0x00}, std::uint8_t{0xff}, static_cast<std::uint8_t>(~whole[at])}) {
      if (!ok || to == whole[at]) continue;
      b[at] = to;
      ok = check(at, "a damaged byte");
    }
    b[at] = whole[at];
    if (!ok) break;  // one report per file is enough to act on
  }
  EXPECT_GT(cases, 10 * whole.size());
}

// The same through the whole of `recover`, for one flip of every bit of every record's opcode
// and length (where the 916 losses came from): the copy is closed and valid and holds
// every message of every chunk the flip missed.
TEST(McapRecover, AFlippedOpcodeOrLengthLosesNoIntactChunk) {
  testing::TempDir dir;
  const fs::path path = dir / "small.mcap";
  WriteStates(path, kSmallStates, mc::Compression::kZstd, kSmallChunkBytes, true, true);
  const std::vector<std::uint8_t> whole = ReadBytes(path);
  const std::vector<ChunkHolds> chunks = ChunksOf(path);
  const std::vector<std::uint64_t> records = RecordOffsets(whole);
  ASSERT_GE(chunks.size(), 8u);
  ASSERT_GT(records.size(), 2 * chunks.size());
  int runs = 0;
  for (const std::uint64_t rec : records) {
    for (std::uint64_t at = rec; at < rec + 9; ++at) {
      for (int bit = 0; bit < 8; ++bit) {
        if (at > rec + 4 && bit != 7 && bit != 0) continue;  // the high bytes: their edges
        std::vector<std::uint8_t> b = whole;
        b[at] ^= static_cast<std::uint8_t>(1u << bit);
        const fs::path bad = dir / "bad.mcap", out = dir / "bad-recovered.mcap";
        WriteBytes(bad, b);
        const auto [code, log] = Recover(bad, out);
        ++runs;
        ASSERT_EQ(code, 0) << log;
        mc::ScanResult res;
        const std::vector<std::string> got = ReadAll(out, &res);
        ASSERT_TRUE(res.complete) << "byte " << at << " bit " << bit << ": " << log;
        const std::multiset<std::string> kept(got.begin(), got.end());
        for (const ChunkHolds& c : chunks) {
          if (at >= c.begin && at < c.end) continue;
          for (const std::string& p : c.payloads) {
            ASSERT_EQ(kept.count(p), 1u) << "byte " << at << " (record at " << rec << ") bit "
                                         << bit << ": the intact chunk at " << c.begin << " lost\n"
                                         << log;
          }
        }
      }
    }
  }
  EXPECT_GT(runs, 100);
}

// Writes `path` again with the data end's CRC set to the CRC of every byte before it (a writer
// that computes that one but leaves its chunks' CRCs at 0, as the spec allows).
void SetDataCrc(const fs::path& path) {
  std::vector<std::uint8_t> b = ReadBytes(path);
  const Layout l = LayoutOf(path);
  const std::uint32_t crc = mc::Crc32(0, std::span<const std::uint8_t>(b.data(), l.data_end));
  for (int i = 0; i < 4; ++i)
    b[l.data_end + 9 + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(crc >> (8 * i));
  WriteBytes(path, b);
}

// A chunk whose own CRC is 0 with one flipped byte: the data section's CRC catches it, so every
// command refuses the file. Recover cannot tell which chunk holds the flip: it keeps every chunk,
// but unchecked - CRC 0 again and no data-section CRC in the copy (which would vouch for them) -
// and says so, and so does `info` of the copy; recovering the copy again does not launder it
// either.
TEST(McapRecover, NeverLaundersWhatNoCrcChecked) {
  testing::TempDir dir;
  const fs::path path = dir / "nocrc.mcap";
  const Written w = WriteStates(path, 3000, mc::Compression::kNone, 16 * 1024, /*chunk_crc=*/false);
  SetDataCrc(path);
  // Untouched, the data section's CRC covers the chunks: checked.
  mc::ScanResult res;
  EXPECT_EQ(ReadAll(path, &res), w.payloads);
  EXPECT_EQ(res.data_crc, mc::ScanResult::DataCrc::kMatched);
  EXPECT_EQ(res.chunks_unchecked, res.chunks);
  EXPECT_THAT(Info(path),
              HasSubstr("carry no CRC of their own; the data section's CRC covers them (checked)"));
  auto [code, log] = Recover(path, dir / "clean-recovered.mcap");
  ASSERT_EQ(code, 0) << log;
  ReadAll(dir / "clean-recovered.mcap", &res);
  EXPECT_EQ(res.chunks_unchecked, 0u) << "the data section's CRC vouched for these chunks";
  EXPECT_EQ(res.data_crc, mc::ScanResult::DataCrc::kMatched);

  // One byte of a state's payload flips in the third chunk.
  const Layout l = LayoutOf(path);
  std::vector<std::uint8_t> b = ReadBytes(path);
  b[l.chunks[2].chunk_start_offset + l.chunks[2].chunk_length / 2] ^= 0x10;
  const fs::path bad = dir / "flipped.mcap";
  WriteBytes(bad, b);
  try {
    ReadAll(bad);
    FAIL() << "a damaged file was accepted";
  } catch (const mc::McapError& e) {
    EXPECT_THAT(e.reason(), HasSubstr("data section CRC mismatch"));
  }
  std::tie(code, log) = Recover(bad, dir / "flipped-recovered.mcap");
  ASSERT_EQ(code, 0) << log;
  EXPECT_THAT(log, HasSubstr("unchecked: 3000 messages"));
  std::vector<std::string> got = ReadAll(dir / "flipped-recovered.mcap", &res);
  EXPECT_EQ(got.size(), w.payloads.size());
  EXPECT_EQ(res.chunks_unchecked, res.chunks) << "a chunk got a CRC nothing had checked";
  EXPECT_EQ(res.data_crc, mc::ScanResult::DataCrc::kAbsent);
  const std::string info = Info(dir / "flipped-recovered.mcap");
  EXPECT_THAT(info, HasSubstr("integrity   UNCHECKED"));
  EXPECT_THAT(info, HasSubstr("recovered   from flipped.mcap"));
  EXPECT_THAT(info, HasSubstr("its data-section CRC mismatched"));
  EXPECT_THAT(info, HasSubstr("UNCHECKED 3000 messages"));
  // Recovered again: still unchecked.
  std::tie(code, log) = Recover(dir / "flipped-recovered.mcap", dir / "again.mcap");
  ASSERT_EQ(code, 0) << log;
  ReadAll(dir / "again.mcap", &res);
  EXPECT_EQ(res.chunks_unchecked, res.chunks);
  EXPECT_EQ(res.data_crc, mc::ScanResult::DataCrc::kAbsent);
  // export says what it cannot vouch for.
  std::ostringstream exported;
  recorder::ExportOptions eo;
  eo.file = dir / "again.mcap";
  eo.csv = dir / "again.csv";
  ASSERT_EQ(recorder::RunExport(eo, exported), 0) << exported.str();
  EXPECT_THAT(exported.str(), HasSubstr("3000 rows come from chunks without a CRC"));
  EXPECT_THAT(exported.str(), HasSubstr("had no CRC that held when it was recovered"));
}

// --- info of foreign content ---------------------------------------------------------------------

// `path` without its summary: the data section, then a footer that points at no summary (as
// another tool may write it).
void DropSummary(const fs::path& path) {
  std::vector<std::uint8_t> b = ReadBytes(path);
  const Layout l = LayoutOf(path);
  b.resize(l.summary_start);
  b.push_back(mc::kFooter);
  for (int i = 0; i < 8; ++i) b.push_back(i == 0 ? 20 : 0);
  for (int i = 0; i < 20; ++i) b.push_back(0);
  b.insert(b.end(), mc::kMagic, mc::kMagic + 8);
  WriteBytes(path, b);
}

TEST(McapInfo, DescribesAForeignFileWithOnlyAFooter) {
  testing::TempDir dir;
  const fs::path path = dir / "camera.mcap";
  {
    mc::Writer w(path, {});
    const std::uint16_t s =
        w.AddSchema("sensor_msgs/msg/Image", "ros2msg", "uint32 height\nuint32 width\n");
    const std::uint16_t ch = w.AddChannel(s, "/camera/image", "cdr", {});
    const std::vector<std::uint8_t> frame(300, 7);
    for (std::uint64_t i = 0; i < 5000; ++i)
      w.WriteMessage(ch, 0, 1'000'000'000 + i * 33'000'000, 0, frame);
    w.Close();
  }
  DropSummary(path);
  mc::ScanResult res;
  EXPECT_EQ(ReadAll(path, &res).size(), 5000u);
  EXPECT_FALSE(res.summary);
  const std::string info = Info(path);
  EXPECT_THAT(info, HasSubstr("5000 messages, 5000 of them not vdyn messages"));
  EXPECT_THAT(info, HasSubstr("closed without a summary"));
  EXPECT_THAT(info, ::testing::Not(HasSubstr("closed with index and summary")));
  EXPECT_THAT(info, HasSubstr("/camera/image #1"));
  EXPECT_THAT(
      info,
      HasSubstr("not a vdyn channel: schema 'sensor_msgs/msg/Image' (ros2msg), messages cdr"));
  const auto [code, log] = Recover(path, dir / "camera-recovered.mcap");
  EXPECT_EQ(code, 0);
  EXPECT_THAT(log, HasSubstr("(5000 messages)"));
}

// Our topic names (and metadata) on channels that do not hold our messages: another schema
// encoding, or our schema with payloads that are not states and events. Neither becomes steps
// ("16517206055757184913 states missing") or hides that events were recorded.
TEST(McapInfo, GarbageUnderOurTopicNamesIsNeitherStatesNorEvents) {
  testing::TempDir dir;
  std::mt19937_64 rng(11);
  auto garbage = [&] {
    std::vector<std::uint8_t> b(40);
    for (auto& x : b) x = static_cast<std::uint8_t>(rng());
    return b;
  };
  for (const bool our_schema : {false, true}) {
    SCOPED_TRACE(our_schema ? "our schema" : "a foreign schema");
    const fs::path path = dir / (our_schema ? "ours.mcap" : "foreign.mcap");
    {
      mc::Writer w(path, {});
      auto channel = [&](transport::TopicId t) {
        const auto* d = recorder::PayloadDescriptor(t);
        const std::uint16_t s =
            our_schema ? w.AddSchema(d->full_name(), "protobuf", FileDescriptorSetOf(d))
                       : w.AddSchema(d->full_name(), "jsonschema", "{}");
        return w.AddChannel(s, recorder::ChannelTopic(t, 1), our_schema ? "protobuf" : "json",
                            recorder::ChannelMetadata(t, 1));
      };
      const std::uint16_t states = channel(transport::TopicId::kState);
      const std::uint16_t events = channel(transport::TopicId::kEvents);
      for (std::uint64_t i = 0; i < 20; ++i) {
        w.WriteMessage(states, 0, 1'000'000'000 + i * 1'000'000, 0, garbage());
        w.WriteMessage(events, 0, 1'000'000'000 + i * 1'000'000, 0, garbage());
      }
      w.Close();
    }
    const std::string info = Info(path);
    EXPECT_THAT(info, ::testing::Not(HasSubstr("states missing"))) << info;
    EXPECT_THAT(info, HasSubstr("no states recorded")) << info;
    if (our_schema) {
      EXPECT_THAT(info, HasSubstr("vdyn/events/1                         20 msgs")) << info;
      EXPECT_THAT(info,
                  HasSubstr("vdyn/events/1: 20 of 20 messages do not parse as the topic's type"))
          << info;
      EXPECT_THAT(
          info,
          HasSubstr(
              "re-simulates no: the 20 messages on vdyn/events do not parse as session events"))
          << info;
    } else {
      EXPECT_THAT(info, HasSubstr("40 messages, 40 of them not vdyn messages")) << info;
      EXPECT_THAT(
          info,
          HasSubstr(
              "not a vdyn channel: schema 'vdyn.pb.SessionEvent' (jsonschema), messages json"))
          << info;
      EXPECT_THAT(info,
                  HasSubstr("re-simulates no: no session events: vdyn/events/1 holds another type"))
          << info;
    }
  }
}

// A sparse channel has no rate worth printing: "2 msgs 76.9 Hz" said nothing true.
TEST(McapInfo, RatesArePrintedOnlyForStreams) {
  testing::TempDir dir;
  const fs::path path = dir / "rates.mcap";
  {
    mc::Writer w(path, {});
    auto channel = [&](transport::TopicId t, std::uint32_t key) {
      const auto* d = recorder::PayloadDescriptor(t);
      return w.AddChannel(w.AddSchema(d->full_name(), "protobuf", FileDescriptorSetOf(d)),
                          recorder::ChannelTopic(t, key), "protobuf",
                          recorder::ChannelMetadata(t, key));
    };
    const std::uint16_t states = channel(transport::TopicId::kState, 1);
    const std::uint16_t replies = channel(transport::TopicId::kControlReply, 1);
    const std::uint64_t t0 = 1'700'000'000'000'000'000ull;
    for (std::uint64_t k = 0; k < 3000; ++k) {
      const std::string b = StateAt(k).SerializeAsString();
      w.WriteMessage(states, 0, t0 + k * 1'000'000, 0,
                     {reinterpret_cast<const std::uint8_t*>(b.data()), b.size()});
    }
    const std::vector<std::uint8_t> reply = {0x08, 0x01};
    w.WriteMessage(replies, 0, t0 + 100'000'000, 0, reply);
    w.WriteMessage(replies, 1, t0 + 113'000'000, 0, reply);
    w.Close();
  }
  const std::string info = Info(path);
  EXPECT_THAT(info, HasSubstr("vdyn/state/1                        3000 msgs    1000.0 Hz"))
      << info;
  EXPECT_THAT(info, HasSubstr("vdyn/control_reply/1                   2 msgs         -    "))
      << info;
  EXPECT_THAT(info, ::testing::Not(HasSubstr("76.9 Hz"))) << info;
}

// --- files laid out record by record, as other writers lay them out -----------------------------

// Little-endian fields of the spec's records, for files our writer would not write.
struct Rec {
  std::string b;
  Rec& Le(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i)
      b.push_back(static_cast<char>(static_cast<std::uint8_t>(v >> (8 * i))));
    return *this;
  }
  Rec& U16(std::uint64_t v) { return Le(v, 2); }
  Rec& U32(std::uint64_t v) { return Le(v, 4); }
  Rec& U64(std::uint64_t v) { return Le(v, 8); }
  Rec& Str(const std::string& s) {
    U32(s.size());
    b += s;
    return *this;
  }
  // The record of opcode `op` that holds these fields.
  std::string As(std::uint8_t op) const {
    Rec r;
    r.b.push_back(static_cast<char>(op));
    return r.U64(b.size()).b + b;
  }
};

// Where the data section of FileOf's files starts: the magic (8), then the header record (9)
// with an empty profile (4) and the library "test" (4 + 4).
constexpr std::size_t kDataAt = 29;

std::string SchemaRecord(std::uint16_t id, const std::string& name) {
  return Rec().U16(id).Str(name).Str("protobuf").Str("fds").As(mc::kSchema);
}
// The state channel of `vehicle`, as our recorder names it.
std::string ChannelRecord(std::uint16_t id, std::uint16_t schema, std::uint32_t vehicle) {
  std::string m;
  for (const auto& [k, v] : recorder::ChannelMetadata(transport::TopicId::kState, vehicle))
    m += Rec().Str(k).Str(v).b;
  return Rec()
      .U16(id)
      .U16(schema)
      .Str(recorder::ChannelTopic(transport::TopicId::kState, vehicle))
      .Str("protobuf")
      .Str(m)
      .As(mc::kChannel);
}
std::uint64_t StateTime(std::uint64_t step) {
  return 1'700'000'000'000'000'000ull + step * 1'000'000;
}
// The states [from, to) of vehicle 1 on `channel`, as message records.
std::string StateRecords(std::uint16_t channel, std::uint64_t from, std::uint64_t to) {
  std::string out;
  for (std::uint64_t s = from; s < to; ++s) {
    Rec r;
    r.U16(channel).U32(s).U64(StateTime(s)).U64(StateTime(s));
    r.b += StateAt(s).SerializeAsString();
    out += r.As(mc::kMessage);
  }
  return out;
}
// An uncompressed chunk of `records` (with its CRC) over the log times of steps [from, to).
std::string ChunkRecord(const std::string& records, std::uint64_t from, std::uint64_t to) {
  const auto* p = reinterpret_cast<const std::uint8_t*>(records.data());
  Rec r;
  r.U64(StateTime(from)).U64(StateTime(to - 1)).U64(records.size());
  r.U32(mc::Crc32(0, {p, records.size()})).Str("").U64(records.size());
  r.b += records;
  return r.As(mc::kChunk);
}
// The magic, a header, `data`, a data end, `summary` (none when empty), a footer, the magic; no
// CRC of the data section or of the summary (0: not computed, as the spec allows).
std::vector<std::uint8_t> FileOf(const std::string& data, const std::string& summary = "") {
  std::string f(reinterpret_cast<const char*>(mc::kMagic), 8);
  f += Rec().Str("").Str("test").As(mc::kHeader) + data + Rec().U32(0).As(mc::kDataEnd);
  const std::uint64_t summary_start = summary.empty() ? 0 : f.size();
  f += summary + Rec().U64(summary_start).U64(0).U32(0).As(mc::kFooter);
  f.append(reinterpret_cast<const char*>(mc::kMagic), 8);
  return {f.begin(), f.end()};
}
// Where FileOf(data, ...) places its summary.
std::uint64_t SummaryAt(const std::string& data) {
  return kDataAt + data.size() + 13;
}

// The McapError a strict scan of `path` throws ("" reason when it reads).
mc::McapError StrictError(const fs::path& path) {
  try {
    ReadAll(path);
  } catch (const mc::McapError& e) {
    return e;
  }
  return mc::McapError(path, 0, "");
}

// The official writers put a schema and a channel into the chunk where they are first used
// (mcap's Python writer, register_channel), and may not copy them into the summary: every
// command read such a file as "a message on channel 1, which no channel record defines". Now
// each takes them there, and a reader that seeks by the summary (play, export, verify) finds
// them all the same.
TEST(McapForeign, SchemasAndChannelsInsideChunksAreTakenAndTheSummaryFindsThem) {
  testing::TempDir dir;
  const fs::path path = dir / "python.mcap";
  const std::string type = pb::VehicleState::descriptor()->full_name();
  const std::string first =
      ChunkRecord(SchemaRecord(1, type) + ChannelRecord(1, 1, 1) + StateRecords(1, 0, 30), 0, 30);
  const std::string second = ChunkRecord(StateRecords(1, 30, 60), 30, 60);
  // The summary: statistics counting channel 1's messages and the chunk indexes, no channel.
  const std::string stats = Rec()
                                .U64(60)
                                .U16(1)
                                .U32(1)
                                .U32(0)
                                .U32(0)
                                .U32(2)
                                .U64(StateTime(0))
                                .U64(StateTime(59))
                                .Str(Rec().U16(1).U64(60).b)
                                .As(mc::kStatistics);
  auto index = [](std::uint64_t at, const std::string& chunk, std::uint64_t from) {
    const std::uint64_t records = chunk.size() - 9 - 40;
    return Rec()
        .U64(StateTime(from))
        .U64(StateTime(from + 29))
        .U64(at)
        .U64(chunk.size())
        .Str("")
        .U64(0)
        .Str("")
        .U64(records)
        .U64(records)
        .As(mc::kChunkIndex);
  };
  WriteBytes(path, FileOf(first + second, stats + index(kDataAt, first, 0) +
                                              index(kDataAt + first.size(), second, 30)));
  mc::ScanResult res;
  EXPECT_EQ(ReadAll(path, &res).size(), 60u);
  EXPECT_TRUE(res.complete);
  const std::string info = Info(path);
  EXPECT_THAT(info, HasSubstr("vdyn/state/1                          60 msgs")) << info;

  const mc::Reader reader(path);
  const auto summary = reader.ReadSummary();
  ASSERT_TRUE(summary.has_value());
  ASSERT_EQ(summary->channels.size(), 1u);
  EXPECT_EQ(summary->channels[0].topic, "vdyn/state/1");
  ASSERT_EQ(summary->schemas.size(), 1u);
  EXPECT_EQ(summary->schemas[0].name, type);
  const auto channels = recorder::VdynChannels(*summary);
  ASSERT_EQ(channels.count(1), 1u);
  EXPECT_EQ(channels.at(1).topic, transport::TopicId::kState);
  EXPECT_EQ(channels.at(1).key, 1u);
  std::size_t seeked = 0;
  std::vector<std::uint8_t> scratch;
  for (const mc::ChunkIndex& c : reader.Chunks())
    reader.ReadChunk(
        c, [&](const mc::Message&) { ++seeked; }, scratch);
  EXPECT_EQ(seeked, 60u);
}

// The spec wants every record of one schema or channel id identical. One that is not made the
// commands disagree (info named channel 1 vdyn/state/2, export took it for vehicle 1's): it is
// refused at the second record, wherever it stands, saying what differs; recover says it is
// damage. Identical copies (the data section's, a chunk's, the summary's) are welcome.
TEST(McapBadFiles, AnIdDefinedTwiceWithOtherContentIsRefusedAtTheSecondRecord) {
  testing::TempDir dir;
  const std::string type = pb::VehicleState::descriptor()->full_name();
  const std::string defs = SchemaRecord(1, type) + ChannelRecord(1, 1, 1);
  const std::string states = ChunkRecord(StateRecords(1, 0, 20), 0, 20);
  const std::string more = ChunkRecord(StateRecords(1, 20, 40), 20, 40);
  const std::string other_schema =
      ChunkRecord(SchemaRecord(1, "vdyn.pb.SessionEvent") + StateRecords(1, 20, 40), 20, 40);
  const std::string channel_at =
      "than at offset " + std::to_string(kDataAt + SchemaRecord(1, type).size());
  struct Case {
    const char* what;
    std::string data, summary;
    std::uint64_t at;
    std::string says;
  };
  const std::vector<Case> cases = {
      {"in the data section", defs + ChannelRecord(1, 1, 2) + states, "", kDataAt + defs.size(),
       "channel 1 is defined again with other content (topic 'vdyn/state/2', was "
       "'vdyn/state/1') " +
           channel_at},
      {"in a chunk", defs + states + other_schema, "", kDataAt + defs.size() + states.size(),
       "inside the chunk, byte 0: schema 1 is defined again with other content (name "
       "'vdyn.pb.SessionEvent', was 'vdyn.pb.VehicleState') than at offset 29"},
      {"in the summary", defs + states + more, ChannelRecord(1, 1, 2),
       SummaryAt(defs + states + more),
       "channel 1 is defined again with other content (topic 'vdyn/state/2', was "
       "'vdyn/state/1') " +
           channel_at},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    const fs::path path = dir / "twice.mcap";
    WriteBytes(path, FileOf(c.data, c.summary));
    const mc::McapError e = StrictError(path);
    EXPECT_EQ(e.offset(), c.at) << e.what();
    EXPECT_THAT(e.reason(), HasSubstr(c.says));
    EXPECT_THROW(Info(path), mc::McapError);
    const auto [code, log] = Recover(path, dir / "twice-recovered.mcap");
    EXPECT_EQ(code, 0);
    EXPECT_THAT(log, ::testing::Not(HasSubstr("was whole"))) << log;
    fs::remove(dir / "twice-recovered.mcap");
  }
  // Identical copies in the data section, in a chunk and in the summary.
  const fs::path path = dir / "copies.mcap";
  WriteBytes(path, FileOf(defs + defs + ChunkRecord(defs + StateRecords(1, 0, 20), 0, 20), defs));
  EXPECT_EQ(ReadAll(path).size(), 20u);
  EXPECT_EQ(mc::Reader(path).ReadSummary()->channels.size(), 1u);
  const auto [code, log] = Recover(path, dir / "copies-recovered.mcap");
  EXPECT_EQ(code, 0);
  EXPECT_THAT(log, HasSubstr("was whole")) << log;
}

// A chunk holds schema, channel and message records (and private ones, which a reader skips):
// a chunk nested in one was skipped as if private, and its messages silently lost (info said
// nothing, recover said "was whole"). Such a chunk is malformed: refused at its offset, naming
// the record; recover drops it as damage.
TEST(McapBadFiles, AChunkHoldsOnlySchemaChannelAndMessageRecords) {
  testing::TempDir dir;
  const std::string defs =
      SchemaRecord(1, pb::VehicleState::descriptor()->full_name()) + ChannelRecord(1, 1, 1);
  const std::string more = ChunkRecord(StateRecords(1, 20, 40), 20, 40);
  struct Case {
    const char* what;
    std::string inner;
    std::string says;
  };
  const std::vector<Case> cases = {
      {"a chunk", ChunkRecord(StateRecords(1, 0, 20), 0, 20),
       "inside the chunk, byte 0: a chunk record (opcode 0x06), which the spec does not allow "
       "inside a chunk"},
      {"metadata", StateRecords(1, 0, 20) + Rec().Str("m").Str("").As(mc::kMetadata),
       "a metadata record (opcode 0x0c), which the spec does not allow inside a chunk"},
      {"an attachment", Rec().U64(0).U64(0).Str("a").Str("").U64(0).U32(0).As(mc::kAttachment),
       "inside the chunk, byte 0: an attachment record (opcode 0x09)"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    const fs::path path = dir / "nested.mcap";
    WriteBytes(path, FileOf(defs + ChunkRecord(c.inner, 0, 20) + more));
    const mc::McapError e = StrictError(path);
    EXPECT_EQ(e.offset(), kDataAt + defs.size()) << e.what();
    EXPECT_THAT(e.reason(), HasSubstr(c.says));
    EXPECT_THROW(Info(path), mc::McapError);
    const mc::Reader reader(path);
    std::vector<std::uint8_t> scratch;
    EXPECT_THROW(reader.ReadChunk(
                     reader.Chunks().at(0), [](const mc::Message&) {}, scratch),
                 mc::McapError);
    const auto [code, log] = Recover(path, dir / "nested-recovered.mcap");
    EXPECT_EQ(code, 0);
    EXPECT_THAT(log, HasSubstr("recovered 20 messages")) << log;
    EXPECT_THAT(log, HasSubstr(c.says)) << log;
    fs::remove(dir / "nested-recovered.mcap");
  }
  // Private records (0x80 and up) and those of a later version of the spec are skipped.
  const fs::path path = dir / "private.mcap";
  const std::string skipped = Rec().Str("mine").As(0x80) + Rec().Str("later").As(0x20);
  WriteBytes(path, FileOf(defs + ChunkRecord(skipped + StateRecords(1, 0, 20), 0, 20) + more));
  EXPECT_EQ(ReadAll(path).size(), 40u);
  const auto [code, log] = Recover(path, dir / "private-recovered.mcap");
  EXPECT_EQ(code, 0);
  EXPECT_THAT(log, HasSubstr("was whole (40 messages)")) << log;
}

}  // namespace
}  // namespace vdyn

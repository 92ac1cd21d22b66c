// The recorder's MCAP files without the network: the layout the spec prescribes (magic, header,
// data end, summary, footer), every message back in order, compression, the schema as a
// FileDescriptorSet that decodes a payload by itself, and bad files - truncated at every kind of
// place, corrupted, empty, foreign - refused with the file, offset and reason; recover salvages.
#include <fstream>
#include <random>
#include <sstream>

#include <gmock/gmock.h>
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/dynamic_message.h>
#include <gtest/gtest.h>

#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/mcap.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/state.pb.h"
#include "test_support.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;
using recorder::FileDescriptorSetOf;
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
  for (int i = 0; i < 8; ++i) v |= static_cast<std::uint64_t>(b[at + static_cast<std::size_t>(i)]) << (8 * i);
  return v;
}

// Where a chunk record keeps its uncompressed size: opcode (1), length (8), message start and
// end times (8 + 8), then the size (8), little-endian.
std::size_t UncompressedSizeAt(const mc::ChunkIndex& chunk) { return chunk.chunk_start_offset + 1 + 8 + 16; }
void PutLe64(std::vector<std::uint8_t>& b, std::size_t at, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (8 * i));
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
  for (int w = 0; w < 4; ++w) s.add_wheels()->set_fp(3000.0 + w + 0.5 * static_cast<double>(step % 17));
  return s;
}

struct Written {
  std::vector<std::string> payloads;
  std::vector<std::uint64_t> times;
};

// A file of `n` state messages at 1 kHz of log time, written with the given compression.
Written WriteStates(const std::filesystem::path& path, int n, mc::Compression c,
                    std::size_t chunk_bytes = 64 * 1024) {
  mc::WriterOptions o;
  o.compression = c;
  o.chunk_bytes = chunk_bytes;
  mc::Writer w(path, o);
  const auto* d = pb::VehicleState::descriptor();
  const std::uint16_t schema = w.AddSchema(d->full_name(), "protobuf", FileDescriptorSetOf(d));
  const std::uint16_t ch = w.AddChannel(schema, "vdyn/state/1", "protobuf",
                                        recorder::ChannelMetadata(transport::TopicId::kState, 1));
  w.WriteMetadata("vdyn.recording", {{"format", recorder::kFormatVersion}, {"domain", "7"}});
  Written out;
  for (int i = 0; i < n; ++i) {
    const std::string bytes = StateAt(static_cast<std::uint64_t>(i)).SerializeAsString();
    const std::uint64_t t = 1'700'000'000'000'000'000ull + static_cast<std::uint64_t>(i) * 1'000'000;
    w.WriteMessage(ch, static_cast<std::uint32_t>(i), t, t - 50'000,
                   {reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()});
    out.payloads.push_back(bytes);
    out.times.push_back(t);
  }
  w.Close();
  return out;
}

std::vector<std::string> ReadAll(const std::filesystem::path& path, mc::ScanResult* result = nullptr,
                                 bool lenient = false) {
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
    r.ReadChunk(ci, [&](const mc::Message& m) {
      ASSERT_LT(n, w.payloads.size());
      EXPECT_EQ(std::string(reinterpret_cast<const char*>(m.data.data()), m.data.size()), w.payloads[n++]);
    }, scratch);
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
  const std::span<const std::uint8_t> p(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
  EXPECT_EQ(recorder::wire::Number(p, 3), 987654u);            // step, a varint
  EXPECT_EQ(recorder::wire::Number(p, 21), 0x9e3779b97f4a7c15ull * 987655);  // state_hash, fixed64
  EXPECT_EQ(recorder::wire::Bytes(p, 2), "test");
  EXPECT_FALSE(recorder::wire::Number(p, 99).has_value());
  const std::span<const std::uint8_t> cut = p.first(p.size() - 3);
  EXPECT_FALSE(recorder::wire::ForEachField(cut, [](const auto&) { return true; }));
  const std::uint8_t bad[] = {0x0f, 0x01};  // wire type 7 does not exist
  EXPECT_FALSE(recorder::wire::ForEachField(bad, [](const auto&) { return true; }));
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
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 40; ++trial) {
    // Cuts everywhere: inside the magic, a record header, a chunk, the summary, the footer.
    std::size_t cut = trial < 6 ? std::vector<std::size_t>{3, 12, 30, whole.size() - 4, whole.size() - 30,
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
      EXPECT_THAT(e.reason(), ::testing::AnyOf(HasSubstr("truncated"), HasSubstr("ends without a data end"),
                                               HasSubstr("ends inside the MCAP magic")))
          << e.what();
    }
    if (cut < 8) continue;
    // Recover: a closed, indexed file with a prefix of the messages, every one intact.
    std::ostringstream log;
    recorder::RecoverOptions ro;
    ro.file = cut_path;
    ro.out = dir / ("rec" + std::to_string(trial) + ".mcap");
    ASSERT_EQ(recorder::RunRecover(ro, log), 0) << log.str();
    mc::ScanResult res;
    const std::vector<std::string> got = ReadAll(ro.out, &res);
    EXPECT_TRUE(res.complete);
    ASSERT_LE(got.size(), w.payloads.size());
    for (std::size_t i = 0; i < got.size(); ++i) ASSERT_EQ(got[i], w.payloads[i]) << "message " << i;
    // A cut in the data section loses at most the chunk it fell into (16 KiB of records,
    // about 180 messages); a cut after the data section loses nothing.
    EXPECT_GE(got.size() + 400, w.payloads.size() * std::min<std::size_t>(cut, whole.size()) / whole.size())
        << "cut at " << cut;
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
  EXPECT_THAT(log.str(), HasSubstr("1 damaged chunks dropped"));
  mc::ScanResult res;
  const std::vector<std::string> got = ReadAll(dir / "flipped-recovered.mcap", &res);
  EXPECT_TRUE(res.complete);
  std::uint64_t in_chunk = 0;
  std::vector<std::uint8_t> scratch;
  r.ReadChunk(chunks[2], [&](const mc::Message&) { ++in_chunk; }, scratch);
  EXPECT_EQ(got.size(), w.payloads.size() - in_chunk);

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
      r.ReadChunk(chunks[1], [](const mc::Message&) {}, scratch);
      FAIL() << "a chunk claiming " << kClaim << " bytes was read";
    } catch (const mc::McapError& e) {
      EXPECT_EQ(e.offset(), chunks[1].chunk_start_offset);
      EXPECT_THAT(e.reason(), HasSubstr(c.reason));
      EXPECT_THAT(e.reason(), HasSubstr("claims " + std::to_string(kClaim)));
    }
    EXPECT_LT(scratch.capacity(), std::size_t{16} << 20) << "the reader allocated what the chunk claims";
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

}  // namespace
}  // namespace vdyn

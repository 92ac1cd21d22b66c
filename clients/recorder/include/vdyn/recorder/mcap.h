// MCAP files (https://mcap.dev/spec), written and read by our own code: magic, opcode + length
// records, chunks (zstd or lz4 frames, or none) with message indexes, a summary with statistics,
// CRC-32 (zlib's) of chunks, of the data section and of the summary. docs/formats.md says what a
// vdyn recording puts in one.
//
// The writer appends chunk by chunk (a killed writer loses at most its open chunk); the reader
// maps the file and walks it record by record, checking every length against the file and every
// CRC, and refuses a truncated, corrupted, empty or foreign file with the file, the byte offset
// and the reason (McapError). A lenient scan stops at the first problem instead and says where:
// `recover` keeps what came before.
#pragma once

#include <atomic>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace vdyn::recorder {
class OutputFile;
}

namespace vdyn::mcap {

inline constexpr std::uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', 0x30, '\r', '\n'};

enum Op : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kAttachment = 0x09,
  kAttachmentIndex = 0x0A,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

// A bad file: which one, where, and why. what() reads "FILE: offset N: REASON".
// A read stopped because the command was asked to stop (Ctrl-C, SIGTERM): see StopReadsWhen.
class Interrupted : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// From now on every Reader's scan and chunk read checks `*flag` at each record and throws
// Interrupted once it is set (a signal handler sets it): a command that reads a whole file stops
// within a record, and its outputs, never committed, are removed as they unwind. nullptr: never.
void StopReadsWhen(const std::atomic<bool>* flag);

class McapError : public std::runtime_error {
 public:
  McapError(const std::filesystem::path& file, std::uint64_t offset, const std::string& reason);
  const std::filesystem::path& file() const { return file_; }
  std::uint64_t offset() const { return offset_; }
  const std::string& reason() const { return reason_; }

 private:
  std::filesystem::path file_;
  std::uint64_t offset_;
  std::string reason_;
};

using StringMap = std::map<std::string, std::string>;

struct Schema {
  std::uint16_t id = 0;
  std::string name;
  std::string encoding;
  std::string data;
};

struct Channel {
  std::uint16_t id = 0;
  std::uint16_t schema_id = 0;
  std::string topic;
  std::string message_encoding;
  StringMap metadata;
};

struct Message {
  std::uint16_t channel_id = 0;
  std::uint32_t sequence = 0;
  std::uint64_t log_time = 0;      // ns
  std::uint64_t publish_time = 0;  // ns
  std::span<const std::uint8_t> data;
  // No CRC of its own vouches for it: it lies in a chunk whose CRC is 0 ("not computed", which
  // the spec allows) or outside any chunk. Only the data section's CRC can cover it (whether it
  // did, a scan says at its end: ScanResult::data_crc).
  bool unchecked = false;
};

struct Metadata {
  std::string name;
  StringMap values;
};

struct ChunkIndex {
  std::uint64_t message_start_time = 0;
  std::uint64_t message_end_time = 0;
  std::uint64_t chunk_start_offset = 0;
  std::uint64_t chunk_length = 0;  // the whole record, opcode and length included
  std::map<std::uint16_t, std::uint64_t> message_index_offsets;
  std::uint64_t message_index_length = 0;
  std::string compression;
  std::uint64_t compressed_size = 0;
  std::uint64_t uncompressed_size = 0;
  std::uint32_t uncompressed_crc = 0;  // from the chunk record itself (0: none); not in the summary
};

struct Statistics {
  std::uint64_t message_count = 0;
  std::uint16_t schema_count = 0;
  std::uint32_t channel_count = 0;
  std::uint32_t attachment_count = 0;
  std::uint32_t metadata_count = 0;
  std::uint32_t chunk_count = 0;
  std::uint64_t message_start_time = 0;
  std::uint64_t message_end_time = 0;
  std::map<std::uint16_t, std::uint64_t> channel_message_counts;
};

enum class Compression { kNone, kZstd, kLz4 };
std::string_view CompressionName(Compression c);  // "", "zstd", "lz4"

// --- writing ------------------------------------------------------------------------------------

struct WriterOptions {
  Compression compression = Compression::kZstd;
  int zstd_level = 1;
  // A chunk is closed when its records reach this size or its messages span this much log time
  // (small chunks: a killed recorder loses little, and a reader can seek finely).
  std::size_t chunk_bytes = 1 << 20;
  std::uint64_t chunk_ns = 250'000'000;
  std::string profile;
  std::string library = "vdyn-recorder";
  // Files the new one must never replace: the command's inputs (recorder::OutputFile).
  std::vector<std::filesystem::path> inputs;
  // A live recording: a new file is written under its own name from its first byte, so a killed
  // recorder leaves it for `recover`. Otherwise (and when the file exists already, so it is not
  // lost before the new one is whole) the writer writes beside it and renames it at Close().
  bool live = false;
};

class Writer {
 public:
  // Creates `path` (parent folders too), or a file beside it that Close() renames to it (see
  // WriterOptions::live), and writes the magic and the header. Throws McapError, or
  // recorder::OutputError for a path that is one of options.inputs.
  Writer(const std::filesystem::path& path, WriterOptions options);
  // Closes (a destructor cannot report: call Close() to see errors). A file that is not live and
  // is destroyed by an exception is abandoned: the destination stays as it was.
  ~Writer();
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  // Schema and channel records go into the data section at once (before any message of theirs).
  std::uint16_t AddSchema(const std::string& name, const std::string& encoding,
                          const std::string& data);
  std::uint16_t AddChannel(std::uint16_t schema_id, const std::string& topic,
                           const std::string& message_encoding, const StringMap& metadata);
  void WriteMessage(std::uint16_t channel_id, std::uint32_t sequence, std::uint64_t log_time,
                    std::uint64_t publish_time, std::span<const std::uint8_t> data);
  void WriteMetadata(const std::string& name, const StringMap& values);
  // Closes the open chunk (written with its message indexes) and hands the bytes to the kernel.
  void Flush();
  // Flushes when the open chunk's first message is older than options.chunk_ns at `now_ns`
  // (log time): a quiet topic does not keep its last messages in memory, where a kill loses them.
  void FlushIfOlder(std::uint64_t now_ns);
  // Flushes, then writes the data end, the summary (schemas, channels, statistics, metadata and
  // chunk indexes, summary offsets), the footer and the closing magic. Throws McapError.
  void Close();
  // Ends a file written beside its destination (WriterOptions::live over an existing file, or
  // not live) without giving it the destination's name: the destination stays as it was and the
  // bytes are removed. False (and nothing done) for a file written under its own name.
  bool Discard();

  std::uint64_t bytes_written() const { return offset_; }
  std::uint64_t messages() const { return stats_.message_count; }
  std::uint32_t chunks() const { return stats_.chunk_count; }
  std::uint64_t uncompressed_bytes() const { return uncompressed_total_; }
  const std::filesystem::path& path() const { return path_; }
  // Where the bytes go until Close(): path(), or the temporary file beside it.
  std::filesystem::path writing_to() const;
  // Messages written from now on go into chunks without a CRC (0, "not checked", as the spec
  // allows) until it is set back: `recover` keeps a source chunk that had none unchecked.
  // A change closes the open chunk. A file with such a chunk gets no data-section CRC either
  // (it would vouch for them).
  void SetChunkCrc(bool on);

 private:
  void Append(const std::string& bytes);  // to the file, updating the data CRC
  void CloseChunk();

  std::filesystem::path path_;
  WriterOptions options_;
  std::unique_ptr<recorder::OutputFile> out_;  // the file beside path_, when not written in place
  int fd_ = -1;
  bool chunk_crc_ = true;
  bool any_unchecked_ = false;
  bool closed_ = false;
  bool write_failed_ = false;  // a write failed part-way: the file ends in a torn record
  std::uint64_t offset_ = 0;
  std::uint32_t data_crc_ = 0;
  std::vector<Schema> schemas_;
  std::vector<Channel> channels_;
  std::vector<std::pair<std::string, std::pair<std::uint64_t, std::uint64_t>>> metadata_index_;
  std::vector<ChunkIndex> chunk_indexes_;
  Statistics stats_;
  std::uint64_t uncompressed_total_ = 0;
  // The open chunk.
  std::string chunk_;
  std::uint64_t chunk_start_ = 0, chunk_end_ = 0;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> chunk_index_;
  struct Codec;
  std::unique_ptr<Codec> codec_;
};

// --- reading ------------------------------------------------------------------------------------

// What a scan visits, in file order. Message data points into the mapped file or into the
// decompressed chunk: valid during the call only.
struct Visitor {
  std::function<void(const Schema&)> on_schema;
  std::function<void(const Channel&)> on_channel;
  std::function<void(const Message&, std::uint64_t record_offset)> on_message;
  std::function<void(const Metadata&, std::uint64_t record_offset)> on_metadata;
  // A chunk, before its messages; false skips it (not decompressed, not checked).
  std::function<bool(const ChunkIndex&)> on_chunk;
  // Progress: bytes of the file scanned so far.
  std::function<void(std::uint64_t)> on_progress;
};

// A part of a file a lenient scan could not use, and why.
struct Damage {
  std::uint64_t offset = 0;  // where it starts
  std::uint64_t length = 0;  // bytes left out (0: nothing skipped, a remark)
  std::string what;
  // A dropped chunk: its place and log-time range (from its record, when its header reads) and
  // the messages its message indexes list (0 when they are damaged too).
  std::optional<ChunkIndex> chunk;
  std::uint64_t messages = 0;
};

struct ScanResult {
  bool complete = false;         // reached the data end record and a valid summary and footer
  bool summary = false;          // the footer points at a summary (a valid one when complete)
  std::uint64_t good_until = 0;  // offset just past the last whole, valid record
  std::string problem;           // lenient scans: the first problem (empty when none)
  std::uint64_t problem_offset = 0;
  std::uint64_t messages = 0;
  std::uint32_t chunks = 0;
  std::uint32_t chunks_skipped = 0;      // lenient: chunks dropped for a bad CRC, compression...
  std::uint32_t chunks_duplicated = 0;   // lenient: exact copies of an earlier chunk, dropped
  std::uint32_t records_skipped = 0;     // lenient: other damaged records, and runs of bytes
  std::uint32_t chunks_unchecked = 0;    // chunks whose CRC is 0
  std::uint64_t messages_unchecked = 0;  // messages delivered with Message::unchecked
  // The data end record's CRC of every byte before it.
  enum class DataCrc {
    kNotReached,
    kAbsent,
    kMatched,
    kMismatched
  } data_crc = DataCrc::kNotReached;
  std::optional<Statistics> statistics;  // from the summary
  std::vector<Damage> damage;            // lenient: everything left out, in file order
};

class MappedFile;
class Scanner;

class Reader {
 public:
  // kSalvage (`recover`): a magic with one damaged byte of eight is read all the same (a scan
  // says so); a foreign file is refused either way.
  enum class Open { kWhole, kSalvage };
  // Maps the file; refuses an empty file, a foreign one (no MCAP magic), a folder, a FIFO or a
  // device. Another program may truncate or rewrite the file while it is read: every read then
  // throws McapError naming the file and the offset (never SIGBUS).
  explicit Reader(const std::filesystem::path& path, Open open = Open::kWhole);
  // The bytes of a file held in memory (tests, fuzzers), named `name` in messages; they must
  // outlive the reader.
  Reader(std::filesystem::path name, std::span<const std::uint8_t> bytes, Open open = Open::kWhole);
  ~Reader();
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;

  // Walks every record of the data section in order, checking lengths, opcodes, CRCs and
  // decompression, then the summary and footer. Strict (the default): throws McapError at the
  // first problem. Lenient (`recover`): never relies on the summary or the footer, and leaves
  // out only what is damaged, saying so in ScanResult::damage - a chunk that fails its CRC or
  // decompression, a record whose fields do not read (its frame is whole: the scan goes on after
  // it), a run of bytes without a readable record (a damaged length: the scan resynchronises on
  // the next valid record, two valid frames in a row), an exact copy of an earlier chunk.
  // Messages on a channel no readable record defines, and channels naming an unknown schema, are
  // delivered all the same: the caller decides (their records may be the damaged ones).
  // Schema and channel records count wherever the spec allows them: the data section, chunks
  // (before the messages that use them), the summary. A second record of an id must be
  // identical to the first (strict: refused at its offset, saying what differs; lenient: left
  // out as damage - with its chunk, when it is in one - and the first stands); identical ones
  // are delivered again. A chunk holds schema,
  // channel and message records, private ones (skipped, as are opcodes past this version's);
  // any other record in it makes the chunk malformed (lenient: dropped as damage).
  ScanResult Scan(const Visitor& visitor, bool lenient = false) const;

  // The summary when the file has a valid footer and summary (nullopt otherwise): channels,
  // schemas, statistics and chunk indexes without reading the data - unless the summary lacks
  // channels it counts messages of (or has none at all): those, and their schemas, are then
  // taken from the data section and the chunks (as far as they read).
  struct Summary {
    std::vector<Schema> schemas;
    std::vector<Channel> channels;
    std::optional<Statistics> statistics;
    std::vector<ChunkIndex> chunk_indexes;
    std::vector<std::pair<std::string, std::uint64_t>> metadata_offsets;
  };
  std::optional<Summary> ReadSummary() const;

  // The messages of one chunk (decompressed and checked), for random access (play, seek).
  void ReadChunk(const ChunkIndex& chunk, const std::function<void(const Message&)>& on_message,
                 std::vector<std::uint8_t>& scratch) const;
  // Every chunk's place and time range, from the summary or (without one) a scan of the records.
  std::vector<ChunkIndex> Chunks() const;
  // Throws McapError when the file shrank under the reader since it was opened (another program
  // truncated it): what was read since may be zeroes. Every read here checks it; a caller that
  // keeps reading a Message's data after its callback returned checks it again.
  void CheckIntact() const;

  std::uint64_t size() const { return size_; }
  const std::filesystem::path& path() const { return path_; }
  std::string header_library() const;  // the writer's name, from the header record

 private:
  friend class Scanner;
  void CheckMagic();
  std::optional<Summary> SummaryOf() const;
  void CompleteSummary(Summary& s) const;
  [[noreturn]] void Fail(std::uint64_t offset, const std::string& reason) const;
  std::filesystem::path path_;
  Open open_ = Open::kWhole;
  std::unique_ptr<MappedFile> map_;  // null for bytes held in memory
  const std::uint8_t* data_ = nullptr;
  std::uint64_t size_ = 0;
  bool magic_damaged_ = false;
};

// CRC-32 (zlib) of bytes, continuing from `crc` (0 to start).
std::uint32_t Crc32(std::uint32_t crc, std::span<const std::uint8_t> bytes);

}  // namespace vdyn::mcap

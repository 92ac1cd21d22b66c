#include "vdyn/recorder/mcap.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <exception>
#include <limits>
#include <map>
#include <set>
#include <tuple>
#include <type_traits>

#include <lz4frame.h>
#include <zlib.h>
#include <zstd.h>

#include "mapped_file.h"
#include "vdyn/base/text.h"
#include "vdyn/recorder/output_file.h"

namespace vdyn::mcap {
namespace {

// The largest chunk we agree to decompress (writers close chunks at a few MiB): a corrupted size
// field or a decompression bomb must not make us allocate without bound.
constexpr std::uint64_t kMaxUncompressedChunk = 1ull << 30;
constexpr std::uint64_t kFooterContent = 8 + 8 + 4;
constexpr std::uint64_t kFooterRecord = 1 + 8 + kFooterContent;

const char* OpName(std::uint8_t op) {
  switch (op) {
    case kHeader:
      return "header";
    case kFooter:
      return "footer";
    case kSchema:
      return "schema";
    case kChannel:
      return "channel";
    case kMessage:
      return "message";
    case kChunk:
      return "chunk";
    case kMessageIndex:
      return "message index";
    case kChunkIndex:
      return "chunk index";
    case kAttachment:
      return "attachment";
    case kAttachmentIndex:
      return "attachment index";
    case kStatistics:
      return "statistics";
    case kMetadata:
      return "metadata";
    case kMetadataIndex:
      return "metadata index";
    case kSummaryOffset:
      return "summary offset";
    case kDataEnd:
      return "data end";
    default:
      return op >= 0x80 ? "private" : "unknown";
  }
}

// --- serialisation (little endian, as the spec says)
// ----------------------------------------------

void PutU8(std::string& o, std::uint8_t v) {
  o.push_back(static_cast<char>(v));
}
template <class T>
void PutLe(std::string& o, T v) {
  for (std::size_t i = 0; i < sizeof(T); ++i) {
    o.push_back(static_cast<char>(static_cast<std::uint8_t>(v >> (8 * i))));
  }
}
void PutU16(std::string& o, std::uint16_t v) {
  PutLe(o, v);
}
void PutU32(std::string& o, std::uint32_t v) {
  PutLe(o, v);
}
void PutU64(std::string& o, std::uint64_t v) {
  PutLe(o, v);
}
void PutStr(std::string& o, std::string_view s) {
  PutU32(o, static_cast<std::uint32_t>(s.size()));
  o.append(s);
}
void PutMap(std::string& o, const StringMap& m) {
  std::string body;
  for (const auto& [k, v] : m) {
    PutStr(body, k);
    PutStr(body, v);
  }
  PutStr(o, body);
}
// Opens a record: opcode and a length placeholder; CloseRecord fills the length in.
std::size_t OpenRecord(std::string& o, Op op) {
  PutU8(o, op);
  const std::size_t at = o.size();
  PutU64(o, 0);
  return at;
}
void CloseRecord(std::string& o, std::size_t at) {
  const std::uint64_t len = o.size() - at - 8;
  for (int i = 0; i < 8; ++i)
    o[at + static_cast<std::size_t>(i)] = static_cast<char>(len >> (8 * i));
}

// Reads fields of one record's content; a field past the end is a malformed record.
struct Malformed {
  std::string what;
};
class Cursor {
 public:
  explicit Cursor(std::span<const std::uint8_t> b) : b_(b) {}
  template <class T>
  T Le(const char* field) {
    Need(sizeof(T), field);
    T v = 0;
    for (std::size_t i = 0; i < sizeof(T); ++i)
      v |= static_cast<T>(static_cast<T>(b_[pos_ + i]) << (8 * i));
    pos_ += sizeof(T);
    return v;
  }
  std::uint8_t U8(const char* f) { return Le<std::uint8_t>(f); }
  std::uint16_t U16(const char* f) { return Le<std::uint16_t>(f); }
  std::uint32_t U32(const char* f) { return Le<std::uint32_t>(f); }
  std::uint64_t U64(const char* f) { return Le<std::uint64_t>(f); }
  std::span<const std::uint8_t> Take(std::uint64_t n, const char* field) {
    Need(n, field);
    auto s = b_.subspan(pos_, static_cast<std::size_t>(n));
    pos_ += static_cast<std::size_t>(n);
    return s;
  }
  std::string Str(const char* field) {
    const std::uint32_t n = U32(field);
    auto s = Take(n, field);
    return {reinterpret_cast<const char*>(s.data()), s.size()};
  }
  StringMap Map(const char* field) {
    const std::uint32_t n = U32(field);
    Cursor m(Take(n, field));
    StringMap out;
    while (!m.done()) {
      std::string k = m.Str(field);
      out[k] = m.Str(field);
    }
    return out;
  }
  std::span<const std::uint8_t> Rest() { return Take(b_.size() - pos_, "data"); }
  bool done() const { return pos_ == b_.size(); }
  std::size_t pos() const { return pos_; }

 private:
  void Need(std::uint64_t n, const char* field) const {
    if (n > b_.size() - pos_) {
      throw Malformed{std::string("field '") + field + "' runs past the record's end (" +
                      std::to_string(n) + " bytes wanted, " + std::to_string(b_.size() - pos_) +
                      " left)"};
    }
  }
  std::span<const std::uint8_t> b_;
  std::size_t pos_ = 0;
};

Schema ParseSchema(std::span<const std::uint8_t> c) {
  Cursor r(c);
  Schema s;
  s.id = r.U16("id");
  s.name = r.Str("name");
  s.encoding = r.Str("encoding");
  const std::uint32_t n = r.U32("data");
  auto d = r.Take(n, "data");
  s.data.assign(reinterpret_cast<const char*>(d.data()), d.size());
  return s;
}

Channel ParseChannel(std::span<const std::uint8_t> c) {
  Cursor r(c);
  Channel ch;
  ch.id = r.U16("id");
  ch.schema_id = r.U16("schema_id");
  ch.topic = r.Str("topic");
  ch.message_encoding = r.Str("message_encoding");
  ch.metadata = r.Map("metadata");
  return ch;
}

Message ParseMessage(std::span<const std::uint8_t> c) {
  Cursor r(c);
  Message m;
  m.channel_id = r.U16("channel_id");
  m.sequence = r.U32("sequence");
  m.log_time = r.U64("log_time");
  m.publish_time = r.U64("publish_time");
  m.data = r.Rest();
  return m;
}

struct ChunkHeader {
  ChunkIndex index;
  std::uint32_t crc = 0;
  std::span<const std::uint8_t> records;
};

ChunkHeader ParseChunk(std::span<const std::uint8_t> c) {
  Cursor r(c);
  ChunkHeader h;
  h.index.message_start_time = r.U64("message_start_time");
  h.index.message_end_time = r.U64("message_end_time");
  h.index.uncompressed_size = r.U64("uncompressed_size");
  h.crc = r.U32("uncompressed_crc");
  h.index.compression = r.Str("compression");
  const std::uint64_t n = r.U64("records");
  h.records = r.Take(n, "records");
  h.index.compressed_size = n;
  return h;
}

ChunkIndex ParseChunkIndex(std::span<const std::uint8_t> c) {
  Cursor r(c);
  ChunkIndex ci;
  ci.message_start_time = r.U64("message_start_time");
  ci.message_end_time = r.U64("message_end_time");
  ci.chunk_start_offset = r.U64("chunk_start_offset");
  ci.chunk_length = r.U64("chunk_length");
  const std::uint32_t n = r.U32("message_index_offsets");
  Cursor m(r.Take(n, "message_index_offsets"));
  while (!m.done()) {
    const std::uint16_t ch = m.U16("message_index_offsets");
    ci.message_index_offsets[ch] = m.U64("message_index_offsets");
  }
  ci.message_index_length = r.U64("message_index_length");
  ci.compression = r.Str("compression");
  ci.compressed_size = r.U64("compressed_size");
  ci.uncompressed_size = r.U64("uncompressed_size");
  return ci;
}

Statistics ParseStatistics(std::span<const std::uint8_t> c) {
  Cursor r(c);
  Statistics s;
  s.message_count = r.U64("message_count");
  s.schema_count = r.U16("schema_count");
  s.channel_count = r.U32("channel_count");
  s.attachment_count = r.U32("attachment_count");
  s.metadata_count = r.U32("metadata_count");
  s.chunk_count = r.U32("chunk_count");
  s.message_start_time = r.U64("message_start_time");
  s.message_end_time = r.U64("message_end_time");
  const std::uint32_t n = r.U32("channel_message_counts");
  Cursor m(r.Take(n, "channel_message_counts"));
  while (!m.done()) {
    const std::uint16_t ch = m.U16("channel_message_counts");
    s.channel_message_counts[ch] = m.U64("channel_message_counts");
  }
  return s;
}

Metadata ParseMetadata(std::span<const std::uint8_t> c) {
  Cursor r(c);
  Metadata m;
  m.name = r.Str("name");
  m.values = r.Map("metadata");
  return m;
}

// "a" or "an" before a record's name ("an attachment").
std::string WithArticle(std::string_view name) {
  return (name.empty() || std::string_view("aeiou").find(name[0]) == std::string_view::npos
              ? "a "
              : "an ") +
         std::string(name);
}

// Why a record of opcode `op` may not lie inside a chunk (empty when it may). The spec puts
// schema, channel and message records in chunks, and allows private records (0x80 and up) and
// records a later version defines (past the data end's opcode) there, which a reader skips. Any
// other record it defines is for elsewhere: a chunk in a chunk, say, would hide its messages
// from every reader that takes the chunk for read.
std::string NotInAChunk(std::uint8_t op) {
  if (op == kSchema || op == kChannel || op == kMessage || op > kDataEnd) return {};
  return WithArticle(OpName(op)) + " record (opcode " + base::FormatHex(op, 2) +
         "), which the spec does not allow inside a chunk (only schema, channel and message "
         "records): the chunk is malformed";
}

// What differs between two records of one schema or channel id ("" when nothing does).
std::string Quoted(const std::string& s) {
  return "'" + base::Quote(s, 60) + "'";
}
std::string Difference(const Schema& was, const Schema& is) {
  if (was.name != is.name) return "name " + Quoted(is.name) + ", was " + Quoted(was.name);
  if (was.encoding != is.encoding)
    return "encoding " + Quoted(is.encoding) + ", was " + Quoted(was.encoding);
  if (was.data != is.data) {
    return "data of " + std::to_string(is.data.size()) + " bytes, other than the " +
           std::to_string(was.data.size()) + " bytes it had";
  }
  return {};
}
std::string Difference(const Channel& was, const Channel& is) {
  if (was.topic != is.topic) return "topic " + Quoted(is.topic) + ", was " + Quoted(was.topic);
  if (was.schema_id != is.schema_id) {
    return "schema " + std::to_string(is.schema_id) + ", was " + std::to_string(was.schema_id);
  }
  if (was.message_encoding != is.message_encoding) {
    return "message encoding " + Quoted(is.message_encoding) + ", was " +
           Quoted(was.message_encoding);
  }
  for (const auto& [k, v] : is.metadata) {
    const auto it = was.metadata.find(k);
    if (it == was.metadata.end()) return "metadata " + Quoted(k) + " added";
    if (it->second != v) {
      return "metadata " + Quoted(k) + " = " + Quoted(v) + ", was " + Quoted(it->second);
    }
  }
  for (const auto& [k, v] : was.metadata) {
    if (is.metadata.count(k) == 0) return "metadata " + Quoted(k) + " dropped";
  }
  return {};
}

// The first record of a schema or channel id, and where it is (its offset, or its chunk's).
template <class T>
struct Defined {
  T record;
  std::uint64_t offset = 0;
};
template <class T>
using Definitions = std::map<std::uint16_t, Defined<T>>;

// Why `again` may not stand beside the record of its id in `known` (empty: it is the first, or
// identical). The spec wants every record of one id identical: were they not, one reader would
// take the first and another the last, and file the same messages under different topics.
template <class T>
std::string Redefinition(const T& again, const Definitions<T>& known) {
  const auto it = known.find(again.id);
  if (it == known.end()) return {};
  const std::string diff = Difference(it->second.record, again);
  if (diff.empty()) return {};
  return std::string(std::is_same_v<T, Schema> ? "schema " : "channel ") +
         std::to_string(again.id) + " is defined again with other content (" + diff +
         ") than at offset " + std::to_string(it->second.offset) +
         ": the spec wants every record of one id identical, and readers would disagree on what "
         "its messages are";
}

// Makes room in `out` past `used` for more decompressed bytes: doubles (from 64 KiB), never past
// `claimed`. The buffer follows the bytes a decompressor really produces, so a chunk that claims
// gigabytes but holds a few broken bytes costs a few bytes, not a gigabyte of zeroes.
// False when `out` already holds `claimed` bytes.
bool GrowDecompressed(std::vector<std::uint8_t>& out, std::size_t used, std::uint64_t claimed) {
  if (used >= claimed) return false;
  constexpr std::size_t kFirst = std::size_t{64} << 10;
  std::size_t size = std::max<std::size_t>(kFirst, used * 2);
  if (size > claimed) size = static_cast<std::size_t>(claimed);
  if (out.size() < size) out.resize(size);
  return true;
}

// What zstd frames' headers state their content sums to: ZSTD_CONTENTSIZE_UNKNOWN when a frame
// does not say, ZSTD_CONTENTSIZE_ERROR when the bytes are not whole zstd frames.
unsigned long long ZstdStatedSize(std::span<const std::uint8_t> in) {
  if (in.empty()) return ZSTD_CONTENTSIZE_ERROR;
  unsigned long long total = 0;
  bool known = true;
  std::size_t at = 0;
  while (at < in.size()) {
    const unsigned long long n = ZSTD_getFrameContentSize(in.data() + at, in.size() - at);
    const std::size_t frame = ZSTD_findFrameCompressedSize(in.data() + at, in.size() - at);
    if (n == ZSTD_CONTENTSIZE_ERROR || ZSTD_isError(frame) || frame == 0)
      return ZSTD_CONTENTSIZE_ERROR;
    if (n == ZSTD_CONTENTSIZE_UNKNOWN) {
      known = false;
    } else {
      // Saturates just past what any chunk may claim (total <= limit + 1: no overflow).
      total = n > kMaxUncompressedChunk
                  ? kMaxUncompressedChunk + 1
                  : std::min<unsigned long long>(total + n, kMaxUncompressedChunk + 1);
    }
    at += frame;
  }
  return known ? total : ZSTD_CONTENTSIZE_UNKNOWN;
}

// Decompresses a chunk's records into `out` (exactly uncompressed_size bytes) or says why not.
std::string Decompress(const std::string& compression, std::span<const std::uint8_t> in,
                       std::uint64_t uncompressed_size, std::vector<std::uint8_t>& out) {
  if (uncompressed_size > kMaxUncompressedChunk) {
    return "a chunk claims " + std::to_string(uncompressed_size) +
           " uncompressed bytes, more than this reader accepts (" +
           std::to_string(kMaxUncompressedChunk) + ")";
  }
  const auto gave = [uncompressed_size](const char* codec, std::size_t got) {
    return std::string(codec) + " gave " +
           (got > uncompressed_size ? "more than " + std::to_string(uncompressed_size)
                                    : std::to_string(got)) +
           " bytes, the chunk claims " + std::to_string(uncompressed_size);
  };
  if (compression.empty()) {
    if (in.size() != uncompressed_size) {
      return "an uncompressed chunk of " + std::to_string(in.size()) + " bytes claims " +
             std::to_string(uncompressed_size);
    }
    out.resize(in.size());
    // An empty chunk has no bytes to copy (and memcpy must not see its null pointers).
    if (!in.empty()) std::memcpy(out.data(), in.data(), in.size());
    return {};
  }
  if (compression == "zstd") {
    // The frame headers may state their content sizes: a mismatch is refused before any work.
    const unsigned long long stated = ZstdStatedSize(in);
    if (stated == ZSTD_CONTENTSIZE_ERROR) return "zstd: the chunk's records are not zstd frames";
    if (stated != ZSTD_CONTENTSIZE_UNKNOWN && stated != uncompressed_size) {
      return "zstd: the frames hold " + std::to_string(stated) + " bytes, the chunk claims " +
             std::to_string(uncompressed_size);
    }
    thread_local std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> ctx(ZSTD_createDCtx(),
                                                                          &ZSTD_freeDCtx);
    ZSTD_DCtx_reset(ctx.get(), ZSTD_reset_session_only);
    ZSTD_inBuffer src{in.data(), in.size(), 0};
    std::size_t used = 0;
    std::uint8_t probe =
        0;  // once `out` holds all it claims: one byte more tells whether it goes on
    out.clear();
    while (true) {
      const bool full = used == out.size() && !GrowDecompressed(out, used, uncompressed_size);
      ZSTD_outBuffer dst =
          full ? ZSTD_outBuffer{&probe, 1, 0} : ZSTD_outBuffer{out.data(), out.size(), used};
      const std::size_t src_before = src.pos, dst_before = dst.pos;
      const std::size_t left = ZSTD_decompressStream(ctx.get(), &dst, &src);
      if (ZSTD_isError(left)) return std::string("zstd: ") + ZSTD_getErrorName(left);
      if (full && dst.pos > 0) return gave("zstd", used + 1);
      if (!full) used = dst.pos;
      if (left == 0 && src.pos == src.size) break;  // the last frame is complete
      if (src.pos == src_before && dst.pos == dst_before) {
        return "zstd: the frame ends early";
      }
    }
    if (used != uncompressed_size) return gave("zstd", used);
    out.resize(used);
    return {};
  }
  if (compression == "lz4") {
    LZ4F_dctx* dctx = nullptr;
    if (LZ4F_isError(LZ4F_createDecompressionContext(&dctx, LZ4F_VERSION))) {
      return "lz4: cannot create a decompression context";
    }
    std::size_t in_pos = 0, out_pos = 0;
    std::uint8_t probe =
        0;  // once `out` holds all it claims: one byte more tells whether it goes on
    std::string why;
    out.clear();
    while (true) {
      const bool full = out_pos == out.size() && !GrowDecompressed(out, out_pos, uncompressed_size);
      std::size_t src = in.size() - in_pos, dst = full ? 1 : out.size() - out_pos;
      const std::size_t hint = LZ4F_decompress(dctx, full ? &probe : out.data() + out_pos, &dst,
                                               in.data() + in_pos, &src, nullptr);
      if (LZ4F_isError(hint)) {
        why = std::string("lz4: ") + LZ4F_getErrorName(hint);
        break;
      }
      if (full && dst > 0) {
        why = gave("lz4", out_pos + 1);
        break;
      }
      in_pos += src;
      out_pos += dst;
      if (hint == 0) break;  // the frame is complete
      if (src == 0 && dst == 0) {
        why = "lz4: the frame ends early";
        break;
      }
    }
    LZ4F_freeDecompressionContext(dctx);
    if (!why.empty()) return why;
    if (out_pos != uncompressed_size) return gave("lz4", out_pos);
    out.resize(out_pos);
    return {};
  }
  return "unknown compression '" + compression + "'";
}

}  // namespace

std::uint32_t Crc32(std::uint32_t crc, std::span<const std::uint8_t> bytes) {
  // zlib takes 32-bit lengths: feed it in pieces.
  uLong c = crc;
  std::size_t at = 0;
  while (at < bytes.size()) {
    const std::size_t n = std::min<std::size_t>(bytes.size() - at, 1u << 30);
    c = crc32(c, bytes.data() + at, static_cast<uInt>(n));
    at += n;
  }
  return static_cast<std::uint32_t>(c);
}

namespace {
std::uint32_t Crc32(std::uint32_t crc, std::string_view s) {
  return mcap::Crc32(crc, {reinterpret_cast<const std::uint8_t*>(s.data()), s.size()});
}
}  // namespace

McapError::McapError(const std::filesystem::path& file, std::uint64_t offset,
                     const std::string& reason)
    : std::runtime_error(file.string() + ": offset " + std::to_string(offset) + ": " + reason),
      file_(file),
      offset_(offset),
      reason_(reason) {}

std::string_view CompressionName(Compression c) {
  switch (c) {
    case Compression::kNone:
      return "";
    case Compression::kZstd:
      return "zstd";
    case Compression::kLz4:
      return "lz4";
  }
  return "";
}

// --- writer -------------------------------------------------------------------------------------

struct Writer::Codec {
  ZSTD_CCtx* zstd = nullptr;
  std::vector<char> out;
  ~Codec() {
    if (zstd != nullptr) ZSTD_freeCCtx(zstd);
  }
  // Compressed bytes, or an empty view when compression does not pay (then stored as is).
  std::string_view Compress(Compression c, int level, const std::string& in) {
    if (c == Compression::kZstd) {
      if (zstd == nullptr) zstd = ZSTD_createCCtx();
      out.resize(ZSTD_compressBound(in.size()));
      const std::size_t n =
          ZSTD_compressCCtx(zstd, out.data(), out.size(), in.data(), in.size(), level);
      if (ZSTD_isError(n) || n >= in.size()) return {};
      return {out.data(), n};
    }
    if (c == Compression::kLz4) {
      LZ4F_preferences_t prefs{};
      prefs.frameInfo.contentSize = in.size();
      out.resize(LZ4F_compressFrameBound(in.size(), &prefs));
      const std::size_t n =
          LZ4F_compressFrame(out.data(), out.size(), in.data(), in.size(), &prefs);
      if (LZ4F_isError(n) || n >= in.size()) return {};
      return {out.data(), n};
    }
    return {};
  }
};

Writer::Writer(const std::filesystem::path& path, WriterOptions options)
    : path_(path), options_(std::move(options)), codec_(std::make_unique<Codec>()) {
  recorder::CheckNotAnInput(path, options_.inputs);
  // A name ending with a slash, a block device or a socket is refused before anything (a
  // folder) is created; a FIFO or a device is written into as a stream (recorder::OutputFile).
  const bool stream = recorder::CheckOutputKind(path) == recorder::OutputKind::kStream;
  if (options_.live && !stream) {
    // A new file, written where it will stay (O_EXCL: never over one that appeared meanwhile).
    std::error_code ec;
    if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd_ < 0 && errno != EEXIST) {
      throw McapError(path, 0, std::string("cannot create the file: ") + std::strerror(errno));
    }
  }
  if (fd_ < 0) {
    out_ = std::make_unique<recorder::OutputFile>(path, options_.inputs);
    fd_ = out_->fd();
  }
  std::string head(reinterpret_cast<const char*>(kMagic), sizeof kMagic);
  const std::size_t at = OpenRecord(head, kHeader);
  PutStr(head, options_.profile);
  PutStr(head, options_.library);
  CloseRecord(head, at);
  Append(head);
  stats_.message_start_time = std::numeric_limits<std::uint64_t>::max();
}

Writer::~Writer() {
  if (!closed_ && out_ && !options_.live && std::uncaught_exceptions() > 0) {
    out_->Abandon();  // an error is unwinding: the destination stays as it was
    fd_ = -1;
    return;
  }
  if (!closed_ && out_ && write_failed_) {
    // A write failed part-way (a full disk): the file ends in a torn record. Closing it now (the
    // disk freed meanwhile) would put a summary after that and take the destination's name, while
    // the error told to recover the temporary file. A recording keeps it as it is; an export
    // leaves the destination as it was.
    if (options_.live) {
      out_->Keep();
    } else {
      out_->Abandon();
    }
    fd_ = -1;
    return;
  }
  try {
    Close();
  } catch (const std::exception&) {
    // Reported by an explicit Close(); a destructor cannot.
  }
  if (out_) {
    // Not renamed (Close failed): a live recording keeps its bytes under the temporary name.
    if (options_.live) {
      out_->Keep();
    } else {
      out_->Abandon();
    }
  } else if (fd_ >= 0) {
    ::close(fd_);
  }
}

bool Writer::Discard() {
  if (closed_ || !out_ || out_->stream()) return false;
  out_->Abandon();
  fd_ = -1;
  closed_ = true;
  return true;
}

std::filesystem::path Writer::writing_to() const {
  return out_ ? out_->temp() : path_;
}

void Writer::SetChunkCrc(bool on) {
  if (on == chunk_crc_) return;
  CloseChunk();
  chunk_crc_ = on;
}

void Writer::Append(const std::string& bytes) {
  if (fd_ < 0) throw McapError(path_, offset_, "the file is closed");
  data_crc_ = Crc32(data_crc_, bytes);
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      write_failed_ = true;
      // Named by the file it writes: a recording (live) stays under its temporary name, which the
      // user must be told to recover (the destination, an older recording perhaps, is untouched).
      throw McapError(writing_to(), offset_ + done,
                      std::string("write failed: ") + std::strerror(errno) +
                          (options_.live ? std::string("; what was written stays in this file: "
                                                       "vdyn-recorder recover ") +
                                               writing_to().string() + " -o OUT.mcap"
                                         : std::string()));
    }
    done += static_cast<std::size_t>(n);
  }
  offset_ += bytes.size();
}

std::uint16_t Writer::AddSchema(const std::string& name, const std::string& encoding,
                                const std::string& data) {
  Schema s{static_cast<std::uint16_t>(schemas_.size() + 1), name, encoding, data};
  std::string rec;
  const std::size_t at = OpenRecord(rec, kSchema);
  PutU16(rec, s.id);
  PutStr(rec, s.name);
  PutStr(rec, s.encoding);
  PutStr(rec, s.data);
  CloseRecord(rec, at);
  Append(rec);
  schemas_.push_back(std::move(s));
  return schemas_.back().id;
}

std::uint16_t Writer::AddChannel(std::uint16_t schema_id, const std::string& topic,
                                 const std::string& message_encoding, const StringMap& metadata) {
  if (channels_.size() >= 65535) throw McapError(path_, offset_, "more than 65535 channels");
  Channel c{static_cast<std::uint16_t>(channels_.size() + 1), schema_id, topic, message_encoding,
            metadata};
  std::string rec;
  const std::size_t at = OpenRecord(rec, kChannel);
  PutU16(rec, c.id);
  PutU16(rec, c.schema_id);
  PutStr(rec, c.topic);
  PutStr(rec, c.message_encoding);
  PutMap(rec, c.metadata);
  CloseRecord(rec, at);
  Append(rec);
  channels_.push_back(std::move(c));
  return channels_.back().id;
}

void Writer::WriteMessage(std::uint16_t channel_id, std::uint32_t sequence, std::uint64_t log_time,
                          std::uint64_t publish_time, std::span<const std::uint8_t> data) {
  if (chunk_.empty()) {
    chunk_start_ = log_time;
    chunk_end_ = log_time;
  }
  chunk_start_ = std::min(chunk_start_, log_time);
  chunk_end_ = std::max(chunk_end_, log_time);
  chunk_index_[channel_id].emplace_back(log_time, chunk_.size());
  const std::size_t at = OpenRecord(chunk_, kMessage);
  PutU16(chunk_, channel_id);
  PutU32(chunk_, sequence);
  PutU64(chunk_, log_time);
  PutU64(chunk_, publish_time);
  chunk_.append(reinterpret_cast<const char*>(data.data()), data.size());
  CloseRecord(chunk_, at);
  ++stats_.message_count;
  ++stats_.channel_message_counts[channel_id];
  stats_.message_start_time = std::min(stats_.message_start_time, log_time);
  stats_.message_end_time = std::max(stats_.message_end_time, log_time);
  if (chunk_.size() >= options_.chunk_bytes || chunk_end_ - chunk_start_ >= options_.chunk_ns) {
    CloseChunk();
  }
}

void Writer::WriteMetadata(const std::string& name, const StringMap& values) {
  std::string rec;
  const std::size_t at = OpenRecord(rec, kMetadata);
  PutStr(rec, name);
  PutMap(rec, values);
  CloseRecord(rec, at);
  metadata_index_.push_back({name, {offset_, rec.size()}});
  Append(rec);
  ++stats_.metadata_count;
}

void Writer::CloseChunk() {
  if (chunk_.empty()) return;
  std::string_view packed = codec_->Compress(options_.compression, options_.zstd_level, chunk_);
  std::string_view compression = CompressionName(options_.compression);
  if (packed.empty()) {  // does not pay (or compression off): store as is
    packed = chunk_;
    compression = "";
  }
  ChunkIndex ci;
  ci.message_start_time = chunk_start_;
  ci.message_end_time = chunk_end_;
  ci.chunk_start_offset = offset_;
  ci.compression = std::string(compression);
  ci.compressed_size = packed.size();
  ci.uncompressed_size = chunk_.size();
  std::string rec;
  rec.reserve(packed.size() + 128);
  const std::size_t at = OpenRecord(rec, kChunk);
  PutU64(rec, chunk_start_);
  PutU64(rec, chunk_end_);
  PutU64(rec, chunk_.size());
  PutU32(rec, chunk_crc_ ? Crc32(0, chunk_) : 0);
  any_unchecked_ = any_unchecked_ || !chunk_crc_;
  PutStr(rec, compression);
  PutU64(rec, packed.size());
  rec.append(packed);
  CloseRecord(rec, at);
  ci.chunk_length = rec.size();
  // One message index per channel of the chunk, in channel order, right after it.
  for (auto& [channel, entries] : chunk_index_) {
    std::stable_sort(entries.begin(), entries.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    ci.message_index_offsets[channel] = offset_ + rec.size();
    const std::size_t mi = OpenRecord(rec, kMessageIndex);
    PutU16(rec, channel);
    PutU32(rec, static_cast<std::uint32_t>(entries.size() * 16));
    for (const auto& [t, off] : entries) {
      PutU64(rec, t);
      PutU64(rec, off);
    }
    CloseRecord(rec, mi);
  }
  ci.message_index_length = rec.size() - ci.chunk_length;
  Append(rec);
  uncompressed_total_ += chunk_.size();
  chunk_indexes_.push_back(std::move(ci));
  ++stats_.chunk_count;
  chunk_.clear();
  chunk_index_.clear();
}

void Writer::Flush() {
  CloseChunk();
}

void Writer::FlushIfOlder(std::uint64_t now_ns) {
  if (!chunk_.empty() && now_ns >= chunk_start_ && now_ns - chunk_start_ >= options_.chunk_ns) {
    CloseChunk();
  }
}

void Writer::Close() {
  if (closed_ || fd_ < 0) return;
  closed_ = true;
  CloseChunk();
  std::string end;
  std::size_t at = OpenRecord(end, kDataEnd);
  // Every byte before this record; none when a chunk went without a CRC (the data section's
  // would vouch for bytes nobody could check).
  PutU32(end, any_unchecked_ ? 0 : data_crc_);
  CloseRecord(end, at);
  Append(end);

  // The summary, grouped by opcode, each group located by a summary offset record.
  const std::uint64_t summary_start = offset_;
  std::string sum;
  std::vector<std::tuple<Op, std::uint64_t, std::uint64_t>> groups;
  auto group = [&](Op op, const std::function<void()>& write) {
    const std::size_t before = sum.size();
    write();
    if (sum.size() > before) groups.emplace_back(op, summary_start + before, sum.size() - before);
  };
  group(kSchema, [&] {
    for (const Schema& s : schemas_) {
      const std::size_t a = OpenRecord(sum, kSchema);
      PutU16(sum, s.id);
      PutStr(sum, s.name);
      PutStr(sum, s.encoding);
      PutStr(sum, s.data);
      CloseRecord(sum, a);
    }
  });
  group(kChannel, [&] {
    for (const Channel& c : channels_) {
      const std::size_t a = OpenRecord(sum, kChannel);
      PutU16(sum, c.id);
      PutU16(sum, c.schema_id);
      PutStr(sum, c.topic);
      PutStr(sum, c.message_encoding);
      PutMap(sum, c.metadata);
      CloseRecord(sum, a);
    }
  });
  group(kStatistics, [&] {
    const std::size_t a = OpenRecord(sum, kStatistics);
    const bool any = stats_.message_count > 0;
    PutU64(sum, stats_.message_count);
    PutU16(sum, static_cast<std::uint16_t>(schemas_.size()));
    PutU32(sum, static_cast<std::uint32_t>(channels_.size()));
    PutU32(sum, 0);
    PutU32(sum, stats_.metadata_count);
    PutU32(sum, stats_.chunk_count);
    PutU64(sum, any ? stats_.message_start_time : 0);
    PutU64(sum, any ? stats_.message_end_time : 0);
    std::string counts;
    for (const auto& [ch, n] : stats_.channel_message_counts) {
      PutU16(counts, ch);
      PutU64(counts, n);
    }
    PutStr(sum, counts);
    CloseRecord(sum, a);
  });
  group(kMetadataIndex, [&] {
    for (const auto& [name, where] : metadata_index_) {
      const std::size_t a = OpenRecord(sum, kMetadataIndex);
      PutU64(sum, where.first);
      PutU64(sum, where.second);
      PutStr(sum, name);
      CloseRecord(sum, a);
    }
  });
  group(kChunkIndex, [&] {
    for (const ChunkIndex& ci : chunk_indexes_) {
      const std::size_t a = OpenRecord(sum, kChunkIndex);
      PutU64(sum, ci.message_start_time);
      PutU64(sum, ci.message_end_time);
      PutU64(sum, ci.chunk_start_offset);
      PutU64(sum, ci.chunk_length);
      std::string offsets;
      for (const auto& [ch, off] : ci.message_index_offsets) {
        PutU16(offsets, ch);
        PutU64(offsets, off);
      }
      PutStr(sum, offsets);
      PutU64(sum, ci.message_index_length);
      PutStr(sum, ci.compression);
      PutU64(sum, ci.compressed_size);
      PutU64(sum, ci.uncompressed_size);
      CloseRecord(sum, a);
    }
  });
  const std::uint64_t summary_offset_start = summary_start + sum.size();
  for (const auto& [op, start, length] : groups) {
    const std::size_t a = OpenRecord(sum, kSummaryOffset);
    PutU8(sum, op);
    PutU64(sum, start);
    PutU64(sum, length);
    CloseRecord(sum, a);
  }
  PutU8(sum, kFooter);
  PutU64(sum, kFooterContent);
  PutU64(sum, summary_start);
  PutU64(sum, summary_offset_start);
  PutU32(sum, Crc32(0, sum));  // from the summary's start through summary_offset_start
  sum.append(reinterpret_cast<const char*>(kMagic), sizeof kMagic);
  Append(sum);
  if (out_) {
    fd_ = -1;  // the output file closes it
    try {
      out_->Commit();
    } catch (const recorder::OutputError& e) {
      throw McapError(path_, offset_, e.what());
    }
    out_.reset();
    return;
  }
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) {
    throw McapError(path_, offset_,
                    std::string("closing the file failed: ") + std::strerror(errno));
  }
}

// --- reader -------------------------------------------------------------------------------------

Reader::Reader(const std::filesystem::path& path, Open open) : path_(path), open_(open) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    throw McapError(path, 0, std::string("cannot open the file: ") + std::strerror(errno));
  }
  if (S_ISDIR(st.st_mode)) throw McapError(path, 0, "a directory, not an MCAP file");
  if (!S_ISREG(st.st_mode)) {
    throw McapError(path, 0,
                    "not a regular file (a FIFO, a device or a socket): a recording is read from "
                    "a file");
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
  if (size_ == 0) throw McapError(path, 0, "empty file (0 bytes): not an MCAP recording");
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0)
    throw McapError(path, 0, std::string("cannot open the file: ") + std::strerror(errno));
  map_ = std::make_unique<MappedFile>();
  const bool mapped = map_->Map(fd, size_);
  const int map_errno = errno;
  ::close(fd);
  if (!mapped) {
    throw McapError(path, 0, std::string("cannot map the file: ") + std::strerror(map_errno));
  }
  data_ = map_->data();
  CheckMagic();
}

Reader::Reader(std::filesystem::path name, std::span<const std::uint8_t> bytes, Open open)
    : path_(std::move(name)), open_(open), data_(bytes.data()), size_(bytes.size()) {
  if (size_ == 0) throw McapError(path_, 0, "empty file (0 bytes): not an MCAP recording");
  CheckMagic();
}

Reader::~Reader() = default;

void Reader::CheckMagic() {
  const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(size_, 8));
  int wrong = 0;
  for (std::size_t i = 0; i < n; ++i) wrong += data_[i] != kMagic[i] ? 1 : 0;
  CheckIntact();
  // Salvaging: one damaged byte of eight still says MCAP (a foreign file differs in most).
  if (wrong > 0 && !(open_ == Open::kSalvage && size_ >= 8 && wrong == 1)) {
    std::string start;
    for (std::size_t i = 0; i < n; ++i) {
      char b[8];
      std::snprintf(b, sizeof b, "%s%02x", i ? " " : "", data_[i]);
      start += b;
    }
    throw McapError(path_, 0,
                    "not an MCAP file: it starts with bytes " + start +
                        ", not the MCAP magic 89 4d 43 41 50 30 0d 0a");
  }
  magic_damaged_ = wrong > 0;
  if (size_ < 8) throw McapError(path_, size_, "truncated: the file ends inside the MCAP magic");
}

namespace {
std::atomic<const std::atomic<bool>*> g_stop_reads{nullptr};
}  // namespace

void StopReadsWhen(const std::atomic<bool>* flag) {
  g_stop_reads.store(flag);
}

void Reader::CheckIntact() const {
  if (const std::atomic<bool>* stop = g_stop_reads.load(std::memory_order_relaxed);
      stop != nullptr && stop->load(std::memory_order_relaxed)) {
    throw Interrupted(path_.string() + ": interrupted (Ctrl-C or SIGTERM) while it was read");
  }
  if (!map_) return;
  if (const std::optional<std::uint64_t> at = map_->fault()) {
    Fail(*at, "the file changed while it was read: it no longer reaches this offset (it held " +
                  std::to_string(size_) +
                  " bytes when it was opened); another program truncated or rewrote it - read "
                  "it again once it is whole");
  }
}

void Reader::Fail(std::uint64_t offset, const std::string& reason) const {
  throw McapError(path_, offset, reason);
}

std::string Reader::header_library() const {
  if (size_ < 17 || data_[8] != kHeader) return {};
  std::string library;
  try {
    const std::uint64_t len = Cursor({data_ + 9, 8}).U64("length");
    if (len > size_ - 17) return {};
    Cursor r({data_ + 17, static_cast<std::size_t>(len)});
    r.Str("profile");
    library = r.Str("library");
  } catch (const Malformed&) {
    library.clear();
  }
  CheckIntact();
  return library;
}

namespace {

// One record's frame: where it is and what it holds.
struct Frame {
  std::uint8_t op = 0;
  std::uint64_t offset = 0;
  std::span<const std::uint8_t> content;
  std::uint64_t end() const { return offset + 9 + content.size(); }
};

// What a file cut short still holds: every whole chunk (the same advice wherever a read finds
// that the recorder did not finish the file).
const std::string kRecoverAdvice = "`vdyn-recorder recover` salvages what is whole";

// The frame at `pos`, or why there is none (truncation).
std::string FrameAt(const std::uint8_t* data, std::uint64_t size, std::uint64_t pos, Frame& f) {
  if (size - pos < 9) {
    return "truncated: a record starts here but the file ends " + std::to_string(size - pos) +
           " bytes later (a record header needs 9); " + kRecoverAdvice;
  }
  f.op = data[pos];
  f.offset = pos;
  std::uint64_t len = 0;
  for (int i = 0; i < 8; ++i)
    len |= static_cast<std::uint64_t>(data[pos + 1 + static_cast<std::uint64_t>(i)]) << (8 * i);
  if (f.op == 0) return "opcode 0 is not a record: the file is corrupted";
  if (len > size - pos - 9) {
    return std::string("truncated: a ") + OpName(f.op) + " record of " + std::to_string(len) +
           " bytes starts here but only " + std::to_string(size - pos - 9) +
           " bytes follow (the recorder was stopped before it closed the file?); " + kRecoverAdvice;
  }
  f.content = {data + pos + 9, static_cast<std::size_t>(len)};
  return {};
}

// An opcode the spec defines (a header only comes first).
bool KnownOp(std::uint8_t op) {
  return op > kHeader && op <= kDataEnd;
}

// Whether a record's content reads exactly as its opcode says: every field within the record,
// nothing left over. A record whose length or opcode was damaged almost never does.
bool ContentReads(std::uint8_t op, std::span<const std::uint8_t> c) {
  try {
    Cursor r(c);
    switch (op) {
      case kHeader:
        r.Str("profile");
        r.Str("library");
        return r.done();
      case kSchema: {
        if (r.U16("id") == 0) return false;
        r.Str("name");
        r.Str("encoding");
        r.Str("data");
        return r.done();
      }
      case kChannel:
        r.U16("id");
        r.U16("schema_id");
        r.Str("topic");
        r.Str("message_encoding");
        r.Map("metadata");
        return r.done();
      case kMessage:
        return c.size() >= 22;
      case kChunk: {
        const ChunkHeader h = ParseChunk(c);
        return (h.index.compression.empty() || h.index.compression == "zstd" ||
                h.index.compression == "lz4") &&
               h.records.data() + h.records.size() == c.data() + c.size();
      }
      case kMessageIndex: {
        r.U16("channel_id");
        const std::uint32_t n = r.U32("records");
        return n % 16 == 0 && r.Take(n, "records").size() == n && r.done();
      }
      case kMetadata:
        r.Str("name");
        r.Map("metadata");
        return r.done();
      case kAttachment: {
        r.U64("log_time");
        r.U64("create_time");
        r.Str("name");
        r.Str("media_type");
        const std::uint64_t n = r.U64("data");
        r.Take(n, "data");
        r.U32("crc");
        return r.done();
      }
      case kDataEnd:
        return c.size() == 4;
      case kFooter:
        return c.size() == kFooterContent;
      case kStatistics:
        ParseStatistics(c);
        return true;
      case kChunkIndex:
        ParseChunkIndex(c);
        return true;
      case kSummaryOffset:
        return c.size() == 17;
      case kMetadataIndex:
        r.U64("offset");
        r.U64("length");
        r.Str("name");
        return r.done();
      default:
        return false;  // unknown and private records: no telling
    }
  } catch (const Malformed&) {
    return false;
  }
}

// Records of the summary section: met in the data section, they are damage (a flipped opcode)
// or say the data end was lost.
bool SummaryOnly(std::uint8_t op) {
  return op == kStatistics || op == kChunkIndex || op == kSummaryOffset || op == kMetadataIndex ||
         op == kAttachmentIndex || op == kFooter;
}

}  // namespace

// One scan of a file (Reader::Scan), as its stages: where a verified summary starts (lenient),
// the data section record by record, then the summary and footer. A strict scan throws at the
// first problem; a lenient one (`recover`) trusts a record boundary only when the record checks
// out - a known opcode, a length that fits, a content that reads exactly, followed by another
// record - and otherwise scans on for the next one that does. It takes the data section for
// ended only at a data end whose CRC holds or that the footer's verified summary follows.
class Scanner {
 public:
  Scanner(const Reader& reader, const Visitor& v, bool lenient)
      : r_(reader), v_(v), lenient_(lenient), data_(reader.data_), size_(reader.size_) {}

  ScanResult Run() {
    res_.good_until = 8;
    if (r_.magic_damaged_) {
      Problem(0, "the MCAP magic at the start is damaged (one byte differs)");
      res_.damage.push_back({0, 0, res_.problem, std::nullopt, 0});
    }
    if (lenient_) FindVerifiedSummary();
    if (!DataSection()) return res_;
    SummarySection();
    r_.CheckIntact();
    return res_;
  }

  // The offset of the next trustworthy record at or after `from` and before `limit`.
  std::optional<std::uint64_t> NextRecord(std::uint64_t from, std::uint64_t limit) const {
    for (std::uint64_t p = from; p < limit && p + 9 <= size_; ++p) {
      if (!KnownOp(data_[p])) continue;
      Frame f;
      if (FrameAt(data_, size_, p, f).empty() && Trusted(f)) return p;
    }
    return std::nullopt;
  }

 private:
  // --- checks ---
  // A record a lenient scan may step over by its length: its content reads exactly as its
  // opcode says, and another record (or the end of the file, or the closing magic) follows it.
  bool Trusted(const Frame& f) const {
    if (f.op == kHeader ? f.offset != 8 : !KnownOp(f.op)) return false;
    // Most records read to their last byte exactly, which a wrong length breaks; a message (its
    // payload takes the rest) and two summary records do not: another record must follow them.
    if (f.op == kMessage || f.op == kStatistics || f.op == kChunkIndex) {
      const std::uint64_t next = f.end();
      const bool followed = next == size_ || size_ - next < 9 || KnownOp(data_[next]) ||
                            (size_ - next == 8 && std::memcmp(data_ + next, kMagic, 8) == 0);
      if (!followed) return false;
    }
    return ContentReads(f.op, f.content);
  }

  // Lenient scans: where the summary starts when the footer and the closing magic read and the
  // summary's CRC holds (the footer vouches for it). The data section cannot reach past it.
  void FindVerifiedSummary() {
    if (size_ < 8 + kFooterRecord + 8) return;
    const std::uint64_t footer = size_ - 8 - kFooterRecord;
    if (std::memcmp(data_ + size_ - 8, kMagic, 8) != 0 || data_[footer] != kFooter ||
        Cursor({data_ + footer + 1, 8}).U64("length") != kFooterContent) {
      return;
    }
    Cursor r({data_ + footer + 9, static_cast<std::size_t>(kFooterContent)});
    std::uint64_t start = r.U64("summary_start");
    r.U64("summary_offset_start");
    const std::uint32_t stored = r.U32("summary_crc");
    if (start == 0) start = footer;  // no summary: the footer follows the data end
    if (start < 8 + 9 || start > footer || stored == 0) return;
    const std::uint32_t got =
        Crc32(0, std::span<const std::uint8_t>(
                     data_ + start, static_cast<std::size_t>(footer + 1 + 8 + 16 - start)));
    r_.CheckIntact();
    if (got == stored) summary_at_ = start;
  }

  // --- problems ---
  void Problem(std::uint64_t at, const std::string& why) {
    if (!lenient_) r_.Fail(at, why);
    if (res_.problem.empty()) {
      res_.problem = why;
      res_.problem_offset = at;
    }
  }
  Damage& Damaged(std::uint64_t at, std::uint64_t length, const std::string& why) {
    Problem(at, why);
    res_.damage.push_back({at, length, why, std::nullopt, 0});
    return res_.damage.back();
  }
  // Lenient: leaves out what starts at `pos_` up to the next trustworthy record (or the verified
  // summary, or the end of the file). False when nothing follows.
  bool SkipToNextRecord(const std::string& why) {
    const std::uint64_t limit = summary_at_.value_or(size_);
    const std::optional<std::uint64_t> next = NextRecord(pos_ + 1, limit);
    r_.CheckIntact();
    const std::uint64_t to = next.value_or(limit);
    ++res_.records_skipped;
    lost_chunk_ = kNone;
    if (!next && !summary_at_) {
      Damaged(pos_, size_ - pos_, why);
      return false;
    }
    Damaged(pos_, to - pos_,
            why + "; skipped " + std::to_string(to - pos_) +
                (next ? " bytes to the next valid record" : " bytes to the summary"));
    pos_ = to;
    return true;
  }

  // --- the data section ---
  // False: the scan stopped (a lenient scan's result says why).
  bool DataSection() {
    pos_ = 8;
    while (!data_end_) {
      if (v_.on_progress && pos_ - last_progress_ > (16u << 20)) {
        v_.on_progress(pos_);
        last_progress_ = pos_;
      }
      r_.CheckIntact();
      if (summary_at_ && pos_ >= *summary_at_) {
        // The data end record is damaged or missing: the verified summary starts here.
        Damaged(pos_, 0,
                "the data end record is damaged or missing; the data section ends at the "
                "summary, which the footer's CRC vouches for");
        return false;
      }
      if (pos_ == size_) {
        Problem(pos_,
                "the file ends without a data end record and footer: the recorder did not "
                "close it (killed?); " +
                    kRecoverAdvice);
        return false;
      }
      Frame f;
      if (std::string why = FrameAt(data_, size_, pos_, f); !why.empty()) {
        // A closed file (its footer and summary whole) is not truncated: a length or opcode was
        // damaged, most likely the record before's, whose length led here (a flipped bit in a
        // message index's length was reported as a truncation 4 MB further on).
        if (!lenient_ && !summary_at_ && why.rfind("truncated", 0) == 0) FindVerifiedSummary();
        if (summary_at_ && why.rfind("truncated", 0) == 0 && KnownOp(data_[pos_])) {
          why = std::string("corrupted: a ") + OpName(data_[pos_]) + " record at offset " +
                std::to_string(pos_) +
                " claims more bytes than the data section holds (the file is closed: its footer "
                "and summary are whole, so it is not cut short): its length is damaged; " +
                kRecoverAdvice;
        } else if (summary_at_ && why.rfind("truncated", 0) == 0 && prev_op_ != 0) {
          why = "corrupted: the bytes at offset " + std::to_string(pos_) +
                " do not read as a record (the file is closed: its footer and summary are whole, "
                "so it is not cut short); the record before, a " + OpName(prev_op_) +
                " at offset " + std::to_string(prev_offset_) + " of " +
                std::to_string(prev_length_) + " bytes, may have a damaged length; " +
                kRecoverAdvice;
        }
        if (!lenient_) r_.Fail(pos_, why);
        if (!SkipToNextRecord(why)) return false;
        continue;
      }
      if (pos_ == 8 && f.op != kHeader) {
        Problem(pos_,
                std::string("the first record is a ") + OpName(f.op) + " record, not the header");
        res_.damage.push_back({pos_, 0, res_.problem, std::nullopt, 0});
      }
      if (lenient_ && !Trusted(f)) {
        if (!SkipToNextRecord(Untrusted(f))) return false;
        continue;
      }
      if (f.op != kMessageIndex) lost_chunk_ = kNone;
      prev_op_ = f.op;
      prev_offset_ = f.offset;
      prev_length_ = f.content.size();
      if (!Record(f)) continue;  // it moved pos_ itself
      pos_ = f.end();
      res_.good_until = pos_;
    }
    return !stopped_;
  }

  // Why a lenient scan does not trust a record.
  std::string Untrusted(const Frame& f) const {
    if (f.op == kHeader && f.offset != 8) return "a second header record (a damaged opcode?)";
    if (!KnownOp(f.op) && f.op != kHeader) {
      return std::string("a record of ") + (f.op >= 0x80 ? "private" : "unknown") + " opcode " +
             base::FormatHex(f.op, 2) + ": a damaged opcode, or another writer's record";
    }
    return std::string("a malformed ") + OpName(f.op) + " record (" +
           std::to_string(f.content.size()) +
           " bytes): its fields do not read as one (a damaged opcode or length)";
  }

  // One record; false when it set pos_ itself (skipped).
  bool Record(const Frame& f) {
    try {
      switch (f.op) {
        case kHeader:
          if (pos_ != 8) r_.Fail(pos_, "a second header record");  // strict only (untrusted)
          {
            Cursor c(f.content);
            c.Str("profile");
            c.Str("library");
          }
          return true;
        case kSchema: {
          const Schema s = ParseSchema(f.content);
          if (s.id == 0) throw Malformed{"a schema with id 0"};
          if (!Define(s, f, schemas_)) return true;
          schema_known_[s.id] = true;
          if (v_.on_schema) v_.on_schema(s);
          return true;
        }
        case kChannel: {
          const Channel c = ParseChannel(f.content);
          if (Define(c, f, channels_)) OnChannel(c);
          return true;
        }
        case kMessage:
          OnLooseMessage(ParseMessage(f.content));
          return true;
        case kChunk:
          OnChunk(f);
          return true;
        case kMessageIndex:
          if (lost_chunk_ != kNone) {
            Cursor c(f.content);
            c.U16("channel_id");
            res_.damage[lost_chunk_].messages += c.U32("records") / 16;
          }
          return true;
        case kMetadata: {
          const Metadata m = ParseMetadata(f.content);
          r_.CheckIntact();
          if (v_.on_metadata) v_.on_metadata(m, pos_);
          return true;
        }
        case kDataEnd:
          return OnDataEnd(f);
        default:
          if (SummaryOnly(f.op)) return OnSummaryRecord(f);
          return true;  // attachments, private records: nothing to check here
      }
    } catch (const Malformed& e) {
      // Strict: the file is refused. Lenient: the record checked out as a whole (Trusted), so
      // only a field's meaning is wrong: leave it out.
      const std::string why = std::string("a malformed ") + OpName(f.op) + " record: " + e.what;
      if (!lenient_) r_.Fail(pos_, why);
      Damaged(pos_, f.end() - pos_,
              why + " (skipped " + std::to_string(f.end() - pos_) + " bytes)");
      ++res_.records_skipped;
      lost_chunk_ = kNone;
      pos_ = f.end();
      return false;
    }
  }

  // A schema or channel record of the data section: the first of its id, or one identical to
  // it. Another is refused (strict) or left out (lenient: the first stands, and the scan says
  // so). False when it is left out.
  template <class T>
  bool Define(const T& rec, const Frame& f, Definitions<T>& known) {
    if (const std::string why = Redefinition(rec, known); !why.empty()) {
      if (!lenient_) r_.Fail(pos_, why);
      Damaged(pos_, f.end() - pos_, why + "; left out, the first stands");
      ++res_.records_skipped;
      return false;
    }
    known.try_emplace(rec.id, Defined<T>{rec, pos_});
    return true;
  }

  void OnChannel(const Channel& c) {
    if (c.schema_id != 0 && !schema_known_[c.schema_id]) {
      const std::string why = "channel " + std::to_string(c.id) + " names schema " +
                              std::to_string(c.schema_id) + ", which no schema record defines";
      if (!lenient_) r_.Fail(pos_, why);
      Damaged(pos_, 0, why);
    }
    channel_known_[c.id] = true;
    if (v_.on_channel) v_.on_channel(c);
  }

  void OnLooseMessage(Message m) {
    if (!channel_known_[m.channel_id]) {
      const std::string why = "a message on channel " + std::to_string(m.channel_id) +
                              ", which no channel record defines";
      if (!lenient_) r_.Fail(pos_, why);
      // No CRC of its own and no channel before it: as likely another record whose opcode was
      // damaged (a channel record reads as a message) as a message. Left out.
      Damaged(pos_, 9 + m.data.size() + 22,
              why + ", outside any chunk (a damaged opcode?): left out");
      ++res_.records_skipped;
      return;
    }
    m.unchecked = true;  // only the data section's CRC covers it
    ++res_.messages;
    ++counted_[m.channel_id];
    ++res_.messages_unchecked;
    r_.CheckIntact();
    if (v_.on_message) v_.on_message(m, pos_);
    r_.CheckIntact();
  }

  // A summary record in the data section: the summary itself when the footer vouches for it
  // (strict scans: the data end is missing), else damage (a flipped opcode).
  bool OnSummaryRecord(const Frame& f) {
    if (!lenient_) {
      if (f.op == kFooter) r_.Fail(pos_, "a footer before the data end record");
      return true;
    }
    const std::string name = OpName(f.op);
    const std::string why = std::string(name[0] == 'a' || name[0] == 'u' ? "an " : "a ") + name +
                            " record inside the data section, which no verified summary follows "
                            "(a damaged opcode, or a summary whose footer is damaged)";
    if (!SkipToNextRecord(why)) stopped_ = data_end_ = true;
    return false;
  }

  bool OnDataEnd(const Frame& f) {
    Cursor c(f.content);
    const std::uint32_t stored = c.U32("data_section_crc");
    const bool crc_holds =
        stored != 0 &&
        stored == Crc32(0, std::span<const std::uint8_t>(data_, static_cast<std::size_t>(pos_)));
    r_.CheckIntact();
    // Lenient: believed when its CRC holds, or the verified summary follows it, or (no verified
    // summary) nothing of the data section's kinds follows it.
    if (lenient_ && !crc_holds && !(summary_at_ && *summary_at_ == f.end()) &&
        !(!summary_at_ && !DataFollows(f.end()))) {
      const bool more = SkipToNextRecord(
          "a data end record that neither its CRC nor the summary confirms, with records of the "
          "data section behind it (a damaged opcode?)");
      if (!more) stopped_ = data_end_ = true;
      return false;
    }
    data_end_ = true;
    if (stored == 0) {
      res_.data_crc = ScanResult::DataCrc::kAbsent;
      return true;
    }
    res_.data_crc = crc_holds ? ScanResult::DataCrc::kMatched : ScanResult::DataCrc::kMismatched;
    if (!crc_holds) {
      const std::uint32_t crc =
          Crc32(0, std::span<const std::uint8_t>(data_, static_cast<std::size_t>(pos_)));
      Problem(pos_, "data section CRC mismatch (stored " + base::FormatHex(stored, 8) +
                        ", computed " + base::FormatHex(crc, 8) + "): the file is corrupted");
      res_.damage.push_back({pos_, 0,
                             "data section CRC mismatch (stored " + base::FormatHex(stored, 8) +
                                 ", computed " + base::FormatHex(crc, 8) +
                                 "): some byte before it is damaged; what no chunk CRC checks is "
                                 "unchecked",
                             std::nullopt, 0});
    }
    return true;
  }

  // Whether a record of the data section's own kinds (a chunk, a message, metadata) can be
  // found from `from` on.
  bool DataFollows(std::uint64_t from) const {
    for (std::uint64_t p = from; p + 9 <= size_;) {
      const std::optional<std::uint64_t> next = NextRecord(p, size_);
      if (!next) return false;
      const std::uint8_t op = data_[*next];
      if (op == kChunk || op == kMessage || op == kMetadata || op == kAttachment) return true;
      Frame f;
      FrameAt(data_, size_, *next, f);
      p = f.end();
    }
    return false;
  }

  void OnChunk(const Frame& f) {
    ChunkHeader h = ParseChunk(f.content);
    h.index.chunk_start_offset = pos_;
    h.index.chunk_length = f.end() - pos_;
    h.index.uncompressed_crc = h.crc;
    if (lenient_ && IsCopy(h, f)) return;
    if (v_.on_chunk && !v_.on_chunk(h.index)) {
      read_every_chunk_ = false;
      return;
    }
    std::string why =
        Decompress(h.index.compression, h.records, h.index.uncompressed_size, scratch_);
    r_.CheckIntact();
    if (why.empty() && h.crc != 0) {
      const std::uint32_t got =
          Crc32(0, std::span<const std::uint8_t>(scratch_.data(), scratch_.size()));
      if (got != h.crc) {
        why = "chunk CRC mismatch (stored " + base::FormatHex(h.crc, 8) + ", computed " +
              base::FormatHex(got, 8) + "): the file is corrupted";
      }
    }
    if (why.empty()) why = InnerRecords(scratch_);
    if (!why.empty()) {
      if (!lenient_) r_.Fail(pos_, why);
      // The chunk's frame is whole: drop the chunk, keep going.
      ++res_.chunks_skipped;
      Damaged(pos_, f.end() - pos_, why + " (chunk dropped)").chunk = h.index;
      lost_chunk_ = res_.damage.size() - 1;
      return;
    }
    DeliverInner(scratch_, h.crc == 0);
    if (h.crc == 0) ++res_.chunks_unchecked;
    ++res_.chunks;
  }

  // Lenient: an exact copy of an earlier chunk is dropped (its messages are kept once).
  bool IsCopy(const ChunkHeader& h, const Frame& f) {
    const auto key = std::make_tuple(h.crc, h.index.uncompressed_size, h.index.message_start_time,
                                     h.records.size());
    const auto [it, fresh] = seen_.try_emplace(key, pos_);
    if (fresh) return false;
    Frame first;
    FrameAt(data_, size_, it->second, first);
    if (first.content.size() != f.content.size() ||
        std::memcmp(first.content.data(), f.content.data(), f.content.size()) != 0) {
      return false;
    }
    Damaged(pos_, f.end() - pos_,
            "an exact copy of the chunk at offset " + std::to_string(it->second) +
                " (dropped: its messages are kept once)");
    ++res_.chunks_duplicated;
    return true;
  }

  // A chunk's records: checked first (framing, opcodes, ids), delivered only when all are good.
  // Schema and channel records count from where they stand: a message may use a channel the
  // chunk defines before it (the official writers put them there, where first used).
  std::string InnerRecords(std::span<const std::uint8_t> recs) {
    inner_.clear();
    chunk_schemas_.clear();
    chunk_channels_.clear();
    for (std::uint64_t p = 0; p < recs.size();) {
      Frame f;
      std::string why = FrameAt(recs.data(), recs.size(), p, f);
      if (why.empty()) why = NotInAChunk(f.op);
      if (why.empty()) {
        try {
          why = InnerRecord(f);
        } catch (const Malformed& e) {
          why = std::string("a malformed ") + OpName(f.op) + " record: " + e.what;
        }
      }
      if (!why.empty()) return "inside the chunk, byte " + std::to_string(p) + ": " + why;
      inner_.push_back(p);
      p = f.end();
    }
    return {};
  }

  // One record of a chunk, checked against what the file defined before it, the chunk's own
  // definitions included: why it is wrong (empty when it is not).
  std::string InnerRecord(const Frame& f) {
    if (f.op == kSchema) {
      const Schema s = ParseSchema(f.content);
      if (s.id == 0) return "a schema with id 0";
      return Pending(s, schemas_, chunk_schemas_);
    }
    if (f.op == kChannel) {
      const Channel c = ParseChannel(f.content);
      if (std::string why = Pending(c, channels_, chunk_channels_); !why.empty()) return why;
      if (c.schema_id != 0 && !schema_known_[c.schema_id] &&
          chunk_schemas_.count(c.schema_id) == 0 && !lenient_) {
        return "channel " + std::to_string(c.id) + " names schema " + std::to_string(c.schema_id) +
               ", which no schema record defines";
      }
    } else if (f.op == kMessage) {
      const Message m = ParseMessage(f.content);
      if (!channel_known_[m.channel_id] && chunk_channels_.count(m.channel_id) == 0 && !lenient_) {
        return "a message on channel " + std::to_string(m.channel_id) +
               ", which no channel record defines";
      }
    }
    return {};
  }

  // A schema or channel record of the chunk being checked: held for the chunk (the file's
  // definitions take it once the chunk is delivered whole), or why it conflicts.
  template <class T>
  std::string Pending(const T& rec, const Definitions<T>& file, Definitions<T>& chunk) {
    std::string why = Redefinition(rec, file);
    if (why.empty()) why = Redefinition(rec, chunk);
    if (why.empty()) chunk.try_emplace(rec.id, Defined<T>{rec, pos_});
    return why;
  }

  void DeliverInner(std::span<const std::uint8_t> recs, bool unchecked) {
    for (const std::uint64_t p : inner_) {
      Frame f;
      FrameAt(recs.data(), recs.size(), p, f);
      if (f.op == kSchema) {
        const Schema s = ParseSchema(f.content);
        schemas_.try_emplace(s.id, Defined<Schema>{s, pos_});
        schema_known_[s.id] = true;
        if (v_.on_schema) v_.on_schema(s);
      } else if (f.op == kChannel) {
        const Channel c = ParseChannel(f.content);
        channels_.try_emplace(c.id, Defined<Channel>{c, pos_});
        channel_known_[c.id] = true;
        if (v_.on_channel) v_.on_channel(c);
      } else if (f.op == kMessage) {
        Message m = ParseMessage(f.content);
        m.unchecked = unchecked;
        ++res_.messages;
        ++counted_[m.channel_id];
        if (unchecked) ++res_.messages_unchecked;
        if (v_.on_message) v_.on_message(m, pos_);
      }
    }
  }

  // --- the summary and the footer ---
  // The footer at the end of the file (and the magic after it), whose CRC covers the summary;
  // then the summary's records between the data end and the footer. A lenient scan needs none
  // of it (the caller rebuilds the summary), and only says what it found.
  void SummarySection() {
    const std::uint64_t summary_pos = pos_;
    if (size_ - pos_ < kFooterRecord + 8) {
      Problem(pos_, "truncated: the file ends after the data end record, before its footer; " +
                        kRecoverAdvice);
      return;
    }
    const std::uint64_t footer = size_ - 8 - kFooterRecord;
    if (std::memcmp(data_ + size_ - 8, kMagic, 8) != 0 || data_[footer] != kFooter ||
        Cursor({data_ + footer + 1, 8}).U64("length") != kFooterContent) {
      Problem(footer, "truncated: the file does not end with a footer record and the MCAP magic; " +
                          kRecoverAdvice);
      return;
    }
    Cursor r({data_ + footer + 9, static_cast<std::size_t>(kFooterContent)});
    const std::uint64_t summary_start = r.U64("summary_start");
    r.U64("summary_offset_start");
    const std::uint32_t stored = r.U32("summary_crc");
    res_.summary = summary_start != 0;
    if (stored != 0) {
      const std::uint32_t got = Crc32(
          0, std::span<const std::uint8_t>(
                 data_ + summary_pos, static_cast<std::size_t>(footer + 1 + 8 + 16 - summary_pos)));
      if (got != stored) {
        Problem(footer, "summary CRC mismatch (stored " + base::FormatHex(stored, 8) +
                            ", computed " + base::FormatHex(got, 8) + "): the file is corrupted");
        return;
      }
    }
    if (summary_start != 0 && summary_start != summary_pos) {
      Problem(footer, "the footer places the summary at offset " + std::to_string(summary_start) +
                          ", but it starts at " + std::to_string(summary_pos));
      return;
    }
    for (std::uint64_t pos = summary_pos; pos < footer;) {
      Frame f;
      if (const std::string why = FrameAt(data_, footer, pos, f); !why.empty()) {
        Problem(pos, why + " (in the summary)");
        return;
      }
      try {
        if (f.op == kStatistics) {
          res_.statistics = ParseStatistics(f.content);
          statistics_at_ = pos;
        }
        // The summary's copies of schema and channel records: the same as the data section's
        // (a reader that seeks by the summary takes these).
        std::string why;
        if (f.op == kSchema) why = SummaryCopy(ParseSchema(f.content), pos, schemas_);
        if (f.op == kChannel) why = SummaryCopy(ParseChannel(f.content), pos, channels_);
        if (!why.empty()) {
          Problem(pos, why + " (in the summary)");
          return;
        }
      } catch (const Malformed& e) {
        Problem(pos,
                std::string("a malformed ") + OpName(f.op) + " record in the summary: " + e.what);
        return;
      }
      pos = f.end();
    }
    if (const std::string why = StatisticsDisagree(); !why.empty()) {
      Problem(statistics_at_, why + " (in the summary)");
      return;
    }
    res_.complete = res_.problem.empty();
    if (v_.on_progress) v_.on_progress(size_);
  }

  // Why the summary's statistics do not describe the messages this scan read (empty when they
  // do, or when the scan left chunks unread): a reader that trusts the summary (Foxglove seeks by
  // it) would show another file than the one here.
  std::string StatisticsDisagree() const {
    if (!res_.statistics || !read_every_chunk_ || !res_.problem.empty()) return {};
    const Statistics& st = *res_.statistics;
    if (st.message_count != res_.messages) {
      return "the statistics count " + std::to_string(st.message_count) +
             " messages; the data section holds " + std::to_string(res_.messages);
    }
    for (const auto& [channel, n] : st.channel_message_counts) {
      const std::uint64_t here = counted_[channel];
      if (n != here) {
        return "the statistics count " + std::to_string(n) + " messages on channel " +
               std::to_string(channel) + "; the data section holds " + std::to_string(here);
      }
    }
    return {};
  }

  template <class T>
  static std::string SummaryCopy(const T& rec, std::uint64_t at, Definitions<T>& known) {
    std::string why = Redefinition(rec, known);
    if (why.empty()) known.try_emplace(rec.id, Defined<T>{rec, at});
    return why;
  }

  static constexpr std::size_t kNone = ~std::size_t{0};
  const Reader& r_;
  const Visitor& v_;
  const bool lenient_;
  const std::uint8_t* const data_;
  const std::uint64_t size_;
  ScanResult res_;
  std::uint64_t pos_ = 8;
  std::uint64_t last_progress_ = 0;
  bool data_end_ = false;
  bool stopped_ = false;  // lenient: nothing trustworthy follows (the result says why)
  std::optional<std::uint64_t> summary_at_;  // lenient: where a verified summary starts
  std::vector<bool> schema_known_ = std::vector<bool>(65536, false);
  std::vector<bool> channel_known_ = std::vector<bool>(65536, false);
  // The first record of each schema and channel id (a second must be identical), and those of
  // the chunk being checked, which count once it is delivered.
  Definitions<Schema> schemas_, chunk_schemas_;
  Definitions<Channel> channels_, chunk_channels_;
  // Messages read per channel, and whether every chunk was (a visitor may skip some), for the
  // check of the summary's statistics.
  std::vector<std::uint64_t> counted_ = std::vector<std::uint64_t>(65536, 0);
  bool read_every_chunk_ = true;
  std::uint64_t statistics_at_ = 0;
  std::vector<std::uint8_t> scratch_;
  std::vector<std::uint64_t> inner_;  // a chunk's records: their offsets
  // Chunks seen, by what their headers say, for telling an exact copy (lenient scans).
  std::map<std::tuple<std::uint32_t, std::uint64_t, std::uint64_t, std::uint64_t>, std::uint64_t>
      seen_;
  std::size_t lost_chunk_ = kNone;  // a dropped chunk's entry in res_.damage (its indexes count)
  std::uint8_t prev_op_ = 0;  // the last record read whole in the data section
  std::uint64_t prev_offset_ = 0, prev_length_ = 0;
};

ScanResult Reader::Scan(const Visitor& v, bool lenient) const {
  return Scanner(*this, v, lenient).Run();
}

std::optional<Reader::Summary> Reader::ReadSummary() const {
  std::optional<Summary> s = SummaryOf();
  CheckIntact();  // what it read was there
  if (s) CompleteSummary(*s);
  return s;
}

// The spec wants the summary to copy every schema and channel that its chunk indexes and
// statistics count messages of, but a writer may leave them in the data section alone, or in
// chunks (the official writers put them in the chunk where they are first used): a reader that
// seeks by the summary (play, export, verify) would not know their messages. They are taken from
// the data section then, reading chunks only until none is missing (a channel comes before its
// first message). A lenient scan: what cannot be read stays missing, and the scan of the command
// says why.
void Reader::CompleteSummary(Summary& s) const {
  std::set<std::uint16_t> channels, schemas;  // ids missing from the summary
  for (const ChunkIndex& c : s.chunk_indexes) {
    for (const auto& [id, offset] : c.message_index_offsets) channels.insert(id);
  }
  if (s.statistics) {
    for (const auto& [id, n] : s.statistics->channel_message_counts) channels.insert(id);
  }
  for (const Channel& c : s.channels) channels.erase(c.id);
  // No channel at all, yet messages: which ones, only the data section says.
  const bool all = s.channels.empty() && (!s.statistics || s.statistics->message_count > 0);
  const auto has_schema = [&s](std::uint16_t id) {
    return id == 0 || std::any_of(s.schemas.begin(), s.schemas.end(),
                                  [id](const Schema& x) { return x.id == id; });
  };
  for (const Channel& c : s.channels) {
    if (!has_schema(c.schema_id)) schemas.insert(c.schema_id);
  }
  if (channels.empty() && schemas.empty() && !all) return;
  std::map<std::uint16_t, Schema> found_schemas;
  Visitor v;
  v.on_schema = [&](const Schema& x) {
    found_schemas.try_emplace(x.id, x);
    schemas.erase(x.id);
  };
  std::set<std::uint16_t> added;
  v.on_channel = [&](const Channel& c) {
    if ((!all && channels.count(c.id) == 0) || !added.insert(c.id).second) return;
    channels.erase(c.id);
    s.channels.push_back(c);
    if (!has_schema(c.schema_id) && found_schemas.count(c.schema_id) == 0)
      schemas.insert(c.schema_id);
  };
  v.on_chunk = [&](const ChunkIndex&) { return all || !channels.empty() || !schemas.empty(); };
  Scan(v, /*lenient=*/true);
  for (const auto& [found_id, x] : found_schemas) {
    const std::uint16_t id = found_id;  // clang before 16 captures no structured binding
    if (has_schema(id)) continue;
    const bool used = std::any_of(s.channels.begin(), s.channels.end(),
                                  [id](const Channel& c) { return c.schema_id == id; });
    if (used) s.schemas.push_back(x);
  }
}

std::optional<Reader::Summary> Reader::SummaryOf() const {
  if (size_ < 8 + kFooterRecord + 8) return std::nullopt;
  if (std::memcmp(data_ + size_ - 8, kMagic, 8) != 0) return std::nullopt;
  const std::uint64_t footer = size_ - 8 - kFooterRecord;
  if (data_[footer] != kFooter) return std::nullopt;
  Cursor fr({data_ + footer + 1, 8 + kFooterContent});
  if (fr.U64("length") != kFooterContent) return std::nullopt;
  const std::uint64_t summary_start = fr.U64("summary_start");
  fr.U64("summary_offset_start");
  const std::uint32_t stored = fr.U32("summary_crc");
  if (summary_start == 0 || summary_start > footer) return std::nullopt;
  if (stored != 0) {
    const std::uint32_t got = Crc32(
        0,
        std::span<const std::uint8_t>(
            data_ + summary_start, static_cast<std::size_t>(footer + 1 + 8 + 16 - summary_start)));
    if (got != stored) {
      Fail(footer, "summary CRC mismatch (stored " + base::FormatHex(stored, 8) + ", computed " +
                       base::FormatHex(got, 8) + "): the file is corrupted");
    }
  }
  Summary s;
  Definitions<Schema> schemas;  // a second record of an id must be identical (the spec)
  Definitions<Channel> channels;
  const auto take = [this](const auto& rec, std::uint64_t at, auto& known, auto& into) {
    if (const std::string why = Redefinition(rec, known); !why.empty())
      Fail(at, why + " (in the summary)");
    if (known.try_emplace(rec.id, typename std::decay_t<decltype(known)>::mapped_type{rec, at})
            .second) {
      into.push_back(rec);
    }
  };
  std::uint64_t pos = summary_start;
  while (pos < footer) {
    Frame f;
    if (const std::string why = FrameAt(data_, footer, pos, f); !why.empty())
      Fail(pos, why + " (in the summary)");
    try {
      switch (f.op) {
        case kSchema:
          take(ParseSchema(f.content), pos, schemas, s.schemas);
          break;
        case kChannel:
          take(ParseChannel(f.content), pos, channels, s.channels);
          break;
        case kStatistics:
          s.statistics = ParseStatistics(f.content);
          break;
        case kChunkIndex:
          s.chunk_indexes.push_back(ParseChunkIndex(f.content));
          break;
        case kMetadataIndex: {
          Cursor r(f.content);
          const std::uint64_t off = r.U64("offset");
          r.U64("length");
          s.metadata_offsets.emplace_back(r.Str("name"), off);
          break;
        }
        default:
          break;
      }
    } catch (const Malformed& e) {
      Fail(pos, std::string("a malformed ") + OpName(f.op) + " record in the summary: " + e.what);
    }
    pos = f.end();
  }
  return s;
}

void Reader::ReadChunk(const ChunkIndex& chunk,
                       const std::function<void(const Message&)>& on_message,
                       std::vector<std::uint8_t>& scratch) const {
  const std::uint64_t pos = chunk.chunk_start_offset;
  if (pos >= size_) Fail(pos, "a chunk index points past the end of the file");
  Frame f;
  if (const std::string why = FrameAt(data_, size_, pos, f); !why.empty()) Fail(pos, why);
  if (f.op != kChunk)
    Fail(pos, std::string("a chunk index points at a ") + OpName(f.op) + " record");
  ChunkHeader h;
  try {
    h = ParseChunk(f.content);
  } catch (const Malformed& e) {
    Fail(pos, std::string("a malformed chunk record: ") + e.what);
  }
  const std::string why =
      Decompress(h.index.compression, h.records, h.index.uncompressed_size, scratch);
  CheckIntact();
  if (!why.empty()) Fail(pos, why);
  if (h.crc != 0) {
    const std::uint32_t got =
        Crc32(0, std::span<const std::uint8_t>(scratch.data(), scratch.size()));
    if (got != h.crc)
      Fail(pos, "chunk CRC mismatch (stored " + base::FormatHex(h.crc, 8) + ", computed " +
                    base::FormatHex(got, 8) + "): the file is corrupted");
  }
  std::uint64_t p = 0;
  while (p < scratch.size()) {
    Frame r;
    std::string bad = FrameAt(scratch.data(), scratch.size(), p, r);
    if (bad.empty()) bad = NotInAChunk(r.op);
    if (!bad.empty()) Fail(pos, "inside the chunk, byte " + std::to_string(p) + ": " + bad);
    if (r.op == kMessage) {
      try {
        Message m = ParseMessage(r.content);
        m.unchecked = h.crc == 0;
        on_message(m);
        CheckIntact();
      } catch (const Malformed& e) {
        Fail(pos, std::string("inside the chunk: a malformed message record: ") + e.what);
      }
    }
    p = r.end();
  }
}

std::vector<ChunkIndex> Reader::Chunks() const {
  // The summary's own chunk indexes (not completed: no channel is wanted here).
  std::optional<Summary> s = SummaryOf();
  CheckIntact();
  if (s && s->statistics && s->chunk_indexes.size() == s->statistics->chunk_count) {
    return s->chunk_indexes;
  }
  // No summary: walk the record frames (chunk contents are not read), up to the first problem.
  std::vector<ChunkIndex> out;
  std::uint64_t pos = 8;
  while (pos < size_) {
    Frame f;
    if (!FrameAt(data_, size_, pos, f).empty()) break;
    if (f.op == kDataEnd) break;
    if (f.op == kChunk) {
      try {
        ChunkHeader h = ParseChunk(f.content);
        h.index.chunk_start_offset = pos;
        h.index.chunk_length = f.end() - pos;
        out.push_back(h.index);
      } catch (const Malformed&) {
        break;
      }
    }
    pos = f.end();
  }
  CheckIntact();
  return out;
}

}  // namespace vdyn::mcap

// A vdyn recording: what goes into the MCAP file and how it is read back (docs/formats.md).
//
//   channel   one per topic and envelope key: "vdyn/state/1" (topic/vehicle), "vdyn/world/7e3f..."
//             (server topics are keyed by the server key, in hex); metadata dds_topic, key,
//             vehicle_id or server_key
//   schema    one per message type: encoding "protobuf", the FileDescriptorSet of its .proto
//             file and every import
//   message   the payload exactly as it arrived (no re-encoding); log_time = when the recorder
//             took it (wall clock, ns since the Unix epoch), publish_time = the DDS source
//             timestamp (the sender's wall clock)
//   metadata  "vdyn.recording" at the start (version, domain, command line, filters, what it
//             branched from), "vdyn.world" and "vdyn.vehicle" as they arrive, "vdyn.recording.end"
//             at the close (duration, counts, losses)
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <google/protobuf/descriptor.h>

#include "vdyn/messages/descriptor_set.h"
#include "vdyn/messages/wire.h"
#include "vdyn/recorder/mcap.h"
#include "vdyn/transport/topics.h"

namespace vdyn::recorder {

inline constexpr const char* kRecorderVersion = "0.1.0";
inline constexpr const char* kFormatVersion = "vdyn-recording 1";

// The FileDescriptorSet (binary) of a message type (vdyn/messages/descriptor_set.h).
using messages::FileDescriptorSetOf;
// The descriptor of a topic's payload type.
const google::protobuf::Descriptor* PayloadDescriptor(transport::TopicId topic);

// Topics whose envelope key is the server key rather than a vehicle id.
bool ServerKeyed(transport::TopicId topic);
std::string ChannelTopic(transport::TopicId topic, std::uint32_t key);
mcap::StringMap ChannelMetadata(transport::TopicId topic, std::uint32_t key);
// A second channel of a topic and key that holds copies of its world or parameters, written in
// chunks of their own so that they survive the loss of any one chunk (docs/formats.md): the same
// topic, metadata "repeat_of" naming the first channel.
mcap::StringMap RepeatChannelMetadata(transport::TopicId topic, std::uint32_t key);

// A channel of a vdyn recording, parsed back.
struct ChannelInfo {
  transport::TopicId topic = transport::TopicId::kState;
  std::uint32_t key = 0;
  bool repeat = false;  // copies of the world or parameters (RepeatChannelMetadata)
};
// nullopt for a channel that is not a vdyn topic (a file written by another tool): its metadata
// names no vdyn topic and key, or (when `schema` is given) its schema or encodings are not the
// protobuf type of that topic.
std::optional<ChannelInfo> ParseChannelInfo(const mcap::Channel& c,
                                            const mcap::Schema* schema = nullptr);
// The vdyn channels of a summary, by id (schemas checked).
std::map<std::uint16_t, ChannelInfo> VdynChannels(const mcap::Reader::Summary& s);

struct RecordedMessage {
  transport::TopicId topic;
  std::uint32_t key = 0;
  std::uint64_t log_time = 0;
  std::uint64_t publish_time = 0;
  std::span<const std::uint8_t> data;
  bool repeat = false;     // a copy of a world or parameters (ChannelInfo::repeat)
  bool unchecked = false;  // mcap::Message::unchecked
};

// Walks a recording in file order (strict: a bad file throws mcap::McapError). Messages of
// channels that are not vdyn topics go to on_foreign (a file of another tool, or garbage under
// our names). `on_progress` gets the fraction of the file read.
struct RecordingVisitor {
  std::function<void(const RecordedMessage&)> on_message;
  // `schema`: the channel's schema record (nullptr when it has none, or none was read).
  std::function<void(const mcap::Channel&, const mcap::Schema* schema, const mcap::Message&)>
      on_foreign;
  std::function<void(const mcap::Metadata&)> on_metadata;
  std::function<void(double)> on_progress;
  // Topics to decompress at all (chunks holding none of them are still checked).
  std::function<bool(transport::TopicId)> wants;
};
mcap::ScanResult ScanRecording(const mcap::Reader& reader, const RecordingVisitor& visitor);

// The fields of a recorded state that gaps and re-simulation go by, read without parsing; nullopt
// when the payload is not protobuf framing or names another vehicle than its channel's key (a
// damaged or foreign payload must never become a step).
struct StateFields {
  std::uint64_t step = 0;
  std::uint64_t step_ns = 0;
  std::uint64_t state_hash = 0;
  std::uint64_t incarnation = 0;  // the server's start that stepped it (0: not stamped)
};
std::optional<StateFields> ReadStateFields(std::span<const std::uint8_t> payload,
                                           std::uint32_t key);

// Refuses (mcap::McapError) what `info` refuses: reads the whole file strictly, every CRC.
// For commands that otherwise read only parts of it (play).
mcap::ScanResult CheckWholeFile(const mcap::Reader& reader, const std::string& label);

// What a reader of the file must not take for granted, one line each: a recovered file's losses
// and unchecked messages (its "vdyn.recovered" metadata), and `unchecked` items (`what`: "states",
// "rows") that came from chunks without a CRC which the data section's CRC did not cover either.
std::vector<std::string> IntegrityNotes(const std::vector<mcap::Metadata>& meta,
                                        const mcap::ScanResult& scan, std::uint64_t unchecked,
                                        const std::string& what);

// Every metadata record of the file, in order (a full scan; cheap next to the messages).
std::vector<mcap::Metadata> ReadMetadata(const mcap::Reader& reader);

// Times: the recording's time axis is the log time since its first message, in seconds.
std::uint64_t FirstLogTime(const mcap::Reader& reader);

// "12.345 s", "1 min 2.3 s"; "1.2 MB".
std::string FormatDuration(double seconds);
std::string FormatBytes(double bytes);
// Wall-clock ns since the epoch as "2026-01-02 03:04:05.678 UTC".
std::string FormatUtc(std::uint64_t ns);
// Counts as a person writes them: Count(1, "mesh", "meshes") is "1 mesh", Count(12, ...) "12
// meshes"; Ordinal(2) is "2nd", Ordinal(11) "11th", Ordinal(23) "23rd".
std::string Count(std::uint64_t n, std::string_view one, std::string_view many);
std::string Ordinal(std::uint64_t n);
// Text that came from a file (a server id, a world's name, a topic, a command line) as a
// terminal may show it: control characters (escape sequences) and bytes that are not UTF-8
// written as \xNN, and at most `max` bytes of it, then "... (N bytes)".
std::string Printable(std::string_view text, std::size_t max = 160);
// A server's sequence number that no server reaches (one event a microsecond for 8 years):
// damage or a foreign writer, never counted as events missing.
inline constexpr std::uint64_t kImpossibleSequence = std::uint64_t{1} << 48;

// The protobuf wire format, read without parsing (vdyn/messages/wire.h).
namespace wire = messages::wire;

}  // namespace vdyn::recorder

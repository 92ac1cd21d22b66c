// The Foxglove WebSocket protocol as Foxglove and Lichtblick speak it (the ws-protocol
// specification, subprotocol foxglove.websocket.v1, and the Foxglove SDK's foxglove.sdk.v1, whose
// messages are the same): the server's JSON and binary messages, the client's parsed with every
// field checked, and the WebSocket framing (RFC 6455) underneath. No I/O here: the server
// (server.h) moves the bytes.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace vdyn::foxglove::protocol {

inline constexpr std::string_view kSubprotocolV1 = "foxglove.websocket.v1";
inline constexpr std::string_view kSubprotocolSdk = "foxglove.sdk.v1";

// A client message that cannot be used: what() names the op, the field and why.
class ProtocolError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The subprotocol to answer a Sec-WebSocket-Protocol request header with: the first one listed
// that this server speaks; empty when it lists none of them.
std::string ChooseSubprotocol(std::string_view header);
// The Sec-WebSocket-Accept value for a client's Sec-WebSocket-Key (SHA-1 and base64).
std::string AcceptKey(std::string_view client_key);
// RFC 6455 4.2.1: a Sec-WebSocket-Key is the base64 of 16 bytes (24 characters, "==" at the end).
bool ValidClientKey(std::string_view key);
// RFC 6455 7.4: a close code an endpoint may send (1000-1003, 1007-1014, 3000-4999).
bool SendableCloseCode(unsigned code);
std::string Base64(std::span<const std::uint8_t> bytes);

// --- server messages ----------------------------------------------------------------------------

struct Channel {
  std::uint32_t id = 0;
  std::string topic;
  std::string encoding;         // "protobuf"
  std::string schema_name;      // "vdyn.pb.VehicleState"
  std::string schema_encoding;  // "protobuf"
  std::string schema;           // the schema's bytes (a FileDescriptorSet), base64 on the wire
};

struct ServerInfo {
  std::string name;
  std::vector<std::string> capabilities;
  std::vector<std::string> supported_encodings;
  std::map<std::string, std::string> metadata;
  std::string session_id;
};

enum class StatusLevel { kInfo = 0, kWarning = 1, kError = 2 };

// A parameter's value: a number (float64), an integer, a boolean or a string.
using ParameterValue = std::variant<double, std::int64_t, bool, std::string>;
struct Parameter {
  std::string name;
  std::optional<ParameterValue> value;  // none: unset (a set request) or unknown
};

std::string ServerInfoJson(const ServerInfo& info);
std::string AdvertiseJson(const std::vector<const Channel*>& channels);
std::string UnadvertiseJson(const std::vector<std::uint32_t>& channel_ids);
std::string StatusJson(StatusLevel level, std::string_view message);
std::string ParameterValuesJson(const std::vector<Parameter>& parameters,
                                const std::optional<std::string>& id);

// Binary: opcode 1, subscription id, log time (ns), then the payload (not included here).
inline constexpr std::size_t kMessageDataHeaderBytes = 13;
void WriteMessageDataHeader(std::uint8_t* out, std::uint32_t subscription_id,
                            std::uint64_t log_time_ns);
// Binary: opcode 2 and the server's time (ns).
inline constexpr std::size_t kTimeBytes = 9;
void WriteTime(std::uint8_t* out, std::uint64_t time_ns);

// --- client messages ----------------------------------------------------------------------------

struct Subscribe {
  std::vector<std::pair<std::uint32_t, std::uint32_t>> subscriptions;  // (id, channel id)
};
struct Unsubscribe {
  std::vector<std::uint32_t> subscription_ids;
};
struct ClientChannel {
  std::uint32_t id = 0;
  std::string topic;
  std::string encoding;
  std::string schema_name;
};
struct ClientAdvertise {
  std::vector<ClientChannel> channels;
};
struct ClientUnadvertise {
  std::vector<std::uint32_t> channel_ids;
};
struct GetParameters {
  std::vector<std::string> names;  // empty: all
  std::optional<std::string> id;
};
struct SetParameters {
  std::vector<Parameter> parameters;
  std::optional<std::string> id;
};
struct SubscribeParameterUpdates {
  std::vector<std::string> names;  // empty: all
};
struct UnsubscribeParameterUpdates {
  std::vector<std::string> names;  // empty: all
};
// An op of the protocol this server does not offer (services, connection graph, assets, ...).
struct Unsupported {
  std::string op;
};
using ClientMessage = std::variant<Subscribe, Unsubscribe, ClientAdvertise, ClientUnadvertise,
                                   GetParameters, SetParameters, SubscribeParameterUpdates,
                                   UnsubscribeParameterUpdates, Unsupported>;

// Parses a text message; throws ProtocolError (not JSON, not an object, no "op", a field missing
// or of the wrong type, a number out of range).
ClientMessage ParseClientText(std::string_view text);

// Client binary message data: opcode 1, the client channel id, the payload.
struct ClientMessageData {
  std::uint32_t channel_id = 0;
  std::span<const std::uint8_t> payload;
};
// Throws ProtocolError for an empty or short message or an opcode other than 1 (service calls
// are not offered).
ClientMessageData ParseClientBinary(std::span<const std::uint8_t> message);

// --- WebSocket framing (RFC 6455, the server's side) --------------------------------------------

enum class WsOpcode : std::uint8_t {
  kContinuation = 0x0,
  kText = 0x1,
  kBinary = 0x2,
  kClose = 0x8,
  kPing = 0x9,
  kPong = 0xA,
};

// Appends the header of one whole, unmasked frame (FIN set) carrying `payload_bytes`.
void AppendFrameHeader(std::string& out, WsOpcode opcode, std::uint64_t payload_bytes);
// The header's size for a payload of that many bytes (2, 4 or 10).
std::size_t FrameHeaderBytes(std::uint64_t payload_bytes);

// Reads a client's frames from a byte stream: masked (a client must mask), fragmented messages
// put together, control frames between fragments. Bounded: a message over `max_message_bytes`
// is an error (the connection closes with 1009).
class FrameReader {
 public:
  explicit FrameReader(std::size_t max_message_bytes) : max_message_(max_message_bytes) {}

  struct Event {
    enum class Kind { kText, kBinary, kPing, kPong, kClose } kind = Kind::kText;
    std::string payload;  // the message, or the control frame's payload
  };
  // Consumes bytes from `in` (advancing it) until one event is whole: true with `out` filled;
  // false when more bytes are needed (everything given was consumed). Throws ProtocolError for
  // a protocol violation (unmasked frame, reserved bits or opcode, a control frame fragmented or
  // over 125 bytes, a continuation without a start, a message too large, text not UTF-8); the
  // error's close code is in close_code().
  bool Next(std::string_view& in, Event& out);
  std::uint16_t close_code() const { return close_code_; }

 private:
  [[noreturn]] void Fail(std::uint16_t code, const std::string& why);
  // RFC 6455 5.5.1, 7.4, 8.1: a close body is empty or a sendable code and a UTF-8 reason.
  void CheckCloseBody(std::string_view body);
  std::size_t max_message_;
  std::string header_;   // the current frame's header bytes, until whole
  std::string message_;  // a fragmented message so far
  bool in_message_ = false;
  bool message_text_ = false;
  // The current frame, once its header is read.
  bool have_header_ = false;
  bool fin_ = false;
  WsOpcode opcode_ = WsOpcode::kText;
  std::uint64_t left_ = 0;
  std::uint8_t mask_[4] = {};
  std::uint64_t masked_ = 0;  // payload bytes unmasked so far (the mask's phase)
  std::string control_;       // a control frame's payload
  std::uint16_t close_code_ = 1002;
};

// True when the bytes are valid UTF-8 (a text message must be).
bool ValidUtf8(std::string_view s);

}  // namespace vdyn::foxglove::protocol

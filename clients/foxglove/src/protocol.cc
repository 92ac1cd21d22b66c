#include "vdyn/foxglove/protocol.h"

#include <openssl/evp.h>

#include <algorithm>
#include <cstring>
#include <limits>

#include <nlohmann/json.hpp>

namespace vdyn::foxglove::protocol {
namespace {

using nlohmann::json;

std::string Dump(const json& j) {
  // A string that is not UTF-8 (a reason from elsewhere) is repaired, never a throw.
  return j.dump(-1, ' ', false, json::error_handler_t::replace);
}

[[noreturn]] void Bad(std::string_view op, const std::string& why) {
  throw ProtocolError(std::string(op) + ": " + why);
}

const json& Field(const json& obj, const char* key, std::string_view op, const std::string& where) {
  const auto it = obj.find(key);
  if (it == obj.end()) Bad(op, where + "'" + key + "' is missing");
  return *it;
}

std::uint32_t U32(const json& v, std::string_view op, const std::string& what) {
  if (v.is_number_unsigned() &&
      v.get<std::uint64_t>() <= std::numeric_limits<std::uint32_t>::max()) {
    return static_cast<std::uint32_t>(v.get<std::uint64_t>());
  }
  if (v.is_number_integer() && v.get<std::int64_t>() >= 0 &&
      v.get<std::int64_t>() <= std::numeric_limits<std::uint32_t>::max()) {
    return static_cast<std::uint32_t>(v.get<std::int64_t>());
  }
  Bad(op, what + " is not a whole number in 0..4294967295");
}

std::string Str(const json& v, std::string_view op, const std::string& what) {
  if (!v.is_string()) Bad(op, what + " is not a string");
  return v.get<std::string>();
}

const json& Array(const json& obj, const char* key, std::string_view op) {
  const json& a = Field(obj, key, op, "");
  if (!a.is_array()) Bad(op, std::string("'") + key + "' is not an array");
  return a;
}

std::vector<std::uint32_t> U32Array(const json& obj, const char* key, std::string_view op) {
  std::vector<std::uint32_t> out;
  const json& a = Array(obj, key, op);
  for (std::size_t i = 0; i < a.size(); ++i) {
    out.push_back(U32(a[i], op, std::string(key) + "[" + std::to_string(i) + "]"));
  }
  return out;
}

std::vector<std::string> Names(const json& obj, std::string_view op) {
  std::vector<std::string> out;
  const auto it = obj.find("parameterNames");
  if (it == obj.end() || it->is_null()) return out;
  if (!it->is_array()) Bad(op, "'parameterNames' is not an array");
  for (std::size_t i = 0; i < it->size(); ++i) {
    out.push_back(Str((*it)[i], op, "parameterNames[" + std::to_string(i) + "]"));
  }
  return out;
}

std::optional<std::string> RequestId(const json& obj, std::string_view op) {
  const auto it = obj.find("id");
  if (it == obj.end() || it->is_null()) return std::nullopt;
  return Str(*it, op, "'id'");
}

ParameterValue ValueOf(const json& v, bool float64, std::string_view op, const std::string& what) {
  if (v.is_boolean()) return v.get<bool>();
  if (v.is_string()) return v.get<std::string>();
  if (v.is_number_float() || (v.is_number() && float64)) return v.get<double>();
  if (v.is_number_unsigned()) {
    if (v.get<std::uint64_t>() >
        static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max())) {
      return static_cast<double>(v.get<std::uint64_t>());
    }
    return static_cast<std::int64_t>(v.get<std::uint64_t>());
  }
  if (v.is_number_integer()) return v.get<std::int64_t>();
  Bad(op, what + ": only numbers, booleans and strings are parameters here");
}

json ValueJson(const ParameterValue& v) {
  return std::visit([](const auto& x) { return json(x); }, v);
}

}  // namespace

std::string ChooseSubprotocol(std::string_view header) {
  while (!header.empty()) {
    const std::size_t comma = header.find(',');
    std::string_view item = header.substr(0, comma);
    while (!item.empty() && (item.front() == ' ' || item.front() == '\t')) item.remove_prefix(1);
    while (!item.empty() && (item.back() == ' ' || item.back() == '\t')) item.remove_suffix(1);
    if (item == kSubprotocolV1 || item == kSubprotocolSdk) return std::string(item);
    if (comma == std::string_view::npos) break;
    header.remove_prefix(comma + 1);
  }
  return {};
}

bool ValidClientKey(std::string_view key) {
  if (key.size() != 24 || key.substr(22) != "==") return false;
  const auto base64 = [](char c) {
    return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '+' ||
           c == '/';
  };
  for (std::size_t i = 0; i < 22; ++i) {
    if (!base64(key[i])) return false;
  }
  return true;
}

bool SendableCloseCode(unsigned code) {
  return (code >= 1000 && code <= 1003) || (code >= 1007 && code <= 1014) ||
         (code >= 3000 && code <= 4999);
}

std::string Base64(std::span<const std::uint8_t> b) {
  static constexpr char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((b.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= b.size(); i += 3) {
    const std::uint32_t v = (std::uint32_t{b[i]} << 16) | (std::uint32_t{b[i + 1]} << 8) | b[i + 2];
    for (int k = 3; k >= 0; --k) out.push_back(kAlphabet[(v >> (6 * k)) & 63]);
  }
  if (i < b.size()) {
    std::uint32_t v = std::uint32_t{b[i]} << 16;
    if (i + 1 < b.size()) v |= std::uint32_t{b[i + 1]} << 8;
    out.push_back(kAlphabet[(v >> 18) & 63]);
    out.push_back(kAlphabet[(v >> 12) & 63]);
    out.push_back(i + 1 < b.size() ? kAlphabet[(v >> 6) & 63] : '=');
    out.push_back('=');
  }
  return out;
}

std::string AcceptKey(std::string_view client_key) {
  const std::string text = std::string(client_key) + "258EAFA5-E914-47DA-95CA-C5AB0DC85B11";
  std::uint8_t digest[EVP_MAX_MD_SIZE];
  unsigned int n = 0;
  if (EVP_Digest(text.data(), text.size(), digest, &n, EVP_sha1(), nullptr) != 1 || n != 20) {
    throw ProtocolError("SHA-1 is not available (OpenSSL)");
  }
  return Base64({digest, n});
}

std::string ServerInfoJson(const ServerInfo& info) {
  json j = {{"op", "serverInfo"}, {"name", info.name}, {"capabilities", info.capabilities}};
  if (!info.supported_encodings.empty()) j["supportedEncodings"] = info.supported_encodings;
  if (!info.metadata.empty()) j["metadata"] = info.metadata;
  if (!info.session_id.empty()) j["sessionId"] = info.session_id;
  return Dump(j);
}

std::string AdvertiseJson(const std::vector<const Channel*>& channels) {
  json list = json::array();
  for (const Channel* c : channels) {
    const auto* bytes = reinterpret_cast<const std::uint8_t*>(c->schema.data());
    list.push_back({{"id", c->id},
                    {"topic", c->topic},
                    {"encoding", c->encoding},
                    {"schemaName", c->schema_name},
                    {"schemaEncoding", c->schema_encoding},
                    {"schema", Base64({bytes, c->schema.size()})}});
  }
  return Dump({{"op", "advertise"}, {"channels", list}});
}

std::string UnadvertiseJson(const std::vector<std::uint32_t>& channel_ids) {
  return Dump({{"op", "unadvertise"}, {"channelIds", channel_ids}});
}

std::string StatusJson(StatusLevel level, std::string_view message) {
  return Dump({{"op", "status"}, {"level", static_cast<int>(level)}, {"message", message}});
}

std::string ParameterValuesJson(const std::vector<Parameter>& parameters,
                                const std::optional<std::string>& id) {
  json list = json::array();
  for (const Parameter& p : parameters) {
    json item = {{"name", p.name}};
    if (p.value) {
      item["value"] = ValueJson(*p.value);
      if (std::holds_alternative<double>(*p.value)) item["type"] = "float64";
    }
    list.push_back(std::move(item));
  }
  json j = {{"op", "parameterValues"}, {"parameters", list}};
  if (id) j["id"] = *id;
  return Dump(j);
}

void WriteMessageDataHeader(std::uint8_t* out, std::uint32_t subscription_id,
                            std::uint64_t log_time_ns) {
  out[0] = 0x01;
  for (int i = 0; i < 4; ++i) out[1 + i] = static_cast<std::uint8_t>(subscription_id >> (8 * i));
  for (int i = 0; i < 8; ++i) out[5 + i] = static_cast<std::uint8_t>(log_time_ns >> (8 * i));
}

void WriteTime(std::uint8_t* out, std::uint64_t time_ns) {
  out[0] = 0x02;
  for (int i = 0; i < 8; ++i) out[1 + i] = static_cast<std::uint8_t>(time_ns >> (8 * i));
}

ClientMessage ParseClientText(std::string_view text) {
  json j;
  try {
    j = json::parse(text);
  } catch (const json::exception& e) {
    throw ProtocolError(std::string("not JSON: ") + e.what());
  }
  if (!j.is_object()) throw ProtocolError("not a JSON object");
  const auto op_it = j.find("op");
  if (op_it == j.end() || !op_it->is_string()) throw ProtocolError("no string 'op'");
  const std::string op = op_it->get<std::string>();
  if (op == "subscribe") {
    Subscribe s;
    const json& a = Array(j, "subscriptions", op);
    for (std::size_t i = 0; i < a.size(); ++i) {
      const std::string at = "subscriptions[" + std::to_string(i) + "]";
      if (!a[i].is_object()) Bad(op, at + " is not an object");
      s.subscriptions.emplace_back(
          U32(Field(a[i], "id", op, at + "."), op, at + ".id"),
          U32(Field(a[i], "channelId", op, at + "."), op, at + ".channelId"));
    }
    return s;
  }
  if (op == "unsubscribe") return Unsubscribe{U32Array(j, "subscriptionIds", op)};
  if (op == "advertise") {
    ClientAdvertise c;
    const json& a = Array(j, "channels", op);
    for (std::size_t i = 0; i < a.size(); ++i) {
      const std::string at = "channels[" + std::to_string(i) + "]";
      if (!a[i].is_object()) Bad(op, at + " is not an object");
      ClientChannel ch;
      ch.id = U32(Field(a[i], "id", op, at + "."), op, at + ".id");
      ch.topic = Str(Field(a[i], "topic", op, at + "."), op, at + ".topic");
      ch.encoding = Str(Field(a[i], "encoding", op, at + "."), op, at + ".encoding");
      const auto name = a[i].find("schemaName");
      if (name != a[i].end() && !name->is_null())
        ch.schema_name = Str(*name, op, at + ".schemaName");
      c.channels.push_back(std::move(ch));
    }
    return c;
  }
  if (op == "unadvertise") return ClientUnadvertise{U32Array(j, "channelIds", op)};
  if (op == "getParameters") return GetParameters{Names(j, op), RequestId(j, op)};
  if (op == "setParameters") {
    SetParameters s;
    const json& a = Array(j, "parameters", op);
    for (std::size_t i = 0; i < a.size(); ++i) {
      const std::string at = "parameters[" + std::to_string(i) + "]";
      if (!a[i].is_object()) Bad(op, at + " is not an object");
      Parameter p;
      p.name = Str(Field(a[i], "name", op, at + "."), op, at + ".name");
      const auto type = a[i].find("type");
      const bool float64 = type != a[i].end() && type->is_string() && *type == "float64";
      const auto value = a[i].find("value");
      if (value != a[i].end() && !value->is_null()) p.value = ValueOf(*value, float64, op, at);
      s.parameters.push_back(std::move(p));
    }
    s.id = RequestId(j, op);
    return s;
  }
  if (op == "subscribeParameterUpdates") return SubscribeParameterUpdates{Names(j, op)};
  if (op == "unsubscribeParameterUpdates") return UnsubscribeParameterUpdates{Names(j, op)};
  return Unsupported{op};
}

ClientMessageData ParseClientBinary(std::span<const std::uint8_t> m) {
  if (m.empty()) throw ProtocolError("empty binary message");
  if (m[0] != 0x01) {
    throw ProtocolError("binary opcode " + std::to_string(m[0]) +
                        " is not offered (only 1, client message data)");
  }
  if (m.size() < 5) throw ProtocolError("client message data shorter than its 5-byte header");
  ClientMessageData d;
  for (int i = 0; i < 4; ++i)
    d.channel_id |= std::uint32_t{m[1 + static_cast<std::size_t>(i)]} << (8 * i);
  d.payload = m.subspan(5);
  return d;
}

// --- WebSocket framing --------------------------------------------------------------------------

std::size_t FrameHeaderBytes(std::uint64_t n) {
  return n < 126 ? 2 : n < 65536 ? 4 : 10;
}

void AppendFrameHeader(std::string& out, WsOpcode opcode, std::uint64_t n) {
  out.push_back(static_cast<char>(0x80 | static_cast<std::uint8_t>(opcode)));
  if (n < 126) {
    out.push_back(static_cast<char>(n));
  } else if (n < 65536) {
    out.push_back(static_cast<char>(126));
    out.push_back(static_cast<char>(n >> 8));
    out.push_back(static_cast<char>(n & 0xff));
  } else {
    out.push_back(static_cast<char>(127));
    for (int i = 7; i >= 0; --i) out.push_back(static_cast<char>((n >> (8 * i)) & 0xff));
  }
}

bool ValidUtf8(std::string_view s) {
  std::size_t i = 0;
  while (i < s.size()) {
    const auto c = static_cast<std::uint8_t>(s[i]);
    int extra = 0;
    std::uint32_t cp = 0;
    if (c < 0x80) {
      ++i;
      continue;
    } else if ((c & 0xE0) == 0xC0) {
      extra = 1, cp = c & 0x1F;
    } else if ((c & 0xF0) == 0xE0) {
      extra = 2, cp = c & 0x0F;
    } else if ((c & 0xF8) == 0xF0) {
      extra = 3, cp = c & 0x07;
    } else {
      return false;
    }
    if (i + static_cast<std::size_t>(extra) >= s.size()) return false;  // cut short
    for (int k = 1; k <= extra; ++k) {
      const auto d = static_cast<std::uint8_t>(s[i + static_cast<std::size_t>(k)]);
      if ((d & 0xC0) != 0x80) return false;
      cp = (cp << 6) | (d & 0x3F);
    }
    // Overlong forms, surrogates and values past U+10FFFF are not UTF-8.
    static constexpr std::uint32_t kMin[] = {0, 0x80, 0x800, 0x10000};
    if (cp < kMin[extra] || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return false;
    i += static_cast<std::size_t>(extra) + 1;
  }
  return true;
}

void FrameReader::Fail(std::uint16_t code, const std::string& why) {
  close_code_ = code;
  throw ProtocolError(why);
}

void FrameReader::CheckCloseBody(std::string_view body) {
  if (body.empty()) return;
  if (body.size() == 1) Fail(1002, "a close frame with a 1-byte body (a code takes 2)");
  const unsigned code =
      (static_cast<unsigned>(static_cast<std::uint8_t>(body[0])) << 8) |
      static_cast<std::uint8_t>(body[1]);
  if (!SendableCloseCode(code))
    Fail(1002, "close code " + std::to_string(code) + ", which an endpoint may not send");
  if (!ValidUtf8(body.substr(2))) Fail(1007, "a close reason that is not UTF-8");
}

bool FrameReader::Next(std::string_view& in, Event& out) {
  for (;;) {
    if (!have_header_) {
      auto need = [&](std::size_t n) {
        while (header_.size() < n && !in.empty()) {
          header_.push_back(in.front());
          in.remove_prefix(1);
        }
        return header_.size() >= n;
      };
      if (!need(2)) return false;
      const auto b0 = static_cast<std::uint8_t>(header_[0]);
      const auto b1 = static_cast<std::uint8_t>(header_[1]);
      const std::uint8_t len7 = b1 & 0x7F;
      const std::size_t len_bytes = len7 == 126 ? 2 : len7 == 127 ? 8 : 0;
      if (!need(2 + len_bytes + 4)) return false;
      if ((b1 & 0x80) == 0) Fail(1002, "a client frame without a mask");
      if ((b0 & 0x70) != 0) Fail(1002, "reserved bits set (no extension was agreed)");
      const std::uint8_t op = b0 & 0x0F;
      if (op != 0 && op != 1 && op != 2 && op != 8 && op != 9 && op != 10) {
        Fail(1002, "reserved opcode " + std::to_string(op));
      }
      std::uint64_t len = len7;
      if (len_bytes > 0) {
        len = 0;
        for (std::size_t k = 0; k < len_bytes; ++k) {
          len = (len << 8) | static_cast<std::uint8_t>(header_[2 + k]);
        }
        if (len_bytes == 8 && (len >> 63) != 0) Fail(1002, "frame length with its top bit set");
      }
      fin_ = (b0 & 0x80) != 0;
      opcode_ = static_cast<WsOpcode>(op);
      if (op >= 8) {
        if (!fin_) Fail(1002, "a fragmented control frame");
        if (len > 125) Fail(1002, "a control frame over 125 bytes");
        control_.clear();
      } else {
        if (op == 0 && !in_message_)
          Fail(1002, "a continuation frame without a message to continue");
        if (op != 0 && in_message_) Fail(1002, "a new message inside a fragmented one");
        if (op != 0) {
          in_message_ = true;
          message_text_ = op == 1;
          message_.clear();
        }
        if (len > max_message_ || message_.size() + len > max_message_) {
          Fail(1009, "a message over " + std::to_string(max_message_) + " bytes");
        }
      }
      std::memcpy(mask_, header_.data() + 2 + len_bytes, 4);
      left_ = len;
      masked_ = 0;
      header_.clear();
      have_header_ = true;
    }
    const bool control = static_cast<std::uint8_t>(opcode_) >= 8;
    std::string& target = control ? control_ : message_;
    const std::size_t take = static_cast<std::size_t>(std::min<std::uint64_t>(left_, in.size()));
    const std::size_t at = target.size();
    target.append(in.data(), take);
    for (std::size_t k = 0; k < take; ++k)
      target[at + k] ^= static_cast<char>(mask_[(masked_ + k) & 3]);
    masked_ += take;
    left_ -= take;
    in.remove_prefix(take);
    if (left_ > 0) return false;
    have_header_ = false;
    if (control) {
      if (opcode_ == WsOpcode::kClose) CheckCloseBody(control_);
      out.kind = opcode_ == WsOpcode::kClose  ? Event::Kind::kClose
                 : opcode_ == WsOpcode::kPing ? Event::Kind::kPing
                                              : Event::Kind::kPong;
      out.payload = std::move(control_);
      control_.clear();
      return true;
    }
    if (!fin_) continue;  // the next fragment
    in_message_ = false;
    if (message_text_ && !ValidUtf8(message_)) Fail(1007, "a text message that is not UTF-8");
    out.kind = message_text_ ? Event::Kind::kText : Event::Kind::kBinary;
    out.payload = std::move(message_);
    message_.clear();
    return true;
  }
}

}  // namespace vdyn::foxglove::protocol

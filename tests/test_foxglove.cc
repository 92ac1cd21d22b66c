// vdyn-foxglove's parts in-process: the WebSocket framing and handshake against RFC 6455's own
// examples, the protocol's client messages (bad ones named), the send queue's bounds, the scene
// against vdyn-viewer's own construction of the same state (the same arrows, anchors, colours),
// the transforms against the state, and the parameters' names. The end-to-end tests (real
// processes, Foxglove's protocol client, the page in Chromium) are in tests/foxglove/.
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <thread>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "foxglove/FrameTransforms.pb.h"
#include "foxglove/SceneUpdate.pb.h"
#include "vdyn/client/palette.h"
#include "vdyn/foxglove/clock.h"
#include "vdyn/foxglove/outbox.h"
#include "vdyn/foxglove/params.h"
#include "vdyn/foxglove/protocol.h"
#include "vdyn/foxglove/scene.h"
#include "vdyn/foxglove/server.h"
#include "vdyn/viewer/draw_list.h"
#include "vdyn/viewer/scene.h"

namespace vdyn {
namespace {

namespace pr = foxglove::protocol;
using pr::WsOpcode;

std::vector<std::uint8_t> Bytes(std::initializer_list<int> b) {
  std::vector<std::uint8_t> v;
  for (int x : b) v.push_back(static_cast<std::uint8_t>(x));
  return v;
}

std::string Str(const std::vector<std::uint8_t>& v) {
  return {v.begin(), v.end()};
}

// A client frame: masked with `mask`, FIN as given.
std::string ClientFrame(WsOpcode op, const std::string& payload, bool fin = true,
                        std::array<std::uint8_t, 4> mask = {0x37, 0xfa, 0x21, 0x3d}) {
  std::string f;
  f.push_back(static_cast<char>((fin ? 0x80 : 0) | static_cast<int>(op)));
  const std::size_t n = payload.size();
  if (n < 126) {
    f.push_back(static_cast<char>(0x80 | n));
  } else if (n < 65536) {
    f.push_back(static_cast<char>(0x80 | 126));
    f.push_back(static_cast<char>(n >> 8));
    f.push_back(static_cast<char>(n & 0xff));
  } else {
    f.push_back(static_cast<char>(0x80 | 127));
    for (int i = 7; i >= 0; --i) f.push_back(static_cast<char>((n >> (8 * i)) & 0xff));
  }
  for (std::uint8_t m : mask) f.push_back(static_cast<char>(m));
  for (std::size_t i = 0; i < n; ++i) f.push_back(static_cast<char>(payload[i] ^ mask[i % 4]));
  return f;
}

// --- handshake and framing (RFC 6455) -----------------------------------------------------------

TEST(FoxgloveWebSocket, AcceptKeyIsRfc6455sExample) {
  // RFC 6455, section 1.3.
  EXPECT_EQ(pr::AcceptKey("dGhlIHNhbXBsZSBub25jZQ=="), "s3pPLMBiTxaQ9kYGzzhZRbK+xOo=");
  // RFC 4648, section 10.
  const std::string foobar = "foobar";
  for (std::size_t n = 0; n <= 6; ++n) {
    static const char* kExpected[] = {"",         "Zg==",     "Zm8=",    "Zm9v",
                                      "Zm9vYg==", "Zm9vYmE=", "Zm9vYmFy"};
    EXPECT_EQ(pr::Base64({reinterpret_cast<const std::uint8_t*>(foobar.data()), n}), kExpected[n]);
  }
}

TEST(FoxgloveWebSocket, SubprotocolIsTheFirstOfferedThatFoxgloveSpeaks) {
  EXPECT_EQ(pr::ChooseSubprotocol("foxglove.websocket.v1"), "foxglove.websocket.v1");
  EXPECT_EQ(pr::ChooseSubprotocol("foxglove.sdk.v1"), "foxglove.sdk.v1");
  EXPECT_EQ(pr::ChooseSubprotocol("x, foxglove.sdk.v1 ,foxglove.websocket.v1"), "foxglove.sdk.v1");
  EXPECT_EQ(pr::ChooseSubprotocol("foxglove.websocket.v2, chat"), "");
  EXPECT_EQ(pr::ChooseSubprotocol(""), "");
}

TEST(FoxgloveWebSocket, ReadsRfc6455sMaskedHelloByteByByte) {
  // RFC 6455, section 5.7: a single-frame masked text message "Hello".
  const std::string frame =
      Str(Bytes({0x81, 0x85, 0x37, 0xfa, 0x21, 0x3d, 0x7f, 0x9f, 0x4d, 0x51, 0x58}));
  pr::FrameReader r(1024);
  pr::FrameReader::Event ev;
  for (std::size_t i = 0; i + 1 < frame.size(); ++i) {
    std::string_view one(frame.data() + i, 1);
    ASSERT_FALSE(r.Next(one, ev));
    EXPECT_TRUE(one.empty());
  }
  std::string_view last(frame.data() + frame.size() - 1, 1);
  ASSERT_TRUE(r.Next(last, ev));
  EXPECT_EQ(ev.kind, pr::FrameReader::Event::Kind::kText);
  EXPECT_EQ(ev.payload, "Hello");
}

TEST(FoxgloveWebSocket, PutsFragmentsTogetherAroundAPing) {
  // RFC 6455, section 5.7: "Hel" + "lo" with a ping between (control frames may interleave).
  const std::string in = ClientFrame(WsOpcode::kText, "Hel", false) +
                         ClientFrame(WsOpcode::kPing, "p") +
                         ClientFrame(WsOpcode::kContinuation, "lo") +
                         ClientFrame(WsOpcode::kBinary, std::string(70000, 'x'));
  pr::FrameReader r(1 << 20);
  std::string_view rest = in;
  pr::FrameReader::Event ev;
  ASSERT_TRUE(r.Next(rest, ev));
  EXPECT_EQ(ev.kind, pr::FrameReader::Event::Kind::kPing);
  EXPECT_EQ(ev.payload, "p");
  ASSERT_TRUE(r.Next(rest, ev));
  EXPECT_EQ(ev.kind, pr::FrameReader::Event::Kind::kText);
  EXPECT_EQ(ev.payload, "Hello");
  ASSERT_TRUE(r.Next(rest, ev));
  EXPECT_EQ(ev.kind, pr::FrameReader::Event::Kind::kBinary);
  EXPECT_EQ(ev.payload, std::string(70000, 'x'));
  EXPECT_FALSE(r.Next(rest, ev));
}

// --- HTTP and the WebSocket handshake, over a real socket to a server on loopback ----------------
class NoClients : public foxglove::ClientHandler {
 public:
  void OnOpen(foxglove::ClientId, const std::shared_ptr<foxglove::Outbox>&, const std::string&,
              const std::string&) override {}
  void OnText(foxglove::ClientId, std::string_view) override {}
  void OnBinary(foxglove::ClientId, std::span<const std::uint8_t>) override {}
  void OnClose(foxglove::ClientId, const std::string&) override {}
};

class FoxgloveHttp : public ::testing::Test {
 protected:
  void SetUp() override {
    foxglove::ServerOptions o;
    o.host = "127.0.0.1";
    o.port = 0;
    o.three_js = "/nonexistent/three.min.js";
    server_ = std::make_unique<foxglove::Server>(o, handler_);
    thread_ = std::thread([this] { server_->Run(); });
  }
  void TearDown() override {
    server_->Stop();
    thread_.join();
  }

  struct Answer {
    std::string bytes;  // everything received
    int end = 0;        // how the connection ended: 0 an orderly close (FIN), else the errno
  };
  // Connects, sends `request` (its whole length, reading meanwhile), and reads until the server
  // ends the connection (or, with `headers_only`, until the answer's headers are in); at most 10 s.
  Answer Exchange(const std::string& request, bool headers_only = false) const {
    Answer a;
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(server_->port());
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) {
      a.end = errno;
      ::close(fd);
      return a;
    }
    std::size_t sent = 0;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (std::chrono::steady_clock::now() < deadline) {
      pollfd p{fd, static_cast<short>(POLLIN | (sent < request.size() ? POLLOUT : 0)), 0};
      if (::poll(&p, 1, 100) <= 0) continue;
      if (p.revents & POLLIN) {
        char buf[4096];
        const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
        if (n <= 0) {
          a.end = n == 0 ? 0 : errno;
          break;
        }
        a.bytes.append(buf, static_cast<std::size_t>(n));
        if (headers_only && a.bytes.find("\r\n\r\n") != std::string::npos) break;
      } else if (p.revents & POLLOUT) {
        const ssize_t n = ::send(fd, request.data() + sent,
                                 std::min<std::size_t>(request.size() - sent, 65536), MSG_NOSIGNAL);
        if (n < 0) {
          sent = request.size();  // the server stopped reading: read what it answered
        } else {
          sent += static_cast<std::size_t>(n);
        }
      } else if (p.revents & (POLLERR | POLLHUP)) {
        a.end = ECONNRESET;
        break;
      }
    }
    ::close(fd);
    return a;
  }

  NoClients handler_;
  std::unique_ptr<foxglove::Server> server_;
  std::thread thread_;
};

// RFC 9112 9.6: an answer to a request the server stops reading (431 for an over-long header, 413
// for an over-large body) is followed by an orderly close. The server closed the socket with the
// client's bytes unread, which resets the connection: the client got ECONNRESET after the answer
// (and a reset can discard the answer itself before it is read).
TEST_F(FoxgloveHttp, ARefusalOfARequestStillBeingSentEndsWithAnOrderlyClose) {
  const Answer headers =
      Exchange("GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + std::string(70000, 'a') + "\r\n\r\n");
  EXPECT_EQ(headers.bytes.rfind("HTTP/1.1 431 ", 0), 0u) << headers.bytes;
  EXPECT_NE(headers.bytes.find("request line and headers over 16 KiB"), std::string::npos);
  EXPECT_EQ(headers.end, 0) << std::strerror(headers.end);
  const Answer body = Exchange("POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 500000\r\n\r\n" +
                               std::string(500000, 'b'));
  EXPECT_EQ(body.bytes.rfind("HTTP/1.1 413 ", 0), 0u) << body.bytes;
  EXPECT_NE(body.bytes.find("request body over 64 KiB"), std::string::npos);
  EXPECT_EQ(body.end, 0) << std::strerror(body.end);
}

// RFC 6455 4.2.1 and 4.2.2; RFC 9110 and 9112 on Host, Allow, 204 and the absolute form.
TEST_F(FoxgloveHttp, TheHandshakeAndHttpAnswersFollowTheRfcs) {
  const std::string upgrade =
      "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
      "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Protocol: "
      "foxglove.websocket.v1\r\n";
  // No version: not a WebSocket handshake (400), saying which header; another version: 426 with
  // the one the server speaks.
  const Answer none = Exchange(upgrade + "\r\n");
  EXPECT_EQ(none.bytes.rfind("HTTP/1.1 400 ", 0), 0u) << none.bytes;
  EXPECT_NE(none.bytes.find("needs Sec-WebSocket-Version: 13"), std::string::npos) << none.bytes;
  const Answer v12 = Exchange(upgrade + "Sec-WebSocket-Version: 12\r\n\r\n");
  EXPECT_EQ(v12.bytes.rfind("HTTP/1.1 426 ", 0), 0u) << v12.bytes;
  EXPECT_NE(v12.bytes.find("Sec-WebSocket-Version: 13\r\n"), std::string::npos) << v12.bytes;
  const Answer v13 = Exchange(upgrade + "Sec-WebSocket-Version: 13\r\n\r\n", true);
  EXPECT_EQ(v13.bytes.rfind("HTTP/1.1 101 ", 0), 0u) << v13.bytes;
  EXPECT_NE(v13.bytes.find("Sec-WebSocket-Accept: s3pPLMBiTxaQ9kYGzzhZRbK+xOo=\r\n"),
            std::string::npos)
      << v13.bytes;  // RFC 6455 1.3's worked example
  const Answer no_host = Exchange("GET / HTTP/1.1\r\n\r\n");
  EXPECT_EQ(no_host.bytes.rfind("HTTP/1.1 400 ", 0), 0u) << no_host.bytes;
  const Answer two_hosts = Exchange("GET / HTTP/1.1\r\nHost: a\r\nHost: b\r\n\r\n");
  EXPECT_EQ(two_hosts.bytes.rfind("HTTP/1.1 400 ", 0), 0u) << two_hosts.bytes;
  const Answer post = Exchange("POST / HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
  EXPECT_EQ(post.bytes.rfind("HTTP/1.1 405 ", 0), 0u) << post.bytes;
  EXPECT_NE(post.bytes.find("Allow: GET, HEAD\r\n"), std::string::npos) << post.bytes;
  const Answer icon = Exchange("GET /favicon.ico HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
  EXPECT_EQ(icon.bytes.rfind("HTTP/1.1 204 ", 0), 0u) << icon.bytes;
  EXPECT_EQ(icon.bytes.find("Content-Length"), std::string::npos) << icon.bytes;
  const Answer absolute =
      Exchange("GET http://x/app.js HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
  EXPECT_EQ(absolute.bytes.rfind("HTTP/1.1 200 ", 0), 0u) << absolute.bytes.substr(0, 200);
  EXPECT_NE(absolute.bytes.find("Content-Type: text/javascript"), std::string::npos);
}

TEST(FoxgloveWebSocket, RefusesWhatAClientMustNotSendWithTheCloseCode) {
  struct Case {
    std::string bytes;
    std::uint16_t code;
    std::string why;
  };
  std::string unmasked = Str(Bytes({0x81, 0x05})) + "Hello";
  std::string reserved = ClientFrame(WsOpcode::kText, "x");
  reserved[0] = static_cast<char>(reserved[0] | 0x40);
  std::string bad_opcode = ClientFrame(WsOpcode::kText, "x");
  bad_opcode[0] = static_cast<char>(0x83);
  const std::vector<Case> cases = {
      {unmasked, 1002, "without a mask"},
      {reserved, 1002, "reserved bits"},
      {bad_opcode, 1002, "reserved opcode 3"},
      {ClientFrame(WsOpcode::kPing, "p", false), 1002, "fragmented control frame"},
      {ClientFrame(WsOpcode::kPing, std::string(126, 'p')), 1002, "control frame over 125 bytes"},
      {ClientFrame(WsOpcode::kContinuation, "x"), 1002, "continuation frame without a message"},
      {ClientFrame(WsOpcode::kText, "a", false) + ClientFrame(WsOpcode::kText, "b"), 1002,
       "new message inside"},
      {ClientFrame(WsOpcode::kBinary, std::string(2000, 'x')), 1009, "over 1024 bytes"},
      {ClientFrame(WsOpcode::kText, "\xc3\x28"), 1007, "not UTF-8"},
  };
  for (const Case& c : cases) {
    pr::FrameReader r(1024);
    std::string_view in = c.bytes;
    pr::FrameReader::Event ev;
    try {
      while (r.Next(in, ev)) {
      }
      ADD_FAILURE() << "accepted: " << c.why;
    } catch (const pr::ProtocolError& e) {
      EXPECT_NE(std::string(e.what()).find(c.why), std::string::npos) << e.what();
      EXPECT_EQ(r.close_code(), c.code) << c.why;
    }
  }
}

// A close frame's body: empty, or a code an endpoint may send and a UTF-8 reason (RFC 6455 5.5.1,
// 7.4, 8.1). The bridge echoed any code back (999, 1005, 1006, 1015, 5000: codes it must not send),
// answered a 1-byte body with an empty close and a reason that is not UTF-8 with 1000.
TEST(FoxgloveWebSocket, AnInvalidCloseBodyIsAProtocolErrorNotEchoed) {
  const auto close_of = [](unsigned code, const std::string& reason) {
    std::string body;
    body.push_back(static_cast<char>(code >> 8));
    body.push_back(static_cast<char>(code & 0xff));
    return ClientFrame(WsOpcode::kClose, body + reason);
  };
  const auto read = [](const std::string& frame, std::uint16_t* code) {
    pr::FrameReader r(1 << 20);
    std::string_view in = frame;
    pr::FrameReader::Event ev;
    try {
      EXPECT_TRUE(r.Next(in, ev));
      *code = 0;
      return ev.kind == pr::FrameReader::Event::Kind::kClose;
    } catch (const pr::ProtocolError&) {
      *code = r.close_code();
      return false;
    }
  };
  std::uint16_t code = 0;
  for (unsigned ok : {1000u, 1001u, 1003u, 1007u, 1011u, 1014u, 3000u, 4999u}) {
    EXPECT_TRUE(read(close_of(ok, "bye"), &code)) << ok;
  }
  EXPECT_TRUE(read(ClientFrame(WsOpcode::kClose, ""), &code));  // no body at all
  for (unsigned bad : {0u, 999u, 1004u, 1005u, 1006u, 1015u, 1016u, 2999u, 5000u, 65535u}) {
    EXPECT_FALSE(read(close_of(bad, ""), &code)) << bad;
    EXPECT_EQ(code, 1002) << bad;
  }
  EXPECT_FALSE(read(ClientFrame(WsOpcode::kClose, "\x03"), &code));
  EXPECT_EQ(code, 1002);
  EXPECT_FALSE(read(close_of(1000, "\xff"), &code));
  EXPECT_EQ(code, 1007);
}

// RFC 6455 4.2.1: the key is 16 bytes in base64 (a key "abc" was accepted).
TEST(FoxgloveWebSocket, AClientKeyIsSixteenBytesInBase64) {
  EXPECT_TRUE(pr::ValidClientKey("dGhlIHNhbXBsZSBub25jZQ=="));  // the RFC's example
  for (const char* bad : {"", "abc", "dGhlIHNhbXBsZSBub25jZQ", "dGhlIHNhbXBsZSBub25jZQ=x",
                          "dGhlIHNhbXBsZSBub25jZ*==", "dGhlIHNhbXBsZSBub25jZQ===",
                          "dGhlIHNhbXBsZSBub25jZSBvZiAzMiBieXRlcw=="}) {
    EXPECT_FALSE(pr::ValidClientKey(bad)) << bad;
  }
}

TEST(FoxgloveWebSocket, FrameHeadersUseTheShortestLength) {
  for (auto [n, header] : std::vector<std::pair<std::uint64_t, std::vector<std::uint8_t>>>{
           {0, {0x82, 0}},
           {125, {0x82, 125}},
           {126, {0x82, 126, 0, 126}},
           {65535, {0x82, 126, 0xff, 0xff}},
           {65536, {0x82, 127, 0, 0, 0, 0, 0, 1, 0, 0}}}) {
    std::string out;
    pr::AppendFrameHeader(out, WsOpcode::kBinary, n);
    EXPECT_EQ(out, Str(header)) << n;
    EXPECT_EQ(pr::FrameHeaderBytes(n), header.size());
  }
}

TEST(FoxgloveWebSocket, Utf8CheckFollowsTheStandard) {
  EXPECT_TRUE(pr::ValidUtf8("vdyn \xc3\xa9\xe2\x82\xac\xf0\x9f\x9a\x97"));
  for (const char* bad :
       {"\x80", "\xc0\xaf", "\xe0\x80\xaf", "\xed\xa0\x80", "\xf4\x90\x80\x80", "\xe2\x82"}) {
    EXPECT_FALSE(pr::ValidUtf8(bad)) << bad;
  }
}

// --- the protocol's messages
// ----------------------------------------------------------------------

// The protocol: "timestamps of published messages must originate from the same time source". The
// bridge's time was the largest simulation time of any state ever heard: after a server restart it
// stood still at the old session's end while the new states were stamped 0 s on, and a second
// server's states were stamped with a clock of their own.
TEST(FoxgloveClock, OneServersTimeFollowedThroughRestartsOthersStampedWithIt) {
  const base::Nanos silence = base::Seconds(3);
  foxglove::BridgeClock clock(silence);
  base::MonoTime t{1'000'000'000};
  const auto ms = [](std::int64_t n) { return base::Milliseconds(n); };
  EXPECT_FALSE(clock.set());
  bool changed = false;
  // The first state's server is the clock; its states keep their own time.
  EXPECT_EQ(clock.OnState("a", 1, 20'000'000'000, t, &changed), 20'000'000'000u);
  EXPECT_TRUE(changed);
  EXPECT_EQ(clock.OnState("a", 1, 20'001'000'000, t + ms(1), &changed), 20'001'000'000u);
  EXPECT_FALSE(changed);
  // Another server on the domain: stamped with the clock's time, the clock unmoved.
  EXPECT_EQ(clock.OnState("b", 7, 340'000'000'000, t + ms(2), &changed), 20'001'000'000u);
  EXPECT_FALSE(changed);
  EXPECT_EQ(clock.now_ns(), 20'001'000'000u);
  EXPECT_EQ(clock.StampOf("b", 340'000'000'000), 20'001'000'000u);  // its diagnostics too
  EXPECT_EQ(clock.StampOf("a", 20'000'500'000), 20'000'500'000u);
  // Another start of server a while this one still sends (a player of its recording beside it):
  // the clock stays (it took each state's source in turn).
  EXPECT_EQ(clock.OnState("a", 2, 7'000'000, t + ms(500), &changed), 20'001'000'000u);
  EXPECT_FALSE(changed);
  // Server a restarts (another incarnation, the old quiet): the clock follows it back to 0 s.
  EXPECT_EQ(clock.OnState("a", 2, 5'000'000, t + ms(3000), &changed), 5'000'000u);
  EXPECT_TRUE(changed);
  EXPECT_EQ(clock.now_ns(), 5'000'000u);
  // A player seeking back takes the clock back with it (same incarnation, an earlier time).
  EXPECT_EQ(clock.OnState("a", 2, 1'000'000, t + ms(3001), &changed), 1'000'000u);
  EXPECT_FALSE(changed);
  // Server a falls silent for longer than `silence`: the next server heard is the clock.
  EXPECT_EQ(clock.OnState("b", 7, 345'000'000'000, t + ms(3002), &changed), 1'000'000u);
  EXPECT_EQ(clock.OnState("b", 7, 349'000'000'000, t + ms(3001 + 3001), &changed),
            349'000'000'000u);
  EXPECT_TRUE(changed);
  EXPECT_EQ(clock.server_id(), "b");
  // A negative simulation time is no log time: 0.
  EXPECT_EQ(clock.StampOf("b", -5), 0u);
}

TEST(FoxgloveProtocol, ParsesTheClientMessagesFoxgloveSends) {
  const auto s = std::get<pr::Subscribe>(pr::ParseClientText(
      R"({"op":"subscribe","subscriptions":[{"id":0,"channelId":3},{"id":1,"channelId":5}]})"));
  ASSERT_EQ(s.subscriptions.size(), 2u);
  EXPECT_EQ(s.subscriptions[1], (std::pair<std::uint32_t, std::uint32_t>{1, 5}));
  const auto sp = std::get<pr::SetParameters>(pr::ParseClientText(
      R"({"op":"setParameters","parameters":[{"name":"vehicle/1/mass","value":3,"type":"float64"},{"name":"b","value":true},{"name":"c"}],"id":"r1"})"));
  ASSERT_EQ(sp.parameters.size(), 3u);
  EXPECT_TRUE(std::holds_alternative<double>(*sp.parameters[0].value));  // float64 by its type
  EXPECT_TRUE(std::get<bool>(*sp.parameters[1].value));
  EXPECT_FALSE(sp.parameters[2].value.has_value());
  EXPECT_EQ(*sp.id, "r1");
  EXPECT_EQ(
      std::get<pr::Unsupported>(pr::ParseClientText(R"({"op":"subscribeConnectionGraph"})")).op,
      "subscribeConnectionGraph");
  const auto d = pr::ParseClientBinary(Bytes({1, 7, 0, 0, 0, 'x'}));
  EXPECT_EQ(d.channel_id, 7u);
  EXPECT_EQ(d.payload.size(), 1u);
}

TEST(FoxgloveProtocol, NamesWhatIsWrongWithABadMessage) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"{", "not JSON"},
      {"[1]", "not a JSON object"},
      {R"({"op":3})", "no string 'op'"},
      {R"({"op":"subscribe"})", "'subscriptions' is missing"},
      {R"({"op":"subscribe","subscriptions":{}})", "'subscriptions' is not an array"},
      {R"({"op":"subscribe","subscriptions":[{"id":-1,"channelId":1}]})",
       "subscriptions[0].id is not a whole number"},
      {R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":4294967296}]})",
       "channelId is not a whole number"},
      {R"({"op":"unsubscribe","subscriptionIds":[1.5]})",
       "subscriptionIds[0] is not a whole number"},
      {R"({"op":"advertise","channels":[{"id":1,"topic":2,"encoding":"json"}]})",
       "channels[0].topic is not a string"},
      {R"({"op":"setParameters","parameters":[{"name":"a","value":[1,2]}]})",
       "only numbers, booleans and strings"},
      {R"({"op":"getParameters","parameterNames":"mass"})", "'parameterNames' is not an array"},
  };
  for (const auto& [text, why] : cases) {
    try {
      (void)pr::ParseClientText(text);
      ADD_FAILURE() << "accepted " << text;
    } catch (const pr::ProtocolError& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << text << ": " << e.what();
    }
  }
  for (const auto& [bytes, why] : std::vector<std::pair<std::vector<std::uint8_t>, std::string>>{
           {{}, "empty"},
           {{2, 0, 0, 0, 0}, "opcode 2 is not offered"},
           {{1, 0, 0}, "shorter than"}}) {
    EXPECT_THROW((void)pr::ParseClientBinary(bytes), pr::ProtocolError) << why;
  }
}

TEST(FoxgloveProtocol, BinaryMessagesAreLittleEndianAsSpecified) {
  std::uint8_t h[pr::kMessageDataHeaderBytes];
  pr::WriteMessageDataHeader(h, 0x01020304u, 0x1122334455667788ull);
  EXPECT_EQ(std::vector<std::uint8_t>(h, h + 13),
            Bytes({1, 4, 3, 2, 1, 0x88, 0x77, 0x66, 0x55, 0x44, 0x33, 0x22, 0x11}));
  std::uint8_t t[pr::kTimeBytes];
  pr::WriteTime(t, 5);
  EXPECT_EQ(std::vector<std::uint8_t>(t, t + 9), Bytes({2, 5, 0, 0, 0, 0, 0, 0, 0}));
}

// --- the send queue
// -------------------------------------------------------------------------------

struct Taken {
  int text = 0, data = 0, time = 0, close = 0;
  std::vector<std::uint32_t> subs;
  std::vector<std::string> texts;
};
Taken Parse(const std::string& frames) {
  Taken t;
  std::size_t i = 0;
  while (i < frames.size()) {
    const auto op = static_cast<std::uint8_t>(frames[i]) & 0x0f;
    std::uint64_t n = static_cast<std::uint8_t>(frames[i + 1]);
    std::size_t at = i + 2;
    if (n == 126) {
      n = (std::uint64_t{static_cast<std::uint8_t>(frames[i + 2])} << 8) |
          static_cast<std::uint8_t>(frames[i + 3]);
      at = i + 4;
    } else if (n == 127) {
      n = 0;
      for (int k = 0; k < 8; ++k)
        n = (n << 8) | static_cast<std::uint8_t>(frames[i + 2 + static_cast<std::size_t>(k)]);
      at = i + 10;
    }
    const std::string payload = frames.substr(at, n);
    if (op == 1) {
      ++t.text;
      t.texts.push_back(payload);
    } else if (op == 8) {
      ++t.close;
    } else if (payload[0] == 2) {
      ++t.time;
    } else {
      ++t.data;
      std::uint32_t sub = 0;
      for (int k = 0; k < 4; ++k)
        sub |= std::uint32_t{static_cast<std::uint8_t>(payload[1 + static_cast<std::size_t>(k)])}
               << (8 * k);
      t.subs.push_back(sub);
    }
    i = at + n;
  }
  return t;
}

Taken TakeAll(foxglove::Outbox& o, base::MonoTime now) {
  std::string out;
  std::vector<std::int64_t> stamps;
  while (o.Take(out, 1 << 30, now, stamps)) {
  }
  return Parse(out);
}

TEST(FoxgloveOutbox, ABoundInBytesDropsTheOldestAndWarnsOnceASecond) {
  foxglove::Outbox::Limits l;
  l.data_bytes = 10'000;
  l.data_age = base::Seconds(100);
  foxglove::Outbox o(l);
  // 4 bytes of frame header, 13 of message data header: 1000 bytes a message.
  auto payload = std::make_shared<const std::string>(983, 'x');
  const base::MonoTime t0{1'000'000'000};
  for (std::uint32_t i = 0; i < 25; ++i) o.PushData(i, i, payload, t0);
  EXPECT_EQ(o.counters().dropped_messages, 15u);
  const Taken t = TakeAll(o, t0);
  EXPECT_EQ(t.data, 10);
  EXPECT_EQ(t.subs.front(), 15u);  // the newest ten are kept
  ASSERT_EQ(t.text, 1);            // said at the first drop, a warning (level 1)
  EXPECT_NE(t.texts[0].find("1 message (1.0 kB) dropped"), std::string::npos) << t.texts[0];
  EXPECT_NE(t.texts[0].find("\"level\":1"), std::string::npos) << t.texts[0];
  for (std::uint32_t i = 0; i < 15; ++i) o.PushData(i, i, payload, t0 + base::Milliseconds(500));
  EXPECT_EQ(o.counters().dropped_messages, 20u);
  EXPECT_EQ(TakeAll(o, t0 + base::Milliseconds(500)).text, 0);    // not again within the second
  const Taken later = TakeAll(o, t0 + base::Milliseconds(1500));  // the rest, said a second on
  ASSERT_EQ(later.text, 1);
  EXPECT_NE(later.texts[0].find("19 messages (19.0 kB) dropped"), std::string::npos)
      << later.texts[0];
}

TEST(FoxgloveOutbox, DataOlderThanTheAgeBoundGoesFirstAndControlIsNeverDropped) {
  foxglove::Outbox::Limits l;
  l.data_age = base::Milliseconds(250);
  foxglove::Outbox o(l);
  auto payload = std::make_shared<const std::string>(10, 'x');
  const base::MonoTime t0{1'000'000'000};
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(o.PushControl(WsOpcode::kText, "{\"op\":\"status\"}"));
  o.PushData(1, 0, payload, t0);
  o.PushData(2, 0, payload, t0 + base::Milliseconds(200));
  const Taken t = TakeAll(o, t0 + base::Milliseconds(300));
  EXPECT_EQ(t.text, 101);  // the hundred and the warning
  EXPECT_EQ(t.subs, std::vector<std::uint32_t>{2});
}

TEST(FoxgloveOutbox, LatestOnlyKeepsOneUnsentMessageInItsPlace) {
  foxglove::Outbox o({});
  const base::MonoTime t0{1'000'000'000};
  auto a = std::make_shared<const std::string>("a"), b = std::make_shared<const std::string>("bb");
  o.PushData(7, 1, a, t0, 0, true);
  o.PushData(8, 1, a, t0);
  o.PushData(7, 2, b, t0, 0, true);
  o.PushTime(99);
  o.PushTime(100);
  std::string out;
  std::vector<std::int64_t> stamps;
  ASSERT_TRUE(o.Take(out, 1 << 20, t0, stamps));
  const Taken t = Parse(out);
  EXPECT_EQ(t.time, 1);
  EXPECT_EQ(t.subs, (std::vector<std::uint32_t>{7, 8}));
  EXPECT_NE(out.find("bb"), std::string::npos);  // the newer payload in the older one's place
  EXPECT_EQ(o.counters().dropped_messages, 0u);
  o.PushData(7, 3, a, t0, 0, true);  // the last was sent: a new one queues
  EXPECT_EQ(Parse([&] {
              std::string x;
              (void)o.Take(x, 1 << 20, t0, stamps);
              return x;
            }())
                .subs,
            std::vector<std::uint32_t>{7});
}

TEST(FoxgloveOutbox, ControlOverItsBoundIsRefusedAndFinishEndsWithClose) {
  foxglove::Outbox::Limits l;
  l.control_bytes = 100;
  foxglove::Outbox o(l);
  EXPECT_TRUE(o.PushControl(WsOpcode::kText, std::string(60, 'x')));
  EXPECT_FALSE(o.PushControl(WsOpcode::kText, std::string(60, 'x')));
  o.PushData(1, 0, std::make_shared<const std::string>("d"), base::MonoTime{0});
  o.Purge({1});
  o.PushData(2, 0, std::make_shared<const std::string>("d"), base::MonoTime{0});
  o.Finish(std::string("\x03\xe8", 2));
  o.PushData(3, 0, std::make_shared<const std::string>("d"), base::MonoTime{0});
  EXPECT_FALSE(o.finished());
  const Taken t = TakeAll(o, base::MonoTime{0});
  EXPECT_EQ(t.text, 1);
  EXPECT_EQ(t.data, 0);  // purged, dropped by the end, or after it
  EXPECT_EQ(t.close, 1);
  EXPECT_TRUE(o.finished());
}

// A client that pings without reading holds one pong, the newest ping's (RFC 6455 5.5.3): it held
// one per ping, up to the control bound (64 MiB), and got no answer past it.
TEST(FoxgloveOutbox, OnlyTheNewestPingsPongWaits) {
  foxglove::Outbox o(foxglove::Outbox::Limits{});
  for (int k = 0; k < 10000; ++k) o.PushPong("ping " + std::to_string(k));
  EXPECT_LT(o.counters().queued_bytes, 1000u);
  std::string out;
  std::vector<std::int64_t> stamps;
  ASSERT_TRUE(o.Take(out, 1 << 20, base::MonoTime{0}, stamps));
  // One pong frame (opcode 10), the last ping's payload.
  ASSERT_GE(out.size(), 2u);
  EXPECT_EQ(static_cast<std::uint8_t>(out[0]), 0x80 | 0x0a);
  EXPECT_EQ(out.substr(2), "ping 9999");
  EXPECT_FALSE(o.Take(out, 1 << 20, base::MonoTime{0}, stamps));
}

// --- the scene
// ------------------------------------------------------------------------------------

pb::VehicleState SomeState(pb::VehicleModel model) {
  pb::VehicleState s;
  s.set_vehicle_id(3);
  s.set_model(model);
  s.set_sim_time_ns(1'234'000'000);
  // Yawed 30 degrees and pitched a little: q = (cos 15, 0, 0, sin 15) then a small pitch.
  const double a = 15 * M_PI / 180;
  s.mutable_q_wb()->set_w(std::cos(a));
  s.mutable_q_wb()->set_z(std::sin(a));
  s.mutable_p_wt_w()->set_x(10), s.mutable_p_wt_w()->set_y(-4), s.mutable_p_wt_w()->set_z(0.55);
  s.mutable_v_wt_w()->set_x(12), s.mutable_v_wt_w()->set_y(7);
  s.mutable_w_wb_b()->set_z(0.3);
  s.set_da(210);
  s.mutable_f_wall_w()->set_x(-300);
  for (int w = 0; w < 4; ++w) {
    pb::WheelState* ws = s.add_wheels();
    ws->set_contact(w != 3);
    ws->set_fp(3500 + 100 * w), ws->set_fh(w < 2 ? 800 : 0), ws->set_fb(150 * w),
        ws->set_fy(-400 + 200 * w);
    ws->set_fx(w % 2 ? -900 : 600);
    ws->set_gamma(w < 2 ? 0.1 : 0);
    ws->mutable_p_a_w()->set_x(10 + (w < 2 ? 1 : -1.4)),
        ws->mutable_p_a_w()->set_y(-4 + (w % 2 ? -0.8 : 0.8));
    ws->mutable_p_a_w()->set_z(0.5);
    ws->mutable_p_b_w()->set_x(10 + (w < 2 ? 1 : -1.4)),
        ws->mutable_p_b_w()->set_y(-4 + (w % 2 ? -0.8 : 0.8));
    ws->mutable_p_b_w()->set_z(-0.05 * w);
    ws->mutable_n_w()->set_x(0.05), ws->mutable_n_w()->set_z(1);
    ws->set_ls(0.25);
  }
  return s;
}

TEST(FoxgloveScene, ArrowsAreTheViewersForTheSameState) {
  for (pb::VehicleModel model : {pb::VEHICLE_MODEL_PAPER, pb::VEHICLE_MODEL_FULL}) {
    const pb::VehicleState s = SomeState(model);
    ASSERT_EQ(foxglove::CheckState(s), "");
    const viewer::VehicleView v =
        viewer::BuildVehicleView(s, viewer::GeometryFor(3, nullptr, nullptr));
    foxglove::SceneOptions o;
    const auto arrows = foxglove::ForceArrows(s, foxglove::GeometryFor(3, nullptr, nullptr), o);
    ASSERT_EQ(v.arrows.size(), arrows.size());
    for (std::size_t i = 0; i < arrows.size(); ++i) {
      const viewer::ForceArrow& va = v.arrows[i];
      const foxglove::Arrow& fa = arrows[i];
      EXPECT_EQ(static_cast<int>(va.kind), static_cast<int>(fa.kind));
      EXPECT_EQ(va.wheel, fa.wheel);
      EXPECT_NEAR(va.force_W.x, fa.force_W.x, 1e-9);
      EXPECT_NEAR(va.force_W.y, fa.force_W.y, 1e-9);
      EXPECT_NEAR(va.force_W.z, fa.force_W.z, 1e-9);
      // The viewer anchors an arrow at its tail, or at its tip (drag, at the nose).
      const double k = va.tip_at_anchor ? o.arrow_m_per_kn / 1000.0 : 0.0;
      if (fa.kind != foxglove::ForceKind::kWall) {  // the wall's is drawn from above the roof
        EXPECT_NEAR(va.anchor_W.x, fa.tail_W.x + k * fa.force_W.x, 1e-9) << i;
        EXPECT_NEAR(va.anchor_W.y, fa.tail_W.y + k * fa.force_W.y, 1e-9) << i;
        EXPECT_NEAR(va.anchor_W.z, fa.tail_W.z + k * fa.force_W.z, 1e-9) << i;
      }
      EXPECT_EQ(viewer::ForceLabel(va.kind), foxglove::ForceLabel(fa.kind));
    }
  }
}

// The colours a user sees: the scene the bridge emits paints each arrow in the palette's colour
// of its kind (six kinds, six colours) and the body in the vehicle's paint, and the viewer's draw
// lists for the same state hold the same colours.
std::array<std::uint8_t, 3> Bytes(const ::foxglove::Color& c) {
  EXPECT_DOUBLE_EQ(c.a(), 1.0);
  auto byte = [](double x) { return static_cast<std::uint8_t>(std::lround(x * 255)); };
  EXPECT_NEAR(c.r() * 255, byte(c.r()), 1e-9);  // a byte of sRGB, as the palette holds
  return {byte(c.r()), byte(c.g()), byte(c.b())};
}

TEST(FoxgloveScene, ArrowsAndBodyWearThePalettesColoursAsInTheViewer) {
  std::set<std::array<std::uint8_t, 3>> paints;
  for (std::uint32_t id = 1; id <= 8; ++id) {
    pb::VehicleState s = SomeState(pb::VEHICLE_MODEL_FULL);
    s.set_vehicle_id(id);
    const foxglove::Geometry g = foxglove::GeometryFor(id, nullptr, nullptr);
    foxglove::SceneOptions o;
    ::foxglove::SceneUpdate u;
    foxglove::BuildVehicleScene(s, g, o, s.sim_time_ns(), u);
    const ::foxglove::SceneEntity* body = nullptr;
    const ::foxglove::SceneEntity* forces = nullptr;
    for (const auto& e : u.entities()) {
      if (e.id() == "vehicle/" + std::to_string(id) + "/body") body = &e;
      if (e.id() == "vehicle/" + std::to_string(id) + "/forces") forces = &e;
    }
    ASSERT_NE(body, nullptr);
    ASSERT_NE(forces, nullptr);
    // The body's lower box is the vehicle's paint, the viewer's body too.
    ASSERT_GE(body->cubes_size(), 1);
    const std::array<std::uint8_t, 3> paint = Bytes(body->cubes(0).color());
    EXPECT_EQ(paint, client::VehiclePaint(id)) << "vehicle " << id;
    paints.insert(paint);
    const viewer::VehicleView v =
        viewer::BuildVehicleView(s, viewer::GeometryFor(id, nullptr, nullptr));
    viewer::FrameLists lists;
    viewer::AppendVehicle(
        v, viewer::ArrowStyle{}, [](const viewer::Vec3&) { return 0.02; },
        viewer::VehicleParts{.body = true, .wheels = false, .arrows = false}, false, lists);
    ASSERT_EQ(lists.bodies.size(), 1u);
    const viewer::Rgb8 vp = lists.bodies[0].paint;
    EXPECT_EQ((std::array<std::uint8_t, 3>{vp.r, vp.g, vp.b}), paint) << "vehicle " << id;

    // Each arrow in its kind's colour (the entity's order: per wheel spring, drive, brake, side;
    // then drag and wall), and the viewer draws that kind's arrow in the same colour.
    ASSERT_EQ(forces->arrows_size(), foxglove::kArrowsPerVehicle);
    ASSERT_EQ(v.arrows.size(), static_cast<std::size_t>(foxglove::kArrowsPerVehicle));
    std::map<int, std::array<std::uint8_t, 3>> by_kind;
    for (int i = 0; i < forces->arrows_size(); ++i) {
      const int kind = i < 4 * foxglove::kWheels ? i % 4 : 4 + (i - 4 * foxglove::kWheels);
      const std::array<std::uint8_t, 3> c = Bytes(forces->arrows(i).color());
      EXPECT_EQ(c, client::ForcePaint(static_cast<client::ForceKind>(kind))) << "arrow " << i;
      by_kind[kind] = c;
      // The viewer's arrow of the same force, alone in a list: every vertex in that colour.
      viewer::VehicleView one = v;
      one.arrows = {v.arrows[static_cast<std::size_t>(i)]};
      ASSERT_EQ(static_cast<int>(one.arrows[0].kind), kind);
      one.arrows[0].force_W = {1000, 0, 0};  // long enough to be drawn, whatever the state's
      viewer::FrameLists arrow;
      viewer::AppendVehicle(
          one, viewer::ArrowStyle{}, [](const viewer::Vec3&) { return 0.02; },
          viewer::VehicleParts{.body = false, .wheels = false, .arrows = true}, false, arrow);
      ASSERT_FALSE(arrow.arrows.vertices().empty()) << "arrow " << i;
      for (const viewer::Vertex& x : arrow.arrows.vertices()) {
        ASSERT_EQ((std::array<std::uint8_t, 3>{x.rgba[0], x.rgba[1], x.rgba[2]}), c)
            << "arrow " << i;
      }
    }
    std::set<std::array<std::uint8_t, 3>> kinds;
    for (const auto& [kind, c] : by_kind) kinds.insert(c);
    EXPECT_EQ(by_kind.size(), static_cast<std::size_t>(client::kForceKinds));
    EXPECT_EQ(kinds.size(), static_cast<std::size_t>(client::kForceKinds))
        << "two kinds of force share a colour";
  }
  EXPECT_EQ(paints.size(), 8u) << "two of the first eight vehicles share a paint";
}

TEST(FoxgloveScene, ArrowPrimitivesPointAlongTheForceWithTheScaledLength) {
  const pb::VehicleState s = SomeState(pb::VEHICLE_MODEL_PAPER);
  const foxglove::Geometry g = foxglove::GeometryFor(3, nullptr, nullptr);
  foxglove::SceneOptions o;
  o.arrow_m_per_kn = 0.8;
  ::foxglove::SceneUpdate u;
  foxglove::BuildVehicleScene(s, g, o, s.sim_time_ns(), u);
  const auto arrows = foxglove::ForceArrows(s, g, o);
  const ::foxglove::SceneEntity* forces = nullptr;
  for (const auto& e : u.entities()) {
    if (e.id() == "vehicle/3/forces") forces = &e;
    EXPECT_EQ(e.timestamp().seconds(), 1);
    EXPECT_EQ(e.timestamp().nanos(), 234'000'000);
  }
  ASSERT_NE(forces, nullptr);
  ASSERT_EQ(forces->arrows_size(), foxglove::kArrowsPerVehicle);
  for (int i = 0; i < forces->arrows_size(); ++i) {
    const auto& p = forces->arrows(i);
    const auto& f = arrows[static_cast<std::size_t>(i)].force_W;
    const double n = std::sqrt(f.x * f.x + f.y * f.y + f.z * f.z);
    EXPECT_NEAR(p.shaft_length() + p.head_length(), n * 0.8 / 1000, 1e-12);
    if (n < 1e-9) continue;
    // +X turned by the orientation is the force's direction: R(q) e_x = (1-2(y²+z²), 2(xy+wz),
    // 2(xz-wy)).
    const auto& q = p.pose().orientation();
    EXPECT_NEAR(1 - 2 * (q.y() * q.y() + q.z() * q.z()), f.x / n, 1e-9);
    EXPECT_NEAR(2 * (q.x() * q.y() + q.w() * q.z()), f.y / n, 1e-9);
    EXPECT_NEAR(2 * (q.x() * q.z() - q.w() * q.y()), f.z / n, 1e-9);
  }
}

TEST(FoxgloveScene, TransformsPlaceTheBodyAndEachWheelCentre) {
  pb::VehicleState s = SomeState(pb::VEHICLE_MODEL_PAPER);
  s.mutable_q_wb()->Clear();  // upright, facing +X: the body frame is the world's, moved to T
  s.mutable_q_wb()->set_w(1);
  const foxglove::Geometry g = foxglove::GeometryFor(3, nullptr, nullptr);
  ::foxglove::FrameTransforms t;
  foxglove::BuildTransforms(s, g, 42, t);
  ASSERT_EQ(t.transforms_size(), 5);
  EXPECT_EQ(t.transforms(0).parent_frame_id(), "world");
  EXPECT_EQ(t.transforms(0).child_frame_id(), "vehicle/3/body");
  EXPECT_EQ(t.transforms(0).translation().x(), 10);
  EXPECT_EQ(t.transforms(0).rotation().w(), 1);
  for (int w = 0; w < 4; ++w) {
    const auto& wt = t.transforms(w + 1);
    EXPECT_EQ(wt.parent_frame_id(), "vehicle/3/body");
    EXPECT_EQ(wt.child_frame_id(), foxglove::WheelFrame(3, w));
    // A stands straight above B here: the centre is one radius above B.
    const auto& b = s.wheels(w).p_b_w();
    EXPECT_NEAR(wt.translation().x(), b.x() - 10, 1e-12);
    EXPECT_NEAR(wt.translation().y(), b.y() + 4, 1e-12);
    EXPECT_NEAR(wt.translation().z(), b.z() + g.radius[static_cast<std::size_t>(w)] - 0.55, 1e-12);
    // Turned by the steering angle about Z.
    EXPECT_NEAR(2 * std::atan2(wt.rotation().z(), wt.rotation().w()), s.wheels(w).gamma(), 1e-12);
  }
}

TEST(FoxgloveScene, TerrainKeepsEveryUsableTriangle) {
  pb::WorldDescription w;
  w.set_server_id("s");
  pb::Mesh* m = w.add_meshes();
  m->set_kind(pb::SURFACE_ROAD);
  for (double v : {0., 0., 0., 1., 0., 0., 0., 1., 0.}) m->add_vertices(v);
  for (std::uint32_t i : {0u, 1u, 2u, 0u, 1u, 9u, 2u, 1u})
    m->add_indices(i);  // one past the end; a part
  ::foxglove::SceneUpdate u;
  foxglove::BuildWorldScene(w, 0, u);
  ASSERT_EQ(u.entities_size(), 1);
  EXPECT_EQ(u.entities(0).id(), "world/s");
  ASSERT_EQ(u.entities(0).triangles_size(), 1);
  EXPECT_EQ(u.entities(0).triangles(0).points_size(), 3);
  EXPECT_EQ(u.entities(0).triangles(0).indices_size(), 3);
}

TEST(FoxgloveScene, StatesThatCannotBeDrawnAreNamed) {
  pb::VehicleState s = SomeState(pb::VEHICLE_MODEL_PAPER);
  s.mutable_wheels()->RemoveLast();
  EXPECT_EQ(foxglove::CheckState(s), "state of vehicle 3: 3 wheels, expected 4");
  s = SomeState(pb::VEHICLE_MODEL_PAPER);
  s.mutable_q_wb()->Clear();
  EXPECT_EQ(foxglove::CheckState(s),
            "state of vehicle 3: orientation quaternion is not a rotation");
  s = SomeState(pb::VEHICLE_MODEL_PAPER);
  s.mutable_wheels(2)->mutable_p_b_w()->set_z(2e7);
  EXPECT_EQ(foxglove::CheckState(s), "state of vehicle 3: wheel LR beyond 1e7 m");
}

// --- parameters
// -----------------------------------------------------------------------------------

TEST(FoxgloveParams, NamesEveryFieldAndSetsItBack) {
  pb::VehicleParams p;
  p.set_mass(1500);
  p.mutable_lf()->set_radius(0.31);
  p.set_gear_count(6);
  p.set_model(pb::VEHICLE_MODEL_FULL);
  const auto list = foxglove::ParametersOf(4, p);
  ASSERT_EQ(list.size(), 4u);
  pb::VehicleParams back;
  for (const auto& q : list) {
    const auto n = foxglove::ParseParameterName(q.name);
    ASSERT_TRUE(n) << q.name;
    EXPECT_EQ(n->vehicle_id, 4u);
    EXPECT_EQ(foxglove::SetParameter(back, n->path, *q.value), "") << q.name;
  }
  EXPECT_EQ(back.SerializeAsString(), p.SerializeAsString());
  EXPECT_EQ(list[1].name, "vehicle/4/lf/radius");
  EXPECT_EQ(list[2].name, "vehicle/4/model");
  EXPECT_EQ(std::get<std::string>(*list[2].value), "VEHICLE_MODEL_FULL");
  EXPECT_EQ(std::get<std::int64_t>(*list[3].value), 6);
}

TEST(FoxgloveParams, RefusesNamesAndValuesThatDoNotFit) {
  for (const char* bad : {"mass", "vehicle/", "vehicle/x/mass", "vehicle/1", "vehicle/1/",
                          "vehicle/99999999999/mass"}) {
    EXPECT_FALSE(foxglove::ParseParameterName(bad)) << bad;
  }
  pb::VehicleParams p;
  EXPECT_EQ(foxglove::SetParameter(p, "lf/nothing", 1.0), "no parameter 'lf/nothing'");
  EXPECT_EQ(foxglove::SetParameter(p, "mass/x", 1.0), "no parameter 'mass/x'");
  EXPECT_EQ(foxglove::SetParameter(p, "mass", true), "'mass' takes a number, not a boolean");
  EXPECT_EQ(foxglove::SetParameter(p, "gear_count", 2.5),
            "'gear_count' takes a whole number in 0..4294967295");
  EXPECT_NE(foxglove::SetParameter(p, "model", std::string("FAST"))
                .find("one of VEHICLE_MODEL_UNSPECIFIED"),
            std::string::npos);
  EXPECT_EQ(p.ByteSizeLong(), 0u);
}

}  // namespace
}  // namespace vdyn

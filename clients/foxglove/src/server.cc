#include "vdyn/foxglove/server.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <vector>

#include <boost/asio.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket/rfc6455.hpp>

#include "vdyn/foxglove/protocol.h"
#include "vdyn/foxglove/web_assets.h"

namespace vdyn::foxglove {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
using tcp = asio::ip::tcp;
using protocol::WsOpcode;

// --- latency histogram
// ----------------------------------------------------------------------------

void LatencyHistogram::Add(std::int64_t ns) {
  if (!bins_) bins_ = std::make_unique<std::uint32_t[]>(kBins);
  const std::int64_t bin = std::clamp<std::int64_t>(ns / 10'000, 0, kBins - 1);
  ++bins_[static_cast<std::size_t>(bin)];
  ++count_;
}

double LatencyHistogram::PercentileMs(double p) const {
  if (count_ == 0) return 0;
  const auto rank = static_cast<std::uint64_t>(std::ceil(p / 100.0 * static_cast<double>(count_)));
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < kBins; ++i) {
    seen += bins_[i];
    if (seen >= std::max<std::uint64_t>(rank, 1)) return (static_cast<double>(i) + 0.5) * 0.01;
  }
  return static_cast<double>(kBins) * 0.01;
}

void LatencyHistogram::Merge(const LatencyHistogram& o) {
  if (o.count_ == 0) return;
  if (!bins_) bins_ = std::make_unique<std::uint32_t[]>(kBins);
  for (std::size_t i = 0; i < kBins; ++i) bins_[i] += o.bins_[i];
  count_ += o.count_;
}

void LatencyHistogram::Clear() {
  if (bins_) std::fill(bins_.get(), bins_.get() + kBins, 0u);
  count_ = 0;
}

// --- connections
// ----------------------------------------------------------------------------------

class ConnectionBase {
 public:
  virtual ~ConnectionBase() = default;
  virtual void Start() = 0;
  virtual void CloseWith(std::uint16_t code, const std::string& reason) = 0;
};

struct Server::Impl {
  ServerOptions options;
  ClientHandler& handler;
  asio::io_context io{1};
  tcp::acceptor acceptor{io};
  std::optional<asio::ssl::context> tls;
  std::string three_js;  // the file's bytes, read at start (empty: not found)
  std::string three_js_error;
  ClientId next_id = 1;
  std::map<ClientId, std::weak_ptr<ConnectionBase>> connections;  // the io thread's
  std::atomic<std::uint64_t> connections_total{0}, http_requests{0}, refused{0}, protocol_errors{0},
      bytes_written{0}, accept_errors{0};
  mutable std::mutex accept_error_mu;
  std::string last_accept_error;
  asio::steady_timer accept_retry{io};
  std::atomic<int> clients{0};
  std::mutex latency_mu;
  LatencyHistogram latency;

  Impl(const ServerOptions& o, ClientHandler& h) : options(o), handler(h) {}
  void Accept();
};

namespace {

std::string CloseFrame(std::uint16_t code, std::string_view reason) {
  std::string p;
  p.push_back(static_cast<char>(code >> 8));
  p.push_back(static_cast<char>(code & 0xff));
  p.append(reason.substr(0, 120));
  return p;
}

template <class Stream>
tcp::socket& Socket(Stream& s) {
  return beast::get_lowest_layer(s);
}

template <class Stream>
class Connection final : public ConnectionBase,
                         public std::enable_shared_from_this<Connection<Stream>> {
 public:
  static constexpr bool kTls = !std::is_same_v<Stream, tcp::socket>;

  Connection(Server::Impl& server, Stream stream, ClientId id)
      : server_(server),
        stream_(std::move(stream)),
        id_(id),
        idle_(server.io),
        reader_(server.options.max_client_message_bytes) {
    beast::error_code ec;
    peer_ = Socket(stream_).remote_endpoint(ec).address().to_string();
  }

  void Start() override {
    ArmIdle();
    if constexpr (kTls) {
      stream_.async_handshake(asio::ssl::stream_base::server,
                              [self = this->shared_from_this()](beast::error_code ec) {
                                if (ec) return self->Drop("TLS handshake: " + ec.message());
                                self->ReadRequest();
                              });
    } else {
      ReadRequest();
    }
  }

  void CloseWith(std::uint16_t code, const std::string& reason) override {
    if (dropped_ || closing_) return;
    if (!outbox_) return Drop(reason);
    closing_ = true;
    close_reason_ = reason;  // the log says it (it said "closed", as for a polite client)
    // A client that does not read keeps its socket and its slot: dropped after a grace period
    // for the close frame to go out (it held its --max-clients slot for as long as it stayed).
    idle_.expires_after(std::chrono::seconds(kCloseGraceS));
    idle_.async_wait([weak = this->weak_from_this()](beast::error_code ec) {
      if (ec) return;
      if (auto self = weak.lock(); self && !self->dropped_) {
        self->Drop(self->close_reason_ + " (the close was not taken within " +
                   std::to_string(kCloseGraceS) + " s: dropped)");
      }
    });
    // Say why in a status first (Foxglove shows it), then the close frame; nothing after it.
    (void)outbox_->PushControl(WsOpcode::kText,
                               protocol::StatusJson(protocol::StatusLevel::kError, reason));
    outbox_->Finish(CloseFrame(code, reason));
    MaybeWrite();
  }

 private:
  // --- HTTP -------------------------------------------------------------------------------------
  // An HTTP connection (or a TLS handshake) that sends no whole request for 30 s is closed; a
  // WebSocket client has no such limit.
  void ArmIdle() {
    idle_.expires_after(std::chrono::seconds(30));
    idle_.async_wait([weak = this->weak_from_this()](beast::error_code ec) {
      if (ec) return;
      if (auto self = weak.lock(); self && !self->opened_) self->Drop("no request for 30 s");
    });
  }

  void ReadRequest() {
    ArmIdle();
    parser_.emplace();
    parser_->header_limit(16 * 1024);
    parser_->body_limit(64 * 1024);
    http::async_read(stream_, buffer_, *parser_,
                     [self = this->shared_from_this()](beast::error_code ec, std::size_t) {
                       // Too long a request line or headers (431), too large a body (413), a
                       // request that is not HTTP (400): answered, then closed.
                       if (ec == http::error::header_limit) {
                         return self->Refuse(http::status::request_header_fields_too_large,
                                             "request line and headers over 16 KiB");
                       }
                       if (ec == http::error::body_limit) {
                         return self->Refuse(http::status::payload_too_large,
                                             "request body over 64 KiB");
                       }
                       if (ec && ec != http::error::end_of_stream &&
                           ec.category() == http::make_error_code(http::error::bad_target).category()) {
                         return self->Refuse(http::status::bad_request, "HTTP: " + ec.message());
                       }
                       if (ec)
                         return self->Drop(
                             ec == http::error::end_of_stream ? "closed" : "HTTP: " + ec.message());
                       self->OnRequest();
                     });
  }

  void OnRequest() {
    ++server_.http_requests;
    http::request<http::string_body> req = parser_->release();
    // RFC 9112 3.2: an HTTP/1.1 request with no Host, or more than one, is answered 400.
    const auto hosts = std::distance(req.equal_range(http::field::host).first,
                                     req.equal_range(http::field::host).second);
    if (hosts > 1 || (hosts == 0 && req.version() >= 11)) {
      return Refuse(http::status::bad_request,
                    hosts == 0 ? "an HTTP/1.1 request needs a Host header"
                               : "a request with more than one Host header");
    }
    if (beast::websocket::is_upgrade(req)) return Upgrade(req);
    auto res = std::make_shared<http::response<http::string_body>>();
    res->version(req.version());
    res->set(http::field::server, "vdyn-foxglove");
    res->set(http::field::cache_control, "no-cache");
    res->keep_alive(req.keep_alive());
    std::string full(req.target());
    // The absolute form (RFC 9112 3.2.2: a server must accept it): its path.
    if (const std::size_t scheme = full.find("://"); scheme != std::string::npos && full[0] != '/') {
      const std::size_t path = full.find('/', scheme + 3);
      full = path == std::string::npos ? "/" : full.substr(path);
    }
    const std::string target = full.substr(0, full.find('?'));
    auto body = [&](http::status s, std::string_view type, std::string_view text) {
      res->result(s);
      res->set(http::field::content_type, std::string(type));
      res->body() = std::string(text);
    };
    if (req.method() != http::verb::get && req.method() != http::verb::head) {
      body(http::status::method_not_allowed, "text/plain", "GET only\n");
      res->set(http::field::allow, "GET, HEAD");  // RFC 9110 15.5.6
    } else if (target == "/" || target == "/index.html") {
      body(http::status::ok, "text/html; charset=utf-8", web::IndexHtml());
    } else if (target == "/app.js") {
      body(http::status::ok, "text/javascript; charset=utf-8", web::AppJs());
    } else if (target == "/three.min.js" && !server_.three_js.empty()) {
      body(http::status::ok, "text/javascript; charset=utf-8", server_.three_js);
    } else if (target == "/favicon.ico") {
      body(http::status::no_content, "image/x-icon", "");
    } else if (target == "/three.min.js") {
      body(http::status::not_found, "text/plain", server_.three_js_error + "\n");
    } else {
      body(http::status::not_found, "text/plain", "not found: " + target + "\n");
    }
    res->prepare_payload();
    if (res->result() == http::status::no_content) {  // RFC 9110 8.6: no Content-Length
      res->erase(http::field::content_length);
      res->erase(http::field::content_type);
    }
    if (req.method() == http::verb::head) res->body().clear();
    http::async_write(stream_, *res,
                      [self = this->shared_from_this(), res](beast::error_code ec, std::size_t n) {
                        if (ec) return self->Drop("HTTP write: " + ec.message());
                        self->server_.bytes_written += n;
                        if (!res->keep_alive()) return self->Drop("HTTP done");
                        self->ReadRequest();
                      });
  }

  void Refuse(http::status status, const std::string& why) {
    ++server_.refused;
    auto res = std::make_shared<http::response<http::string_body>>(status, 11);
    res->set(http::field::server, "vdyn-foxglove");
    // RFC 6455 4.4: a version this server does not speak is answered with the one it does.
    if (status == http::status::upgrade_required) res->set(http::field::sec_websocket_version, "13");
    res->set(http::field::content_type, "text/plain");
    res->body() = why + "\n";
    res->keep_alive(false);
    res->prepare_payload();
    http::async_write(stream_, *res,
                      [self = this->shared_from_this(), res](beast::error_code ec, std::size_t) {
                        if (ec) return self->Drop("refused");
                        self->LingerThenDrop();
                      });
  }

  // RFC 9112 9.6: after a refusal the client may still be sending (the rest of an over-long
  // header or body). Closing a socket with unread data resets the connection, and a reset can
  // discard the answer before the client reads it (its own or the server's queue). So the answer
  // is followed by a FIN, and what the client still sends is read and discarded, for at most 2 s
  // and 1 MiB, before the socket is closed.
  void LingerThenDrop() {
    beast::error_code ec;
    Socket(stream_).shutdown(tcp::socket::shutdown_send, ec);
    if (ec) return Drop("refused");
    idle_.expires_after(std::chrono::seconds(2));
    idle_.async_wait([weak = this->weak_from_this()](beast::error_code e) {
      if (e) return;
      if (auto self = weak.lock()) self->Drop("refused");
    });
    DiscardInput();
  }
  void DiscardInput() {
    Socket(stream_).async_read_some(
        asio::buffer(rbuf_), [self = this->shared_from_this()](beast::error_code ec, std::size_t n) {
          self->lingered_ += n;
          if (ec || self->lingered_ > (1u << 20)) return self->Drop("refused");
          self->DiscardInput();
        });
  }

  void Upgrade(const http::request<http::string_body>& req) {
    const std::string key(req[http::field::sec_websocket_key]);
    // The subprotocols offered, on one header line or several (RFC 6455 11.3.4: the same).
    std::string offered;
    for (auto [it, end] = req.equal_range(http::field::sec_websocket_protocol); it != end; ++it)
      offered += (offered.empty() ? "" : ",") + std::string(it->value());
    const std::string subprotocol = protocol::ChooseSubprotocol(offered);
    // RFC 6455 4.2.1: an upgrade without a version is not a WebSocket handshake (400); 4.2.2: one
    // with a version this server does not speak gets 426 and the version it does.
    if (req.count(http::field::sec_websocket_version) == 0) {
      return Refuse(http::status::bad_request,
                    "a WebSocket upgrade needs Sec-WebSocket-Version: 13");
    }
    if (req[http::field::sec_websocket_version] != "13") {
      return Refuse(http::status::upgrade_required,
                    "vdyn-foxglove speaks WebSocket version 13 (Sec-WebSocket-Version)");
    }
    if (!protocol::ValidClientKey(key)) {
      return Refuse(http::status::bad_request,
                    "a WebSocket upgrade needs a Sec-WebSocket-Key of 16 bytes in base64");
    }
    if (subprotocol.empty()) {
      return Refuse(http::status::bad_request,
                    "vdyn-foxglove speaks the Foxglove WebSocket protocol: offer the subprotocol "
                    "foxglove.websocket.v1 or foxglove.sdk.v1");
    }
    if (server_.clients.load() >= static_cast<int>(server_.options.max_clients)) {
      return Refuse(http::status::service_unavailable,
                    "vdyn-foxglove has " + std::to_string(server_.options.max_clients) +
                        " clients already (--max-clients)");
    }
    auto accept = std::make_shared<std::string>(
        "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Accept: " +
        protocol::AcceptKey(key) + "\r\nSec-WebSocket-Protocol: " + subprotocol +
        "\r\nServer: vdyn-foxglove\r\n\r\n");
    asio::async_write(
        stream_, asio::buffer(*accept),
        [self = this->shared_from_this(), accept, subprotocol](beast::error_code ec, std::size_t) {
          if (ec) return self->Drop("handshake write: " + ec.message());
          self->Open(subprotocol);
        });
  }

  // --- WebSocket
  // ----------------------------------------------------------------------------------
  void Open(const std::string& subprotocol) {
    idle_.cancel();
    outbox_ = std::make_shared<Outbox>(server_.options.limits);
    std::weak_ptr<Connection> weak = this->shared_from_this();
    asio::io_context& io = server_.io;
    outbox_->SetWake([weak, &io] {
      asio::post(io, [weak] {
        if (auto self = weak.lock()) {
          self->outbox_->ClearWake();
          self->MaybeWrite();
        }
      });
    });
    opened_ = true;
    ++server_.clients;
    ++server_.connections_total;
    server_.handler.OnOpen(id_, outbox_, subprotocol, peer_);
    // Frames the client sent right behind its request.
    const std::string early(static_cast<const char*>(buffer_.data().data()), buffer_.size());
    buffer_.consume(buffer_.size());
    if (!Feed(early)) return;
    ReadFrames();
    MaybeWrite();
  }

  void ReadFrames() {
    stream_.async_read_some(asio::buffer(rbuf_),
                            [self = this->shared_from_this()](beast::error_code ec, std::size_t n) {
                              if (ec)
                                return self->Drop(ec == asio::error::eof ? "closed by the client"
                                                                         : "read: " + ec.message());
                              if (!self->Feed({self->rbuf_.data(), n})) return;
                              if (!self->closing_) self->ReadFrames();
                            });
  }

  // False when the connection is closing.
  bool Feed(std::string_view in) {
    protocol::FrameReader::Event ev;
    try {
      while (!closing_ && reader_.Next(in, ev)) {
        switch (ev.kind) {
          case protocol::FrameReader::Event::Kind::kText:
            server_.handler.OnText(id_, ev.payload);
            break;
          case protocol::FrameReader::Event::Kind::kBinary:
            server_.handler.OnBinary(
                id_, {reinterpret_cast<const std::uint8_t*>(ev.payload.data()), ev.payload.size()});
            break;
          case protocol::FrameReader::Event::Kind::kPing:
            outbox_->PushPong(ev.payload);  // the newest ping's pong (it queued one per ping)
            break;
          case protocol::FrameReader::Event::Kind::kPong:
            break;
          case protocol::FrameReader::Event::Kind::kClose:
            // Answer with the client's code (or none), then close.
            closing_ = true;
            close_reason_ = "closed by the client";
            outbox_->Finish(ev.payload.size() >= 2 ? ev.payload.substr(0, 2) : std::string());
            MaybeWrite();
            return false;
        }
      }
    } catch (const protocol::ProtocolError& e) {
      ++server_.protocol_errors;
      CloseWith(reader_.close_code(), std::string("WebSocket protocol error: ") + e.what());
      return false;
    }
    return !closing_;
  }

  void MaybeWrite() {
    if (writing_ || dropped_ || !outbox_) return;
    wbuf_.clear();
    stamps_.clear();
    if (!outbox_->Take(wbuf_, server_.options.write_batch_bytes, base::MonotonicNow(), stamps_)) {
      if (closing_ && outbox_->finished()) Shutdown();
      return;
    }
    writing_ = true;
    asio::async_write(stream_, asio::buffer(wbuf_),
                      [self = this->shared_from_this()](beast::error_code ec, std::size_t n) {
                        self->writing_ = false;
                        if (ec) return self->Drop("write: " + ec.message());
                        self->server_.bytes_written += n;
                        if (!self->stamps_.empty()) {
                          const std::int64_t now = base::WallNow().ns;
                          std::lock_guard lock(self->server_.latency_mu);
                          for (std::int64_t s : self->stamps_) self->server_.latency.Add(now - s);
                        }
                        self->MaybeWrite();
                      });
  }

  void Shutdown() {
    beast::error_code ec;
    Socket(stream_).shutdown(tcp::socket::shutdown_send, ec);
    Drop(closing_ ? (close_reason_.empty() ? "closed" : close_reason_) : "shut down");
  }

  void Drop(const std::string& why) {
    if (dropped_) return;
    dropped_ = true;
    beast::error_code ec;
    Socket(stream_).close(ec);
    idle_.cancel();
    if (opened_) {
      --server_.clients;
      server_.handler.OnClose(id_, why);
    }
    server_.connections.erase(id_);
  }

  Server::Impl& server_;
  Stream stream_;
  ClientId id_;
  std::string peer_;
  asio::steady_timer idle_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  protocol::FrameReader reader_;
  std::array<char, 16384> rbuf_{};
  std::size_t lingered_ = 0;  // bytes read and discarded after a refusal
  std::shared_ptr<Outbox> outbox_;
  std::string wbuf_;
  std::vector<std::int64_t> stamps_;
  bool opened_ = false, writing_ = false, closing_ = false, dropped_ = false;
  std::string close_reason_;  // why it is closing, for the log
  static constexpr int kCloseGraceS = 5;
};

}  // namespace

void Server::Impl::Accept() {
  acceptor.async_accept([this](beast::error_code ec, tcp::socket socket) {
    if (ec == asio::error::operation_aborted) return;
    if (ec) {
      // Out of file descriptors (or another failure): counted and said by the status loop, and
      // tried again after a pause. Re-armed at once, the failing accept spun a core and served
      // nobody.
      ++accept_errors;
      {
        std::lock_guard lock(accept_error_mu);
        last_accept_error = ec.message();
      }
      accept_retry.expires_after(std::chrono::milliseconds(100));
      accept_retry.async_wait([this](beast::error_code wait_ec) {
        if (!wait_ec) Accept();
      });
      return;
    }
    if (!ec) {
      beast::error_code ignore;
      socket.set_option(tcp::no_delay(true), ignore);
      socket.set_option(asio::socket_base::send_buffer_size(options.socket_send_bytes), ignore);
      const ClientId id = next_id++;
      std::shared_ptr<ConnectionBase> c;
      if (tls) {
        c = std::make_shared<Connection<asio::ssl::stream<tcp::socket>>>(
            *this, asio::ssl::stream<tcp::socket>(std::move(socket), *tls), id);
      } else {
        c = std::make_shared<Connection<tcp::socket>>(*this, std::move(socket), id);
      }
      connections[id] = c;
      c->Start();
    }
    Accept();
  });
}

Server::Server(const ServerOptions& options, ClientHandler& handler)
    : impl_(std::make_unique<Impl>(options, handler)) {
  if (options.tls_cert.empty() != options.tls_key.empty()) {
    throw std::runtime_error("--tls-cert and --tls-key go together");
  }
  if (!options.tls_cert.empty()) {
    impl_->tls.emplace(asio::ssl::context::tls_server);
    try {
      impl_->tls->set_options(asio::ssl::context::default_workarounds |
                              asio::ssl::context::no_sslv2 | asio::ssl::context::no_sslv3 |
                              asio::ssl::context::no_tlsv1 | asio::ssl::context::no_tlsv1_1);
      impl_->tls->use_certificate_chain_file(options.tls_cert.string());
    } catch (const std::exception& e) {
      throw std::runtime_error(options.tls_cert.string() + ": not a usable PEM certificate (" +
                               e.what() + ")");
    }
    try {
      impl_->tls->use_private_key_file(options.tls_key.string(), asio::ssl::context::pem);
    } catch (const std::exception& e) {
      throw std::runtime_error(options.tls_key.string() + ": not a usable PEM private key for " +
                               options.tls_cert.string() + " (" + e.what() + ")");
    }
  }
  std::ifstream three(options.three_js, std::ios::binary);
  if (three) {
    std::ostringstream s;
    s << three.rdbuf();
    impl_->three_js = s.str();
  } else {
    impl_->three_js_error = "three.js not found at " + options.three_js.string() +
                            ": install Debian's libjs-three, or give --three-js FILE";
  }
  beast::error_code ec;
  const auto address = asio::ip::make_address(options.host, ec);
  if (ec) throw std::runtime_error("--host " + options.host + ": not an IP address");
  const tcp::endpoint at(address, options.port);
  auto fail = [&](const char* what) {
    throw std::runtime_error(std::string(what) + " " + options.host + ":" +
                             std::to_string(options.port) + ": " + ec.message());
  };
  impl_->acceptor.open(at.protocol(), ec);
  if (ec) fail("cannot open a socket for");
  impl_->acceptor.set_option(asio::socket_base::reuse_address(true), ec);
  impl_->acceptor.bind(at, ec);
  if (ec) fail("cannot listen on");
  impl_->acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) fail("cannot listen on");
  impl_->Accept();
}

Server::~Server() = default;

std::uint16_t Server::port() const {
  beast::error_code ec;
  return impl_->acceptor.local_endpoint(ec).port();
}

bool Server::tls() const {
  return impl_->tls.has_value();
}

void Server::Run() {
  impl_->io.run();
}

void Server::Stop() {
  asio::post(impl_->io, [this] {
    beast::error_code ec;
    impl_->acceptor.close(ec);
    for (auto& [id, weak] : std::map(impl_->connections)) {
      if (auto c = weak.lock()) c->CloseWith(1001, "vdyn-foxglove is shutting down");
    }
    // Give the close frames a moment, then stop whatever is left.
    auto timer = std::make_shared<asio::steady_timer>(impl_->io, std::chrono::milliseconds(300));
    timer->async_wait([this, timer](beast::error_code) { impl_->io.stop(); });
  });
}

void Server::Close(ClientId id, const std::string& reason) {
  asio::post(impl_->io, [this, id, reason] {
    const auto it = impl_->connections.find(id);
    if (it == impl_->connections.end()) return;
    if (auto c = it->second.lock()) c->CloseWith(1008, reason);
  });
}

Server::Stats Server::stats() const {
  Stats s;
  s.connections = impl_->connections_total;
  s.http_requests = impl_->http_requests;
  s.refused = impl_->refused;
  s.protocol_errors = impl_->protocol_errors;
  s.bytes_written = impl_->bytes_written;
  s.accept_errors = impl_->accept_errors;
  {
    std::lock_guard lock(impl_->accept_error_mu);
    s.last_accept_error = impl_->last_accept_error;
  }
  s.clients = impl_->clients;
  return s;
}

void Server::TakeLatencies(LatencyHistogram& into) {
  std::lock_guard lock(impl_->latency_mu);
  into.Merge(impl_->latency);
  impl_->latency.Clear();
}

}  // namespace vdyn::foxglove

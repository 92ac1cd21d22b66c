// `vdyn-recorder play FILE`: the recording republished to DDS as it was recorded - world,
// parameters, states and driver inputs, the payloads exactly as they were received - at their
// recorded times (log time), at 1x or another rate. Pause, step, seek, loop and rate from the
// keyboard (a person at a terminal) or as control requests (pause, resume, step N, playback
// {seek_ns, loop, rate}) addressed to the player's server id; a viewer shows the playback exactly
// as it shows a live drive.
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <map>
#include <memory>
#include <set>

#include "vdyn/base/deadline.h"
#include "vdyn/base/limits.h"
#include "vdyn/base/time.h"
#include "vdyn/control.pb.h"
#include "vdyn/diagnostics.pb.h"
#include "vdyn/messages/control_reply.h"
#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/state_writers.h"
#include "vdyn/world.pb.h"

namespace vdyn::recorder {

using transport::TopicId;

namespace {

// The terminal in raw mode while the player runs (keys without Enter, no echo), restored after.
class RawTerminal {
 public:
  RawTerminal() {
    if (isatty(STDIN_FILENO) != 1 || tcgetattr(STDIN_FILENO, &saved_) != 0) return;
    termios raw = saved_;
    raw.c_lflag &= ~static_cast<tcflag_t>(ICANON | ECHO);
    raw.c_cc[VMIN] = 0;
    raw.c_cc[VTIME] = 0;
    active_ = tcsetattr(STDIN_FILENO, TCSANOW, &raw) == 0;
  }
  ~RawTerminal() {
    if (active_) tcsetattr(STDIN_FILENO, TCSANOW, &saved_);
  }
  bool active() const { return active_; }
  // The keys typed since the last call ("\x1b[C" for an arrow).
  std::string Read() {
    std::string keys;
    if (!active_) return keys;
    pollfd p{STDIN_FILENO, POLLIN, 0};
    while (poll(&p, 1, 0) > 0 && (p.revents & POLLIN) != 0) {
      char b[64];
      const ssize_t n = ::read(STDIN_FILENO, b, sizeof b);
      if (n <= 0) break;
      keys.append(b, static_cast<std::size_t>(n));
    }
    return keys;
  }

 private:
  termios saved_{};
  bool active_ = false;
};

struct PlayChannel {
  TopicId topic;
  std::uint32_t key;
  bool play = false;
  bool repeat = false;  // copies of a world or parameters (RepeatChannelMetadata)
};

class Player {
 public:
  Player(const PlayOptions& o, std::ostream& out) : o_(o), out_(out), reader_(o.file) {}

  int Run(const std::atomic<bool>& stop);

 private:
  bool Load();
  void LoadChunk(std::size_t index);
  void Seek(std::uint64_t pos_ns);
  void PublishLatched(std::uint64_t pos_ns);
  // `latched`: a world or parameters republished at a seek (a copy may stand in for them).
  void Publish(const mcap::Message& m, bool latched = false);
  // Sends the states published since the last call (vdyn/states: one sample).
  void FlushStates();
  void Step(int n);
  void HandleKeys(const std::string& keys, bool& quit);
  void HandleRequests();
  void Status(bool force);
  void Announce(bool force);
  std::uint64_t Now() const { return static_cast<std::uint64_t>(base::MonotonicNow().ns); }
  // Where the playback is, ns from the recording's first message.
  std::uint64_t Position() const {
    if (paused_) return pos0_;
    const double run = static_cast<double>(Now() - wall0_) * rate_;
    return pos0_ + static_cast<std::uint64_t>(run);
  }
  void Anchor(std::uint64_t pos) {
    pos0_ = pos;
    wall0_ = Now();
  }

  const PlayOptions& o_;
  std::ostream& out_;
  mcap::Reader reader_;
  std::vector<mcap::ChunkIndex> chunks_;
  std::map<std::uint16_t, PlayChannel> channels_;
  std::uint64_t first_ = 0, last_ = 0;   // log times
  std::uint64_t from_ = 0, to_ = 0;      // ns from first
  std::uint32_t lead_vehicle_ = 0;        // "step" counts this vehicle's states
  // World and parameters: (time, channel, payload), republished on every seek.
  struct Latched {
    std::uint64_t t;
    std::uint16_t channel;
    std::vector<std::uint8_t> data;
  };
  std::vector<Latched> latched_;
  // The current chunk, decompressed.
  std::size_t chunk_ = 0;
  std::vector<std::uint8_t> scratch_;
  std::vector<mcap::Message> messages_;
  std::size_t next_ = 0;
  bool at_end_ = false;
  // Clock.
  double rate_ = 1.0;
  bool paused_ = false;
  bool loop_ = false;
  std::uint64_t pos0_ = 0, wall0_ = 0;
  std::uint64_t sent_ = 0;
  std::uint64_t last_status_ = 0;
  // DDS.
  std::unique_ptr<transport::Participant> participant_;
  transport::DropCounters drops_;
  std::map<TopicId, std::unique_ptr<transport::RawWriter>> writers_;  // every topic but states
  // States: to everyone, and to a vehicle's partition while one-vehicle readers read there.
  std::unique_ptr<transport::StateWriters> states_;
  std::unique_ptr<transport::Reader<pb::ControlRequest>> control_;
  std::unique_ptr<transport::Writer<pb::ControlReply>> replies_;
  // What it is, once a second on vdyn/diagnostics: a player (mode "playback"), of which
  // recording, republishing which servers' topics (a viewer labels their view PLAYBACK).
  std::unique_ptr<transport::Writer<pb::Diagnostics>> announce_;
  std::set<std::string> servers_;
  std::uint64_t last_announce_ = 0;
  bool tty_ = false;
};

bool Player::Load() {
  // What `info` refuses, play refuses too (a damaged file: `recover` first); what no CRC checked
  // plays, and says so.
  const mcap::ScanResult check = CheckWholeFile(reader_, "check");
  if (check.chunks_unchecked > 0 && check.data_crc != mcap::ScanResult::DataCrc::kMatched) {
    out_ << "vdyn-recorder play: " << o_.file.string() << ": " << check.messages_unchecked
         << " messages lie in chunks without a CRC: nothing checked their bytes (vdyn-recorder "
            "info)\n";
  }
  const auto summary = reader_.ReadSummary();
  if (!summary || !summary->statistics) {
    out_ << "vdyn-recorder play: " << o_.file.string()
         << " has no summary (it was not closed): run `vdyn-recorder recover` first\n";
    return false;
  }
  chunks_ = summary->chunk_indexes;
  std::sort(chunks_.begin(), chunks_.end(), [](const auto& a, const auto& b) {
    return a.message_start_time < b.message_start_time;
  });
  first_ = summary->statistics->message_start_time;
  last_ = summary->statistics->message_end_time;
  std::set<std::uint32_t> vehicles;
  for (const auto& [id, info] : VdynChannels(*summary)) {
    // Copies of the world and parameters serve when the first is lost; they are not replayed.
    PlayChannel pc{info.topic, info.key, false, info.repeat};
    pc.play = o_.topics.count(transport::Spec(info.topic).name) != 0 &&
              (!o_.vehicle || ServerKeyed(info.topic) || info.key == *o_.vehicle);
    if (pc.play && info.topic == TopicId::kState) vehicles.insert(info.key);
    channels_[id] = pc;
  }
  if (vehicles.empty()) {
    out_ << "vdyn-recorder play: no vehicle states to play in " << o_.file.string() << "\n";
    return false;
  }
  lead_vehicle_ = *vehicles.begin();
  from_ = static_cast<std::uint64_t>(base::FromSeconds(o_.from_s).ns);
  to_ = o_.to_s ? static_cast<std::uint64_t>(base::FromSeconds(*o_.to_s).ns) : last_ - first_;
  to_ = std::min(to_, last_ - first_);
  if (from_ > to_) {
    out_ << "vdyn-recorder play: --from is after the end of the recording ("
         << FormatDuration(static_cast<double>(last_ - first_) * 1e-9) << ")\n";
    return false;
  }
  // World and parameters: their messages, from the chunks that hold any (message indexes).
  for (const mcap::ChunkIndex& ci : chunks_) {
    bool any = false;
    for (const auto& [ch, off] : ci.message_index_offsets) {
      const auto it = channels_.find(ch);
      any = any || (it != channels_.end() && it->second.play &&
                    (it->second.topic == TopicId::kWorld || it->second.topic == TopicId::kParams));
    }
    if (!any) continue;
    reader_.ReadChunk(ci, [&](const mcap::Message& m) {
      const auto it = channels_.find(m.channel_id);
      if (it == channels_.end() || !it->second.play) return;
      if (it->second.topic != TopicId::kWorld && it->second.topic != TopicId::kParams) return;
      latched_.push_back({m.log_time - first_, m.channel_id, {m.data.begin(), m.data.end()}});
      pb::WorldDescription w;
      if (it->second.topic == TopicId::kWorld && w.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) {
        servers_.insert(w.server_id());
      }
    }, scratch_);
  }
  return true;
}

void Player::LoadChunk(std::size_t index) {
  chunk_ = index;
  messages_.clear();
  next_ = 0;
  if (index >= chunks_.size()) return;
  reader_.ReadChunk(chunks_[index], [&](const mcap::Message& m) { messages_.push_back(m); }, scratch_);
  std::stable_sort(messages_.begin(), messages_.end(),
                   [](const auto& a, const auto& b) { return a.log_time < b.log_time; });
}

void Player::Seek(std::uint64_t pos) {
  pos = std::clamp(pos, from_, to_);
  const std::uint64_t t = first_ + pos;
  std::size_t c = 0;
  while (c < chunks_.size() && chunks_[c].message_end_time < t) ++c;
  LoadChunk(c);
  while (next_ < messages_.size() && messages_[next_].log_time < t) ++next_;
  at_end_ = false;
  PublishLatched(pos);
  Anchor(pos);
}

void Player::PublishLatched(std::uint64_t pos) {
  // The newest world and parameters of each topic and key as of pos (the first ones when none
  // yet); a copy (repeat channel) counts as the message it copies.
  std::map<std::pair<TopicId, std::uint32_t>, const Latched*> newest;
  for (const Latched& l : latched_) {
    const PlayChannel& c = channels_.at(l.channel);
    auto& n = newest[{c.topic, c.key}];
    if (n == nullptr || (l.t <= pos && (l.t > n->t || n->t > pos))) n = &l;
  }
  for (const auto& [id, l] : newest) {
    mcap::Message m;
    m.channel_id = l->channel;
    m.log_time = first_ + l->t;
    m.data = l->data;
    Publish(m, /*latched=*/true);
  }
  FlushStates();
}

void Player::Publish(const mcap::Message& m, bool latched) {
  const auto it = channels_.find(m.channel_id);
  if (it == channels_.end() || !it->second.play || (it->second.repeat && !latched)) return;
  if (it->second.topic == TopicId::kState) {
    if (!states_) {
      states_ = std::make_unique<transport::StateWriters>(
          *participant_, drops_,
          transport::StateWriters::Options{.sending = transport::Sending::kEach,
                                           .states_key = transport::ServerKey(o_.server_id)});
    }
    // Sent at FlushStates(): the states published together go out as one vdyn/states sample.
    const bool ok = states_->WriteBytes(it->second.key, m.data);
    if (!ok) {
      drops_.Count("write failed on vdyn/state", states_->last_error());
      return;
    }
    ++sent_;
    return;
  }
  auto& w = writers_[it->second.topic];
  if (!w) w = std::make_unique<transport::RawWriter>(*participant_, it->second.topic);
  if (states_) FlushStates();  // what went before goes first
  if (!w->WriteBytes(it->second.key, m.data)) {
    drops_.Count("write failed on " + std::string(transport::Spec(it->second.topic).name), w->last_error());
    return;
  }
  ++sent_;
}

void Player::FlushStates() {
  if (!states_) return;
  // Also creates the own writers of vehicles seen since the last call.
  if (!states_->Flush()) drops_.Count("write failed on vdyn/states", states_->last_error());
}

// Publishes every message up to and including the n-th next state of the lead vehicle.
void Player::Step(int n) {
  int states = 0;
  std::uint64_t pos = pos0_;
  while (states < n && !at_end_) {
    if (next_ >= messages_.size()) {
      if (chunk_ + 1 >= chunks_.size()) {
        at_end_ = true;
        break;
      }
      LoadChunk(chunk_ + 1);
      continue;
    }
    const mcap::Message& m = messages_[next_++];
    if (m.log_time - first_ > to_) {
      at_end_ = true;
      break;
    }
    Publish(m);
    pos = m.log_time - first_;
    const auto it = channels_.find(m.channel_id);
    if (it != channels_.end() && it->second.topic == TopicId::kState && it->second.key == lead_vehicle_) ++states;
  }
  FlushStates();
  Anchor(pos);
}

void Player::HandleKeys(const std::string& keys, bool& quit) {
  for (std::size_t i = 0; i < keys.size(); ++i) {
    const char k = keys[i];
    if (k == '\x1b' && i + 2 < keys.size() && keys[i + 1] == '[') {
      const char a = keys[i + 2];
      i += 2;
      if (a == 'C') Seek(Position() + 5'000'000'000ull);                          // right
      if (a == 'D') Seek(Position() > 5'000'000'000ull ? Position() - 5'000'000'000ull : 0);  // left
      if (a == 'A') rate_ = std::min(limits::kPlaybackRate.hi, rate_ * 2.0), Anchor(Position());  // up
      if (a == 'B') rate_ = std::max(limits::kPlaybackRate.lo, rate_ / 2.0), Anchor(Position());  // down
      continue;
    }
    switch (k) {
      case ' ':
        Anchor(Position());
        paused_ = !paused_;
        Anchor(pos0_);
        break;
      case 'n':
      case '.':
        paused_ = true;
        Step(1);
        break;
      case 'N':
        paused_ = true;
        Step(100);
        break;
      case 'l':
        loop_ = !loop_;
        break;
      case 'r':
        Seek(from_);
        break;
      case 'q':
        quit = true;
        break;
      default:
        if (k >= '0' && k <= '9') Seek(from_ + (to_ - from_) / 10 * static_cast<std::uint64_t>(k - '0'));
        break;
    }
  }
  Status(true);
}

void Player::HandleRequests() {
  (void)control_->Take([&](const pb::ControlRequest& r, const transport::SampleInfo&) {
    const bool player_command =
        r.has_pause() || r.has_resume() || r.has_step() || r.has_playback() || r.has_hello();
    if (!player_command) return;  // for a server
    if (!r.server_id().empty() && r.server_id() != o_.server_id) return;
    pb::ControlReply reply = messages::ReplyTo(&r, o_.server_id);
    if (r.has_hello()) {
      // accepted: nothing to do
    } else if (r.has_pause()) {
      Anchor(Position());
      paused_ = true;
    } else if (r.has_resume()) {
      paused_ = false;
      Anchor(pos0_);
    } else if (r.has_step()) {
      if (r.step().steps() == 0 || r.step().steps() > limits::kMaxStepsPerRequest) {
        messages::Refuse(reply,
                         "step needs 1.." + std::to_string(limits::kMaxStepsPerRequest) + " steps");
      } else {
        Anchor(Position());
        paused_ = true;
        Step(static_cast<int>(r.step().steps()));
      }
    } else {
      const auto& p = r.playback();
      if (p.has_rate() && !limits::Check(limits::kPlaybackRate, p.rate()).empty()) {
        messages::Refuse(reply, limits::Check(limits::kPlaybackRate, p.rate()));
      } else if (p.has_seek_ns() &&
                 (p.seek_ns() < 0 || static_cast<std::uint64_t>(p.seek_ns()) > to_)) {
        messages::Refuse(
            reply, "seek_ns must be in [0, " + std::to_string(to_) + "], the recording's length");
      } else {
        if (p.has_rate()) {
          Anchor(Position());
          rate_ = p.rate();
        }
        if (p.has_loop()) loop_ = p.loop();
        if (p.has_seek_ns()) Seek(static_cast<std::uint64_t>(p.seek_ns()));
      }
    }
    reply.set_sim_time_ns(static_cast<std::int64_t>(Position()));
    if (!replies_->Write(r.vehicle_id(), reply)) {
      drops_.Count("write failed on vdyn/control_reply", replies_->last_error());
    }
    Status(true);
  });
}

void Player::Status(bool force) {
  if (!o_.status_line) return;
  const std::uint64_t now = Now();
  if (!force && now - last_status_ < 100'000'000) return;
  last_status_ = now;
  std::fprintf(stderr, "%splay %9.3f / %.3f s  x%-6g %-7s loop %-3s | %" PRIu64 " messages sent%s",
               tty_ ? "\r" : "", static_cast<double>(Position()) * 1e-9,
               static_cast<double>(to_) * 1e-9, rate_, paused_ ? "PAUSED" : "PLAYING",
               loop_ ? "on" : "off", sent_, tty_ ? "\033[K" : "\n");
  std::fflush(stderr);
}

void Player::Announce(bool force) {
  const std::uint64_t now = Now();
  if (!force && now - last_announce_ < 1'000'000'000) return;
  last_announce_ = now;
  pb::Diagnostics d;
  d.set_server_id(o_.server_id);
  d.set_mode("playback");
  d.set_sim_time_ns(static_cast<std::int64_t>(Position()));
  d.set_recording(o_.file.filename().string().substr(0, limits::kMaxNameBytes));
  for (const std::string& s : servers_) d.add_replayed_servers(s);
  if (!announce_->Write(transport::ServerKey(o_.server_id), d)) {
    drops_.Count("write failed on vdyn/diagnostics", announce_->last_error());
  }
}

int Player::Run(const std::atomic<bool>& stop) {
  if (!Load()) return 1;
  participant_ = std::make_unique<transport::Participant>(o_.domain);
  // Writers first: readers discover them while we look for a live server, so the first states
  // of the playback are not sent before anyone listens.
  for (const auto& [id, ch] : channels_) {
    if (!ch.play) continue;
    if (ch.topic == TopicId::kState) {
      if (!states_) {
        states_ = std::make_unique<transport::StateWriters>(
            *participant_, drops_,
            transport::StateWriters::Options{.sending = transport::Sending::kEach,
                                           .states_key = transport::ServerKey(o_.server_id)});
      }
      // The vehicle's own writer now: one-vehicle readers match it before the first state.
      states_->Prepare(ch.key);
    } else if (!writers_[ch.topic]) {
      writers_[ch.topic] = std::make_unique<transport::RawWriter>(*participant_, ch.topic);
    }
  }
  if (!o_.force) {
    // A live server on this domain would get our states and (worse) our driver inputs.
    transport::Reader<pb::WorldDescription> worlds(*participant_, TopicId::kWorld, &drops_);
    std::string live;
    (void)base::PollUntil(
        base::Deadline::AfterSeconds(o_.server_check_s), base::Milliseconds(50),
        [&] {
          (void)worlds.Take([&](const pb::WorldDescription& w, const transport::SampleInfo&) {
            live = w.server_id();
          });
          return !live.empty() || stop.load();
        },
        [&](base::Nanos slice) { (void)worlds.Wait(base::Chrono(slice)); });
    if (!live.empty()) {
      out_ << "vdyn-recorder play: server '" << live << "' is live on domain " << o_.domain
           << ": a playback there would mix with its vehicles and drive them with the recorded inputs; "
              "play on another --domain (a viewer joins it with the same --domain), or --force\n";
      return 2;
    }
  }
  control_ = std::make_unique<transport::Reader<pb::ControlRequest>>(*participant_, TopicId::kControl, &drops_);
  replies_ = std::make_unique<transport::Writer<pb::ControlReply>>(*participant_, TopicId::kControlReply);
  announce_ = std::make_unique<transport::Writer<pb::Diagnostics>>(*participant_, TopicId::kDiagnostics);
  Announce(true);
  RawTerminal terminal;
  const bool keys = o_.keyboard && terminal.active();
  tty_ = isatty(STDERR_FILENO) == 1;
  rate_ = o_.rate;
  loop_ = o_.loop;
  out_ << "playing " << o_.file.string() << " (" << FormatDuration(static_cast<double>(to_ - from_) * 1e-9)
       << ") on domain " << o_.domain << " as '" << o_.server_id << "'";
  if (keys) out_ << "\n  keys: space pause/resume, n step, N 100 steps, left/right -/+5 s, 0-9 seek to 0-90%, "
                    "up/down rate x2 /2, l loop, r restart, q quit";
  out_ << "\n";
  out_.flush();
  Seek(from_);
  paused_ = o_.paused;
  Anchor(from_);
  bool quit = false;
  while (!stop.load() && !quit) {
    if (keys) HandleKeys(terminal.Read(), quit);
    HandleRequests();
    Status(false);
    Announce(false);
    if (paused_) {
      (void)control_->Wait(std::chrono::milliseconds(20));
      continue;
    }
    // Publish everything that is due; then sleep until the next message (or 20 ms at most).
    const std::uint64_t pos = Position();
    while (!at_end_) {
      if (next_ >= messages_.size()) {
        if (chunk_ + 1 >= chunks_.size()) {
          at_end_ = true;
          break;
        }
        LoadChunk(chunk_ + 1);
        continue;
      }
      const mcap::Message& m = messages_[next_];
      const std::uint64_t t = m.log_time - first_;
      if (t > to_) {
        at_end_ = true;
        break;
      }
      if (t > pos) break;
      Publish(m);
      ++next_;
    }
    FlushStates();
    if (at_end_) {
      if (loop_) {
        Seek(from_);
        continue;
      }
      if (!keys) break;
      Anchor(to_);  // a person may seek back: stay, paused at the end
      paused_ = true;
      Status(true);
      continue;
    }
    const std::uint64_t due = messages_[next_].log_time - first_;
    const auto wait_ns = static_cast<std::int64_t>(static_cast<double>(due - pos) / rate_);
    base::SleepUntil(base::MonotonicNow() + base::Nanos{std::min<std::int64_t>(wait_ns, 20'000'000)});
  }
  if (o_.status_line && tty_) std::fprintf(stderr, "\n");
  out_ << "played " << sent_ << " messages\n";
  return 0;
}

}  // namespace

int RunPlay(const PlayOptions& o, const std::atomic<bool>& stop, std::ostream& out) {
  Player p(o, out);
  return p.Run(stop);
}

}  // namespace vdyn::recorder

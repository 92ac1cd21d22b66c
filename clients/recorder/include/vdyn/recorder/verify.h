// The subcommands of vdyn-recorder that re-simulate, linked by name (vdyn_replay, whose interface
// speaks messages; the physics stays behind it): `verify` re-simulates a recording from its events and compares the state hash of every
// recorded step; `takeover` finds the exact state at a moment of a recording and has a live server
// restore it. This library (vdyn_recorder_physics) is the only part of the recorder that links
// the physics (through vdyn_replay); record, info, export, play, plot and recover never do.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "vdyn/session.pb.h"
#include "vdyn/state.pb.h"
#include "vdyn/vehicle_params.pb.h"
#include "vdyn/world.pb.h"

namespace vdyn::recorder {

// --- verify -------------------------------------------------------------------------------------

struct FieldDiff {
  std::string field;      // "wheels[2].fy", "input.throttle", "state_hash"
  std::string recorded;
  std::string resimulated;
};

// `start`, where a recording holds a server restarted with the same id: which of its starts (from
// 1, in time order) stepped the vehicle; 0 when the server started once.
struct Divergence {
  std::uint32_t vehicle = 0;
  std::uint32_t start = 0;
  std::uint64_t step = 0;
  double t = 0;  // s of simulation at the step's start
  std::uint64_t recorded_hash = 0, resimulated_hash = 0;
  // The state message of the step, recorded against re-simulated, in field order (the hash is
  // the state after the step: it differs; the fields are at the step's start).
  std::vector<FieldDiff> fields;
  // When the step's own fields all agree: the state after it (the next recorded state).
  std::vector<FieldDiff> next_fields;
  std::uint64_t matched_before = 0;  // steps of this vehicle that matched before it
};

// Which recorded states of one vehicle were verified and which could not be, in step order:
// runs of consecutive recorded states (`why` empty: verified; else the reason).
struct StepRun {
  std::uint32_t start = 0;  // the server's start (Divergence::start)
  std::uint64_t first = 0, last = 0, count = 0;
  std::string why;
};

// A recorded state whose hash matches its re-simulation but whose other fields do not: its
// bytes were damaged where no CRC covered them (a chunk without one).
struct Damaged {
  std::uint32_t vehicle = 0;
  std::uint32_t start = 0;
  std::uint64_t step = 0;
  std::vector<FieldDiff> fields;  // recorded, re-simulated
};

struct VerifyResult {
  bool resimulated = false;   // false: it could not be re-simulated (see cannot)
  std::string cannot;
  std::uint64_t compared = 0;        // recorded states whose hash was compared
  std::uint64_t mismatched = 0;
  std::uint64_t not_resimulated = 0;  // states before a vehicle's first spawn or checkpoint
  std::uint64_t unverified = 0;       // states a loss of events kept from being verified
  std::uint64_t malformed = 0;        // state messages that do not read as this vehicle's states
  std::vector<std::string> holes;     // the events lost, per server
  struct Range {
    std::uint64_t first = 0, last = 0, count = 0;
  };
  std::map<std::uint32_t, Range> vehicles;  // the compared states
  std::map<std::uint32_t, std::vector<StepRun>> runs;
  std::optional<Divergence> first;
  // States from chunks without a CRC (Message::unchecked): compared field by field too.
  std::uint64_t unchecked = 0;
  std::uint64_t damaged = 0;
  std::optional<Damaged> first_damaged;
  // States from chunks with a CRC whose hash matched but whose other message fields differ from
  // what this build writes: another version's writer (the message changed, the physics not), or
  // bytes changed with their CRCs written anew. Said, not counted as damage.
  std::uint64_t field_differences = 0;
  std::optional<Damaged> first_field_difference;
  bool data_crc_checked = false;  // the file's data-section CRC held (it covered them)
  double sim_seconds = 0;  // simulated time re-simulated
  double wall_seconds = 0;
  // Every recorded state after a spawn or checkpoint re-simulated bit for bit, and none damaged.
  bool ok() const {
    return resimulated && mismatched == 0 && compared > 0 && unverified == 0 && damaged == 0 &&
           malformed == 0;
  }
  void Verified(std::uint32_t vehicle, std::uint32_t start, std::uint64_t step);
  // A stretch with a reason. `counts`: a state a loss kept from being verified (`unverified`);
  // false: one before the vehicle's start, or one compared that differs or is damaged.
  void Unverified(std::uint32_t vehicle, std::uint32_t start, std::uint64_t step,
                  const std::string& why, bool counts = true);
};

struct VerifyOptions {
  std::filesystem::path file;
  std::optional<std::uint32_t> vehicle;
  std::function<void(double)> on_progress;
};
VerifyResult Verify(const VerifyOptions& o);
// Prints the result as a person reads it; 0 bit-exact, 1 diverged or cannot re-simulate.
int RunVerify(const VerifyOptions& o, std::ostream& out);

// --- takeover -----------------------------------------------------------------------------------

// The exact moment of a recording a live session resumes from.
struct BranchPoint {
  std::uint32_t vehicle = 0;
  std::uint64_t step = 0;
  double at_s = 0;             // s from the recording's start
  pb::ExactState state;        // at the step boundary
  pb::VehicleParams params;    // complete, in effect
  pb::InputSample input;       // applied from the step
  std::string server_id;
  std::string world_name;
  std::uint64_t terrain_hash = 0;
  bool checked = false;        // the re-simulated hash before it matched the recording
  std::string label;           // "run.mcap@12.500s (vehicle 1, step 12500)"
};
// Re-simulates the recording up to the first recorded state of `vehicle` (default: the first
// vehicle) at or after `at_s` and returns that moment. Throws std::runtime_error saying why not.
BranchPoint FindBranchPoint(const std::filesystem::path& file, double at_s,
                            std::optional<std::uint32_t> vehicle);

struct TakeoverOptions {
  std::filesystem::path file;
  double at_s = 0;
  std::optional<std::uint32_t> vehicle;
  std::optional<std::uint32_t> as_vehicle;  // restore into this live vehicle id (default: same)
  std::uint32_t domain = 0;
  std::filesystem::path out;                // the new recording (default: FILE-takeover.mcap)
  double duration_s = 0;                    // 0: until stopped
  double wait_s = 10;                       // for the live server's world
  std::string command_line;
  bool status_line = false;
  bool status_tty = false;
};
int RunTakeover(const TakeoverOptions& o, const std::atomic<bool>& stop, std::ostream& out);

}  // namespace vdyn::recorder

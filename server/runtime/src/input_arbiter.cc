#include "vdyn/runtime/input_arbiter.h"

#include <algorithm>

namespace vdyn {

base::Nanos OwnershipLease(base::Nanos watchdog) {
  const base::Nanos liveliness = base::Milliseconds(200);
  // Never under 10 ms: samples 1 ms apart, late by a few, must not pass the vehicle back and forth.
  const base::Nanos floor = base::Milliseconds(10);
  const base::Nanos before_watchdog{std::max(watchdog.ns / 4 * 3, floor.ns)};
  return before_watchdog.ns < liveliness.ns ? before_watchdog : liveliness;
}

bool InputArbiter::Live(const Source& s, base::MonoTime now) const {
  return s.last_valid.ns >= 0 && now - s.last_valid <= lease_;
}

std::uint64_t InputArbiter::Owner(std::uint32_t vehicle_id, base::MonoTime now) const {
  // The current owner keeps the vehicle while live and no live source is stronger.
  std::uint64_t best = 0;
  std::int32_t best_strength = 0;
  const auto cur = owner_.find(vehicle_id);
  if (cur != owner_.end()) {
    const auto it = sources_.find(cur->second);
    if (it != sources_.end() && Live(it->second, now)) {
      best = it->first;
      best_strength = it->second.strength;
    }
  }
  for (const auto& [handle, s] : sources_) {
    if (s.vehicle_id != vehicle_id || !Live(s, now)) continue;
    if (best == 0 || s.strength > best_strength) {
      best = handle;
      best_strength = s.strength;
    }
  }
  return best;
}

bool InputArbiter::Offer(const pb::DriverInput& in, std::uint64_t handle, std::int32_t strength,
                         base::MonoTime now) {
  Source& s = sources_[handle];
  s.handle = handle;
  s.vehicle_id = in.vehicle_id();
  if (s.source_id != in.source_id()) s.source_id = in.source_id();
  s.strength = strength;
  s.last_valid = now;
  ++s.accepted;
  const std::uint64_t owner = Owner(in.vehicle_id(), now);
  owner_[in.vehicle_id()] = owner;
  return owner == handle;
}

void InputArbiter::Refuse(std::uint64_t handle, std::uint32_t vehicle_id,
                          const std::string& source_id, const std::string& reason,
                          base::MonoTime now) {
  Source& s = sources_[handle];
  s.handle = handle;
  if (vehicle_id != 0) s.vehicle_id = vehicle_id;
  if (!source_id.empty() && s.source_id != source_id) s.source_id = source_id;
  s.last_refused = now;
  s.last_refusal = reason;
  ++s.refused;
}

void InputArbiter::Forget(const std::vector<std::uint64_t>& live_handles) {
  for (auto it = sources_.begin(); it != sources_.end();) {
    if (std::find(live_handles.begin(), live_handles.end(), it->first) == live_handles.end()) {
      it = sources_.erase(it);
    } else {
      ++it;
    }
  }
}

std::vector<InputArbiter::Source> InputArbiter::Snapshot(base::MonoTime now) const {
  std::vector<Source> out;
  for (const auto& [handle, s] : sources_) {
    Source c = s;
    c.driving = c.vehicle_id != 0 && Owner(c.vehicle_id, now) == handle;
    out.push_back(std::move(c));
  }
  return out;
}

}  // namespace vdyn

#include "vdyn/viewer/motion.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/reflection.h>

#include <algorithm>
#include <cmath>

namespace vdyn::viewer {
namespace {

namespace gp = google::protobuf;

double Lerp(double a, double b, double u) {
  return a + (b - a) * u;
}

// The short way round between two angles, rad.
double LerpAngle(double a, double b, double u) {
  return a + std::remainder(b - a, 2.0 * 3.14159265358979323846) * u;
}

// Slerp of unit quaternions (w, x, y, z), the short way round; nlerp where they nearly agree.
void Slerp(const pb::Quat& a, const pb::Quat& b, double u, pb::Quat& out) {
  double bw = b.w(), bx = b.x(), by = b.y(), bz = b.z();
  double d = a.w() * bw + a.x() * bx + a.y() * by + a.z() * bz;
  if (d < 0) {  // q and -q are one rotation
    bw = -bw, bx = -bx, by = -by, bz = -bz;
    d = -d;
  }
  double ka = 1 - u, kb = u;
  if (d < 0.9995) {
    const double theta = std::acos(std::min(d, 1.0));
    const double s = std::sin(theta);
    ka = std::sin((1 - u) * theta) / s;
    kb = std::sin(u * theta) / s;
  }
  double w = ka * a.w() + kb * bw, x = ka * a.x() + kb * bx, y = ka * a.y() + kb * by,
         z = ka * a.z() + kb * bz;
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  if (n > 0) w /= n, x /= n, y /= n, z /= n;
  out.set_w(w);
  out.set_x(x);
  out.set_y(y);
  out.set_z(z);
}

// Every continuous number of `out` (a copy of a) blended towards b; `angles`: the numbers are
// angles (roll, pitch, yaw), blended the short way round.
void Blend(const gp::Message& a, const gp::Message& b, double u, gp::Message& out, bool angles) {
  const gp::Descriptor* d = a.GetDescriptor();
  const gp::Reflection* ra = a.GetReflection();
  const gp::Reflection* rb = b.GetReflection();
  const gp::Reflection* ro = out.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const gp::FieldDescriptor* f = d->field(i);
    if (f->is_repeated()) {
      if (f->cpp_type() != gp::FieldDescriptor::CPPTYPE_MESSAGE) continue;
      const int n = ra->FieldSize(a, f);
      if (n != rb->FieldSize(b, f) || n != ro->FieldSize(out, f)) continue;
      for (int k = 0; k < n; ++k) {
        Blend(ra->GetRepeatedMessage(a, f, k), rb->GetRepeatedMessage(b, f, k), u,
              *ro->MutableRepeatedMessage(&out, f, k), false);
      }
      continue;
    }
    switch (f->cpp_type()) {
      case gp::FieldDescriptor::CPPTYPE_DOUBLE: {
        const double x = ra->GetDouble(a, f), y = rb->GetDouble(b, f);
        ro->SetDouble(&out, f, angles ? LerpAngle(x, y, u) : Lerp(x, y, u));
        break;
      }
      case gp::FieldDescriptor::CPPTYPE_FLOAT: {
        const double x = ra->GetFloat(a, f), y = rb->GetFloat(b, f);
        ro->SetFloat(&out, f, static_cast<float>(Lerp(x, y, u)));
        break;
      }
      case gp::FieldDescriptor::CPPTYPE_MESSAGE: {
        if (!ra->HasField(a, f) || !rb->HasField(b, f)) break;
        const gp::Message& ma = ra->GetMessage(a, f);
        const gp::Message& mb = rb->GetMessage(b, f);
        gp::Message* mo = ro->MutableMessage(&out, f);
        if (f->message_type() == pb::Quat::descriptor()) {
          Slerp(static_cast<const pb::Quat&>(ma), static_cast<const pb::Quat&>(mb), u,
                static_cast<pb::Quat&>(*mo));
        } else {
          Blend(ma, mb, u, *mo, f->name() == "rpy");
        }
        break;
      }
      default:  // integers, booleans, enums, strings: a's
        break;
    }
  }
}

double Length(const pb::Vec3& v) {
  return std::sqrt(v.x() * v.x() + v.y() * v.y() + v.z() * v.z());
}

}  // namespace

void InterpolateState(const pb::VehicleState& a, const pb::VehicleState& b, double u,
                      pb::VehicleState& out) {
  u = std::clamp(u, 0.0, 1.0);
  out.CopyFrom(a);
  if (u == 0) return;
  Blend(a, b, u, out, false);
  // Terrain normals stay unit vectors.
  for (pb::WheelState& w : *out.mutable_wheels()) {
    pb::Vec3& n = *w.mutable_n_w();
    const double len = Length(n);
    if (len > 1e-9) {
      n.set_x(n.x() / len);
      n.set_y(n.y() / len);
      n.set_z(n.z() / len);
    }
  }
}

bool Continuous(const pb::VehicleState& a, const pb::VehicleState& b) {
  if (a.server_id() != b.server_id() || a.vehicle_id() != b.vehicle_id()) return false;
  if (b.step() <= a.step()) return false;
  const std::int64_t steps = static_cast<std::int64_t>(b.step() - a.step());
  const std::int64_t dt_ns = b.sim_time_ns() - a.sim_time_ns();
  if (a.step_ns() > 0 && dt_ns != steps * a.step_ns()) return false;  // a restore: a new life
  if (dt_ns <= 0) return false;
  // A reset or teleport keeps counting steps: the vehicle moved further than it could drive.
  const double dt = static_cast<double>(dt_ns) * 1e-9;
  const double speed = std::max(Length(a.v_wt_w()), Length(b.v_wt_w()));
  pb::Vec3 d;
  d.set_x(b.p_wt_w().x() - a.p_wt_w().x());
  d.set_y(b.p_wt_w().y() - a.p_wt_w().y());
  d.set_z(b.p_wt_w().z() - a.p_wt_w().z());
  return Length(d) <= (1.5 * speed + 2.0) * dt + 0.25;
}

void ClockOffset::Observe(std::int64_t source_ns, std::int64_t arrived_wall_ns) {
  const std::int64_t transit = arrived_wall_ns - source_ns;
  if (!known_) {
    known_ = true;
    offset_ns_ = transit;
  } else {
    // Rise by 1 ms per second since the last observation, then take the smaller.
    const std::int64_t since = std::max<std::int64_t>(arrived_wall_ns - last_arrival_ns_, 0);
    offset_ns_ = std::min(offset_ns_ + since / 1000, transit);
  }
  last_arrival_ns_ = arrived_wall_ns;
}

void StateHistory::Add(const pb::VehicleState& s, std::int64_t source_ns, std::int64_t) {
  if (!entries_.empty()) {
    const Entry& last = entries_.back();
    if (s.step() == last.state.step() && s.server_id() == last.state.server_id()) return;
    const bool older = s.step() < last.state.step() || source_ns < last.source_ns;
    if (older && !Continuous(last.state, s)) entries_.clear();
  }
  if (entries_.size() == kCapacity) {
    // Reuse the oldest entry's message (its wheels keep their allocations).
    Entry e = std::move(entries_.front());
    entries_.pop_front();
    e.state.CopyFrom(s);
    e.source_ns = source_ns;
    entries_.push_back(std::move(e));
    return;
  }
  entries_.push_back({s, source_ns});
}

StateHistory::Sample StateHistory::At(std::int64_t t_ns) const {
  Sample out;
  if (entries_.empty()) return out;
  // The newest entry at or before t.
  std::size_t i = entries_.size();
  while (i > 0 && entries_[i - 1].source_ns > t_ns) --i;
  if (i == 0) {  // before the oldest: the oldest as it is
    out.a = &entries_.front().state;
    out.a_source_ns = out.source_ns = entries_.front().source_ns;
    return out;
  }
  const Entry& a = entries_[i - 1];
  out.a = &a.state;
  out.a_source_ns = a.source_ns;
  out.source_ns = t_ns;
  if (i == entries_.size()) {  // after the newest: held
    out.source_ns = a.source_ns;
    return out;
  }
  const Entry& b = entries_[i];
  if (!Continuous(a.state, b.state) || b.source_ns <= a.source_ns) return out;
  out.b = &b.state;
  out.u = static_cast<double>(t_ns - a.source_ns) / static_cast<double>(b.source_ns - a.source_ns);
  return out;
}

}  // namespace vdyn::viewer

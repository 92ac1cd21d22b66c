// Google Benchmark suite for the physics core, with Bullet's btRaycastVehicle as the peer measured
// in the same run. Names: <what>/<engine>/<world>[/<pattern>].
//
//   step/vdyn/W     one Simulator::Step of the default (full) model (RK4: 4 stages x 4 wheel rays
//                   = 16 rays, plus the wall probes and the wheels' kerb traces near steep
//                   surfaces) while driving course W (cars.h)
//   step/vdyn_paper/W  the same with the paper's model
//   step/bullet/W   one btDiscreteDynamicsWorld::stepSimulation(1 ms) of the same car (4 wheel
//                   rays, chassis box vs mesh collision, solver, integration)
//   step/bullet_nobox/W  the same without the chassis box's collision: only the wheel rays touch
//                   the terrain (the least a btRaycastVehicle costs)
//   trace/vdyn/W/P  one vertical Terrain::Trace; P = moving (1.4 cm further each call, a car at
//                   50 km/h at 1 kHz) or random (uniform over the world)
//   trace4/vdyn/W/P one Terrain::Trace4 (the four wheels of a car as one packet);
//                   per_ray = time / 4
//   ray/bullet/W/P  one ray through btDefaultVehicleRaycaster (what btRaycastVehicle casts)
//   state/encode    a step's state message (FillVehicleState, then the bytes), as a stepping thread
//                   makes it for every vehicle of every step
//   state/decode    what every state reader does with those bytes (transport::Reader: a fresh
//                   message on its arena, DecodeEnvelope: the protobuf parse and the finite-number
//                   and string checks on the wire bytes)
//   state/wire_check  those checks alone (messages::WireClean)
//   state/parse     the peer: protobuf's ParseFromArray alone into a reused message on the heap,
//                   what a plain protobuf reader pays
//   state/copy      the floor: copying the bytes
//   tyre/mf/load    MagicFormulaLoad: the law's load-dependent terms (Kxk, Kya, relaxation lengths),
//                   as each wheel's every RK4 stage computes them
//   tyre/mf/front   MagicFormulaLoad + EvaluateMagicFormula with the aligning moment (a front
//                   wheel's stage: its Mz is the steering torque), over 64 operating points of the
//                   synthetic tyre (loads, slips, camber, speeds, as a drive visits them)
//   tyre/mf/rear    the same without the aligning moment (a rear wheel's stage that is not published)
//   libm/atan, libm/sin, libm/cos  one call of glibc's function over the same spread of arguments,
//                   independent calls (throughput: what a law of many such calls pays each)
//
// After the run, the medians are printed as vdyn / Bullet ratios (below 1: vdyn is faster).
// Respawning a car (cars.h) is excluded from the timed region with PauseTiming.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <unistd.h>

#include "cars.h"
#include "rays.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/messages/checks.h"
#include "vdyn/physics/magic_formula.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"

namespace vdyn::bench {
namespace {

const Course& CourseNamed(const std::string& name) {
  static const Course facility = FacilityCourse();
  static const Course terrain = TerrainCourse();
  return name == "facility" ? facility : terrain;
}

// The cars live across benchmark invocations (Google Benchmark calls a function several times while
// it sizes the run): each continues its drive instead of restarting from rest at the spawn.
// `model`: "full" (the default car: the full model, brush tyres), "paper", or "mf" (the full model
// on the synthetic Magic Formula tyre, tires/).
VdynCar& OurCar(const std::string& world, const std::string& model = "full") {
  static std::map<std::string, std::unique_ptr<VdynCar>> cars;
  auto& car = cars[world + "/" + model];
  if (!car) {
    car = std::make_unique<VdynCar>(CourseNamed(world), model == "paper" ? PaperBenchParams()
                                                        : model == "mf"  ? MagicFormulaBenchParams()
                                                                         : BenchParams());
  }
  return *car;
}

BulletCar& PeerCar(const std::string& world, bool chassis_box = true) {
  static std::map<std::string, std::unique_ptr<BulletCar>> cars;
  auto& car = cars[world + (chassis_box ? "" : "/nobox")];
  if (!car) car = std::make_unique<BulletCar>(CourseNamed(world), BenchParams(), chassis_box);
  return *car;
}

template <class Car>
void StepLoop(benchmark::State& st, Car& car) {
  for (auto _ : st) {
    if (!car.Step()) {
      st.SkipWithError("the step was not finite");
      break;
    }
    if (car.NeedsRespawn()) {
      st.PauseTiming();
      car.Respawn();
      st.ResumeTiming();
    }
  }
}

void BM_StepVdyn(benchmark::State& st, const std::string& world, const std::string& model) {
  StepLoop(st, OurCar(world, model));
}
void BM_StepBullet(benchmark::State& st, const std::string& world, bool chassis_box) {
  StepLoop(st, PeerCar(world, chassis_box));
}

const RaySet& Rays(const std::string& world, const std::string& pattern) {
  static std::map<std::string, RaySet> sets;
  RaySet& set = sets[world + "/" + pattern];
  if (set.origins.empty()) {
    set = pattern == "moving" ? MovingRays(CourseNamed(world)) : RandomRays(CourseNamed(world));
  }
  return set;
}

void BM_Trace(benchmark::State& st, const std::string& world, const std::string& pattern) {
  const Terrain& terrain = CourseNamed(world).world->terrain;
  const RaySet& rays = Rays(world, pattern);
  const Eigen::Vector3d down = -Eigen::Vector3d::UnitZ();
  std::size_t i = 0;
  for (auto _ : st) {
    TraceHit hit = terrain.Trace(rays.origins[i][0], down, rays.t_max);
    benchmark::DoNotOptimize(hit);
    if (++i == rays.origins.size()) i = 0;
  }
}

void BM_Trace4(benchmark::State& st, const std::string& world, const std::string& pattern) {
  const Terrain& terrain = CourseNamed(world).world->terrain;
  const RaySet& rays = Rays(world, pattern);
  std::array<Eigen::Vector3d, 4> down;
  down.fill(-Eigen::Vector3d::UnitZ());
  std::array<double, 4> t_max;
  t_max.fill(rays.t_max);
  std::array<TraceHit, 4> hits;
  std::size_t i = 0;
  for (auto _ : st) {
    terrain.Trace4(rays.origins[i], down, t_max, hits);
    benchmark::DoNotOptimize(hits);
    if (++i == rays.origins.size()) i = 0;
  }
  st.counters["per_ray"] = benchmark::Counter(
      4, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_BulletRay(benchmark::State& st, const std::string& world, const std::string& pattern) {
  BulletCar& car = PeerCar(world);
  const RaySet& rays = Rays(world, pattern);
  const Eigen::Vector3d reach(0.0, 0.0, -rays.t_max);
  std::size_t i = 0;
  for (auto _ : st) {
    double fraction = 0;
    const Eigen::Vector3d& o = rays.origins[i][0];
    benchmark::DoNotOptimize(car.CastRay(o, o + reach, &fraction));
    benchmark::DoNotOptimize(fraction);
    if (++i == rays.origins.size()) i = 0;
  }
}

// A state of the facility course after 5 s of driving (every field a reader decodes is set).
const std::string& StateBytes() {
  static const std::string bytes = [] {
    VdynCar& car = OurCar("facility");
    for (int i = 0; i < 5000; ++i) {
      if (!car.Step()) break;
      if (car.NeedsRespawn()) car.Respawn();
    }
    pb::VehicleState msg;
    FillVehicleState(1, "bench", 1'000'000, 5'000'000'000, car.sim().last_step(), pb::DriverInput{},
                     false, car.sim().last_step().derived.steering_torque, msg);
    return msg.SerializeAsString();
  }();
  return bytes;
}

void BM_StateEncode(benchmark::State& st) {
  VdynCar& car = OurCar("facility");
  (void)StateBytes();
  const StepRecord& r = car.sim().last_step();
  pb::VehicleState msg;
  std::string out(StateBytes().size() * 2, '\0');
  for (auto _ : st) {
    FillVehicleState(1, "bench", 1'000'000, 5'000'000'000, r, pb::DriverInput{}, false,
                     r.derived.steering_torque, msg);
    const std::size_t size = msg.ByteSizeLong();
    msg.SerializeWithCachedSizesToArray(reinterpret_cast<std::uint8_t*>(out.data()));
    benchmark::DoNotOptimize(size);
    benchmark::DoNotOptimize(out.data());
  }
  st.SetBytesProcessed(static_cast<std::int64_t>(st.iterations() * StateBytes().size()));
}

std::span<const std::uint8_t> StateSpan() {
  const std::string& b = StateBytes();
  return {reinterpret_cast<const std::uint8_t*>(b.data()), b.size()};
}

// As transport::Reader does it: into a fresh message on its arena each time.
void BM_StateDecode(benchmark::State& st) {
  const std::span<const std::uint8_t> bytes = StateSpan();
  transport::ArenaMessage<pb::VehicleState> scratch(128 * 1024);
  for (auto _ : st) {
    pb::VehicleState& msg = scratch.Fresh();
    const transport::Decoded d =
        transport::DecodeEnvelope(transport::TopicId::kState,
                                  transport::Spec(transport::TopicId::kState).payload, bytes, msg);
    if (d.outcome != transport::Decoded::Outcome::kOk) {
      st.SkipWithError("the state did not decode");
      break;
    }
    benchmark::DoNotOptimize(msg);
  }
  st.SetBytesProcessed(static_cast<std::int64_t>(st.iterations() * bytes.size()));
}

void BM_StateWireCheck(benchmark::State& st) {
  const std::span<const std::uint8_t> bytes = StateSpan();
  for (auto _ : st) {
    if (!messages::WireClean(*pb::VehicleState::descriptor(), bytes)) {
      st.SkipWithError("the state is not clean");
      break;
    }
  }
  st.SetBytesProcessed(static_cast<std::int64_t>(st.iterations() * bytes.size()));
}

void BM_StateParse(benchmark::State& st) {
  const std::span<const std::uint8_t> bytes = StateSpan();
  pb::VehicleState msg;
  for (auto _ : st) {
    if (!msg.ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) {
      st.SkipWithError("the state did not parse");
      break;
    }
    benchmark::DoNotOptimize(msg);
  }
  st.SetBytesProcessed(static_cast<std::int64_t>(st.iterations() * bytes.size()));
}

void BM_StateCopy(benchmark::State& st) {
  const std::span<const std::uint8_t> bytes = StateSpan();
  std::vector<std::uint8_t> out(bytes.size());
  for (auto _ : st) {
    std::memcpy(out.data(), bytes.data(), bytes.size());
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  st.SetBytesProcessed(static_cast<std::int64_t>(st.iterations() * bytes.size()));
}

// 64 operating points of a wheel on the synthetic tyre: loads 1-8 kN, slip ratios to +-0.3, slip
// angles to +-12 degrees, camber to +-3 degrees, 5-40 m/s.
struct MfPoint {
  double Fz, gamma, kappa, tan_alpha, Vx;
};
std::vector<MfPoint> MfPoints() {
  std::vector<MfPoint> pts;
  for (int i = 0; i < 64; ++i) {
    const double u = (i % 8) / 7.0, v = (i / 8) / 7.0;
    pts.push_back({1000.0 + 7000.0 * u, (v - 0.5) * 0.1, (u - 0.5) * 0.6 * (i % 3 == 0 ? 1 : 0.1),
                   std::tan((v - 0.5) * 0.42 * (i % 2 == 0 ? 1 : 0.2)), 5.0 + 35.0 * v});
  }
  return pts;
}

const MagicFormula& BenchTyre() {
  static const ValidParams params = MagicFormulaBenchParams();
  return params->wheel[0].mf;
}

void BM_MfLoad(benchmark::State& st) {
  const MagicFormula& mf = BenchTyre();
  const std::vector<MfPoint> pts = MfPoints();
  std::size_t i = 0;
  for (auto _ : st) {
    const MfPoint& q = pts[i++ & 63];
    benchmark::DoNotOptimize(MagicFormulaLoad(mf, q.Fz, q.gamma, mf.inflpres));
  }
}

void BM_MfWheel(benchmark::State& st, bool aligning) {
  const MagicFormula& mf = BenchTyre();
  const std::vector<MfPoint> pts = MfPoints();
  std::size_t i = 0;
  for (auto _ : st) {
    const MfPoint& q = pts[i++ & 63];
    const MfLoad L = MagicFormulaLoad(mf, q.Fz, q.gamma, mf.inflpres);
    const double Vc = q.Vx * std::sqrt(1.0 + q.tan_alpha * q.tan_alpha);
    benchmark::DoNotOptimize(
        EvaluateMagicFormula(mf, L, {q.kappa, q.tan_alpha, q.Vx, Vc}, aligning, false));
  }
}

void BM_Libm(benchmark::State& st, double (*f)(double)) {
  std::vector<double> xs;
  for (const MfPoint& q : MfPoints()) xs.push_back(8.0 * q.kappa + q.tan_alpha);
  std::size_t i = 0;
  for (auto _ : st) benchmark::DoNotOptimize(f(xs[i++ & 63]));
}

// Console output as usual; also keeps each benchmark's median (or single run) for the ratios.
// (A reporter given to RunSpecifiedBenchmarks does not follow --benchmark_color: colour only when
// stdout is a terminal, so result files stay plain text.)
class RatioReporter : public benchmark::ConsoleReporter {
 public:
  RatioReporter() : ConsoleReporter(isatty(STDOUT_FILENO) ? OO_ColorTabular : OO_Tabular) {}

  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs) {
      if (r.error_occurred) continue;
      if (r.run_type == Run::RT_Aggregate && r.aggregate_name != "median") continue;
      const double ns =
          r.GetAdjustedRealTime() / benchmark::GetTimeUnitMultiplier(r.time_unit) * 1e9;
      ns_[r.run_name.function_name] = ns;
    }
    ConsoleReporter::ReportRuns(runs);
  }

  void PrintRatios() const {
    std::printf("\nvdyn / Bullet, medians of this run (real time; below 1: vdyn is faster)\n");
    std::printf("%-36s %12s %12s %8s\n", "", "vdyn ns", "Bullet ns", "ratio");
    for (const char* world : {"facility", "terrain_1m"}) {
      const std::string w = world;
      Ratio("step/" + w, "step/vdyn/" + w, "step/bullet/" + w);
      Ratio("step/" + w + " (Bullet without box)", "step/vdyn/" + w, "step/bullet_nobox/" + w);
      Ratio("step/" + w + " (paper model)", "step/vdyn_paper/" + w, "step/bullet/" + w);
      Ratio("step/" + w + " (full / paper model)", "step/vdyn/" + w, "step/vdyn_paper/" + w);
      Ratio("step/" + w + " (Magic Formula / brush tyre)", "step/vdyn_mf/" + w, "step/vdyn/" + w);
      for (const char* pattern : {"moving", "random"}) {
        const std::string wp = std::string(world) + "/" + pattern;
        Ratio("ray/" + wp + " (Trace)", "trace/vdyn/" + wp, "ray/bullet/" + wp);
        Ratio("ray/" + wp + " (Trace4 / 4)", "trace4/vdyn/" + wp, "ray/bullet/" + wp, 0.25);
      }
    }
    Ratio("tyre: front wheel / libm atan", "tyre/mf/front", "libm/atan");
    Ratio("state: decode (checked) / plain protobuf parse", "state/decode", "state/parse");
    Ratio("state: decode / copying the bytes", "state/decode", "state/copy");
    std::fflush(stdout);
  }

 private:
  void Ratio(const std::string& label, const std::string& ours, const std::string& peer,
             double ours_scale = 1.0) const {
    const auto a = ns_.find(ours), b = ns_.find(peer);
    if (a == ns_.end() || b == ns_.end()) return;  // filtered out of this run
    const double x = a->second * ours_scale;
    std::printf("%-36s %12.1f %12.1f %8.2f\n", label.c_str(), x, b->second, x / b->second);
  }

  std::map<std::string, double> ns_;
};

void Register() {
  for (const std::string world : {"facility", "terrain_1m"}) {
    benchmark::RegisterBenchmark(("step/vdyn/" + world).c_str(), BM_StepVdyn, world, "full");
    benchmark::RegisterBenchmark(("step/vdyn_paper/" + world).c_str(), BM_StepVdyn, world, "paper");
    benchmark::RegisterBenchmark(("step/vdyn_mf/" + world).c_str(), BM_StepVdyn, world, "mf");
    benchmark::RegisterBenchmark(("step/bullet/" + world).c_str(), BM_StepBullet, world, true);
    benchmark::RegisterBenchmark(("step/bullet_nobox/" + world).c_str(), BM_StepBullet, world,
                                 false);
  }
  for (const std::string world : {"facility", "terrain_1m"}) {
    for (const std::string pattern : {"moving", "random"}) {
      const std::string wp = world + "/" + pattern;
      benchmark::RegisterBenchmark(("trace/vdyn/" + wp).c_str(), BM_Trace, world, pattern);
      benchmark::RegisterBenchmark(("trace4/vdyn/" + wp).c_str(), BM_Trace4, world, pattern);
      benchmark::RegisterBenchmark(("ray/bullet/" + wp).c_str(), BM_BulletRay, world, pattern);
    }
  }
  benchmark::RegisterBenchmark("state/encode", BM_StateEncode);
  benchmark::RegisterBenchmark("state/decode", BM_StateDecode);
  benchmark::RegisterBenchmark("state/wire_check", BM_StateWireCheck);
  benchmark::RegisterBenchmark("state/parse", BM_StateParse);
  benchmark::RegisterBenchmark("state/copy", BM_StateCopy);
  benchmark::RegisterBenchmark("tyre/mf/load", BM_MfLoad);
  benchmark::RegisterBenchmark("tyre/mf/front", BM_MfWheel, true);
  benchmark::RegisterBenchmark("tyre/mf/rear", BM_MfWheel, false);
  benchmark::RegisterBenchmark("libm/atan", BM_Libm, static_cast<double (*)(double)>(std::atan));
  benchmark::RegisterBenchmark("libm/sin", BM_Libm, static_cast<double (*)(double)>(std::sin));
  benchmark::RegisterBenchmark("libm/cos", BM_Libm, static_cast<double (*)(double)>(std::cos));
}

}  // namespace
}  // namespace vdyn::bench

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  vdyn::bench::Register();
  vdyn::bench::RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  reporter.PrintRatios();
  benchmark::Shutdown();
  return 0;
}

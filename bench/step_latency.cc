// The distribution of single-step times: every one of N steps timed on its own with
// std::chrono::steady_clock, for vdyn and for the Bullet peer (cars.h), on both courses.
//
// The cars (vdyn's full model - the default -, vdyn's paper model, Bullet, Bullet without the
// chassis box's collision) take turns in blocks of
// 10,000 steps, so all see the same machine (a shared, noisy 2-core box drifts over seconds).
// Respawns happen between timed steps, never inside one.
// Usage: step_latency [N]   (default 200000 steps per car and world)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <string>
#include <vector>

#include "cars.h"

namespace vdyn::bench {
namespace {

using Clock = std::chrono::steady_clock;

struct Stats {
  double mean = 0, p50 = 0, p99 = 0, p999 = 0, max = 0;  // us
};

Stats Summarise(std::vector<double> us) {
  std::sort(us.begin(), us.end());
  auto at = [&us](double q) {  // nearest rank
    const auto k = static_cast<std::size_t>(std::ceil(q * static_cast<double>(us.size())));
    return us[std::clamp<std::size_t>(k, 1, us.size()) - 1];
  };
  return {std::accumulate(us.begin(), us.end(), 0.0) / static_cast<double>(us.size()), at(0.5),
          at(0.99), at(0.999), us.back()};
}

template <class Car>
bool TimeSteps(Car& car, int n, std::vector<double>& us) {
  for (int i = 0; i < n; ++i) {
    const auto t0 = Clock::now();
    const bool ok = car.Step();
    const auto t1 = Clock::now();
    if (!ok) return false;
    us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
    if (car.NeedsRespawn()) car.Respawn();
  }
  return true;
}

void Print(const char* world, const char* engine, const Stats& s) {
  std::printf("%-11s %-12s %9.2f %9.2f %9.2f %9.2f %9.2f\n", world, engine, s.mean, s.p50, s.p99,
              s.p999, s.max);
}

}  // namespace
}  // namespace vdyn::bench

int main(int argc, char** argv) {
  using namespace vdyn::bench;
  const int n = argc > 1 ? std::atoi(argv[1]) : 200000;
  if (n <= 0) {
    std::fprintf(stderr, "usage: step_latency [N > 0]\n");
    return 2;
  }
  // What reading the clock costs (it is inside every sample): the median of back-to-back pairs.
  std::vector<double> clock_us;
  for (int i = 0; i < 100000; ++i) {
    const auto t0 = Clock::now();
    const auto t1 = Clock::now();
    clock_us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
  }
  std::printf("steady_clock pair overhead: %.3f us (median), included in every sample below\n",
              Summarise(clock_us).p50);
  std::printf("%d steps per car and world, h = 1 ms, in blocks of 10000 steps taking turns\n", n);
  std::printf("bullet: chassis box collides with the terrain; bullet_nobox: wheel rays only\n\n");
  std::printf("%-11s %-12s %9s %9s %9s %9s %9s\n", "world", "engine", "mean_us", "p50_us", "p99_us",
              "p99.9_us", "max_us");

  for (const Course& course : {TerrainCourse(), FacilityCourse()}) {
    VdynCar ours(course, BenchParams());
    VdynCar paper(course, PaperBenchParams());
    BulletCar peer(course, BenchParams());
    BulletCar peer_nobox(course, BenchParams(), /*chassis_box=*/false);
    std::vector<double> ours_us, paper_us, peer_us, nobox_us, discard;
    auto run = [&](int steps, std::vector<double>& a, std::vector<double>& p,
                   std::vector<double>& b, std::vector<double>& c) {
      if (TimeSteps(ours, steps, a) && TimeSteps(paper, steps, p) && TimeSteps(peer, steps, b) &&
          TimeSteps(peer_nobox, steps, c)) {
        return true;
      }
      std::fprintf(stderr, "%s: a step was not finite\n", course.name.c_str());
      return false;
    };
    // Warm-up: caches, page faults, the cars settling after the first spawn.
    if (!run(5000, discard, discard, discard, discard)) return 1;
    for (auto* v : {&ours_us, &paper_us, &peer_us, &nobox_us}) {
      v->reserve(static_cast<std::size_t>(n));
    }
    for (int done = 0; done < n; done += 10000) {
      if (!run(std::min(10000, n - done), ours_us, paper_us, peer_us, nobox_us)) return 1;
    }
    const Stats a = Summarise(ours_us), b = Summarise(peer_us), c = Summarise(nobox_us);
    const Stats pa = Summarise(paper_us);
    const char* w = course.name.c_str();
    Print(w, "vdyn", a);
    Print(w, "vdyn_paper", pa);
    Print(w, "bullet", b);
    Print(w, "bullet_nobox", c);
    std::printf("%-11s %-12s %9.2f %9s %9.2f   (mean, p99)\n", w, "vdyn/bullet", a.mean / b.mean,
                "", a.p99 / b.p99);
    std::printf("%-11s %-12s %9.2f %9s %9.2f   (mean, p99)\n", w, "vdyn/nobox", a.mean / c.mean, "",
                a.p99 / c.p99);
    std::printf("%-11s %-12s %9.2f %9s %9.2f   (mean, p99)\n", w, "full/paper", a.mean / pa.mean,
                "", a.p99 / pa.p99);
    if (course.name == "terrain_1m") {
      std::printf("%-11s targets: mean <= 15 us %s, p99 <= 50 us %s\n", "",
                  a.mean <= 15.0 ? "met" : "NOT met", a.p99 <= 50.0 ? "met" : "NOT met");
    }
  }
  return 0;
}

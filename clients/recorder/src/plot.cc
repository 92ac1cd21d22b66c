// `vdyn-recorder plot FILE`: the pictures a person would rather look at than read - speed,
// accelerations, per-wheel spring, drive, brake and side forces, steering and pedals, and the
// trajectory over a height map of the world - drawn by gnuplot (PNG or SVG) from the recorded
// states, with one HTML page that shows them all. Columns are found by name in the CSV's column
// table (io/csv.h), so the figures follow the export and the batch CSV.
#include <fcntl.h>
#include <spawn.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <sstream>

#include "vdyn/base/time.h"
#include "vdyn/io/csv.h"
#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/output_file.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/state.pb.h"
#include "vdyn/world.pb.h"

extern char** environ;

namespace vdyn::recorder {

using transport::TopicId;

namespace {

namespace fs = std::filesystem;

constexpr std::size_t kMaxRows = 20000;  // per figure: finer than any screen
constexpr int kMapCells = 400;           // along the map's longer side
constexpr int kNoSurface = 7;            // a map cell with no surface above it

// One panel of a figure: its lines (CSV column, legend) on one y axis. The y range holds zero and
// spans at least `min_span` (a drive without braking draws its brake forces flat at zero, not a
// 0.3 N ripple magnified to fill the panel); `lo`/`hi` fix the ends they name (pedals 0..1).
struct Panel {
  std::string ylabel;
  std::vector<std::pair<std::string, std::string>> lines;
  double min_span = 1;
  bool nonnegative = false;  // never below zero (a spring or brake force): grow the range upwards
  double lo = std::numeric_limits<double>::quiet_NaN();
  double hi = std::numeric_limits<double>::quiet_NaN();
};

struct Figure {
  std::string file;  // without extension
  std::string title;
  std::vector<Panel> panels;  // stacked, sharing the time axis
};

// The bounds of the world's surfaces in x and y (nullopt for a world without vertices).
std::optional<std::array<double, 4>> WorldBounds(const pb::WorldDescription& w) {
  std::array<double, 4> b = {1e300, -1e300, 1e300, -1e300};
  bool any = false;
  for (const pb::Mesh& m : w.meshes()) {
    for (int i = 0; i + 2 < m.vertices_size(); i += 3) {
      const double x = m.vertices(i), y = m.vertices(i + 1);
      if (!std::isfinite(x) || !std::isfinite(y)) continue;
      b = {std::min(b[0], x), std::max(b[1], x), std::min(b[2], y), std::max(b[3], y)};
      any = true;
    }
  }
  return any ? std::optional(b) : std::nullopt;
}

// A top-down map of the world's meshes from (x0, y0), nx by ny cells of cx by cy metres: each
// cell holds the surface kind (road, ground, ramp...) of the highest surface above its centre,
// kNoSurface where there is none; rasterised triangle by triangle.
std::vector<double> SurfaceMap(const pb::WorldDescription& w, double x0, double y0, double cx_m,
                               double cy_m, int nx, int ny) {
  const std::size_t n = static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny);
  std::vector<double> z(n, std::numeric_limits<double>::quiet_NaN());
  std::vector<double> kind(n, kNoSurface);
  for (const pb::Mesh& m : w.meshes()) {
    const int nv = m.vertices_size() / 3;
    for (int t = 0; t + 2 < m.indices_size(); t += 3) {
      const std::uint32_t ia = m.indices(t), ib = m.indices(t + 1), ic = m.indices(t + 2);
      if (ia >= static_cast<std::uint32_t>(nv) || ib >= static_cast<std::uint32_t>(nv) ||
          ic >= static_cast<std::uint32_t>(nv))
        continue;
      auto V = [&](std::uint32_t i, int k) { return m.vertices(static_cast<int>(3 * i) + k); };
      const double ax = V(ia, 0), ay = V(ia, 1), az = V(ia, 2);
      const double bx = V(ib, 0), by = V(ib, 1), bz = V(ib, 2);
      const double cx = V(ic, 0), cy = V(ic, 1), cz = V(ic, 2);
      const double det = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy);
      if (!(std::abs(det) >= 1e-12)) continue;  // vertical, degenerate or not finite: no top
      const int i0 =
          std::max(0, static_cast<int>(std::floor((std::min({ax, bx, cx}) - x0) / cx_m)));
      const int i1 =
          std::min(nx - 1, static_cast<int>(std::floor((std::max({ax, bx, cx}) - x0) / cx_m)));
      const int j0 =
          std::max(0, static_cast<int>(std::floor((std::min({ay, by, cy}) - y0) / cy_m)));
      const int j1 =
          std::min(ny - 1, static_cast<int>(std::floor((std::max({ay, by, cy}) - y0) / cy_m)));
      for (int j = j0; j <= j1; ++j) {
        const double py = y0 + (j + 0.5) * cy_m;
        for (int i = i0; i <= i1; ++i) {
          const double px = x0 + (i + 0.5) * cx_m;
          const double l1 = ((by - cy) * (px - cx) + (cx - bx) * (py - cy)) / det;
          const double l2 = ((cy - ay) * (px - cx) + (ax - cx) * (py - cy)) / det;
          const double l3 = 1.0 - l1 - l2;
          if (l1 < 0 || l2 < 0 || l3 < 0) continue;
          const double h = l1 * az + l2 * bz + l3 * cz;
          const std::size_t at = static_cast<std::size_t>(j) * static_cast<std::size_t>(nx) +
                                 static_cast<std::size_t>(i);
          if (std::isnan(z[at]) || h > z[at]) {
            z[at] = h;
            kind[at] = static_cast<double>(std::clamp<int>(m.kind(), 0, kNoSurface - 1));
          }
        }
      }
    }
  }
  return kind;
}

std::string Escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '"' || c == '\\') o += '\\';
    o += c;
  }
  return o;
}

std::string Html(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '<')
      o += "&lt;";
    else if (c == '>')
      o += "&gt;";
    else if (c == '&')
      o += "&amp;";
    else
      o += c;
  }
  return o;
}

// A scratch folder inside the output folder (so its files are renamed into place, never
// copied), removed with whatever is left in it.
class ScratchFolder {
 public:
  explicit ScratchFolder(const fs::path& parent) {
    std::string tmpl = (fs::absolute(parent) / ".plot-partial-XXXXXX").string();
    if (::mkdtemp(tmpl.data()) == nullptr) {
      throw OutputError(parent.string() +
                        ": cannot create a scratch folder in it: " + std::strerror(errno));
    }
    path_ = tmpl;
  }
  ~ScratchFolder() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  ScratchFolder(const ScratchFolder&) = delete;
  ScratchFolder& operator=(const ScratchFolder&) = delete;
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

// `name` found on PATH (or a path itself), else empty.
std::string FindProgram(const std::string& name) {
  if (name.find('/') != std::string::npos)
    return ::access(name.c_str(), X_OK) == 0 ? name : std::string();
  const char* path = std::getenv("PATH");
  std::string dirs = path != nullptr ? path : "/usr/bin:/bin";
  std::size_t at = 0;
  while (at <= dirs.size()) {
    std::size_t end = dirs.find(':', at);
    if (end == std::string::npos) end = dirs.size();
    const std::string candidate =
        (end > at ? dirs.substr(at, end - at) : std::string(".")) + "/" + name;
    if (::access(candidate.c_str(), X_OK) == 0) return candidate;
    at = end + 1;
  }
  return {};
}

// Runs gnuplot on `folder`/plot.gp inside `folder` (an absolute path); its messages go to
// `folder`/gnuplot.log. Every error names its own cause.
int RunGnuplot(const std::string& gnuplot, const fs::path& folder, std::ostream& out) {
  const std::string program = FindProgram(gnuplot);
  if (program.empty()) {
    out << "vdyn-recorder plot: cannot run '" << gnuplot << "': not found"
        << (gnuplot.find('/') == std::string::npos ? " on PATH" : "")
        << " (install gnuplot-nox: scripts/install-deps.sh)\n";
    return 1;
  }
  const fs::path log = folder / "gnuplot.log";
  const int log_fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (log_fd < 0) {
    out << "vdyn-recorder plot: cannot create " << log.string() << ": " << std::strerror(errno)
        << "\n";
    return 1;
  }
  std::vector<std::string> args = {program, "plot.gp"};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_adddup2(&fa, log_fd, 2);
  posix_spawn_file_actions_addchdir_np(&fa, folder.c_str());
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, program.c_str(), &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  ::close(log_fd);
  if (rc != 0) {
    out << "vdyn-recorder plot: cannot start " << program << " in " << folder.string() << ": "
        << std::strerror(rc) << "\n";
    return 1;
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  std::ostringstream text;
  if (std::ifstream in(log); in && in.peek() != std::ifstream::traits_type::eof())
    text << in.rdbuf();
  const std::string said = text.str();
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    out << "vdyn-recorder plot: gnuplot failed on plot.gp:\n" << said << "\n";
    return 1;
  }
  // The figures are drawn; what gnuplot had to say about them is worth reading.
  if (!said.empty()) out << "vdyn-recorder plot: gnuplot said:\n" << said;
  return 0;
}

// The y range of a panel: the data's, holding 0, at least min_span wide, a margin each side.
std::pair<double, double> PanelRange(const Panel& p, double lo, double hi) {
  if (!(lo <= hi)) lo = hi = 0;  // no finite value
  lo = std::min(lo, 0.0);
  hi = std::max(hi, 0.0);
  if (hi - lo < p.min_span) {
    const double grow = p.min_span - (hi - lo);
    // Grow away from zero: a signal above it stays at the bottom, one below at the top; one
    // that is zero throughout sits in the middle, unless it cannot go negative.
    if (lo < 0 && hi <= 0) {
      lo -= grow;
    } else if (lo >= 0 && (hi > 0 || p.nonnegative)) {
      hi += grow;
    } else {
      lo -= grow / 2;
      hi += grow / 2;
    }
  }
  // A margin each side: a line at the range's end (a force at rest at zero) stays in sight.
  const double margin = 0.05 * (hi - lo);
  lo = std::isnan(p.lo) ? lo - margin : std::min(p.lo, lo);
  hi = std::isnan(p.hi) ? hi + margin : std::max(p.hi, hi);
  return {lo, hi};
}

// The figures, in the order the page shows them (columns by the CSV's names).
std::vector<Figure> Figures() {
  const std::vector<std::string> wheels = {"LF", "RF", "LR", "RR"};
  auto per_wheel = [&](const char* prefix) {
    std::vector<std::pair<std::string, std::string>> lines;
    for (const std::string& w : wheels) lines.push_back({std::string(prefix) + "_" + w + "_N", w});
    return lines;
  };
  return {
      {"speed",
       "Speed",
       {{"km/h", {{"speed_kmh", "speed"}, {"cruise_set_kmh", "cruise set speed"}}, 10}}},
      {"acceleration",
       "Acceleration of T, body axes (kinematic)",
       {{"m/s^2",
         {{"ax_mps2", "a_x (forward)"}, {"ay_mps2", "a_y (left)"}, {"az_mps2", "a_z (up)"}},
         2}}},
      {"spring_forces", "Spring (normal) force per wheel", {{"N", per_wheel("Fp"), 200, true}}},
      {"drive_forces", "Drive force per wheel", {{"N", per_wheel("Fh"), 200}}},
      {"brake_forces", "Brake force per wheel", {{"N", per_wheel("Fb"), 200, true}}},
      {"side_forces", "Side force per wheel (positive left)", {{"N", per_wheel("Fy"), 200}}},
      // The pedals on panels of their own, 0..1 with a margin: a pedal at rest is a visible line.
      {"controls",
       "Steering and pedals",
       {{"steering, rad", {{"steer_in_rad", "steer input"}}, 0.05},
        {"throttle, 0..1",
         {{"throttle_in", "input"}, {"throttle", "applied"}},
         1,
         true,
         -0.05,
         1.05},
        {"brake, 0..1", {{"brake_in", "input"}, {"brake", "applied"}}, 1, true, -0.05, 1.05}}},
  };
}

// `plot` as its stages: the output folder, the vehicle, the columns the figures use, the data
// (one pass over the recording), the map, the gnuplot script, gnuplot, the page, and everything
// renamed into place. A stage that fails prints why and gives the exit code.
class Plotter {
 public:
  Plotter(const PlotOptions& o, std::ostream& out) : o_(o), out_(out), reader_(o.file) {}

  // A failure leaves no folder that plot made (an empty one was left behind, also for a bad file).
  int Run() {
    int rc = 0;
    try {
      rc = Stages();
    } catch (...) {
      RemoveFolderIfMade();
      throw;
    }
    if (rc != 0) RemoveFolderIfMade();
    return rc;
  }

 private:
  void RemoveFolderIfMade() {
    std::error_code ec;
    if (made_folder_) fs::remove(dir_, ec);  // only when empty: nothing of anyone else's goes
  }

  int Stages() {
    if (const int rc = PrepareFolder(); rc != 0) return rc;
    if (const int rc = ChooseVehicle(); rc != 0) return rc;
    if (const int rc = ChooseColumns(); rc != 0) return rc;
    // Everything is made in a scratch folder inside the output folder and renamed into place
    // once gnuplot has drawn it all: an error leaves the folder as it was, and no output
    // replaces the recording (whatever it is called).
    const ScratchFolder work(dir_);
    work_ = work.path();
    if (const int rc = WriteData(); rc != 0) return rc;
    outputs_ = {"states.dat", "plot.gp"};
    if (have_xy_ && world_) WriteMap();
    WriteScript();
    if (const int rc = RunGnuplot(o_.gnuplot, work_, out_); rc != 0) return rc;
    for (const std::string& f : made_) outputs_.push_back(f + "." + o_.format);
    WritePage();
    outputs_.push_back("index.html");
    // Into place, all checked against the recording first (none moves when one may not).
    for (const std::string& f : outputs_) CheckNotAnInput(dir_ / f, {o_.file});
    for (const std::string& f : outputs_) MoveInto(work_ / f, dir_ / f, {o_.file});
    out_ << made_.size() << " figures (" << o_.format << ") and index.html in " << dir_.string()
         << "\n";
    return 0;
  }

  // The map's cells: from (x0, y0), nx by ny cells of cell_x by cell_y metres.
  struct MapGrid {
    double x0 = 0, y0 = 0, cell_x = 1, cell_y = 1;
    int nx = 0, ny = 0;
  };

  int PrepareFolder() {
    dir_ = o_.out_dir;
    if (dir_.empty()) {
      dir_ = o_.file;
      dir_.replace_filename(o_.file.stem().string() + "-plots");
    }
    std::error_code ec;
    if (fs::exists(dir_, ec) && !fs::is_directory(dir_, ec)) {
      out_ << "vdyn-recorder plot: " << dir_.string()
           << " is a file, not a folder: give --out a folder\n";
      return 2;
    }
    made_folder_ = !fs::exists(dir_, ec);
    fs::create_directories(dir_, ec);
    if (ec) {
      out_ << "vdyn-recorder plot: cannot create the folder " << dir_.string() << ": "
           << ec.message() << "\n";
      return 1;
    }
    return 0;
  }

  // The vehicle and the size of its state channel (for decimation), from the summary.
  int ChooseVehicle() {
    std::map<std::uint32_t, std::uint64_t> state_counts;
    if (auto s = reader_.ReadSummary(); s && s->statistics) {
      for (const auto& [id, info] : VdynChannels(*s)) {
        if (info.topic != TopicId::kState) continue;
        const auto n = s->statistics->channel_message_counts.find(id);
        state_counts[info.key] += n == s->statistics->channel_message_counts.end() ? 0 : n->second;
      }
    } else {
      out_ << "vdyn-recorder plot: " << o_.file.string()
           << " has no summary (it was not closed): run `vdyn-recorder recover` first\n";
      return 2;  // a bad file, as the other commands say
    }
    if (state_counts.empty()) {
      out_ << "vdyn-recorder plot: no vehicle states in " << o_.file.string() << "\n";
      return 1;
    }
    vehicle_ = o_.vehicle.value_or(state_counts.begin()->first);
    if (state_counts.count(vehicle_) == 0) {
      out_ << "vdyn-recorder plot: no states of vehicle " << vehicle_ << " in " << o_.file.string()
           << "\n";
      return 2;
    }
    stride_ = std::max<std::uint64_t>(1, (state_counts[vehicle_] + kMaxRows - 1) / kMaxRows);
    return 0;
  }

  // A CSV column into the data file (once); false when this build's CSV has no such column.
  bool Use(const std::string& n) {
    if (data_col_of_.count(n)) return true;
    const auto it = std::find(names_.begin(), names_.end(), n);
    if (it == names_.end()) return false;
    data_col_of_[n] = static_cast<int>(data_cols_.size()) + 1;
    data_cols_.push_back(static_cast<int>(it - names_.begin()));
    return true;
  }

  // The columns the figures use, by name; a figure whose columns this build lacks is left out.
  int ChooseColumns() {
    names_ = CsvColumns();
    figures_ = Figures();
    const bool have_time = Use("t_s");
    have_xy_ = Use("x_m") && Use("y_m");
    if (!have_time) {
      out_ << "vdyn-recorder plot: this build's CSV has no t_s column\n";
      return 1;
    }
    for (Figure& f : figures_) {
      for (Panel& p : f.panels) {
        std::vector<std::pair<std::string, std::string>> kept;
        for (auto& [c, legend] : p.lines) {
          if (Use(c))
            kept.push_back({c, legend});
          else
            skipped_.push_back(c);
        }
        p.lines = kept;
      }
      std::erase_if(f.panels, [](const Panel& p) { return p.lines.empty(); });
    }
    col_lo_.assign(data_cols_.size(), 1e300);
    col_hi_.assign(data_cols_.size(), -1e300);
    return 0;
  }

  // The data: every stride-th state of the vehicle in the time range, and the world.
  int WriteData() {
    const std::uint64_t start = FirstLogTime(reader_);
    from_ = start + static_cast<std::uint64_t>(base::FromSeconds(o_.from_s).ns);
    to_ = o_.to_s ? start + static_cast<std::uint64_t>(base::FromSeconds(*o_.to_s).ns) : ~0ull;
    data_.open(work_ / "states.dat");
    data_ << "#";
    for (int c : data_cols_) data_ << " " << names_[static_cast<std::size_t>(c)];
    data_ << "\n";
    Progress progress("plot");
    RecordingVisitor v;
    v.wants = [](TopicId t) { return t == TopicId::kState || t == TopicId::kWorld; };
    v.on_progress = [&](double f) { progress.Update(f); };
    v.on_message = [this](const RecordedMessage& m) {
      if (m.topic == TopicId::kWorld) {
        KeepWorld(m);
      } else {
        AddState(m);
      }
    };
    ScanRecording(reader_, v);
    progress.Finish();
    data_.close();
    if (rows_ == 0) {
      out_ << "vdyn-recorder plot: no states of vehicle " << vehicle_ << " in the time range\n";
      return 1;
    }
    return 0;
  }

  // The first world description that reads.
  void KeepWorld(const RecordedMessage& m) {
    if (world_) return;
    world_.emplace();
    if (!world_->ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) world_.reset();
  }

  // One state: into the trajectory's bounds and the page's figures, and (every stride-th) a row.
  void AddState(const RecordedMessage& m) {
    if (m.key != vehicle_ || m.log_time < from_ || m.log_time > to_) return;
    if (!state_.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) return;
    const double x = state_.p_wt_w().x(), y = state_.p_wt_w().y();
    if (any_) distance_ += std::hypot(x - last_x_, y - last_y_);
    last_x_ = x;
    last_y_ = y;
    top_kmh_ = std::max(top_kmh_, state_.speed_kmh());
    x_lo_ = std::min(x_lo_, x);
    x_hi_ = std::max(x_hi_, x);
    y_lo_ = std::min(y_lo_, y);
    y_hi_ = std::max(y_hi_, y);
    const double t =
        static_cast<double>(state_.step()) * static_cast<double>(state_.step_ns()) * 1e-9;
    if (!any_) t_first_ = t;
    t_last_ = t;
    any_ = true;
    if (n_++ % stride_ != 0) return;
    CsvRowValues(state_, values_);
    char buf[64];
    for (std::size_t i = 0; i < data_cols_.size(); ++i) {
      const double val = values_[static_cast<std::size_t>(data_cols_[i])];
      if (std::isfinite(val)) {
        col_lo_[i] = std::min(col_lo_[i], val);
        col_hi_[i] = std::max(col_hi_[i], val);
      }
      const auto r = std::to_chars(buf, buf + sizeof buf, val);
      data_ << (i ? " " : "") << std::string_view(buf, static_cast<std::size_t>(r.ptr - buf));
    }
    data_ << "\n";
    ++rows_;
  }

  // The map's area: the trajectory's bounds with a margin, within the world's surfaces (no empty
  // band where the world ends), in square cells.
  MapGrid MapArea() const {
    const double margin = std::max(20.0, 0.1 * std::max(x_hi_ - x_lo_, y_hi_ - y_lo_));
    double x0 = x_lo_ - margin, x1 = x_hi_ + margin, y0 = y_lo_ - margin, y1 = y_hi_ + margin;
    if (const auto b = WorldBounds(*world_)) {
      // Clipped to the surfaces, as long as the trajectory stays inside what is left.
      if (std::max(x0, (*b)[0]) <= x_lo_ && std::min(x1, (*b)[1]) >= x_hi_) {
        x0 = std::max(x0, (*b)[0]);
        x1 = std::min(x1, (*b)[1]);
      }
      if (std::max(y0, (*b)[2]) <= y_lo_ && std::min(y1, (*b)[3]) >= y_hi_) {
        y0 = std::max(y0, (*b)[2]);
        y1 = std::min(y1, (*b)[3]);
      }
    }
    // kMapCells along the longer side, as many on the other as keep the cells nearly square; the
    // cells tile the area exactly (no row half outside the world).
    MapGrid g;
    const double longer = std::max({x1 - x0, y1 - y0, 1.0});
    g.nx = std::clamp(static_cast<int>(std::lround(kMapCells * (x1 - x0) / longer)), 2, kMapCells);
    g.ny = std::clamp(static_cast<int>(std::lround(kMapCells * (y1 - y0) / longer)), 2, kMapCells);
    g.cell_x = std::max(x1 - x0, 1e-3) / g.nx;
    g.cell_y = std::max(y1 - y0, 1e-3) / g.ny;
    g.x0 = x0;
    g.y0 = y0;
    return g;
  }

  void WriteMap() {
    map_ = MapArea();
    const MapGrid& g = *map_;
    const std::vector<double> kind =
        SurfaceMap(*world_, g.x0, g.y0, g.cell_x, g.cell_y, g.nx, g.ny);
    std::ofstream mf(work_ / "map.dat");
    // gnuplot's "nonuniform matrix": first row the x of each column, then y and the row's values.
    mf << g.nx;
    for (int i = 0; i < g.nx; ++i) mf << " " << g.x0 + (i + 0.5) * g.cell_x;
    mf << "\n";
    for (int j = 0; j < g.ny; ++j) {
      mf << g.y0 + (j + 0.5) * g.cell_y;
      for (int i = 0; i < g.nx; ++i) {
        mf << " "
           << kind[static_cast<std::size_t>(j) * static_cast<std::size_t>(g.nx) +
                   static_cast<std::size_t>(i)];
      }
      mf << "\n";
    }
    outputs_.push_back("map.dat");
  }

  std::string Terminal(int width, int height) const {
    return std::string(o_.format == "png" ? "pngcairo" : "svg") + " size " + std::to_string(width) +
           "," + std::to_string(height) + (o_.format == "png" ? "" : " dynamic") +
           " font 'sans,10'";
  }

  // The gnuplot script: one terminal per figure.
  void WriteScript() {
    std::ofstream gp(work_ / "plot.gp");
    gp << "# Written by vdyn-recorder plot from " << o_.file.filename().string()
       << "; run: gnuplot plot.gp\n";
    gp << "set grid\nset key outside right top\n";
    for (const Figure& f : figures_) {
      if (f.panels.empty()) continue;
      WriteFigure(gp, f);
      made_.push_back(f.file);
    }
    if (map_) {
      WriteTrajectory(gp);
      made_.push_back("trajectory");
    }
    gp << "unset output\n";
  }

  void WriteFigure(std::ofstream& gp, const Figure& f) {
    const int panels = static_cast<int>(f.panels.size());
    gp << "set terminal " << Terminal(1200, panels == 1 ? 480 : 200 + 220 * panels) << "\n";
    gp << "set output '" << f.file << "." << o_.format << "'\n";
    const std::string title = Escape(f.title) + " (vehicle " + std::to_string(vehicle_) + ")";
    if (panels > 1) {
      // The same margins on every panel, so their time axes line up whatever their legends.
      gp << "set multiplot layout " << panels << ",1 title \"" << title << "\"\nunset title\n";
      gp << "set lmargin 12\nset rmargin 18\n";
    } else {
      gp << "set title \"" << title << "\"\n";
    }
    for (int pi = 0; pi < panels; ++pi) {
      WritePanel(gp, f.panels[static_cast<std::size_t>(pi)], pi + 1 == panels);
    }
    if (panels > 1) gp << "unset multiplot\nset lmargin -1\nset rmargin -1\n";
    gp << "set autoscale y\n";
  }

  void WritePanel(std::ofstream& gp, const Panel& p, bool bottom) {
    double lo = 1e300, hi = -1e300;
    for (const auto& [c, legend] : p.lines) {
      const std::size_t k = static_cast<std::size_t>(data_col_of_[c] - 1);
      lo = std::min(lo, col_lo_[k]);
      hi = std::max(hi, col_hi_[k]);
    }
    const auto [ylo, yhi] = PanelRange(p, lo, hi);
    gp << "set ylabel '" << p.ylabel << "'\nset yrange [" << ylo << ":" << yhi << "]\n";
    gp << "set xlabel '" << (bottom ? "time, s" : "") << "'\n";
    gp << "plot ";
    for (std::size_t i = 0; i < p.lines.size(); ++i) {
      const auto& [c, legend] = p.lines[i];
      // Dashed: the right wheels, and an input under what was applied.
      const bool dashed = legend == "RF" || legend == "RR" || legend == "input";
      gp << (i ? ", " : "") << "'states.dat' using " << data_col_of_["t_s"] << ":"
         << data_col_of_[c] << " with lines lw " << (legend == "input" ? 2.5 : 1.5) << " dt "
         << (dashed ? 2 : 1) << " title \"" << Escape(legend) << "\"";
    }
    gp << "\n";
  }

  void WriteTrajectory(std::ofstream& gp) {
    const MapGrid& g = *map_;
    // As wide as the page, as tall as the map's shape needs (the plot area is about 740 px wide).
    const double aspect = (g.ny * g.cell_y) / (g.nx * g.cell_x);
    const int height = std::clamp(static_cast<int>(740 * aspect) + 180, 360, 1100);
    gp << "set terminal " << Terminal(1000, height) << "\nset output 'trajectory." << o_.format
       << "'\n";
    gp << "set title \"Trajectory of vehicle " << vehicle_ << " over world '"
       << Escape(world_->name()) << "'\"\n";
    gp << "set xlabel 'x, m'\nset ylabel 'y, m'\nset size ratio -1\nset key outside bottom center "
          "horizontal\n";
    // Surface kinds (world.proto's SurfaceKind), one colour each, and the cells without one.
    // A step palette: each kind one flat colour over [k - 0.5, k + 0.5].
    gp << "set palette defined (";
    const char* colours[] = {"#74a57f", "#9a9a9a", "#e07a1f", "#8d6e63",
                             "#e9c46a", "#c1121f", "#7b2cbf", "#f4f4f4"};
    for (int k = 0; k <= kNoSurface; ++k) {
      gp << (k ? ", " : "") << k - 0.5 << " '" << colours[k] << "', " << k + 0.5 << " '"
         << colours[k] << "'";
    }
    gp << ")\nset cbrange [-0.5:" << kNoSurface + 0.5
       << "]\nset cbtics ('ground' 0, 'road' 1, 'obstacle' 2, "
          "'rough' 3, 'ramp' 4, 'barrier' 5, 'prop' 6, 'no surface' 7)\nunset cblabel\n";
    gp << "set xrange [" << g.x0 << ":" << g.x0 + g.nx * g.cell_x << "]\nset yrange [" << g.y0
       << ":" << g.y0 + g.ny * g.cell_y << "]\n";
    const int x = data_col_of_["x_m"], y = data_col_of_["y_m"];
    gp << "plot 'map.dat' nonuniform matrix with image notitle, "
       << "'states.dat' using " << x << ":" << y
       << " with lines lw 2.5 lc rgb '#c1121f' title 'trajectory', "
       << "'states.dat' every ::0::0 using " << x << ":" << y
       << " with points pt 7 ps 1.5 lc rgb '#003049' title 'start', "
       << "'' using " << x << ":" << y << " every ::" << rows_ - 1 << "::" << rows_ - 1
       << " with points pt 5 ps 1.5 lc rgb '#000000' title 'end'\n";
  }

  // One page that shows them all.
  void WritePage() {
    std::ofstream html(work_ / "index.html");
    html << "<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>vdyn recording: "
         << Html(o_.file.filename().string())
         << "</title>\n<style>body{font-family:sans-serif;margin:2em;"
         << "max-width:1250px}img,object{width:100%;border:1px solid #ddd;margin:0.5em 0}"
         << "td{padding:0.2em 1em 0.2em 0}</style></head><body>\n";
    html << "<h1>" << Html(o_.file.filename().string()) << ": vehicle " << vehicle_
         << "</h1>\n<table>\n";
    auto row = [&](const std::string& k, const std::string& val) {
      html << "<tr><td>" << k << "</td><td>" << Html(val) << "</td></tr>\n";
    };
    row("simulation time", FormatDuration(t_first_) + " .. " + FormatDuration(t_last_));
    char b[64];
    std::snprintf(b, sizeof b, "%.1f m", distance_);
    row("distance", b);
    std::snprintf(b, sizeof b, "%.1f km/h", top_kmh_);
    row("top speed", b);
    if (world_) row("world", world_->name() + " (server " + world_->server_id() + ")");
    row("states plotted",
        std::to_string(rows_) + (stride_ > 1 ? " (every " + Ordinal(stride_) + ")" : ""));
    html << "</table>\n";
    for (const std::string& f : made_) {
      if (o_.format == "png") {
        html << "<img src=\"" << f << ".png\" alt=\"" << f << "\">\n";
      } else {
        html << "<object type=\"image/svg+xml\" data=\"" << f << ".svg\"></object>\n";
      }
    }
    if (!skipped_.empty()) {
      html << "<p>Columns this build's CSV does not have (left out):";
      for (const std::string& s : skipped_) html << " " << Html(s);
      html << "</p>\n";
    }
    html << "<p>Data: <a href=\"states.dat\">states.dat</a>, script: <a "
            "href=\"plot.gp\">plot.gp</a>.</p>\n</body></html>\n";
  }

  const PlotOptions& o_;
  std::ostream& out_;
  mcap::Reader reader_;
  fs::path dir_, work_;
  std::uint32_t vehicle_ = 0;
  std::uint64_t stride_ = 1;
  // The columns: the CSV's names, the figures' lines, the data file's columns (CSV index of
  // each; 1-based data-file column by name) and each data column's finite range.
  std::vector<std::string> names_;
  std::vector<Figure> figures_;
  std::vector<int> data_cols_;
  std::map<std::string, int> data_col_of_;
  std::vector<std::string> skipped_;
  bool have_xy_ = false;
  std::vector<double> col_lo_, col_hi_;
  // The data pass.
  std::uint64_t from_ = 0, to_ = 0;
  std::ofstream data_;
  pb::VehicleState state_;
  std::vector<double> values_;
  std::optional<pb::WorldDescription> world_;
  std::uint64_t n_ = 0, rows_ = 0;
  double x_lo_ = 1e300, x_hi_ = -1e300, y_lo_ = 1e300, y_hi_ = -1e300, top_kmh_ = 0, distance_ = 0;
  double last_x_ = 0, last_y_ = 0, t_first_ = 0, t_last_ = 0;
  bool any_ = false;
  // What is written.
  std::optional<MapGrid> map_;
  std::vector<std::string> made_;     // figures, without extension
  std::vector<std::string> outputs_;  // files renamed into the output folder
  bool made_folder_ = false;          // the output folder did not exist before
};

}  // namespace

int RunPlot(const PlotOptions& o, std::ostream& out) {
  // Before the recording is opened.
  if (o.format != "png" && o.format != "svg") {
    out << "vdyn-recorder plot: --format must be png or svg\n";
    return 2;
  }
  return Plotter(o, out).Run();
}

}  // namespace vdyn::recorder

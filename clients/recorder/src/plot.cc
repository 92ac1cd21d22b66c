// `vdyn-recorder plot FILE`: the pictures a person would rather look at than read - speed,
// accelerations, per-wheel spring, drive, brake and side forces, steering and pedals, and the
// trajectory over a height map of the world - drawn by gnuplot (PNG or SVG) from the recorded
// states, with one HTML page that shows them all. Columns are found by name in the CSV's column
// table (io/csv.h), so the figures follow the export and the batch CSV.
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <optional>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <set>

#include "vdyn/io/csv.h"
#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/state.pb.h"
#include "vdyn/world.pb.h"

extern char** environ;

namespace vdyn::recorder {

using transport::TopicId;

namespace {

constexpr std::size_t kMaxRows = 20000;  // per figure: finer than any screen
constexpr int kMapCells = 400;

struct Figure {
  std::string file;      // without extension
  std::string title;
  std::string ylabel;
  std::vector<std::pair<std::string, std::string>> lines;  // column, legend
  std::string y2label;   // lines whose legend starts with "y2:" go on the right axis
};

// A top-down map of the world's meshes from (x0, y0), kMapCells square cells a side: each cell
// holds the surface kind (road, ground, ramp...) of the highest surface above its centre, NaN
// where there is none; rasterised triangle by triangle.
std::vector<double> SurfaceMap(const pb::WorldDescription& w, double x0, double y0, double cell) {
  const std::size_t n = static_cast<std::size_t>(kMapCells) * kMapCells;
  std::vector<double> z(n, std::numeric_limits<double>::quiet_NaN());
  std::vector<double> kind(n, std::numeric_limits<double>::quiet_NaN());
  for (const pb::Mesh& m : w.meshes()) {
    const int nv = m.vertices_size() / 3;
    for (int t = 0; t + 2 < m.indices_size(); t += 3) {
      const std::uint32_t ia = m.indices(t), ib = m.indices(t + 1), ic = m.indices(t + 2);
      if (ia >= static_cast<std::uint32_t>(nv) || ib >= static_cast<std::uint32_t>(nv) || ic >= static_cast<std::uint32_t>(nv)) continue;
      auto V = [&](std::uint32_t i, int k) { return m.vertices(static_cast<int>(3 * i) + k); };
      const double ax = V(ia, 0), ay = V(ia, 1), az = V(ia, 2);
      const double bx = V(ib, 0), by = V(ib, 1), bz = V(ib, 2);
      const double cx = V(ic, 0), cy = V(ic, 1), cz = V(ic, 2);
      const double det = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy);
      if (std::abs(det) < 1e-12) continue;  // vertical or degenerate: no top
      const int i0 = std::max(0, static_cast<int>(std::floor((std::min({ax, bx, cx}) - x0) / cell)));
      const int i1 = std::min(kMapCells - 1, static_cast<int>(std::floor((std::max({ax, bx, cx}) - x0) / cell)));
      const int j0 = std::max(0, static_cast<int>(std::floor((std::min({ay, by, cy}) - y0) / cell)));
      const int j1 = std::min(kMapCells - 1, static_cast<int>(std::floor((std::max({ay, by, cy}) - y0) / cell)));
      for (int j = j0; j <= j1; ++j) {
        const double py = y0 + (j + 0.5) * cell;
        for (int i = i0; i <= i1; ++i) {
          const double px = x0 + (i + 0.5) * cell;
          const double l1 = ((by - cy) * (px - cx) + (cx - bx) * (py - cy)) / det;
          const double l2 = ((cy - ay) * (px - cx) + (ax - cx) * (py - cy)) / det;
          const double l3 = 1.0 - l1 - l2;
          if (l1 < 0 || l2 < 0 || l3 < 0) continue;
          const double h = l1 * az + l2 * bz + l3 * cz;
          double& cellz = z[static_cast<std::size_t>(j) * kMapCells + static_cast<std::size_t>(i)];
          if (std::isnan(cellz) || h > cellz) {
            cellz = h;
            kind[static_cast<std::size_t>(j) * kMapCells + static_cast<std::size_t>(i)] = static_cast<double>(m.kind());
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
    if (c == '<') o += "&lt;";
    else if (c == '>') o += "&gt;";
    else if (c == '&') o += "&amp;";
    else o += c;
  }
  return o;
}

int RunGnuplot(const std::string& gnuplot, const std::filesystem::path& script, std::ostream& out) {
  std::vector<std::string> args = {gnuplot, script.filename().string()};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addchdir_np(&fa, script.parent_path().c_str());
  const std::string log = (script.parent_path() / "gnuplot.log").string();
  posix_spawn_file_actions_addopen(&fa, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid = -1;
  const int rc = posix_spawnp(&pid, gnuplot.c_str(), &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) {
    out << "vdyn-recorder plot: cannot run '" << gnuplot << "': " << std::strerror(rc)
        << " (install gnuplot-nox: scripts/install-deps.sh)\n";
    return 1;
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::ifstream in(log);
    out << "vdyn-recorder plot: gnuplot failed on " << script.string() << ":\n" << in.rdbuf() << "\n";
    return 1;
  }
  return 0;
}

}  // namespace

int RunPlot(const PlotOptions& o, std::ostream& out) {
  if (o.format != "png" && o.format != "svg") {
    out << "vdyn-recorder plot: --format must be png or svg\n";
    return 2;
  }
  mcap::Reader reader(o.file);
  std::filesystem::path dir = o.out_dir;
  if (dir.empty()) {
    dir = o.file;
    dir.replace_filename(o.file.stem().string() + "-plots");
  }
  std::filesystem::create_directories(dir);
  // Vehicle and the size of its state channel (for decimation), from the summary.
  std::map<std::uint32_t, std::uint64_t> state_counts;
  if (auto s = reader.ReadSummary(); s && s->statistics) {
    for (const mcap::Channel& c : s->channels) {
      const auto info = ParseChannelInfo(c);
      if (!info || info->topic != TopicId::kState) continue;
      const auto n = s->statistics->channel_message_counts.find(c.id);
      state_counts[info->key] += n == s->statistics->channel_message_counts.end() ? 0 : n->second;
    }
  } else {
    out << "vdyn-recorder plot: " << o.file.string()
        << " has no summary (it was not closed): run `vdyn-recorder recover` first\n";
    return 1;
  }
  if (state_counts.empty()) {
    out << "vdyn-recorder plot: no vehicle states in " << o.file.string() << "\n";
    return 1;
  }
  const std::uint32_t vehicle = o.vehicle.value_or(state_counts.begin()->first);
  if (state_counts.count(vehicle) == 0) {
    out << "vdyn-recorder plot: no states of vehicle " << vehicle << " in " << o.file.string() << "\n";
    return 2;
  }
  const std::uint64_t stride = std::max<std::uint64_t>(1, (state_counts[vehicle] + kMaxRows - 1) / kMaxRows);

  // The columns the figures use, by name; a figure whose columns this build lacks is left out.
  const std::vector<std::string> names = CsvColumns();
  auto col = [&](const std::string& n) -> int {
    const auto it = std::find(names.begin(), names.end(), n);
    return it == names.end() ? -1 : static_cast<int>(it - names.begin());
  };
  const std::vector<std::string> wheels = {"LF", "RF", "LR", "RR"};
  std::vector<Figure> figures = {
      {"speed", "Speed", "km/h", {{"speed_kmh", "speed"}, {"cruise_set_kmh", "cruise set speed"}}, ""},
      {"acceleration", "Acceleration of T, body axes (kinematic)", "m/s^2",
       {{"ax_mps2", "a_x (forward)"}, {"ay_mps2", "a_y (left)"}, {"az_mps2", "a_z (up)"}}, ""},
      {"spring_forces", "Spring (normal) force per wheel", "N", {}, ""},
      {"drive_forces", "Drive force per wheel", "N", {}, ""},
      {"brake_forces", "Brake force per wheel", "N", {}, ""},
      {"side_forces", "Side force per wheel (positive left)", "N", {}, ""},
      {"controls", "Steering and pedals", "road-wheel angle, rad",
       {{"steer_in_rad", "steer input"}, {"y2:throttle_in", "throttle input"}, {"y2:brake_in", "brake input"},
        {"y2:throttle", "throttle applied"}, {"y2:brake", "brake applied"}}, "pedal, 0..1"},
  };
  const char* prefixes[] = {"Fp", "Fh", "Fb", "Fy"};
  for (int f = 0; f < 4; ++f) {
    for (const std::string& w : wheels) figures[2 + static_cast<std::size_t>(f)].lines.push_back({std::string(prefixes[f]) + "_" + w + "_N", w});
  }
  std::vector<int> data_cols;  // CSV column index of each data-file column
  std::map<std::string, int> data_col_of;
  auto use = [&](const std::string& n) {
    if (data_col_of.count(n)) return true;
    const int c = col(n);
    if (c < 0) return false;
    data_col_of[n] = static_cast<int>(data_cols.size()) + 1;
    data_cols.push_back(c);
    return true;
  };
  std::vector<std::string> skipped;
  const bool have_time = use("t_s");
  const bool have_xy = use("x_m") && use("y_m");
  if (!have_time) {
    out << "vdyn-recorder plot: this build's CSV has no t_s column\n";
    return 1;
  }
  for (Figure& f : figures) {
    std::vector<std::pair<std::string, std::string>> kept;
    for (auto& [c, legend] : f.lines) {
      const std::string name = c.rfind("y2:", 0) == 0 ? c.substr(3) : c;
      if (use(name)) kept.push_back({c, legend});
      else skipped.push_back(name);
    }
    f.lines = kept;
  }

  // The data: every stride-th state of the vehicle in the time range.
  const std::uint64_t start = FirstLogTime(reader);
  const auto from = start + static_cast<std::uint64_t>(o.from_s * 1e9);
  const auto to = o.to_s ? start + static_cast<std::uint64_t>(*o.to_s * 1e9) : ~0ull;
  std::ofstream data(dir / "states.dat");
  data << "#";
  for (int c : data_cols) data << " " << names[static_cast<std::size_t>(c)];
  data << "\n";
  pb::VehicleState state;
  std::vector<double> values;
  std::optional<pb::WorldDescription> world;
  std::uint64_t n = 0, rows = 0;
  double x_lo = 1e300, x_hi = -1e300, y_lo = 1e300, y_hi = -1e300, top_kmh = 0, distance = 0;
  double last_x = 0, last_y = 0, t_first = 0, t_last = 0;
  bool any = false;
  char buf[64];
  Progress progress("plot");
  RecordingVisitor v;
  v.wants = [](TopicId t) { return t == TopicId::kState || t == TopicId::kWorld; };
  v.on_progress = [&](double f) { progress.Update(f); };
  v.on_message = [&](const RecordedMessage& m) {
    if (m.topic == TopicId::kWorld) {
      if (!world) {
        world.emplace();
        if (!world->ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) world.reset();
      }
      return;
    }
    if (m.key != vehicle || m.log_time < from || m.log_time > to) return;
    if (!state.ParseFromArray(m.data.data(), static_cast<int>(m.data.size()))) return;
    const double x = state.p_wt_w().x(), y = state.p_wt_w().y();
    if (any) distance += std::hypot(x - last_x, y - last_y);
    last_x = x;
    last_y = y;
    top_kmh = std::max(top_kmh, state.speed_kmh());
    x_lo = std::min(x_lo, x);
    x_hi = std::max(x_hi, x);
    y_lo = std::min(y_lo, y);
    y_hi = std::max(y_hi, y);
    const double t = static_cast<double>(state.step()) * static_cast<double>(state.step_ns()) * 1e-9;
    if (!any) t_first = t;
    t_last = t;
    any = true;
    if (n++ % stride != 0) return;
    CsvRowValues(state, values);
    for (std::size_t i = 0; i < data_cols.size(); ++i) {
      const double val = values[static_cast<std::size_t>(data_cols[i])];
      const auto r = std::to_chars(buf, buf + sizeof buf, val);
      data << (i ? " " : "") << std::string_view(buf, static_cast<std::size_t>(r.ptr - buf));
    }
    data << "\n";
    ++rows;
  };
  ScanRecording(reader, v);
  progress.Finish();
  data.close();
  if (rows == 0) {
    out << "vdyn-recorder plot: no states of vehicle " << vehicle << " in the time range\n";
    return 1;
  }

  // The map: the trajectory's bounds with a margin, square cells.
  const bool map = have_xy && world.has_value();
  double mx0 = 0, my0 = 0, cell = 1;
  if (map) {
    const double span = std::max({x_hi - x_lo, y_hi - y_lo, 40.0}) * 1.3;
    cell = span / kMapCells;
    mx0 = 0.5 * (x_lo + x_hi) - 0.5 * span;
    my0 = 0.5 * (y_lo + y_hi) - 0.5 * span;
    const std::vector<double> z = SurfaceMap(*world, mx0, my0, cell);
    std::ofstream mf(dir / "map.dat");
    // gnuplot's "nonuniform matrix": first row the x of each column, then y and the row's values.
    mf << kMapCells;
    for (int i = 0; i < kMapCells; ++i) mf << " " << mx0 + (i + 0.5) * cell;
    mf << "\n";
    for (int j = 0; j < kMapCells; ++j) {
      mf << my0 + (j + 0.5) * cell;
      for (int i = 0; i < kMapCells; ++i) {
        const double h = z[static_cast<std::size_t>(j) * kMapCells + static_cast<std::size_t>(i)];
        mf << " ";
        if (std::isnan(h)) mf << "NaN"; else mf << h;
      }
      mf << "\n";
    }
  }

  // The gnuplot script: one terminal per figure.
  const std::string ext = o.format;
  const std::string term = o.format == "png" ? "pngcairo size 1200,480 font 'sans,10'" : "svg size 1200,480 dynamic font 'sans,10'";
  std::ofstream gp(dir / "plot.gp");
  gp << "# Written by vdyn-recorder plot from " << o.file.filename().string() << "; run: gnuplot plot.gp\n";
  gp << "set terminal " << term << "\nset grid\nset key outside right top\nset xlabel 'time, s'\n";
  gp << "set datafile missing 'NaN'\n";
  std::vector<std::string> made;
  for (const Figure& f : figures) {
    if (f.lines.empty()) continue;
    gp << "set output '" << f.file << "." << ext << "'\n";
    gp << "set title \"" << Escape(f.title) << " (vehicle " << vehicle << ")\"\n";
    gp << "set ylabel '" << f.ylabel << "'\n";
    const bool y2 = !f.y2label.empty();
    if (y2) gp << "set y2label '" << f.y2label << "'\nset y2tics\nset ytics nomirror\n";
    gp << "plot ";
    for (std::size_t i = 0; i < f.lines.size(); ++i) {
      const bool right = f.lines[i].first.rfind("y2:", 0) == 0;
      const std::string name = right ? f.lines[i].first.substr(3) : f.lines[i].first;
      gp << (i ? ", " : "") << "'states.dat' using " << data_col_of["t_s"] << ":" << data_col_of[name]
         << " with lines lw 1.5 dt " << (f.lines[i].second == "RF" || f.lines[i].second == "RR" ? 2 : 1)
         << " title \"" << Escape(f.lines[i].second) << "\"" << (right ? " axes x1y2" : "");
    }
    gp << "\n";
    if (y2) gp << "unset y2label\nunset y2tics\nset ytics mirror\n";
    made.push_back(f.file);
  }
  if (map) {
    const std::string sq = o.format == "png" ? "pngcairo size 900,800 font 'sans,10'" : "svg size 900,800 dynamic font 'sans,10'";
    gp << "set terminal " << sq << "\nset output 'trajectory." << ext << "'\n";
    gp << "set title \"Trajectory of vehicle " << vehicle << " over world '" << Escape(world->name())
       << "'\"\n";
    gp << "set xlabel 'x, m'\nset ylabel 'y, m'\nset size ratio -1\nset key outside bottom center horizontal\n";
    // Surface kinds (world.proto's SurfaceKind), one colour each.
    // A step palette: each kind one flat colour over [k - 0.5, k + 0.5].
    gp << "set palette defined (";
    const char* colours[] = {"#74a57f", "#9a9a9a", "#e07a1f", "#8d6e63", "#e9c46a", "#c1121f", "#7b2cbf"};
    for (int k = 0; k < 7; ++k) {
      gp << (k ? ", " : "") << k - 0.5 << " '" << colours[k] << "', " << k + 0.5 << " '" << colours[k] << "'";
    }
    gp << ")\nset cbrange [-0.5:6.5]\nset cbtics ('ground' 0, 'road' 1, 'obstacle' 2, 'rough' 3, "
          "'ramp' 4, 'barrier' 5, 'prop' 6)\nunset cblabel\n";
    gp << "set xrange [" << mx0 << ":" << mx0 + kMapCells * cell << "]\nset yrange [" << my0 << ":"
       << my0 + kMapCells * cell << "]\n";
    gp << "plot 'map.dat' nonuniform matrix with image notitle, "
       << "'states.dat' using " << data_col_of["x_m"] << ":" << data_col_of["y_m"]
       << " with lines lw 2.5 lc rgb '#c1121f' title 'trajectory', "
       << "'states.dat' every ::0::0 using " << data_col_of["x_m"] << ":" << data_col_of["y_m"]
       << " with points pt 7 ps 1.5 lc rgb '#003049' title 'start', "
       << "'' using " << data_col_of["x_m"] << ":" << data_col_of["y_m"]
       << " every ::" << rows - 1 << "::" << rows - 1 << " with points pt 5 ps 1.5 lc rgb '#000000' title 'end'\n";
    made.push_back("trajectory");
  }
  gp << "unset output\n";
  gp.close();
  if (const int rc = RunGnuplot(o.gnuplot, dir / "plot.gp", out); rc != 0) return rc;

  // One page that shows them all.
  std::ofstream html(dir / "index.html");
  html << "<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>vdyn recording: "
       << Html(o.file.filename().string()) << "</title>\n<style>body{font-family:sans-serif;margin:2em;"
       << "max-width:1250px}img,object{width:100%;border:1px solid #ddd;margin:0.5em 0}"
       << "td{padding:0.2em 1em 0.2em 0}</style></head><body>\n";
  html << "<h1>" << Html(o.file.filename().string()) << ": vehicle " << vehicle << "</h1>\n<table>\n";
  auto row = [&](const std::string& k, const std::string& val) { html << "<tr><td>" << k << "</td><td>" << Html(val) << "</td></tr>\n"; };
  row("simulation time", FormatDuration(t_first) + " .. " + FormatDuration(t_last));
  char b[64];
  std::snprintf(b, sizeof b, "%.1f m", distance);
  row("distance", b);
  std::snprintf(b, sizeof b, "%.1f km/h", top_kmh);
  row("top speed", b);
  if (world) row("world", world->name() + " (server " + world->server_id() + ")");
  row("states plotted", std::to_string(rows) + (stride > 1 ? " (every " + std::to_string(stride) + "th)" : ""));
  html << "</table>\n";
  for (const std::string& f : made) {
    if (o.format == "png") {
      html << "<img src=\"" << f << ".png\" alt=\"" << f << "\">\n";
    } else {
      html << "<object type=\"image/svg+xml\" data=\"" << f << ".svg\"></object>\n";
    }
  }
  if (!skipped.empty()) {
    html << "<p>Columns this build's CSV does not have (left out):";
    for (const std::string& s : skipped) html << " " << Html(s);
    html << "</p>\n";
  }
  html << "<p>Data: <a href=\"states.dat\">states.dat</a>, script: <a href=\"plot.gp\">plot.gp</a>.</p>\n</body></html>\n";
  html.close();
  out << made.size() << " figures (" << o.format << ") and index.html in " << dir.string() << "\n";
  return 0;
}

}  // namespace vdyn::recorder

#include "tools/show_command.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

#include "tools/gnuplot.hpp"
#include "tools/recording.hpp"

namespace pvcgel::tools {

namespace {

struct ShowArgs {
  std::string path, plot;
  double settle = NAN;
};

/// The file's size, rate and damaged rows, and the run's header fields.
void print_header_summary(const ShowArgs& a, const Recording& rec) {
  const auto& t = rec.col("t_s");
  std::printf("%s: %zu rows, %.3f s at %.0f Hz", a.path.c_str(), t.size(), t.back() - t.front(), 1.0 / rec.sample_time_s);
  if (rec.skipped_rows) std::printf(" (%ld invalid rows skipped)", rec.skipped_rows);
  if (rec.invalid_rows) std::printf(" (%ld rows with a non-finite reading)", rec.invalid_rows);
  if (rec.truncated_rows) std::printf(" (last line cut, as a crash leaves it: %ld row skipped)", rec.truncated_rows);
  std::printf("\n");
  for (const auto& [k, v] : rec.header)
    if (k == "trajectory" || k == "mode" || k == "hal_backend" || k == "start_time") std::printf("  %s: %s\n", k.c_str(), v.c_str());
}

/// Mean and max |r - y| over RUNNING rows after the soft start and a settling time (rows without a state
/// column count as RUNNING; a non-finite reading is left out).
void print_tracking_error(const ShowArgs& a, const Recording& rec) {
  double soft = 0.0;
  if (auto it = rec.header.find("soft_start_s"); it != rec.header.end()) soft = std::atof(it->second.c_str());
  const double settle = std::isnan(a.settle) ? soft + 3.0 : a.settle;
  const auto& t = rec.col("t_s");
  const auto& y = rec.col("y_um");
  const auto& r = rec.col("r_um");
  const bool has_state = rec.text.count("state") > 0;
  double first_running = NAN, sum = 0.0, mx = 0.0;
  long count = 0;
  for (size_t k = 0; k < t.size(); ++k) {
    if (has_state && rec.text.at("state")[k] != "RUNNING") continue;
    if (std::isnan(first_running)) first_running = t[k];
    if (t[k] - first_running < settle || !std::isfinite(y[k])) continue;
    const double e = std::abs(r[k] - y[k]);
    sum += e;
    mx = std::max(mx, e);
    ++count;
  }
  if (count > 0)
    std::printf("tracking error |r - y| while RUNNING (after %.1f s): mean %.3f um, max %.3f um over %ld samples\n",
                settle, sum / static_cast<double>(count), mx, count);
  else
    std::printf("tracking error: no RUNNING samples after %.1f s of settling\n", settle);
}

/// The first ramp-down (its start voltage, fault and time to 0 V) and the final state and output.
void print_shutdown(const Recording& rec) {
  const auto& t = rec.col("t_s");
  const auto& u = rec.col("u_V");
  const size_t n = t.size();
  const auto& state = rec.text.at("state");
  const auto& fault = rec.text.count("fault") ? rec.text.at("fault") : state;
  const size_t ramp = static_cast<size_t>(std::find(state.begin(), state.end(), "RAMP_DOWN") - state.begin());
  if (ramp < n) {
    size_t zero = ramp;
    while (zero < n && u[zero] > 0.0) ++zero;
    std::printf("ramp-down from %.1f V at t = %.3f s%s", ramp > 0 ? u[ramp - 1] : 0.0, t[ramp],
                rec.text.count("fault") && fault[ramp] != "none" ? (" (fault: " + fault[ramp] + ")").c_str() : "");
    if (zero < n) std::printf(", 0 V after %.3f s", t[zero] - t[ramp]);
    std::printf("\n");
  }
  std::printf("final state %s, output %.3f V", state.back().c_str(), u.back());
  if (rec.numeric.count("hv")) std::printf(", high voltage %s", rec.col("hv").back() > 0.5 ? "ENABLED" : "disabled");
  std::printf("\n");
}

/// Reference and measurement, tracking error and command against time, as a PNG through gnuplot (at most
/// ~20000 points per trace).
void plot_recording(const ShowArgs& a, const Recording& rec) {
  namespace fs = std::filesystem;
  const auto& t = rec.col("t_s");
  const auto& u = rec.col("u_V");
  const auto& y = rec.col("y_um");
  const std::vector<double>* r = rec.numeric.count("r_um") ? &rec.col("r_um") : nullptr;
  const size_t n = t.size();
  const fs::path png(a.plot);
  const ScratchDirectory scratch("pvcgel-show");  // only the PNG is wanted
  const fs::path dat = scratch.path() / "recording.dat";
  const fs::path gp = scratch.path() / "plot.gp";
  std::ofstream f(dat);
  const size_t stride = std::max<size_t>(1, n / 20000);
  for (size_t k = 0; k < n; k += stride)
    f << t[k] << ' ' << y[k] << ' ' << (r ? (*r)[k] : NAN) << ' ' << u[k] << '\n';
  f.close();
  std::ofstream g(gp);
  g << "set terminal pngcairo noenhanced size 1100,900 font ',10'\nset output '" << png.string() << "'\n"
    << "set multiplot layout 3,1 title '" << fs::path(a.path).filename().string() << "'\nset grid\nset xlabel 't (s)'\n"
    << "set ylabel 'displacement (um)'\nplot '" << dat.string() << "' u 1:3 w l lw 2 lc rgb 'black' t 'reference', '' u 1:2 w l lc rgb '#1f77b4' t 'measured'\n"
    << "set ylabel 'r - y (um)'\nplot '" << dat.string() << "' u 1:($3-$2) w l lc rgb '#d62728' t 'tracking error'\n"
    << "set ylabel 'voltage (V)'\nplot '" << dat.string() << "' u 1:4 w l lc rgb '#2ca02c' t 'amplifier command'\n"
    << "unset multiplot\n";
  g.close();
  run_gnuplot(gp);
  std::printf("wrote %s\n", png.string().c_str());
}

int show(const ShowArgs& a) {
  // Keep rows with a NaN reading (a faulted sensor): the summary must end at the true last row.
  const Recording rec = read_recording(a.path, true);
  print_header_summary(a, rec);
  if (rec.numeric.count("r_um")) print_tracking_error(a, rec);
  if (rec.text.count("state")) print_shutdown(rec);
  if (!a.plot.empty()) plot_recording(a, rec);
  return 0;
}

}  // namespace

void add_show_command(CLI::App& app) {
  auto args = std::make_shared<ShowArgs>();
  auto* cmd = app.add_subcommand("show", "Summarise (and plot) a recording: tracking error, ramp-down, final state");
  cmd->add_option("recording", args->path, "recording CSV (pvcgeld --record)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--plot", args->plot, "write a PNG: reference and displacement, error, voltage");
  cmd->add_option("--settle", args->settle, "seconds of RUNNING excluded from the error (default: soft start + 3 s)");
  cmd->callback([args] { show(*args); });
}

}  // namespace pvcgel::tools

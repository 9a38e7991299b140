#include "tools/bench_command.hpp"
#include "tools/diagnose_suite.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>

#include <toml++/toml.h>

#include "control/config/config_parser.hpp"
#include "daemon/config_file.hpp"

#include "tools/gnuplot.hpp"
#include "tools/paper_bench.hpp"
#include "tools/text_output.hpp"

namespace pvcgel::tools {

namespace fs = std::filesystem;

namespace {

struct PaperArgs {
  double crossover = 45.0, phase_margin = 60.0, duration = 60.0, settle = 20.0;
  std::uint64_t seed = 1;
  std::string json, plot_dir, config;
  bool sweep = false, crossover_given = false, seed_given = false, phase_margin_given = false;
  std::vector<double> sweep_values{15, 20, 30, 45, 60, 80, 120, 160, 250};
};

void plot_references(const PaperBenchResult& r, const PaperBenchOptions& o, const fs::path& dir) {
  fs::create_directories(dir);
  const char* titles[] = {"PID", "inverse/PID", "inverse/PID/DOB", "inverse/PID/DOB/FF"};
  const char* colors[] = {"#d62728", "#1f77b4", "#2ca02c", "#ff7f0e"};
  for (const auto& rr : r.references) {
    const auto ref = *control::paper_reference(rr.name);
    // Like the paper's Figs. 11-13: a few periods at the end of the run.
    const double window = std::min(std::max(2.0 * ref.slowest_period_s(), 4.0), o.duration_s - o.settle_s);
    const fs::path dat = dir / (rr.name + ".dat");
    std::ofstream f(dat);
    f << "# t_s r_um y_pid y_inv y_dob y_ff e_pid e_inv e_dob e_ff\n";
    const auto& t = rr.modes[0].trace.t_s;
    for (size_t k = 0; k < t.size(); k += 2) {
      if (t[k] < o.duration_s - window) continue;
      f << t[k] << ' ' << rr.modes[0].trace.r_um[k];
      for (const auto& m : rr.modes) f << ' ' << m.trace.y_um[k];
      for (const auto& m : rr.modes) f << ' ' << m.trace.r_um[k] - m.trace.y_um[k];
      f << '\n';
    }
    f.close();
    std::string gp = "set terminal pngcairo noenhanced size 1100,800 font ',10'\nset output '" + (dir / (rr.name + ".png")).string() +
                     "'\nset multiplot layout 2,1 title 'Paper reference " + rr.name +
                     " on the simulated paper rig'\nset grid\nset xlabel 't (s)'\n";
    gp += "set ylabel 'displacement (um)'\nset key outside right\nplot '" + dat.string() +
          "' u 1:2 w l lw 2 lc rgb 'black' t 'reference'";
    for (int m = 0; m < 4; ++m)
      gp += ", '' u 1:" + std::to_string(3 + m) + " w l lc rgb '" + colors[m] + "' t '" + titles[m] + "'";
    gp += "\nset ylabel 'tracking error r - y (um)'\nplot ";
    for (int m = 0; m < 4; ++m)
      gp += std::string(m ? ", " : "") + "'" + dat.string() + "' u 1:" + std::to_string(7 + m) + " w l lc rgb '" +
            colors[m] + "' t '" + titles[m] + "'";
    gp += "\nunset multiplot\n";
    const fs::path script = dir / (rr.name + ".gp");
    write_text_file(script, gp);
    run_gnuplot(script);
    std::cout << "wrote " << (dir / (rr.name + ".png")).string() << "\n";
  }
}

/// The bench's options from the command line: the configuration's model, rig and controller when given,
/// then the tuning target, durations and seed. Throws when --duration does not exceed --settle by 1 s.
PaperBenchOptions paper_options(const PaperArgs& a) {
  PaperBenchOptions o;
  if (!a.config.empty()) {
    const toml::table root = daemon::read_config_file(a.config, "--config").root;
    const auto cfg = control::parse_configuration(root, a.config);
    o.model = cfg.model;
    o.rig = cfg.sim;
    o.controller = cfg.controller;
    if (cfg.controller.tuning) o.tuning = *cfg.controller.tuning;
  }
  if (a.crossover_given) o.tuning.crossover_rad_s = a.crossover;
  if (a.phase_margin_given) o.tuning.phase_margin_deg = a.phase_margin;
  o.duration_s = a.duration;
  o.settle_s = a.settle;
  if (a.seed_given || a.config.empty()) o.rig.seed = a.seed;
  if (!(a.settle >= 0.0 && a.duration > a.settle + 1.0))
    throw std::runtime_error("--duration must exceed --settle by at least 1 s");
  o.keep_traces = !a.plot_dir.empty();
  return o;
}

/// sweep.png in `plot_dir` from the sweep's table `dat` (crossover, then mean |e| per mode and reference).
void plot_sweep(const std::string& plot_dir, const std::string& dat) {
  fs::create_directories(plot_dir);
  const fs::path d = fs::path(plot_dir) / "sweep.dat";
  write_text_file(d, dat);
  std::string gp = "set terminal pngcairo noenhanced size 1100,800 font ',10'\nset output '" +
                   (fs::path(plot_dir) / "sweep.png").string() +
                   "'\nset multiplot layout 2,2 title 'Mean tracking error vs PID crossover target'\n"
                   "set logscale xy\nset grid\nset xlabel 'crossover (rad/s)'\nset ylabel 'mean |e| (um)'\n";
  const char* refs[] = {"0.1Hz", "0.5Hz", "1Hz", "multi"};
  for (int i = 0; i < 4; ++i) {
    gp += std::string("set title '") + refs[i] + "'\nplot ";
    const char* names[] = {"PID", "inverse/PID", "inverse/PID/DOB", "inverse/PID/DOB/FF"};
    for (int m = 0; m < 4; ++m)
      gp += std::string(m ? ", " : "") + "'" + d.string() + "' u 1:" + std::to_string(2 + 4 * i + m) + " w lp t '" +
            names[m] + "'";
    gp += "\n";
  }
  gp += "unset multiplot\n";
  const auto script = fs::path(plot_dir) / "sweep.gp";
  write_text_file(script, gp);
  run_gnuplot(script);
  std::cout << "wrote " << (fs::path(plot_dir) / "sweep.png").string() << "\n";
}

/// The mean |e| of every mode and reference at each crossover of --sweep, as a table (and a plot with
/// --plot); a crossover no PID reaches is reported as skipped.
void run_sweep(const PaperArgs& a, const PaperBenchOptions& o) {
  std::cout << "Sweep over the PID tuning target (phase margin " << a.phase_margin
            << " deg): mean |e| in um per reference and mode\n\n";
  std::cout << " crossover |        0.1Hz            |        0.5Hz            |         1Hz             |        multi            | ranking\n";
  std::cout << "  (rad/s)  |  pid   inv   dob   ff   |  pid   inv   dob   ff   |  pid   inv   dob   ff   |  pid   inv   dob   ff   | holds\n";
  std::string dat = "# crossover then mean |e| for (pid inv dob ff) x (0.1Hz 0.5Hz 1Hz multi)\n";
  for (double wc : a.sweep_values) {
    auto so = o;
    so.keep_traces = false;
    so.tuning.crossover_rad_s = wc;
    PaperBenchResult r;
    try {
      r = run_paper_bench(so);
    } catch (const std::exception& e) {
      std::printf("  %7.0f  | skipped: %s\n", wc, e.what());
      continue;
    }
    std::printf("  %7.0f  ", wc);
    dat += std::to_string(wc);
    int holds = 0;
    for (const auto& rr : r.references) {
      std::printf("|");
      for (const auto& m : rr.modes) {
        std::printf(" %5.3f", m.errors.mean_abs_um);
        dat += " " + std::to_string(m.errors.mean_abs_um);
      }
      std::printf(" ");
      holds += paper_ranking_holds(rr);
    }
    dat += "\n";
    std::printf("| %d/4\n", holds);
    std::fflush(stdout);
  }
  if (!a.plot_dir.empty()) plot_sweep(a.plot_dir, dat);
}

void run_paper(const PaperArgs& a) {
  const PaperBenchOptions o = paper_options(a);
  if (a.sweep) return run_sweep(a, o);
  std::cout << "Running 4 references x 4 controllers, " << o.duration_s << " s each, accelerated...\n" << std::flush;
  const auto r = run_paper_bench(o);
  std::cout << format_table(r, o);
  std::printf("\nSimulation speed: %.2f million closed-loop steps/s (%.0fx real time at 1 kHz)\n",
              r.steps_per_second / 1e6, r.steps_per_second / 1000.0);
  if (!a.json.empty()) {
    write_text_file(a.json, to_json(r, o));
    std::cout << "wrote " << a.json << "\n";
  }
  if (!a.plot_dir.empty()) plot_references(r, o, a.plot_dir);
}

/// `pvcgel bench diagnose`: the full blind suite of issue 7.
void add_diagnose_bench(CLI::App& bench) {
  struct Args {
    int cases = 44;
    std::uint64_t seed = 7;
    std::string save;
    std::string suite;
    int jobs = 1;
    int limit = 0;
    int retime = 5;
  };
  auto args = std::make_shared<Args>();
  auto* cmd = bench.add_subcommand("diagnose", "Blind suite for pvcgel diagnose: concealed effects, confusion matrix, accuracy");
  cmd->add_option("--cases", args->cases, "number of cases (every effect and none, evenly)")->capture_default_str()->check(CLI::Range(11, 10000));
  cmd->add_option("--seed", args->seed, "suite seed")->capture_default_str();
  cmd->add_option("--save", args->save, "also write the cases as recordings to DIR (labels apart, in labels.csv)");
  cmd->add_option("--suite", args->suite,
                  "score a suite made elsewhere instead: DIR with caseNNN/{model.toml,rec*.csv} and labels.csv "
                  "(case,effects,dominant,...; effects none, a name or a+b)")->check(CLI::ExistingDirectory);
  cmd->add_option("--jobs", args->jobs, "cases diagnosed in parallel (--suite)")->capture_default_str()->check(CLI::Range(1, 64));
  cmd->add_option("--limit", args->limit, "only the first N cases of --suite (0: all)")->capture_default_str();
  cmd->add_option("--retime", args->retime,
                  "with --jobs > 1 (each case then fits on a share of the cores): diagnose the N slowest cases "
                  "again, one at a time on every core, as a user runs one (--suite)")
      ->capture_default_str()
      ->check(CLI::Range(0, 10000));
  cmd->callback([args] {
    if (!args->suite.empty()) {
      std::cout << format_directory_suite(
          run_directory_suite(args->suite, args->jobs, std::cout, args->limit, args->retime));
      return;
    }
    const auto r = run_blind_suite(args->cases, args->seed, std::cout, {}, args->save);
    std::cout << format_suite(r);
  });
}

}  // namespace

void add_bench_command(CLI::App& app) {
  auto* bench = app.add_subcommand("bench", "Benchmarks on the simulated rig");
  bench->require_subcommand(1);
  auto args = std::make_shared<PaperArgs>();
  auto* paper = bench->add_subcommand(
      "paper", "The paper's tracking comparison (Table III) under all four controller modes, accelerated");
  paper->add_option("--crossover", args->crossover, "PID tuning target: gain crossover (rad/s)")
      ->capture_default_str()->check(CLI::PositiveNumber);
  paper->add_option("--phase-margin", args->phase_margin, "PID tuning target: phase margin (deg)")
      ->capture_default_str()->check(CLI::Range(1.0, 89.0));
  paper->add_option("--duration", args->duration, "simulated seconds per run")->capture_default_str()->check(CLI::PositiveNumber);
  paper->add_option("--settle", args->settle, "start-up transient excluded from the errors (s)")->capture_default_str();
  paper->add_option("--config", args->config, "TOML file with [model], [controller] and [sim] tables (default: the paper rig)")
      ->check(CLI::ExistingFile);
  paper->add_option("--seed", args->seed, "sensor-noise seed")->capture_default_str();
  paper->add_option("--json", args->json, "write results as JSON to FILE");
  paper->add_option("--plot", args->plot_dir, "write PNG plots (like the paper's Figs. 11-13) to DIR");
  paper->add_flag("--sweep", args->sweep, "sweep the crossover target instead (plots go to --plot DIR)");
  paper->add_option("--sweep-values", args->sweep_values, "crossover values for --sweep (rad/s)");
  add_diagnose_bench(*bench);
  paper->callback([args, paper] {
    args->crossover_given = paper->count("--crossover") > 0;
    args->phase_margin_given = paper->count("--phase-margin") > 0;
    args->seed_given = paper->count("--seed") > 0;
    run_paper(*args);
  });
}

}  // namespace pvcgel::tools

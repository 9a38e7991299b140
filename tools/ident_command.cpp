#include "tools/ident_command.hpp"
#include "tools/ident_rig.hpp"

#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <numbers>
#include <optional>
#include <sstream>

#include "control/config_error.hpp"
#include "control/config/config_parser.hpp"
#include "control/identification/model_selection.hpp"
#include "daemon/config_file.hpp"
#include "tools/gnuplot.hpp"
#include "tools/recording.hpp"
#include "tools/text_output.hpp"

namespace pvcgel::tools {

namespace fs = std::filesystem;
using namespace control::identification;
using control::HammersteinModel;

namespace {

constexpr double kPi = std::numbers::pi;

std::string roots_text(const Eigen::VectorXcd& r) {
  std::string s;
  for (Eigen::Index i = 0; i < r.size(); ++i) {
    s += i ? ", " : "";
    s += std::abs(r(i).imag()) < 1e-12 ? format("%.4f", r(i).real()) : format("%.4f%+.4fj", r(i).real(), r(i).imag());
  }
  return s.empty() ? "none" : s;
}

std::vector<std::complex<double>> sorted_roots(const Eigen::VectorXcd& r) {
  std::vector<std::complex<double>> v(r.data(), r.data() + r.size());
  std::sort(v.begin(), v.end(), [](auto a, auto b) { return a.real() < b.real(); });
  return v;
}

/// A record kept for time-domain validation.
struct Validation {
  std::string label;
  SineRecord record;
  double settle_s = 10.0;
  bool held_out = true;
  std::vector<std::vector<double>> prediction;  ///< per n (index n - 1)
  std::vector<PredictionMetrics> metrics;
};

bool is_validation_target(const IdentArgs& a, double A, double B, double f) {
  if (std::abs(A - a.validation_amplitude_V) > a.options.regime_tolerance_V ||
      std::abs(B - a.validation_bias_V) > a.options.regime_tolerance_V)
    return false;
  return std::any_of(a.validation_frequencies_Hz.begin(), a.validation_frequencies_Hz.end(),
                     [&](double vf) { return std::abs(f - vf) <= 0.02 * vf; });
}

double header_number(const Recording& r, const std::string& key, double fallback) {
  const auto it = r.header.find(key);
  if (it == r.header.end()) return fallback;
  char* end = nullptr;
  const double v = std::strtod(it->second.c_str(), &end);
  return end != it->second.c_str() && std::isfinite(v) ? v : fallback;
}

SineRecord to_record(const Recording& r) {
  SineRecord s;
  s.point.amplitude_V = s.point.bias_V = s.point.frequency_Hz = NAN;  // estimated from u, not read
  s.sample_time_s = r.sample_time_s;
  s.t_s = r.col("t_s");
  s.u_V = r.col("u_V");
  s.y_um = r.col("y_um");
  return s;
}

std::vector<fs::path> csv_files(const fs::path& dir) {
  if (!fs::is_directory(dir)) throw std::runtime_error("--from: '" + dir.string() + "' is not a directory");
  std::vector<fs::path> v;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file() && e.path().extension() == ".csv") v.push_back(e.path());
  std::sort(v.begin(), v.end());
  if (v.empty()) throw std::runtime_error("--from: no *.csv recordings in '" + dir.string() + "'");
  return v;
}

void plot_bode(const IdentificationResult& r, const fs::path& dir) {
  const fs::path meas = dir / "bode_measured.dat", model = dir / "bode_model.dat";
  std::ofstream m(meas);
  m << "# f_Hz |H| sigma phase_deg  (reference regime, sampling delays removed)\n";
  for (size_t i : r.reference) {
    const auto& p = r.points[i];
    const auto h = r.continuous[i];
    m << p.frequency_Hz << ' ' << std::abs(h) << ' ' << p.response_sigma << ' ' << std::arg(h) * 180 / kPi << '\n';
  }
  std::ofstream g(model);
  for (double f : log_spaced(0.05, 20.0, 200)) {
    const auto h = r.G_fit.G({0.0, 2 * kPi * f});
    g << f << ' ' << std::abs(h) << ' ' << std::arg(h) * 180 / kPi << '\n';
  }
  m.close();
  g.close();
  std::ostringstream gp;
  gp << "set terminal pngcairo noenhanced size 900,900 font ',10'\nset output '" << (dir / "bode.png").string() << "'\n"
     << "set multiplot layout 2,1 title 'Frequency response at the reference regime: measured vs identified G(s) (like Fig. 6)'\n"
     << "set logscale x\nset grid\nset xlabel 'frequency (Hz)'\nset logscale y\nset ylabel 'magnitude (um/V)'\n"
     << "plot '" << meas.string() << "' u 1:2:3 w yerrorbars pt 7 lc rgb 'black' t 'measured', '" << model.string()
     << "' u 1:2 w l lw 2 lc rgb '#1f77b4' t 'G(s)'\nunset logscale y\nset ylabel 'phase (deg)'\n"
     << "plot '" << meas.string() << "' u 1:4 w p pt 7 lc rgb 'black' t 'measured', '" << model.string()
     << "' u 1:3 w l lw 2 lc rgb '#1f77b4' t 'G(s)'\nunset multiplot\n";
  write_text_file(dir / "bode.gp", gp.str());
  run_gnuplot(dir / "bode.gp");
}

void plot_gains(const IdentificationResult& r, const fs::path& dir) {
  // Distinct amplitudes and biases of the valid points (rounded to 1 V).
  std::map<long, int> amps, biases;
  for (size_t i : r.used) {
    amps[std::lround(r.points[i].amplitude_V)] = 0;
    biases[std::lround(r.points[i].bias_V)] = 0;
  }
  const char* colors[] = {"#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b"};
  for (const auto& cand : r.f_fit.candidates) {
    const int n = cand.terms;
    const auto model = r.model(n);
    std::ostringstream gp;
    const fs::path png = dir / ("gain_n" + std::to_string(n) + ".png");
    gp << "set terminal pngcairo noenhanced size 1500,500 font ',10'\nset output '" << png.string() << "'\n"
       << "set multiplot layout 1," << biases.size() << " title 'Overall gain N(A,B)|G(jw)|: measured (M, points) vs model (E, lines), n = "
       << n << " (like Figs. 7-9)'\nset logscale xy\nset grid\nset xlabel 'frequency (Hz)'\nset ylabel 'gain (um/V)'\nset key bottom left\n";
    for (const auto& [B, unused] : biases) {
      const fs::path dat = dir / ("gain_n" + std::to_string(n) + "_B" + std::to_string(B) + ".dat");
      std::ofstream d(dat);
      int ai = 0;
      std::string plot = "plot ";
      for (const auto& [A, unused2] : amps) {
        d << "# A = " << A << " measured\n";
        for (size_t i : r.used)
          if (std::lround(r.points[i].amplitude_V) == A && std::lround(r.points[i].bias_V) == B)
            d << r.points[i].frequency_Hz << ' ' << std::abs(r.continuous[i]) << '\n';
        d << "\n\n# A = " << A << " model\n";
        for (double f : log_spaced(0.05, 20.0, 120))
          d << f << ' ' << overall_gain(model, static_cast<double>(A), static_cast<double>(B), 2 * kPi * f) << '\n';
        d << "\n\n";
        const char* c = colors[ai % 6];
        plot += std::string(ai ? ", " : "") + "'" + dat.string() + "' index " + std::to_string(2 * ai) +
                " w p pt 7 lc rgb '" + c + "' t '" + std::to_string(A) + " V M', '' index " +
                std::to_string(2 * ai + 1) + " w l lc rgb '" + c + "' t '" + std::to_string(A) + " V E'";
        ++ai;
      }
      gp << "set title 'bias " << B << " V'\n" << plot << "\n";
    }
    gp << "unset multiplot\n";
    const fs::path script = dir / ("gain_n" + std::to_string(n) + ".gp");
    write_text_file(script, gp.str());
    run_gnuplot(script);
  }
}

void plot_validation(const std::vector<Validation>& vals, int max_n, const fs::path& dir) {
  if (vals.empty()) return;
  const char* colors[] = {"#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b"};
  std::ostringstream gp;
  gp << "set terminal pngcairo noenhanced size 1100," << 420 * vals.size() << " font ',10'\nset output '"
     << (dir / "validation.png").string() << "'\nset multiplot layout " << vals.size()
     << ",1 title 'Time-domain validation: measured vs model prediction from the recorded u (like Fig. 10)'\n"
     << "set grid\nset xlabel 't (s)'\nset ylabel 'displacement (um)'\nset key outside right\n";
  for (size_t v = 0; v < vals.size(); ++v) {
    const auto& val = vals[v];
    const fs::path dat = dir / ("validation_" + std::to_string(v) + ".dat");
    std::ofstream d(dat);
    const auto& t = val.record.t_s;
    // The last two periods (at most 25 s), like the paper's figure.
    const double f = val.record.point.frequency_Hz > 0 ? val.record.point.frequency_Hz : 1.0;
    const double from = t.back() - std::min(2.0 / f, 25.0);
    for (size_t k = 0; k < t.size(); ++k) {
      if (t[k] < from) continue;
      d << t[k] << ' ' << val.record.y_um[k];
      for (const auto& p : val.prediction) d << ' ' << p[k];
      d << '\n';
    }
    gp << "set title '" << val.label << (val.held_out ? " (held out)" : " (also in the fit data)") << "'\nplot '"
       << dat.string() << "' u 1:2 w l lw 2 lc rgb 'black' t 'measured'";
    for (int n = 1; n <= max_n; ++n)
      gp << ", '' u 1:" << 2 + n << " w l lc rgb '" << colors[(n - 1) % 6] << "' t 'model n = " << n << "'";
    gp << "\n";
  }
  gp << "unset multiplot\n";
  write_text_file(dir / "validation.gp", gp.str());
  run_gnuplot(dir / "validation.gp");
}

}  // namespace

std::string model_toml(const HammersteinModel& m, const std::string& comment) {
  std::string s;
  std::istringstream in(comment);
  for (std::string line; std::getline(in, line);) s += "# " + line + "\n";
  s += "[model]\npoly = " + toml_array(m.f.coefficients()) + "\nG_num = " + toml_array(m.G.num()) + "\nG_den = " + toml_array(m.G.den()) + "\n";
  return s;
}

void write_sine_recording(const fs::path& path, const SineRecord& r, const daemon::RecordingHeader& header) {
  // The daemon's writer: an open-loop experiment is what the loop records while it plays voltage setpoints.
  daemon::Recorder out(path.string(), header);
  daemon::CycleRecord row;
  row.r_um = row.e_um = NAN;
  row.state = daemon::LoopState::running;
  row.target = daemon::LoopTarget::voltage;
  row.high_voltage = true;
  for (size_t k = 0; k < r.t_s.size(); ++k) {
    row.seq = k;
    row.t_s = r.t_s[k];
    row.u_V = r.u_V[k];
    row.y_um = r.y_um[k];
    out.write(row);
  }
  out.finish();
}

namespace {

/// What one acquisition (simulated rig or recordings) produced for the fit.
struct Acquisition {
  std::vector<FrequencyResponsePoint> points;
  std::vector<Validation> validations;
  double sample_time_s = 1e-3;
  double cpu_s = 0.0;                           ///< extraction only
  std::optional<control::SimRigConfig> truth;   ///< the simulated rig, for the comparison
};

control::SimRigConfig sim_rig_config(const IdentArgs& a) {
  control::SimRigConfig cfg;
  if (!a.config.empty()) {
    const toml::table root = daemon::read_config_file(a.config, "--config").root;
    cfg = control::parse_configuration(root, a.config, {"loop", "hal", "safety", "run", "dds", "setpoints"}).sim;
  }
  cfg.seed = a.seed;
  if (a.ideal) {
    cfg.hysteresis.enabled = false;
    cfg.creep.enabled = false;
  }
  return cfg;
}

daemon::RecordingHeader sim_recording_header(const SinePoint& p, double Ts) {
  return {{"rate_hz", format("%.0f", 1.0 / Ts)},
          {"hal_backend", "sim"},
          {"trajectory", format("ident-sine:%g,%g,%g", p.bias_V, p.amplitude_V, p.frequency_Hz)},
          {"mode", "open_loop"},
          {"settle_s", format("%g", p.settle_s)}};
}

std::string sine_label(const SinePoint& p) {
  return format("A%03.0f_B%03.0f_f%07.4fHz", p.amplitude_V, p.bias_V, p.frequency_Hz);
}

/// Held-out experiments: separate runs (other noise) of the paper's Fig. 10 settings.
std::vector<Validation> held_out_on_sim(const IdentArgs& a, const control::SimRigConfig& cfg) {
  control::SimRigConfig vcfg = cfg;
  vcfg.seed = a.seed + 1000;
  control::SimulatedRig vrig(vcfg);
  std::vector<Validation> validations;
  for (double f : a.validation_frequencies_Hz) {
    SinePoint p{a.validation_amplitude_V, a.validation_bias_V, f, a.grid.settle_s,
                std::max(ExcitationPlan::kMinPeriods, static_cast<int>(std::ceil(10.0 * f)))};
    (void)ExcitationPlan({p}, cfg.sample_time_s);  // validates the voltage range
    Validation v;
    v.label = format("A = %.0f V, B = %.0f V, f = %g Hz", p.amplitude_V, p.bias_V, f);
    v.record = run_sine_experiment(vrig, p);
    v.settle_s = p.settle_s;
    if (!a.save_recordings.empty())
      write_sine_recording(fs::path(a.save_recordings) / "validation" / (sine_label(p) + ".csv"), v.record,
                           sim_recording_header(p, cfg.sample_time_s));
    validations.push_back(std::move(v));
  }
  return validations;
}

Acquisition acquire_from_sim(const IdentArgs& a, std::ostream& out) {
  Acquisition acq;
  const control::SimRigConfig cfg = sim_rig_config(a);
  acq.sample_time_s = cfg.sample_time_s;
  acq.truth = cfg;
  const auto plan = ExcitationPlan::from_grid(a.grid, acq.sample_time_s);
  control::SimulatedRig rig(cfg);
  out << "Simulated rig: truth f = " << toml_array(cfg.truth.f.coefficients()) << ", G = " << cfg.truth.G.to_string()
      << ", I/O delay " << cfg.io_delay_samples << " sample(s), noise " << cfg.noise_sigma_um << " um, hysteresis "
      << (cfg.hysteresis.enabled ? "on" : "off") << ", creep " << (cfg.creep.enabled ? "on" : "off") << "\n";
  out << "Plan: " << plan.points().size() << " sine experiments, " << format("%.0f", plan.total_duration_s())
      << " s of rig time (settling " << a.grid.settle_s << " s each)\n";
  size_t i = 0;
  for (const auto& p : plan.points()) {
    ++i;
    const auto rec = run_sine_experiment(rig, p);
    if (!a.save_recordings.empty())
      write_sine_recording(fs::path(a.save_recordings) / (sine_label(p) + ".csv"), rec,
                           sim_recording_header(p, acq.sample_time_s));
    ExtractionOptions eo;
    eo.settle_s = p.settle_s;
    eo.min_periods = a.min_periods;
    const double c0 = process_cpu_s();
    acq.points.push_back(extract_frequency_response(rec.t_s, rec.u_V, rec.y_um, eo, sine_label(p)));
    acq.cpu_s += process_cpu_s() - c0;
    if (!a.quiet)
      std::fprintf(stderr, "[%zu/%zu] A = %.0f V, B = %.0f V, f = %.3f Hz: %.1f s simulated, |H| = %.5f um/V%s\n", i,
                   plan.points().size(), p.amplitude_V, p.bias_V, p.frequency_Hz, p.duration_s(),
                   acq.points.back().gain(),
                   acq.points.back().valid ? "" : (" FLAGGED: " + acq.points.back().problem).c_str());
  }
  acq.validations = held_out_on_sim(a, cfg);
  if (!a.save_recordings.empty())
    out << "Recordings written to " << a.save_recordings << "/ (held-out ones in validation/)\n";
  return acq;
}

/// Held-out recordings in `dir`; each one's frequency is estimated from its u.
std::vector<Validation> held_out_recordings(const fs::path& dir, double default_settle_s) {
  std::vector<Validation> validations;
  for (const auto& file : csv_files(dir)) {
    const auto rec = read_recording(file.string());
    Validation v;
    v.label = file.filename().string();
    v.record = to_record(rec);
    v.settle_s = header_number(rec, "settle_s", default_settle_s);
    const auto est = estimate_sine(v.record.t_s, v.record.u_V, 0, v.record.t_s.size());
    v.record.point.frequency_Hz = est.frequency_Hz;
    validations.push_back(std::move(v));
  }
  return validations;
}

/// One recording's frequency-response point; unreadable files become flagged points.
FrequencyResponsePoint extract_from_file(const IdentArgs& a, const fs::path& file, std::optional<double>& Ts_seen,
                                         Acquisition& acq, double& read_s) {
  const double c0 = process_cpu_s();
  Recording rec;
  try {
    rec = read_recording(file.string());
  } catch (const std::exception& e) {
    // Unusable file (gaps, non-uniform time, ...): flagged, excluded, reported.
    FrequencyResponsePoint bad;
    bad.source = file.filename().string();
    bad.problem = e.what();
    return bad;
  }
  read_s += process_cpu_s() - c0;
  if (Ts_seen && std::abs(*Ts_seen - rec.sample_time_s) > 1e-3 * *Ts_seen)
    throw std::runtime_error(file.string() + ": sample time " + format("%g", rec.sample_time_s) +
                             " s differs from the other recordings' " + format("%g", *Ts_seen) + " s");
  Ts_seen = rec.sample_time_s;
  ExtractionOptions eo;
  eo.settle_s = header_number(rec, "settle_s", a.settle_s);
  eo.min_periods = a.min_periods;
  const double c1 = process_cpu_s();
  auto p = extract_frequency_response(rec.col("t_s"), rec.col("u_V"), rec.col("y_um"), eo, file.filename().string());
  acq.cpu_s += process_cpu_s() - c1;
  if (p.valid && is_validation_target(a, p.amplitude_V, p.bias_V, p.frequency_Hz)) {
    Validation v;  // an in-fit stand-in, replaced by held-out recordings when there are any
    v.label = p.source;
    v.record = to_record(rec);
    v.record.point.frequency_Hz = p.frequency_Hz;
    v.settle_s = eo.settle_s;
    v.held_out = false;
    acq.validations.push_back(std::move(v));
  }
  return p;
}

Acquisition acquire_from_recordings(const IdentArgs& a, std::ostream& out) {
  Acquisition acq;
  acq.sample_time_s = a.options.sample_time_s;
  const auto files = csv_files(a.from);
  out << "Recordings: " << files.size() << " in " << a.from << "\n";
  double read_s = 0.0;
  std::optional<double> Ts_seen;
  for (size_t i = 0; i < files.size(); ++i) {
    acq.points.push_back(extract_from_file(a, files[i], Ts_seen, acq, read_s));
    const auto& p = acq.points.back();
    if (a.quiet) continue;
    if (!p.valid && p.frequency_Hz == 0.0)
      std::fprintf(stderr, "[%zu/%zu] %s: FLAGGED: %s\n", i + 1, files.size(), p.source.c_str(), p.problem.c_str());
    else
      std::fprintf(stderr, "[%zu/%zu] %s: A = %.1f V, B = %.1f V, f = %.4f Hz, |H| = %.5f um/V%s\n", i + 1,
                   files.size(), p.source.c_str(), p.amplitude_V, p.bias_V, p.frequency_Hz, p.gain(),
                   p.valid ? "" : (" FLAGGED: " + p.problem).c_str());
  }
  if (Ts_seen) acq.sample_time_s = *Ts_seen;
  out << format("Reading the recordings took %.2f s CPU (not counted below)\n", read_s);
  const fs::path vdir = a.validation_dir.empty() ? fs::path(a.from) / "validation" : fs::path(a.validation_dir);
  if (fs::is_directory(vdir)) acq.validations = held_out_recordings(vdir, a.settle_s);
  else if (!a.validation_dir.empty())
    throw std::runtime_error("--validation-dir: '" + a.validation_dir + "' is not a directory");
  return acq;
}

/// The experiments run on the rig and are kept as recordings; the fit is then
/// exactly that of `--from` on them.
IdentOutcome run_on_rig(const IdentArgs& a) {
  ClientOptions o;
  o.rig = a.rig;
  o.domain = a.domain;
  o.dds_config = a.dds_config;
  if (o.dds_config.empty())
    if (const char* env = std::getenv("PVCGEL_DDS_CONFIG")) o.dds_config = env;
  char stamp[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(stamp, sizeof stamp, "%Y%m%dT%H%M%S", std::gmtime(&now));
  const fs::path dir = a.save_recordings.empty() ? fs::path("ident-" + a.rig + "-" + stamp) : fs::path(a.save_recordings);
  const std::string rig_line = run_plan_on_rig(a, o, dir);
  IdentArgs b = a;
  b.rig.clear();
  b.save_recordings.clear();
  b.from = dir.string();
  IdentOutcome fitted = run_ident(b);
  fitted.summary = rig_line + fitted.summary;
  return fitted;
}

void describe_points(const IdentificationResult& r, const IdentificationOptions& io, std::ostream& out) {
  out << "\nFrequency responses (fundamental; phase and |H| with the " << io.io_delay_samples
      << "-sample I/O delay and the ZOH removed; sigma from the per-period spread; H2, H3 relative to H1)\n";
  out << "   A (V)   B (V)    f (Hz)  periods   |H| (um/V)  sigma (%)  phase (deg)   DC (um)   H2 (%)  H3 (%)  status\n";
  size_t flagged = 0;
  for (size_t i = 0; i < r.points.size(); ++i) {
    const auto& p = r.points[i];
    if (!p.valid && p.frequency_Hz == 0.0) {
      out << "  " << p.source << ": FLAGGED, excluded: " << p.problem << "\n";
      ++flagged;
      continue;
    }
    const auto h = r.continuous[i];
    const double h1 = p.harmonic_um.empty() ? NAN : p.harmonic_um[0];
    out << format("  %6.1f  %6.1f  %8.4f  %7d  %11.6f  %9.3f  %11.2f  %8.3f  %7.3f %7.3f  ", p.amplitude_V,
                  p.bias_V, p.frequency_Hz, p.periods, std::abs(h), 100.0 * p.response_sigma / std::max(p.gain(), 1e-300),
                  std::arg(h) * 180 / kPi, p.dc_um, p.harmonic_um.size() > 1 ? 100 * p.harmonic_um[1] / h1 : NAN,
                  p.harmonic_um.size() > 2 ? 100 * p.harmonic_um[2] / h1 : NAN);
    if (p.valid) out << (std::find(r.reference.begin(), r.reference.end(), i) != r.reference.end() ? "ref" : "ok");
    else {
      out << "FLAGGED, excluded: " << p.problem;
      ++flagged;
    }
    out << "\n";
  }
  out << r.used.size() << " valid points, " << flagged << " flagged and excluded, " << r.reference.size()
      << " at the reference regime A = " << io.reference_amplitude_V << " V, B = " << io.reference_bias_V << " V\n";
}

void describe_fits(const IdentificationResult& r, const IdentificationOptions& io, std::ostream& out) {
  const auto& g = r.G_fit;
  out << "\nG(s) (numerator order " << io.G.numerator_order << ", denominator order " << io.G.denominator_order
      << "; Levy/SK " << g.sk_iterations << " iterations, fit " << format("%.2f", g.sk_fit_percent)
      << "%, then Levenberg-Marquardt: " << g.lm_status << ")\n";
  out << "  G(s) = " << g.G.to_string() << "\n";
  out << format("  fit %.3f%% (tfest measure), max relative error %.3f%%, DC gain %.6g um/V\n", g.fit_percent,
                100 * g.max_relative_error, g.G.dc_gain());
  out << "  poles: " << roots_text(g.poles) << "\n  zeros: " << roots_text(g.zeros) << "\n";
  out << "  normalisation: " << kNormalisation << "\n";
  out << "\nNonlinearity f (paper eq. (10), d = measured gain / |G(jw)| per valid grid point)\n";
  out << "   n   ||Hc - d||   relative   vs n-1    monotone on [0, " << io.f.voltage_max_V << "] V   c\n";
  for (const auto& c : r.f_fit.candidates) {
    std::string vs = "";
    if (c.terms > 1)
      vs = format("%+.1f%%", 100.0 * (c.residual_norm / r.f_fit.candidate(c.terms - 1).residual_norm - 1.0));
    out << format("  %2d  %11.5g  %9.5f  %8s    %-28s", c.terms, c.residual_norm, c.relative_residual, vs.c_str(),
                  c.monotone() ? "yes" : format("no: turns over at %.1f V", *c.turnover_V).c_str())
        << toml_array(c.c) << "\n";
  }
  out << "  frequency-domain rule: n = " << r.f_fit.chosen_terms << ": " << r.f_fit.rule << "\n";
}

void describe_against_truth(const IdentificationResult& r, const IdentificationOptions& io,
                            const control::SimRigConfig& rig, std::ostream& out) {
  const auto& truth = rig.truth;
  out << "\nAgainst the simulated truth (f = " << toml_array(truth.f.coefficients()) << ", G = " << truth.G.to_string()
      << ")\n";
  const auto p = sorted_roots(r.G_fit.poles), pt = sorted_roots(truth.G.poles());
  for (size_t i = 0; i < std::min(p.size(), pt.size()); ++i)
    out << format("  pole %.4f vs %.4f: %.3f%%\n", p[i].real(), pt[i].real(), 100 * std::abs(p[i] - pt[i]) / std::abs(pt[i]));
  const auto z = sorted_roots(r.G_fit.zeros), zt = sorted_roots(truth.G.zeros());
  for (size_t i = 0; i < std::min(z.size(), zt.size()); ++i)
    out << format("  zero %.4f vs %.4f: %.3f%%\n", z[i].real(), zt[i].real(), 100 * std::abs(z[i] - zt[i]) / std::abs(zt[i]));
  const double Nref = truth.f.describing_function(io.reference_amplitude_V, io.reference_bias_V);
  std::vector<double> ct = truth.f.coefficients();
  for (auto& c : ct) c *= Nref;
  out << "  truth in this normalisation: c = " << toml_array(ct) << " (c_true x N_true(A_ref, B_ref) = "
      << format("%.5g", Nref) << "), G_true / " << format("%.5g", Nref) << "\n";
  for (const auto& c : r.f_fit.candidates) {
    const auto m = r.model(c.terms);
    double worst = 0.0;
    for (size_t i : r.used) {
      const auto& q = r.points[i];
      const double gt = overall_gain(truth, q.amplitude_V, q.bias_V, q.omega_rad_s());
      worst = std::max(worst, std::abs(overall_gain(m, q.amplitude_V, q.bias_V, q.omega_rad_s()) - gt) / gt);
    }
    out << format("  n = %d: max |overall gain N(A,B)|G(jw)| - truth's| over the grid: %.3f%%%s\n", c.terms,
                  100 * worst, c.terms == truth.f.terms() ? "  (n of the truth)" : "");
  }
}

/// Predicts every validation record with every n and prints the metrics.
void validate_in_time(std::vector<Validation>& validations, const IdentificationResult& r,
                      const IdentificationOptions& io, std::ostream& out) {
  if (validations.empty()) return;
  const int max_n = static_cast<int>(r.f_fit.candidates.size());
  out << "\nTime-domain validation (model driven by the recorded u with ZOH and the I/O delay, from its steady state "
         "at u[0]; metrics after the settling time)\n";
  for (auto& v : validations) {
    const auto begin = static_cast<size_t>(std::llround(v.settle_s / v.record.sample_time_s));
    if (begin >= v.record.t_s.size()) continue;
    out << "  " << v.label << (v.held_out ? " (held out)" : " (also in the fit data: no held-out recordings)") << "\n";
    for (int n = 1; n <= max_n; ++n) {
      v.prediction.push_back(simulate_hammerstein(r.model(n), v.record.u_V, v.record.sample_time_s, io.io_delay_samples));
      v.metrics.push_back(prediction_metrics(v.record.y_um, v.prediction.back(), begin, v.record.t_s.size()));
      const auto& m = v.metrics.back();
      out << format("    n = %d: NRMSE %.4f, rms %.3f um, max %.3f um, mean offset %+.3f um\n", n, m.nrmse,
                    m.rms_error_um, m.max_error_um, m.mean_error_um);
    }
  }
}

/// Chooses n by held-out time-domain validation (the frequency-domain rule when
/// there is no held-out data or n was forced) and prints both rules' picks.
ModelChoice choose_model(const IdentArgs& a, const std::vector<Validation>& validations, IdentificationResult& r,
                         std::ostream& out) {
  std::vector<std::vector<PredictionMetrics>> metrics;
  for (const auto& v : validations)
    if (v.held_out && !v.metrics.empty()) metrics.push_back(v.metrics);
  ModelChoiceOptions o;
  for (size_t i : r.used) o.highest_bias_V = std::max(o.highest_bias_V, r.points[i].bias_V);
  out << "\nChoice of n (frequency-domain rule above: n = " << r.f_fit.chosen_terms << ")\n";
  ModelChoice choice;
  if (a.options.f.forced_terms || metrics.empty()) {
    choice.terms = r.f_fit.chosen_terms;
    choice.rule = a.options.f.forced_terms ? r.f_fit.rule : "no held-out recordings: " + r.f_fit.rule;
    if (const auto turn = r.f_fit.chosen().turnover_V) choice.voltage_max_V = std::floor(0.98 * *turn);
  } else {
    choice = choose_by_validation(r.f_fit, metrics, o);
  }
  out << "  held-out time-domain rule: n = " << choice.terms << ": " << choice.rule << "\n  chosen: n = "
      << choice.terms;
  if (choice.voltage_max_V) out << format(", with controller.voltage_max_V = %.0f V", *choice.voltage_max_V);
  out << "\n";
  r.f_fit.chosen_terms = choice.terms;
  return choice;
}

void write_model(const IdentArgs& a, const IdentificationResult& r, const IdentificationOptions& io,
                 const ModelChoice& choice, std::ostream& out) {
  const auto model = r.chosen_model();
  std::string comment =
      "pvcgel ident: " + (a.sim ? std::string("simulated rig") : "recordings in " + a.from) +
      "\nn = " + std::to_string(choice.terms) + ": " + choice.rule + "\nfrequency-domain rule: " + r.f_fit.rule +
      "\nnormalisation: N(A_ref = " + format("%g", io.reference_amplitude_V) + " V, B_ref = " +
      format("%g", io.reference_bias_V) + " V) = 1 for the fit of G; f carries the scale" +
      "\nconventions: f maps the amplifier voltage u (V) to the linear block's input; G maps that to the "
      "displacement y (um), coefficients in descending powers of s; u[k] is applied at the cycle after y[k] is "
      "measured and held (zero-order hold), plus io_delay_samples whole samples of I/O delay, which the fit removed";
  std::string text = model_toml(model, comment) + format("io_delay_samples = %d\n", io.io_delay_samples);
  if (choice.voltage_max_V)
    text += format("\n# f turns over above this: the inverse controller needs f strictly increasing up to the limit\n"
                   "[controller]\nvoltage_max_V = %.0f\n",
                   *choice.voltage_max_V);
  // The file must be what the daemon accepts (model and controller).
  write_checked_toml(
      a.out, text, [](const toml::table& t, const std::string& p) { (void)control::parse_configuration(t, p); },
      "internal: the model file does not parse back");
  out << "wrote " << a.out << " (n = " << choice.terms << ")\n";
}

void write_report(const IdentArgs& a, const IdentificationResult& r, const IdentificationOptions& io,
                  const std::vector<Validation>& validations, const std::string& results, std::ostream& out) {
  const fs::path dir(a.report);
  fs::create_directories(dir);
  const int max_n = static_cast<int>(r.f_fit.candidates.size());
  plot_bode(r, dir);
  plot_gains(r, dir);
  plot_validation(validations, max_n, dir);
  std::ostringstream md;
  md << "# pvcgel ident report\n\nSource: " << (a.sim ? "simulated rig" : "recordings in `" + a.from + "`")
     << ".\n\n## Method\n\n"
     << "- Extraction: fundamental (and harmonics 2..5, DC, linear drift) by least squares over the last whole "
        "periods after the settling time; A, B and f estimated from `u_V` (four-parameter sine fit). Uncertainty: "
        "spread of per-period estimates / sqrt(periods). Points with too few periods, a clipped or distorted input "
        "or an unreadable file are flagged and excluded.\n"
     << "- Sampling: the measured discrete response includes the zero-order hold and the rig's I/O delay ("
     << io.io_delay_samples << " sample(s), a configured fact of the rig); both are removed (e^{+jw(d+1/2)Ts} / sinc) "
        "before fitting the continuous G(s).\n"
     << "- G(s): Levy / Sanathanan-Koerner, then Levenberg-Marquardt on the relative complex error, at the "
        "reference regime.\n"
     << "- Normalisation: " << kNormalisation << "\n"
     << "- f: paper eq. (10) for n = 1.." << max_n << "; frequency-domain rule: " << r.f_fit.rule << ".\n"
     << "- n used: the smallest whose mean held-out time-domain NRMSE is within 5% of the best; a degree whose f "
        "turns over below 1000 V comes with `controller.voltage_max_V` just below the turnover (see Results).\n\n"
     << "## Results\n\n```\n" << results << "```\n\n## Plots\n\n"
     << "- Fig. 6 analogue: ![bode](bode.png)\n";
  for (const auto& c : r.f_fit.candidates)
    md << "- Figs. 7-9 analogue, n = " << c.terms << ": ![gain n=" << c.terms << "](gain_n" << c.terms << ".png)\n";
  if (!validations.empty()) md << "- Fig. 10 analogue: ![validation](validation.png)\n";
  write_text_file(dir / "report.md", md.str());
  out << "wrote " << (dir / "report.md").string() << " and plots\n";
}

}  // namespace

IdentRefused::IdentRefused(const std::string& why, std::string summary_text)
    : std::runtime_error(why + "; no model written"), summary(std::move(summary_text)) {}

IdentOutcome run_ident(const IdentArgs& a) {
  if (static_cast<int>(a.sim) + static_cast<int>(!a.from.empty()) + static_cast<int>(!a.rig.empty()) != 1)
    throw std::runtime_error("give exactly one of --sim, --from DIR or --rig ID");
  if (!a.save_recordings.empty() && a.sim + !a.rig.empty() == 0)
    throw std::runtime_error("--save-recordings needs --sim or --rig");
  if (!a.rig.empty()) return run_on_rig(a);

  std::ostringstream out;
  Acquisition acq = a.sim ? acquire_from_sim(a, out) : acquire_from_recordings(a, out);
  IdentificationOptions io = a.options;
  io.sample_time_s = acq.sample_time_s;
  const double c0 = process_cpu_s();
  IdentOutcome outcome{identify(acq.points, io), "", 0.0, false};
  outcome.cpu_extract_fit_s = acq.cpu_s + process_cpu_s() - c0;
  const auto& r = outcome.result;
  describe_points(r, io, out);
  describe_fits(r, io, out);
  if (acq.truth) describe_against_truth(r, io, *acq.truth, out);
  validate_in_time(acq.validations, outcome.result, io, out);
  const ModelChoice choice = choose_model(a, acq.validations, outcome.result, out);
  out << format("\nCPU time for extraction and fits (%zu points): %.3f s\n", r.points.size(), outcome.cpu_extract_fit_s);
  const std::string problem = r.G_fit.control_problem();
  if (!problem.empty()) out << "\nREFUSED: " << problem << "\n";
  if (problem.empty() && !a.out.empty()) {
    write_model(a, r, io, choice, out);
    outcome.model_written = true;
  }
  if (!a.report.empty()) write_report(a, r, io, acq.validations, out.str(), out);
  outcome.summary = out.str();
  if (!problem.empty()) throw IdentRefused(problem, outcome.summary);
  return outcome;
}

void add_ident_command(CLI::App& app) {
  auto a = std::make_shared<IdentArgs>();
  auto* c = app.add_subcommand("ident", "Describing-function system identification from sine experiments (paper Section III)");
  c->add_flag("--sim", a->sim, "run the excitation plan on the simulated rig (accelerated)");
  c->add_option("--rig", a->rig, "run the plan on this rig (a running pvcgeld, open-loop voltage mode over DDS)");
  c->add_option("--domain", a->domain, "--rig: DDS domain")->capture_default_str();
  c->add_option("--dds-config", a->dds_config, "--rig: Cyclone DDS XML (default $PVCGEL_DDS_CONFIG)");
  c->add_option("--from", a->from, "directory of recordings (*.csv, pvcgeld format), one sine experiment each");
  c->add_option("--validation-dir", a->validation_dir, "held-out recordings for time-domain validation (default FROM/validation)");
  c->add_option("--out", a->out, "write the model file to FILE: [model] (poly, G_num, G_den, io_delay_samples), and [controller] voltage_max_V when f turns over below 1000 V");
  c->add_option("--report", a->report, "write report.md and PNG plots to DIR");
  c->add_option("--save-recordings", a->save_recordings,
                "--sim: also write every experiment as a recording to DIR; --rig: where the recordings go "
                "(default ident-RIG-TIME)");
  c->add_option("--config", a->config, "--sim: TOML file with a [sim] table (default: the paper rig)")->check(CLI::ExistingFile);
  c->add_flag("--ideal", a->ideal, "--sim: hysteresis and creep off (the truth is exactly a Hammerstein model)");
  c->add_option("--seed", a->seed, "--sim: sensor-noise seed")->capture_default_str();
  c->add_option("--amplitudes", a->grid.amplitudes_V, "sine amplitudes A (V)")->capture_default_str();
  c->add_option("--biases", a->grid.biases_V, "sine biases B (V)")->capture_default_str();
  c->add_option("--freq-min", a->grid.frequency_min_Hz, "lowest frequency (Hz)")->capture_default_str();
  c->add_option("--freq-max", a->grid.frequency_max_Hz, "highest frequency (Hz)")->capture_default_str();
  c->add_option("--freq-count", a->grid.frequency_count, "log-spaced frequencies")->capture_default_str();
  c->add_option("--plan-settle", a->grid.settle_s, "--sim: settling time per experiment (s)")->capture_default_str();
  c->add_option("--min-analysed", a->grid.min_analysed_s, "--sim: analysed seconds per experiment at least")->capture_default_str();
  c->add_option("--settle", a->settle_s, "--from: settling time when a recording has no '# settle_s:' header (s)")->capture_default_str();
  c->add_option("--min-periods", a->min_periods, "fewer whole periods after settling: flagged")->capture_default_str()->check(CLI::Range(2, 1000));
  c->add_option("--num-order", a->options.G.numerator_order, "numerator order of G")->capture_default_str();
  c->add_option("--den-order", a->options.G.denominator_order, "denominator order of G")->capture_default_str();
  c->add_option("--ref-amplitude", a->options.reference_amplitude_V, "reference regime amplitude for G (V)")->capture_default_str();
  c->add_option("--ref-bias", a->options.reference_bias_V, "reference regime bias for G (V)")->capture_default_str();
  c->add_option("--max-n", a->options.f.max_terms, "fit polynomials n = 1..N")->capture_default_str()->check(CLI::Range(1, 8));
  auto* nopt = c->add_option("--n", "use this n instead of the rule")->check(CLI::Range(1, 8));
  c->add_option("--tolerance", a->options.f.tolerance, "rule: residual within this fraction of the best")->capture_default_str();
  c->add_option("--voltage-max", a->options.f.voltage_max_V, "rule: f must be increasing on [0, this] V")->capture_default_str();
  c->add_option("--io-delay-samples", a->options.io_delay_samples, "the rig's I/O delay, removed before fitting G")->capture_default_str();
  c->add_option("--validation-freqs", a->validation_frequencies_Hz,
                "held-out experiments at these frequencies (Hz), at --validation-amplitude/--validation-bias")
      ->capture_default_str();
  c->add_option("--validation-amplitude", a->validation_amplitude_V, "held-out experiments' A (V)")->capture_default_str();
  c->add_option("--validation-bias", a->validation_bias_V, "held-out experiments' B (V)")->capture_default_str();
  c->add_flag("--quiet", a->quiet, "no progress lines");
  c->callback([a, nopt] {
    if (nopt->count()) a->options.f.forced_terms = nopt->as<int>();
    try {
      std::cout << run_ident(*a).summary << std::flush;
    } catch (const IdentRefused& refused) {
      std::cout << refused.summary << std::flush;  // the numbers that led to the refusal
      throw;
    }
  });
}

}  // namespace pvcgel::tools

#include "tools/diagnose_command.hpp"

#include <toml++/toml.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <mutex>
#include <sstream>

#include "control/config_error.hpp"
#include "control/config/config_parser.hpp"
#include "control/text_format.hpp"
#include "daemon/config_file.hpp"
#include "tools/gnuplot.hpp"
#include "tools/parallel_for.hpp"
#include "tools/recording.hpp"
#include "tools/text_output.hpp"

namespace pvcgel::tools {

namespace fs = std::filesystem;
using namespace control;
using namespace control::diagnosis;

namespace {

std::string quoted(const std::string& s) {
  std::string o = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') o += '\\', o += c;
    else if (c == '\n') o += "\\n";
    else if (static_cast<unsigned char>(c) < 0x20) o += ' ';
    else o += c;
  }
  return o + "\"";
}

/// A JSON array of strings: `["a", "b"]`.
std::string quoted_array(const std::vector<std::string>& names) {
  std::string o = "[";
  for (size_t i = 0; i < names.size(); ++i) o += (i ? ", " : "") + quoted(names[i]);
  return o + "]";
}

/// What a refit stopped at its tolerance means for the verdict, and what to do about it.
std::string at_bounds_note(const DiagnosisResult& r) {
  const std::string names = join(r.nominal_refit.at_bounds, ", ");
  const std::string which = r.mixture.empty() ? "the nuisance-only refit" : "the nominal refit fitted with the named effects";
  return which + " stops at its tolerance on " + names + ": the nominal model is further off than the refit may move it" +
         (r.mixture.empty() ? std::string() : ", so the named effects may stand in for part of that model error") +
         "; re-identify the nominal model (pvcgel ident) on recordings of this rig";
}

/// Why the widened run is the one reported when f's shape alone stopped at its bound (the gain stopping at
/// its own is reason enough): the data are `none` there, or its model predicts the held-out data better.
std::string widened_why(const DiagnosisResult& r) {
  const auto& from = r.nominal_refit.widened_from;
  if (std::find(from.begin(), from.end(), "gain") != from.end()) return "";
  if (r.verdict == "none") return ", where the data are none";
  return ", a second analysis beside the ordinary one, reported because its model predicts the held-out data better";
}

/// Why the refit ran with widened tolerances, and with which (DiagnosisOptions::widen_off_nominal).
std::string widened_note(const DiagnosisResult& r) {
  const DiagnosisOptions ordinary, wide = widened_tolerances(ordinary);
  const auto range = [](std::pair<double, double> b) { return format("%.3g", b.first) + ".." + format("%.3g", b.second); };
  return "the nuisance-only refit stopped at its ordinary tolerance on " + join(r.nominal_refit.widened_from, ", ") +
         " (gain within " + range(gain_bounds(ordinary)) + ", f's shape within " + range(poly_shape_bounds(ordinary)) +
         "): the nominal model's static curve is further off, so the analysis ran with the gain within " +
         range(gain_bounds(wide)) + ", f's shape within " + range(poly_shape_bounds(wide)) +
         " and its next term's slope share within +-" + format("%.2g", wide.poly_next_tolerance) + " (f kept increasing to " +
         format("%.3g", wide.f_increasing_margin) + "x the largest recorded voltage)" + widened_why(r) +
         "; re-identify the nominal model (pvcgel ident)";
}

/// Line of a key in the parsed file (0 when unknown).
long line_of(const toml::table& root, const std::string& table, const std::string& key) {
  if (const auto* t = root[table].as_table())
    if (const auto* n = t->get(key)) return static_cast<long>(n->source().begin.line);
  return 0;
}

std::string where(const std::string& path, long line) { return line > 0 ? path + ":" + std::to_string(line) : path; }

/// Every `step`-th sample, so plot files stay small.
size_t stride(size_t n) { return std::max<size_t>(1, n / 6000); }

std::string effect_params_json(const CandidateResult& c) {
  std::string s = "{";
  const Effect e = c.in_recorded_units();
  for (size_t i = 0; i < c.specs.size(); ++i) s += (i ? ", " : "") + quoted(c.specs[i].name) + ": " + number_or_null(e.p[i]);
  return s + "}";
}

/// The regime variable to plot the residual against for this verdict.
enum class RegimeAxis { voltage, displacement, time, voltage_rate };

RegimeAxis regime_axis(EffectKind k) {
  switch (k) {
    case EffectKind::drift: return RegimeAxis::time;
    case EffectKind::saturation:
    case EffectKind::bias_dependent_dynamics:
    case EffectKind::asymmetric_dynamics: return RegimeAxis::displacement;
    case EffectKind::delay:
    case EffectKind::slew_limit:
    case EffectKind::resonance: return RegimeAxis::voltage_rate;
    default: return RegimeAxis::voltage;
  }
}

/// rec<i>.dat per recording, what the plots read: t, y, y_baseline, y_fitted, residual_baseline,
/// residual_fitted, u, du/dt, direction, held out.
void write_plot_data(const fs::path& dir, const DiagnosisResult& r, const std::vector<Series>& data) {
  for (size_t i = 0; i < data.size(); ++i) {
    std::ostringstream d;
    d << "# t_s y_um y_baseline y_fitted res_baseline res_fitted u_V du_dt_V_per_s rising held_out\n";
    const auto& s = data[i];
    const size_t st = stride(s.t_s.size());
    for (size_t k = 0; k < s.t_s.size(); k += st) {
      const double du = k > 0 ? (s.u_V[k] - s.u_V[k - 1]) / s.sample_time_s : 0.0;
      const size_t kn = std::min(k + st, s.t_s.size() - 1);
      const int rising = s.u_V[kn] >= s.u_V[k] ? 1 : 0;
      d << s.t_s[k] << ' ' << s.y_um[k] << ' ' << r.y_baseline_um[i][k] << ' ' << r.y_fitted_um[i][k] << ' '
        << s.y_um[k] - r.y_baseline_um[i][k] << ' ' << s.y_um[k] - r.y_fitted_um[i][k] << ' ' << s.u_V[k] << ' ' << du
        << ' ' << rising << ' ' << static_cast<int>(r.held_out[i][k]) << '\n';
    }
    write_text_file(dir / ("rec" + std::to_string(i) + ".dat"), d.str());
  }
}

/// The gnuplot script of the report's plots, reading write_plot_data's files.
class ReportPlots {
 public:
  ReportPlots(const fs::path& dir, const DiagnosisResult& r, const std::vector<std::string>& names)
      : dir_(dir), r_(r), names_(names), rows_(std::to_string(names.size())) {
    gp_ << stacked_terminal() << "set grid\nset key outside right\n";
  }

  void measured_vs_simulated() {
    gp_ << "set output '" << (dir_ / "measured_vs_simulated.png").string() << "'\nset multiplot layout " << rows_
        << ",1 title 'Measured vs simulated from the recorded u (output error)'\nset xlabel 't (s)'\nset ylabel 'y (um)'\n";
    for (size_t i = 0; i < names_.size(); ++i)
      gp_ << title(i) << "plot " << dat(i)
          << " u 1:2 w l lc rgb '#999999' t 'measured', '' u 1:3 w l lc rgb '#1f77b4' t 'nominal model', '' u 1:4 w l lc rgb '#d62728' t 'augmented model'\n";
    gp_ << "unset multiplot\n";
  }

  /// Residual over time with the mismatch windows shaded.
  void residual() {
    gp_ << "set output '" << (dir_ / "residual.png").string() << "'\nset multiplot layout " << rows_
        << ",1 title 'Residual of the nominal model; shaded: located mismatch windows; dashed: +-2 sigma noise'\n"
        << "set ylabel 'y minus model (um)'\n";
    for (size_t i = 0; i < names_.size(); ++i) {
      int obj = 1;
      for (const auto& w : r_.mismatch)
        if (w.recording == static_cast<int>(i))
          gp_ << "set object " << obj++ << " rect from " << w.t_start_s << ", graph 0 to " << w.t_end_s
              << ", graph 1 fc rgb '#ffe0e0' fs solid 1.0 noborder behind\n";
      gp_ << title(i) << "plot " << dat(i) << " u 1:5 w l lc rgb '#1f77b4' t 'residual', " << 2 * r_.noise_sigma_um
          << " w l dt 2 lc rgb 'black' t '+2 sigma', " << -2 * r_.noise_sigma_um << " w l dt 2 lc rgb 'black' notitle\n";
      for (int o = 1; o < obj; ++o) gp_ << "unset object " << o << "\n";
    }
    gp_ << "unset multiplot\n";
  }

  /// Residual against the regime variable of the leading effect, split by the voltage's direction.
  void residual_vs_regime() {
    const auto axis = regime_axis(r_.chosen == EffectKind::none && !r_.candidates.empty() ? r_.candidates.front().effect.kind : r_.chosen);
    std::string col = "7", xlabel = "u (V)";
    if (axis == RegimeAxis::displacement) col = "3", xlabel = "simulated displacement (um)";
    if (axis == RegimeAxis::time) col = "1", xlabel = "t (s)";
    if (axis == RegimeAxis::voltage_rate) col = "8", xlabel = "du/dt (V/s)";
    gp_ << "set output '" << (dir_ / "residual_vs_regime.png").string() << "'\nset terminal pngcairo noenhanced size 1000,600\n"
        << "set title 'Nominal-model residual vs the regime variable, split by direction of the voltage'\nset xlabel '" << xlabel
        << "'\nset ylabel 'y minus model (um)'\nplot ";
    for (size_t i = 0; i < names_.size(); ++i)
      gp_ << (i ? ", " : "") << dat(i) << " u " << col << ":($9==1?$5:1/0) w p pt 7 ps 0.3 lc rgb '#d62728' t '" << (i ? "" : "u rising")
          << "', " << dat(i) << " u " << col << ":($9==0?$5:1/0) w p pt 7 ps 0.3 lc rgb '#1f77b4' t '" << (i ? "" : "u falling") << "'";
    gp_ << "\n";
  }

  /// Before / after on the held-out segments.
  void validation() {
    gp_ << "set output '" << (dir_ / "validation.png").string() << "'\n" << stacked_terminal() << "set multiplot layout " << rows_
        << ",1 title 'Held-out segment: residual of the nominal (before) and the augmented (after) model'\nset xlabel 't (s)'\n";
    for (size_t i = 0; i < names_.size(); ++i)
      gp_ << title(i) << "plot " << dat(i)
          << " u 1:($10==1?$5:1/0) w l lc rgb '#1f77b4' t 'before', '' u 1:($10==1?$6:1/0) w l lc rgb '#d62728' t 'after'\n";
    gp_ << "unset multiplot\n";
  }

  /// Each fitted candidate's held-out excess left (the verdict's yardstick, excess_share_left) as a bar, best
  /// at the top, the mixture's members in red, and the augmented model's when it holds two effects; the dashed
  /// line is the bar a verdict must reach. Reads candidates.dat (write_candidate_data).
  void candidates(size_t bars, double bar_share) {
    if (bars == 0) return;
    const std::string dat = "'" + (dir_ / "candidates.dat").string() + "'";
    gp_ << "set output '" << (dir_ / "candidates.png").string() << "'\nset terminal pngcairo noenhanced size 900,"
        << 120 + 36 * bars << " font ',10'\nset title 'Candidates: the held-out excess MSE each leaves'\n"
        << "unset key\nset xlabel 'share of the nuisance-only refit''s excess left (0: at the noise; dashed: the bar a "
        << "verdict must reach)'\nset ylabel ''\nset yrange [-0.7:" << static_cast<double>(bars) - 0.3 << "]\nset xrange [*:*]\nset xzeroaxis\n"
        << "set arrow 1 from " << bar_share << ", graph 0 to " << bar_share << ", graph 1 nohead dt 2 lc rgb 'black'\n"
        << "set style fill solid 0.8 noborder\nplot " << dat
        << " u ($3/2):1:($3/2):(0.35):($4==1?0xd62728:0x1f77b4):ytic(2) w boxxyerror lc rgb variable, " << dat
        << " u 3:1:(sprintf(' %.2f', $3)) w labels left\nunset arrow 1\n";
  }

  [[nodiscard]] std::string script() const { return gp_.str(); }

 private:
  /// The PNG terminal of the stacked plots: one 360-pixel row per recording.
  [[nodiscard]] std::string stacked_terminal() const {
    return "set terminal pngcairo noenhanced size 1200," + std::to_string(360 * names_.size()) + " font ',10'\n";
  }
  [[nodiscard]] std::string dat(size_t i) const { return "'" + (dir_ / ("rec" + std::to_string(i) + ".dat")).string() + "'"; }
  [[nodiscard]] std::string title(size_t i) const { return "set title '" + fs::path(names_[i]).filename().string() + "'\n"; }

  const fs::path& dir_;
  const DiagnosisResult& r_;
  const std::vector<std::string>& names_;
  const std::string rows_;
  std::ostringstream gp_;
};

/// report.md: the verdict, the errors before and after, where the model disagrees, the candidates.
std::string report_markdown(const DiagnosisResult& r, const std::vector<std::string>& names, const std::string& summary,
                            const std::string& model_path) {
  std::ostringstream md;
  md << "# pvcgel diagnose\n\n**Verdict: " << r.verdict << "**\n\n" << r.explanation << "\n\n";
  md << "| | RMSE all (um) | fit segment (um) | held-out (um) |\n|---|---|---|---|\n";
  md << "| nominal model | " << number_or_null(r.baseline.rmse_um, "%.4f") << " | " << number_or_null(r.baseline.rmse_fit_um, "%.4f") << " | "
     << number_or_null(r.baseline.rmse_validation_um, "%.4f") << " |\n";
  md << "| augmented model | " << number_or_null(r.fitted.rmse_um, "%.4f") << " | " << number_or_null(r.fitted.rmse_fit_um, "%.4f") << " | "
     << number_or_null(r.fitted.rmse_validation_um, "%.4f") << " |\n\nSensor noise estimated from the data: "
     << number_or_null(r.noise_sigma_um, "%.4f") << " um.\n\n";
  if (r.nominal_refit.widened()) md << "**Note:** " << widened_note(r) << ".\n\n";
  if (!r.nominal_refit.at_bounds.empty()) md << "**Note:** " << at_bounds_note(r) << ".\n\n";
  if (!model_path.empty()) md << "Augmented model (daemon-loadable): `" << model_path << "`\n\n";
  md << "## Where the model disagrees\n\n";
  if (r.mismatch.empty()) md << "No window exceeds the noise.\n\n";
  else {
    md << "| recording | from (s) | to (s) | RMS (um) | regime |\n|---|---|---|---|---|\n";
    for (const auto& w : r.mismatch)
      md << "| " << fs::path(names[static_cast<size_t>(w.recording)]).filename().string() << " | " << number_or_null(w.t_start_s, "%.2f")
         << " | " << number_or_null(w.t_end_s, "%.2f") << " | " << number_or_null(w.rms_um, "%.3f") << " | " << w.regime << " |\n";
    md << "\n";
  }
  md << "![measured vs simulated](measured_vs_simulated.png)\n\n![residual](residual.png)\n\n"
     << "![residual vs regime](residual_vs_regime.png)\n\n## Candidates (best first)\n\n"
     << "\"Excess left\" is the share of the nuisance-only refit's above-noise held-out MSE that the candidate still "
     << "leaves (0: to the noise); a verdict must leave at most " << DiagnosisOptions{}.explained_excess << ".\n\n"
     << "![candidates](candidates.png)\n\n";
  md << "| effect | parameters | evidence R2 | fit RMSE (um) | held-out RMSE (um) | excess left |\n|---|---|---|---|---|---|\n";
  for (const auto& c : r.candidates) {
    md << "| " << to_string(c.effect.kind) << " | " << parameters_text(c.in_recorded_units(), c.specs) << " | " << number_or_null(c.evidence_r2, "%.3f") << " | "
       << (c.fitted ? number_or_null(c.errors.rmse_fit_um, "%.4f") : "-") << " | " << (c.fitted ? number_or_null(c.errors.rmse_validation_um, "%.4f") : "-")
       << " | " << (c.fitted ? number_or_null(excess_share_left(r, c.errors), "%.3f") : "-") << " |\n";
  }
  md << "\n## Before and after on held-out data\n\n![validation](validation.png)\n\n```\n" << summary << "```\n";
  return md.str();
}

/// candidates.dat, what ReportPlots::candidates reads: row, name, excess share left (clipped to -0.5..1.5 so a
/// candidate far off does not squeeze the rest), 1 when it is in the mixture; the augmented model first when it
/// holds two effects, then the fitted candidates best first. Returns the number of rows.
size_t write_candidate_data(const fs::path& dir, const DiagnosisResult& r) {
  struct Bar {
    std::string name;
    double share;
    bool in_mixture;
  };
  std::vector<Bar> bars;
  if (r.mixture.size() > 1) bars.push_back({"augmented model (mixture)", excess_share_left(r, r.fitted), true});
  for (const auto& c : r.candidates) {
    const double share = c.fitted ? excess_share_left(r, c.errors) : NAN;
    if (!std::isfinite(share)) continue;
    const bool member = std::any_of(r.mixture.begin(), r.mixture.end(), [&](const Effect& e) { return e.kind == c.effect.kind; });
    bars.push_back({std::string(to_string(c.effect.kind)), share, member});
  }
  if (bars.empty() || !std::isfinite(bars.front().share)) return 0;
  std::ostringstream d;
  d << "# row name excess_share_left in_mixture\n";
  for (size_t i = 0; i < bars.size(); ++i)
    d << bars.size() - 1 - i << " \"" << bars[i].name << "\" " << std::clamp(bars[i].share, -0.5, 1.5) << ' '
      << (bars[i].in_mixture ? 1 : 0) << '\n';
  write_text_file(dir / "candidates.dat", d.str());
  return bars.size();
}

void write_report(const fs::path& dir, const DiagnosisResult& r, const std::vector<Series>& data,
                  const std::vector<std::string>& names, const std::string& summary, const std::string& model_path) {
  fs::create_directories(dir);
  write_plot_data(dir, r, data);
  ReportPlots plots(dir, r, names);
  plots.measured_vs_simulated();
  plots.residual();
  plots.residual_vs_regime();
  plots.validation();
  plots.candidates(write_candidate_data(dir, r), DiagnosisOptions{}.explained_excess);
  write_text_file(dir / "diagnose.gp", plots.script());
  run_gnuplot(dir / "diagnose.gp");
  write_text_file(dir / "report.md", report_markdown(r, names, summary, model_path));
}

}  // namespace

LoadedModel load_model(const std::string& path) {
  // A bad model file is a configuration error (exit 2), as in every subcommand.
  const toml::table root = daemon::read_config_file(path, "--model").root;
  LoadedModel m;
  try {
    m.model = control::parse_model(root, path);
  } catch (const control::ConfigError& e) {
    const auto dot = e.key().find('.');
    const std::string key = dot == std::string::npos ? "" : e.key().substr(dot + 1, e.key().find_first_of(".[", dot + 1) - dot - 1);
    throw control::ConfigError(where(path, line_of(root, "model", key)), e.what());
  }
  if (const auto* t = root["model"].as_table(); t && t->contains("io_delay_samples")) {
    const auto v = t->get("io_delay_samples")->value_exact<int64_t>();
    if (!v || *v < 0 || *v > 8)
      throw control::ConfigError(where(path, line_of(root, "model", "io_delay_samples")),
                                 "model.io_delay_samples: must be an integer 0..8");
    m.io_delay_samples = static_cast<int>(*v);
    m.io_delay_declared = true;
  }
  if (const auto v = root["controller"]["voltage_max_V"].value<double>()) m.voltage_max_V = *v;
  toml::table others;
  for (const auto& [k, v] : root)
    if (k.str() != "model" && k.str() != "sim") others.insert(k, v);
  if (!others.empty()) {
    std::ostringstream o;
    o << others;
    m.other_tables = o.str();
  }
  if (!m.model.G.is_stable())
    throw control::ConfigError(where(path, line_of(root, "model", "G_den")),
                               "model.G_den: G(s) = " + m.model.G.to_string() +
                                   " is unstable (a pole in the closed right half plane): an output-error "
                                   "simulation of it diverges");
  if (m.model.G.relative_degree() < 0)
    throw control::ConfigError(where(path, line_of(root, "model", "G_num")), "model.G_num: G(s) is improper");
  return m;
}

std::string augmented_model_path(const DiagnoseArgs& a) {
  if (!a.out.empty()) return a.out;
  if (!a.report.empty()) return (fs::path(a.report) / "augmented_model.toml").string();
  if (!a.predict.empty()) return a.predict + "augmented_model.toml";
  if (!a.json.empty()) return (fs::path(a.json).replace_extension("").string()) + ".augmented.toml";
  return "";
}

namespace {

/// `[[KEY]]` tables for the diagnosed effects, dominant first (the format of README "Effect tables").
std::string effect_tables_toml(const std::vector<Effect>& effects, const std::string& key) {
  std::ostringstream s;
  for (const auto& e : effects) {
    const auto specs = parameter_specs(e.kind, DataScale::unbounded(1e-3));
    s << "\n# " << physical_meaning(e.kind) << ".\n[[" << key << "]]\nname = " << quoted(std::string(to_string(e.kind))) << "\n";
    for (size_t i = 0; i < specs.size(); ++i) s << specs[i].name << " = " << number_or_null(e.p[i], "%.8g") << "\n";
  }
  return s.str();
}

}  // namespace

namespace {

/// The augmented model's opening comment: the diagnosis's own (`comment`), then what the tables below are
/// and how the refit that goes with the effects changed the file's nominal model.
std::string augmented_header(const LoadedModel& lm, const DiagnosisResult& r, const std::string& comment) {
  const auto& nr = r.nominal_refit;
  std::ostringstream s;
  std::istringstream in(comment);
  for (std::string line; std::getline(in, line);) s << "# " << line << "\n";
  s << "#\n# [model] is what the controller uses: the model file's nominal model with the refit the diagnosis made\n"
    << "# (overall gain x " << number_or_null(nr.gain, "%.4g") << ", G's time constants x " << number_or_null(nr.time_scale, "%.4g")
    << ", f's nonlinear coefficients x " << number_or_null(nr.poly_shape, "%.4g")
    << (nr.poly_next != 0.0 ? ", plus the next odd term (coefficient " + number_or_null(nr.poly_next, "%.4g") + ")" : std::string())
    << "; "
    << (r.mixture.empty() ? "the nuisance-only refit, no effect named" : "fitted jointly with the effects below") << ")\n"
    << "# and [[model.effect]], the diagnosed effects, dominant first: a controller in a mode that uses f^-1\n"
    << "# compensates them. The effects' parameters hold only together with this refit, so both go together.\n"
    << "# The nominal model as the file stated it: poly = " << toml_array(lm.model.f.coefficients())
    << ", G_num = " << toml_array(lm.model.G.num()) << ", G_den = " << toml_array(lm.model.G.den()) << ".\n"
    << "# [sim.truth] is the same model with the same effects ([[sim.truth.effect]]), so\n"
    << "#   pvcgeld --config THIS_FILE   (sim backend)\n"
    << "# simulates the rig the recordings came from; [sim] noise is the noise estimated from them.\n";
  if (!lm.io_delay_declared)
    s << "# io_delay_samples: not declared in the model file; estimated " << number_or_null(r.alignment.io_delay_samples, "%.3g")
      << " samples from the data (rounded here).\n";
  if (!lm.other_tables.empty()) s << "# The model file's other tables follow [model] unchanged.\n";
  return s.str();
}

/// A [controller] table for a model file without one: the loop, and so the sim backend, at the recordings'
/// period (io_delay_samples counts in it, and a mode above 0.4x the default 1 kHz, a 10 kHz piezo's, is out
/// of range at 1 kHz), its upper limit below a turnover of f (the default 1000 V may be past it).
std::string controller_table(const control::HammersteinModel& refit, double sample_time_s) {
  std::ostringstream s;
  s << "# The recordings' sample time: the sim backend runs at it.\n[controller]\nperiod_s = "
    << number_or_null(sample_time_s, "%.9g") << "\n";
  if (const auto turn = refit.f.first_turnover(1000.0))
    s << "# f turns over at " << number_or_null(*turn, "%.1f") << " V: the controller must stay below it.\nvoltage_max_V = "
      << number_or_null(std::floor(0.99 * *turn), "%.0f") << "\n";
  return s.str() + "\n";
}

/// [sim] (the estimated noise, the built-in effects off) and [sim.truth]: the refitted model, `model_keys`,
/// with the diagnosed effects.
std::string sim_tables(const DiagnosisResult& r, int io, const std::string& model_keys, const std::vector<Effect>& effects) {
  std::ostringstream s;
  s << "[sim]\nio_delay_samples = " << io << "\nnoise_sigma_um = " << number_or_null(r.noise_sigma_um, "%.4g")
    << "\nquantization_um = 0.0\n\n"
    << "# The rig's built-in Bouc-Wen hysteresis and creep are off: the diagnosed effects replace them.\n"
    << "[sim.hysteresis]\nenabled = false\n\n[sim.creep]\nenabled = false\n\n";
  s << "[sim.truth]\n" << model_keys;
  if (r.mixture.empty()) s << "\n# No effect added (verdict: " << r.verdict << ").\n";
  s << effect_tables_toml(effects, "sim.truth.effect");
  return s.str();
}

}  // namespace

std::string augmented_model_toml(const LoadedModel& lm, const DiagnosisResult& r, double sample_time_s,
                                 const std::string& comment) {
  const auto& nr = r.nominal_refit;
  const int io = lm.io_delay_declared ? lm.io_delay_samples : static_cast<int>(std::lround(r.alignment.used_samples));
  // The effects' parameters were fitted jointly with this refit: they describe the rig only together with it.
  auto refit = refit_model(lm.model, nr.time_scale, nr.poly_shape, nr.poly_next);
  std::vector<double> poly = refit.f.coefficients();
  for (double& c : poly) c *= nr.gain;
  refit.f = control::OddPolynomial(poly);
  // With the gain in f, the effects' parameters in um scale with it (those in V, s or shares do not).
  std::vector<Effect> effects;
  for (const auto& e : r.mixture) effects.push_back(with_displacement_scaled(e, nr.gain));
  const std::string model_keys = "poly = " + toml_array(poly) + "\nG_num = " + toml_array(refit.G.num()) +
                                 "\nG_den = " + toml_array(refit.G.den()) + "\n";
  std::ostringstream s;
  s << augmented_header(lm, r, comment) << "\n[model]\n" << model_keys << "io_delay_samples = " << io << "\n";
  if (r.mixture.empty()) s << "\n# No effect to compensate (verdict: " << r.verdict << ").\n";
  s << effect_tables_toml(effects, "model.effect") << "\n";
  if (!lm.other_tables.empty()) s << lm.other_tables << "\n\n";
  if (lm.other_tables.find("[controller]") == std::string::npos) s << controller_table(refit, sample_time_s);
  s << sim_tables(r, io, model_keys, effects);
  return s.str();
}

/// The best pair's test (SecondEffectTest), null when no pair was fitted.
std::string second_effect_test_json(const SecondEffectTest& t) {
  if (t.effects.size() != 2) return "null";
  std::ostringstream j;
  j << "{\"effects\": " << quoted_array(t.effects) << ", \"rmse_validation_um\": " << number_or_null(t.rmse_validation_um)
    << ", \"members\": [";
  for (size_t i = 0; i < 2; ++i) {
    const HeldOutTest& m = t.member[i];
    j << (i ? ", " : "") << "{\"name\": " << quoted(t.effects[i]) << ", \"heldout_mse_removed_um2\": " << number_or_null(m.mean_um2)
      << ", \"t\": " << number_or_null(m.t) << ", \"t_threshold\": " << number_or_null(m.threshold)
      << ", \"signed_rank_p\": " << number_or_null(m.signed_rank_p) << ", \"blocks\": " << m.blocks
      << ", \"significant\": " << (m.significant ? "true" : "false") << "}";
  }
  j << "], \"explains_excess\": " << (t.explained ? "true" : "false")
    << ", \"material\": " << (t.material ? "true" : "false")
    << ", \"named\": " << (t.named ? "true" : "false")
    << ", \"single_over_noise\": " << number_or_null(t.single_over_noise) << ", \"pairs_tried\": [";
  for (size_t i = 0; i < t.tried.size(); ++i) {
    const PairTried& p = t.tried[i];
    j << (i ? ", " : "") << "{\"effects\": " << quoted_array(p.effects)
      << ", \"rmse_fit_um\": " << number_or_null(p.rmse_fit_um)
      << ", \"rmse_validation_um\": " << number_or_null(p.rmse_validation_um)
      << ", \"score\": " << number_or_null(p.score) << "}";
  }
  j << "]}";
  return j.str();
}

/// The keys of issue 11: mixture, ambiguity, alignment, the nuisance refit and the none test.
std::string extension_json(const DiagnosisResult& r) {
  std::ostringstream j;
  j << "  \"mixture\": [";
  for (size_t i = 0; i < r.mixture.size(); ++i) {
    CandidateResult c;
    c.effect = r.mixture[i];
    c.gain = r.nominal_refit.gain;
    c.specs = parameter_specs(c.effect.kind, DataScale::unbounded(1e-3));
    j << (i ? ", " : "") << "{\"name\": " << quoted(std::string(to_string(c.effect.kind))) << ", \"params\": " << effect_params_json(c)
      << ", \"heldout_mse_removed_um2\": " << number_or_null(i < r.contribution.size() ? r.contribution[i] : NAN) << "}";
  }
  j << "],\n  \"ambiguous_with\": " << quoted_array(r.ambiguous_with) << ",\n";
  j << "  \"candidates_judged_on\": "
    << (r.candidates_judged_on.empty() ? std::string("null") : quoted(r.candidates_judged_on)) << ",\n";
  if (!r.ambiguous_with.empty()) j << "  \"separating_experiment\": " << quoted(r.separating_experiment) << ",\n";
  j << "  \"withheld_second_effect\": "
    << (r.withheld_second.empty() ? std::string("null")
                                  : "{\"name\": " + quoted(r.withheld_second) +
                                        ", \"refit_at_bounds\": " + quoted_array(r.withheld_at_bounds) + "}")
    << ",\n";
  j << "  \"second_effect_test\": " << second_effect_test_json(r.second_effect_test) << ",\n";
  const auto& a = r.alignment;
  j << "  \"alignment\": {\"io_delay_samples\": " << number_or_null(a.io_delay_samples, "%.3g") << ", \"declared\": "
    << (a.declared ? std::to_string(*a.declared) : "null") << ", \"used_samples\": " << number_or_null(a.used_samples, "%.3g")
    << ", \"offset_um\": " << number_or_null(a.offset_um.empty() ? NAN : a.offset_um.front()) << ", \"offset_per_recording_um\": [";
  for (size_t i = 0; i < a.offset_um.size(); ++i) j << (i ? ", " : "") << number_or_null(a.offset_um[i]);
  j << "], \"initial_V\": [";
  for (size_t i = 0; i < a.initial_V.size(); ++i) j << (i ? ", " : "") << number_or_null(a.initial_V[i]);
  j << "], \"declared_delay_excess_noise_variances\": " << number_or_null(a.declared_delay_excess_noise_variances, "%.3g")
    << ", \"note\": " << quoted(a.note) << "},\n";
  const auto& n = r.nominal_refit;
  j << "  \"baseline_aligned\": {\"rmse_um\": " << number_or_null(r.aligned.rmse_um) << ", \"rmse_fit_um\": " << number_or_null(r.aligned.rmse_fit_um)
    << ", \"rmse_validation_um\": " << number_or_null(r.aligned.rmse_validation_um) << "},\n";
  j << "  \"nominal_refit\": {\"gain\": " << number_or_null(n.gain) << ", \"time_scale\": " << number_or_null(n.time_scale)
    << ", \"poly_shape\": " << number_or_null(n.poly_shape) << ", \"poly_next\": " << number_or_null(n.poly_next)
    << ", \"poly_next_slope\": " << number_or_null(n.poly_next_slope)
    << ", \"rmse_um\": " << number_or_null(n.errors.rmse_um) << ", \"rmse_validation_um\": " << number_or_null(n.errors.rmse_validation_um)
    << ", \"at_bounds\": " << quoted_array(n.at_bounds) << ", \"widened\": " << (n.widened() ? "true" : "false")
    << ", \"widened_from\": " << quoted_array(n.widened_from) << "},\n";
  const auto& t = r.none_test;
  j << "  \"none_test\": {\"false_alarm_rate\": " << number_or_null(t.false_alarm_rate) << ", \"windows\": " << t.windows
    << ", \"worst_window_ratio\": " << number_or_null(t.worst_window_ratio) << ", \"window_threshold\": " << number_or_null(t.window_threshold)
    << ", \"ljung_box_q\": " << number_or_null(t.whiteness_q) << ", \"ljung_box_threshold\": " << number_or_null(t.whiteness_threshold)
    << ", \"level_ok\": " << (t.level_ok ? "true" : "false") << ", \"white\": " << (t.white ? "true" : "false")
    << ", \"longer_delay_pending\": " << (t.longer_delay_pending ? "true" : "false") << "}";
  return j.str();
}

/// A fitted loop's start per recording (", \"loop_start\": [\"virgin\", \"rising\", ...], \"loop_start_share\":
/// [0, 1, ...]": the share of the widest play the start sits along the branch, + rising, - falling), empty otherwise.
std::string loop_start_json(const CandidateResult& c) {
  if (c.loop_memory.empty()) return "";
  std::string names, shares;
  for (size_t r = 0; r < c.loop_memory.size(); ++r) {
    names += (r ? ", " : "") + quoted(std::string(loop_start_name(c.loop_memory[r])));
    shares += (r ? ", " : "") + number_or_null(c.loop_memory[r]);
  }
  return ", \"loop_start\": [" + names + "], \"loop_start_share\": [" + shares + "]";
}

/// A fitted slew limit's drive start per recording (", \"drive_start\": [\"at_rest\", \"at_start\", ...]": where
/// the actuator rests, or at the analysis's start), empty otherwise.
std::string drive_start_json(const CandidateResult& c) {
  if (c.drive_at_rest.empty()) return "";
  std::string names;
  for (size_t r = 0; r < c.drive_at_rest.size(); ++r) names += (r ? ", " : "") + quoted(c.drive_at_rest[r] ? "at_rest" : "at_start");
  return ", \"drive_start\": [" + names + "]";
}

/// How the held-out samples were chosen, one rule for all recordings or one per recording.
std::string validation_sentence(const DiagnosisResult& r) {
  const auto& rules = r.held_out_rule;
  if (std::all_of(rules.begin(), rules.end(), [&](const std::string& x) { return x == rules.front(); }))
    return "held out (never fitted), in each recording: " + (rules.empty() ? std::string() : rules.front());
  std::vector<std::string> parts;
  for (size_t i = 0; i < rules.size(); ++i) parts.push_back("recording " + std::to_string(i) + ": " + rules[i]);
  return "held out (never fitted): " + join(parts, "; ");
}

std::string diagnosis_json(const DiagnosisResult& r, const std::vector<std::string>& recordings,
                           const std::vector<long>& skipped, double cpu) {
  std::ostringstream j;
  j << "{\n  \"verdict\": " << quoted(r.verdict) << ",\n  \"explanation\": " << quoted(r.explanation)
    << ",\n  \"noise_sigma_um\": " << number_or_null(r.noise_sigma_um) << ",\n  \"effects\": [";
  bool first = true;
  for (const auto& c : r.candidates) {
    if (!c.fitted) continue;
    const double improvement = r.baseline.rmse_validation_um > 0 ? 1.0 - c.errors.rmse_validation_um / r.baseline.rmse_validation_um : 0.0;
    j << (first ? "\n" : ",\n") << "    {\"name\": " << quoted(std::string(to_string(c.effect.kind)))
      << ", \"params\": " << effect_params_json(c) << loop_start_json(c) << drive_start_json(c) << ", \"explanation\": " << quoted(c.explanation)
      << ", \"rmse_fit_um\": " << number_or_null(c.errors.rmse_fit_um) << ", \"rmse_validation_um\": " << number_or_null(c.errors.rmse_validation_um)
      << ", \"excess_share_left\": " << number_or_null(excess_share_left(r, c.errors)) << ", \"evidence\": {\"coarse_grid_r2\": " << number_or_null(c.evidence_r2) << ", \"validation_rmse_reduction\": " << number_or_null(improvement)
      << ", \"rmse_all_um\": " << number_or_null(c.errors.rmse_um) << ", \"penalised_score\": " << number_or_null(c.score)
      << ", \"parameters\": " << c.specs.size() << "}}";
    first = false;
  }
  j << "\n  ],\n  \"baseline\": {\"rmse_um\": " << number_or_null(r.baseline.rmse_um) << ", \"rmse_fit_um\": " << number_or_null(r.baseline.rmse_fit_um)
    << ", \"rmse_validation_um\": " << number_or_null(r.baseline.rmse_validation_um) << "},\n  \"fitted\": {\"rmse_um\": "
    << number_or_null(r.fitted.rmse_um) << ", \"rmse_fit_um\": " << number_or_null(r.fitted.rmse_fit_um)
    << ", \"rmse_validation_um\": " << number_or_null(r.fitted.rmse_validation_um) << "},\n  \"mismatch\": [";
  for (size_t i = 0; i < r.mismatch.size(); ++i) {
    const auto& w = r.mismatch[i];
    j << (i ? ",\n" : "\n") << "    {\"recording\": " << w.recording << ", \"t_start_s\": " << number_or_null(w.t_start_s)
      << ", \"t_end_s\": " << number_or_null(w.t_end_s) << ", \"regime\": " << quoted(w.regime) << ", \"rms_um\": " << number_or_null(w.rms_um) << "}";
  }
  j << "\n  ],\n" << extension_json(r) << ",\n  \"recordings\": [";
  for (size_t i = 0; i < recordings.size(); ++i)
    j << (i ? ", " : "") << "{\"path\": " << quoted(recordings[i]) << ", \"skipped_rows\": " << skipped[i]
      << ", \"held_out_samples\": " << std::count(r.held_out[i].begin(), r.held_out[i].end(), 1) << "}";
  j << "],\n  \"validation\": " << quoted(validation_sentence(r)) << ",\n  \"simulations\": " << r.simulations << ",\n  \"cpu_s\": " << number_or_null(cpu) << "\n}\n";
  return j.str();
}

namespace {

/// Progress on stderr, with the seconds since the diagnosis started: on a terminal one line per stage,
/// rewritten as its tasks end; otherwise (a log) a line when a stage ends.
std::function<void(std::string_view, std::size_t, std::size_t)> progress_printer() {
  const bool terminal = isatty(STDERR_FILENO) != 0;
  const auto start = std::chrono::steady_clock::now();
  auto lock = std::make_shared<std::mutex>();
  return [terminal, start, lock](std::string_view stage, std::size_t done, std::size_t total) {
    if (!terminal && done < total) return;
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const std::lock_guard hold(*lock);
    std::fprintf(stderr, "%sdiagnose: %.*s %zu/%zu (%.1f s)%s", terminal ? "\r\033[K" : "", static_cast<int>(stage.size()),
                 stage.data(), done, total, s, !terminal || done == total ? "\n" : "");
    std::fflush(stderr);
  };
}

}  // namespace

LoadedRecordings load_recordings(const DiagnoseArgs& a, const LoadedModel& lm) {
  LoadedRecordings out;
  for (const auto& path : a.recordings) {
    const Recording rec = read_recording(path);
    Series s;
    s.t_s = rec.col("t_s");
    s.u_V = rec.col("u_V");
    s.y_um = rec.col("y_um");
    s.sample_time_s = rec.sample_time_s;
    try {
      check_series(s, lm.model);
    } catch (const std::invalid_argument& e) {
      throw std::runtime_error(path + ": " + e.what());
    }
    out.data.push_back(std::move(s));
    out.skipped.push_back(rec.skipped_rows);
  }
  return out;
}

DiagnosisOptions diagnosis_options(const DiagnoseArgs& a, const LoadedModel& lm) {
  DiagnosisOptions opt;
  opt.io_delay_samples = lm.io_delay_samples;
  opt.io_delay_declared = lm.io_delay_declared;
  opt.f_increasing_up_to_V = lm.voltage_max_V;  // the augmented model's f must be increasing over the file's controller range
  if (const int threads = a.threads > 0 ? a.threads : threads_per_job(1); threads > 1)
    opt.run_tasks = [threads](std::size_t count, const std::function<void(std::size_t)>& task) {
      parallel_for(count, threads, task);
    };
  if (a.progress) opt.progress = progress_printer();
  return opt;
}

namespace {

/// The best pair's test in one line: each member's held-out contribution and test, and what it lacked.
std::string second_effect_test_line(const SecondEffectTest& t) {
  std::ostringstream s;
  s << "best pair: " << t.effects[0] << " + " << t.effects[1] << ", held-out " << number_or_null(t.rmse_validation_um, "%.4f") << " um;";
  for (size_t i = 0; i < 2; ++i) {
    const HeldOutTest& m = t.member[i];
    s << " " << t.effects[i] << " removes " << number_or_null(m.mean_um2, "%.3g") << " um^2 (t " << number_or_null(m.t, "%.2f")
      << " against " << number_or_null(m.threshold, "%.2f") << ", signed-rank p " << number_or_null(m.signed_rank_p, "%.2g") << ", "
      << m.blocks << " blocks: " << (m.significant ? "significant" : "not significant") << ");";
  }
  if (t.single_over_noise > 0.0) s << " the best single effect alone leaves " << format("%.3g", t.single_over_noise) << "x the noise;";
  return s.str() + (t.named ? " both named" : " not named (" + join(second_effect_shortfalls(t), ", ") + ")");
}

/// What the command prints: the verdict, alignment, nominal refit, errors, mismatch windows, candidates.
std::string summary_text(const DiagnosisResult& r, const DiagnoseArgs& a, const std::vector<long>& skipped, double cpu) {
  std::ostringstream s;
  s << "verdict: " << r.verdict << "\n" << r.explanation << "\n";
  s << "noise (estimated): " << number_or_null(r.noise_sigma_um, "%.4f") << " um\n";
  s << "alignment: I/O delay " << number_or_null(r.alignment.io_delay_samples, "%.3g") << " samples estimated, "
    << (r.alignment.declared ? std::to_string(*r.alignment.declared) + " declared" : std::string("none declared")) << ", "
    << number_or_null(r.alignment.used_samples, "%.3g") << " used; sensor offset " << number_or_null(r.alignment.offset_um.front(), "%.4g") << " um"
    << (r.alignment.note.empty() ? "" : "\n  NOTE: " + r.alignment.note) << "\n";
  s << "nominal refit (" << (r.mixture.empty() ? "nuisance only" : "with the named effects") << "): gain " << number_or_null(r.nominal_refit.gain, "%.4g") << ", G time scale "
    << number_or_null(r.nominal_refit.time_scale, "%.4g") << ", f shape " << number_or_null(r.nominal_refit.poly_shape, "%.4g") << ", f next-term slope share "
    << number_or_null(r.nominal_refit.poly_next_slope, "%.3g") << ", held-out (nuisance only) " << number_or_null(r.nominal_refit.errors.rmse_validation_um, "%.4f") << " um\n";
  if (r.nominal_refit.widened()) s << "  NOTE: " << widened_note(r) << "\n";
  if (!r.nominal_refit.at_bounds.empty()) s << "  NOTE: " << at_bounds_note(r) << "\n";
  if (r.mixture.size() > 1) s << "mixture: " << to_string(r.mixture[0].kind) << " (dominant) + " << to_string(r.mixture[1].kind) << "\n";
  if (!r.withheld_second.empty())
    s << "withheld second effect: " << r.withheld_second << " (significant, but the pair's nominal refit stops at its tolerance on "
      << join(r.withheld_at_bounds, ", ") << ")\n";
  if (const auto& t = r.second_effect_test; t.effects.size() == 2) s << second_effect_test_line(t) << "\n";
  if (!r.ambiguous_with.empty()) {
    s << "ambiguous with:";
    for (const auto& n : r.ambiguous_with) s << " " << n;
    s << "\n  " << r.separating_experiment << "\n";
  }
  s << "nominal model:   RMSE " << number_or_null(r.baseline.rmse_um, "%.4f") << " um, held-out " << number_or_null(r.baseline.rmse_validation_um, "%.4f") << " um\n";
  s << "augmented model: RMSE " << number_or_null(r.fitted.rmse_um, "%.4f") << " um, held-out " << number_or_null(r.fitted.rmse_validation_um, "%.4f") << " um\n";
  for (size_t i = 0; i < skipped.size(); ++i)
    if (skipped[i] > 0) s << a.recordings[i] << ": " << skipped[i] << " rows with non-finite t_s/u_V/y_um skipped\n";
  for (const auto& w : r.mismatch)
    s << "mismatch: recording " << w.recording << " t " << number_or_null(w.t_start_s, "%.2f") << ".." << number_or_null(w.t_end_s, "%.2f")
      << " s, RMS " << number_or_null(w.rms_um, "%.3f") << " um, " << w.regime << "\n";
  s << "candidates (best first):\n";
  for (const auto& c : r.candidates) {
    s << "  " << to_string(c.effect.kind) << ": evidence R2 " << number_or_null(c.evidence_r2, "%.3f");
    if (c.fitted) s << ", fit " << number_or_null(c.errors.rmse_fit_um, "%.4f") << " um, held-out " << number_or_null(c.errors.rmse_validation_um, "%.4f") << " um";
    s << "\n";
  }
  s << "cpu: " << number_or_null(cpu, "%.2f") << " s (" << r.simulations << " simulations)\n";
  return s.str();
}

/// PREFIX<i>.csv per recording: t, the nominal's and the augmented model's prediction.
void write_predictions(const std::string& prefix, const DiagnosisResult& r, const std::vector<Series>& data) {
  for (size_t i = 0; i < data.size(); ++i) {
    std::ostringstream p;
    p << "t_s,y_um_baseline,y_um_fitted\n";
    for (size_t k = 0; k < data[i].t_s.size(); ++k)
      p << number_or_null(data[i].t_s[k], "%.6f") << ',' << number_or_null(r.y_baseline_um[i][k], "%.6f") << ',' << number_or_null(r.y_fitted_um[i][k], "%.6f") << '\n';
    write_text_file(prefix + std::to_string(i) + ".csv", p.str());
  }
}

}  // namespace

DiagnoseOutcome run_diagnose(const DiagnoseArgs& a) {
  const double cpu0 = process_cpu_s();
  const LoadedModel lm = load_model(a.model);
  const auto [data, skipped] = load_recordings(a, lm);
  DiagnoseOutcome out;
  try {
    out.result = diagnose(lm.model, data, diagnosis_options(a, lm));
  } catch (const control::ConfigError& e) {
    const toml::table root = toml::parse_file(a.model);
    const std::string key = e.key() == "model.poly" ? "poly" : "G_den";
    throw std::runtime_error(where(a.model, line_of(root, "model", key)) + ": " + e.what());
  }
  const auto& r = out.result;
  const double cpu = process_cpu_s() - cpu0;
  out.summary = summary_text(r, a, skipped, cpu);
  if (!a.predict.empty()) write_predictions(a.predict, r, data);
  // The JSON and the report first: nothing after this can lose them.
  const std::string model_path = augmented_model_path(a);
  if (!a.json.empty()) write_text_file(a.json, diagnosis_json(r, a.recordings, skipped, cpu));
  if (!a.report.empty()) write_report(a.report, r, data, a.recordings, out.summary, model_path);
  if (!model_path.empty()) {
    // The slowest recording's period: the fitted effects' bounds (a mode below 0.4x its rate) hold at it.
    const double period_s = std::max_element(data.begin(), data.end(), [](const Series& x, const Series& y) {
                              return x.sample_time_s < y.sample_time_s;
                            })->sample_time_s;
    const std::string text = augmented_model_toml(lm, r, period_s, "pvcgel diagnose: augmented model\nverdict: " + r.verdict + "\n" + r.explanation);
    // The file must be what the sim backend accepts (a controller is not needed to diagnose).
    write_checked_toml(
        model_path, text, [](const toml::table& t, const std::string& p) { (void)control::parse_simulated_rig(t, p); },
        "the augmented model " + model_path + " was not written (the JSON and report were)");
    out.augmented_model_path = model_path;
  }
  return out;
}

void add_diagnose_command(CLI::App& app) {
  auto args = std::make_shared<DiagnoseArgs>();
  auto* cmd = app.add_subcommand(
      "diagnose",
      "Locate the sim-to-real mismatch in recordings, name the missing physics (hysteresis, creep, dead_zone, "
      "saturation, delay, asymmetric_dynamics, slew_limit, resonance, drift, bias_dependent_dynamics), fit it and "
      "show the improvement on held-out data (the last 3 s of every 10 s of each recording; 30% of each third of "
      "a recording shorter than 20 s, neither end held out; the last 30 of every 100 samples on a rig sampled "
      "below 10 Hz)");
  cmd->add_option("--model", args->model, "TOML file with the [model] table (or a full daemon config)")
      ->required()->check(CLI::ExistingFile);
  cmd->add_option("--json", args->json, "write the machine-readable report to FILE");
  cmd->add_option("--predict", args->predict, "write PREFIX<k>.csv (t_s,y_um_baseline,y_um_fitted) per recording");
  cmd->add_option("--report", args->report, "write report.md and PNG plots to DIR");
  cmd->add_option("--out", args->out,
                  "augmented model file (default: DIR/augmented_model.toml with --report, else "
                  "PREFIXaugmented_model.toml with --predict, else REPORT.augmented.toml next to --json)");
  cmd->add_flag("--quiet", args->quiet, "print nothing on success");
  cmd->add_option("--threads", args->threads, "threads the candidate fits run on (0: every core; the result is the same)")
      ->check(CLI::Range(0, 256));
  cmd->add_option("recordings", args->recordings, "recordings (daemon format: t_s,u_V,y_um, ...)")
      ->required()->check(CLI::ExistingFile);
  cmd->callback([args] {
    args->progress = !args->quiet;
    const auto out = run_diagnose(*args);
    if (!args->quiet) {
      std::cout << out.summary;
      if (!out.augmented_model_path.empty()) std::cout << "wrote " << out.augmented_model_path << "\n";
      if (!args->json.empty()) std::cout << "wrote " << args->json << "\n";
      if (!args->report.empty()) std::cout << "wrote " << (fs::path(args->report) / "report.md").string() << "\n";
    }
  });
}

}  // namespace pvcgel::tools

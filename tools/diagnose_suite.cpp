#include "tools/diagnose_suite.hpp"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <ostream>

#include "tools/ident_command.hpp"

namespace pvcgel::tools {

using namespace control::diagnosis;

namespace {

int label_index(const std::string& verdict) {
  if (verdict == "unexplained") return BlindSuiteResult::kLabels - 1;
  if (const auto k = parse_effect_kind(verdict)) return static_cast<int>(*k);
  return BlindSuiteResult::kLabels - 1;
}

std::string label_name(int i) {
  return i == BlindSuiteResult::kLabels - 1 ? "unexplained" : std::string(to_string(static_cast<EffectKind>(i)));
}

}  // namespace

BlindSuiteResult run_blind_suite(int cases, std::uint64_t seed, std::ostream& log, const GeneratorOptions& options,
                                 const std::string& save_dir) {
  namespace fs = std::filesystem;
  const auto model = control::paper_model(3);
  BlindSuiteResult r;
  std::ofstream labels;
  if (!save_dir.empty()) {
    fs::create_directories(save_dir);
    std::ofstream(fs::path(save_dir) / "model.toml") << model_toml(model, "the nominal model of the blind suite (paper n = 3)");
    labels.open(fs::path(save_dir) / "labels.csv");
    labels << "recording,effect,magnitude,effect_rms_um,effect_peak_um,closed_loop,input\n";
  }
  double ratio_sum = 0.0, time_sum = 0.0;
  int ratio_n = 0;
  for (const auto& [kind, case_seed] : blind_suite_plan(cases, seed)) {
    const GeneratedCase c = generate_case(model, kind, case_seed, options);
    if (labels.is_open()) {
      char name[32];
      std::snprintf(name, sizeof name, "case%02d.csv", r.cases + 1);
      control::identification::SineRecord rec;
      rec.sample_time_s = c.recordings[0].sample_time_s;
      rec.t_s = c.recordings[0].t_s;
      rec.u_V = c.recordings[0].u_V;
      rec.y_um = c.recordings[0].y_um;
      write_sine_recording(fs::path(save_dir) / name, rec, {{"source", "pvcgel bench diagnose (blind case; its label is in labels.csv)"}});
      labels << name << ',' << to_string(kind) << ',' << c.truth.magnitude << ',' << c.truth.effect_rms_um << ','
             << c.truth.effect_peak_um << ',' << c.truth.closed_loop << ",\"" << c.truth.input << "\"\n";
    }
    // The diagnosis sees the recordings and the model only.
    const auto t0 = std::chrono::steady_clock::now();
    const DiagnosisResult d = diagnose(model, c.recordings);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const int truth = static_cast<int>(c.truth.effect), verdict = label_index(d.verdict);
    ++r.confusion[static_cast<size_t>(truth)][static_cast<size_t>(verdict)];
    ++r.cases;
    const bool ok = truth == verdict;
    r.correct += ok;
    if (kind == EffectKind::none) {
      ++r.none_cases;
      r.false_alarms += !ok;
    }
    r.out_of_spec += !c.truth.within_spec;
    double ratio = NAN;
    if (ok && kind != EffectKind::none) {
      ratio = d.fitted.rmse_validation_um / d.baseline.rmse_validation_um;
      r.worst_ratio = std::max(r.worst_ratio, ratio);
      ratio_sum += ratio;
      ++ratio_n;
    }
    r.max_case_s = std::max(r.max_case_s, secs);
    time_sum += secs;
    char line[512];
    std::snprintf(line, sizeof line,
                  "%3d verdict %-24s truth %-24s %s  effect RMS %.3f um (peak %.2f um)%s  held-out RMSE %.4f -> %.4f um  "
                  "%.2f s  [%s%s]\n",
                  r.cases, d.verdict.c_str(), std::string(to_string(kind)).c_str(), ok ? "ok   " : "WRONG",
                  c.truth.effect_rms_um, c.truth.effect_peak_um, c.truth.within_spec ? "" : " (out of spec)",
                  d.baseline.rmse_validation_um, d.fitted.rmse_validation_um, secs, c.truth.closed_loop ? "closed loop: " : "",
                  c.truth.input.c_str());
    log << line << std::flush;
  }
  r.mean_ratio = ratio_n ? ratio_sum / ratio_n : NAN;
  r.mean_case_s = r.cases ? time_sum / r.cases : 0.0;
  return r;
}

std::string format_suite(const BlindSuiteResult& r) {
  std::string s = "confusion matrix (rows: truth, columns: verdict)\n";
  char b[256];
  std::snprintf(b, sizeof b, "%-24s", "");
  s += b;
  for (int j = 0; j < BlindSuiteResult::kLabels; ++j) {
    std::snprintf(b, sizeof b, " %4.4s", label_name(j).c_str());
    s += b;
  }
  s += "\n";
  for (int i = 0; i < BlindSuiteResult::kLabels - 1; ++i) {
    std::snprintf(b, sizeof b, "%-24s", label_name(i).c_str());
    s += b;
    for (int j = 0; j < BlindSuiteResult::kLabels; ++j) {
      std::snprintf(b, sizeof b, " %4d", r.confusion[static_cast<size_t>(i)][static_cast<size_t>(j)]);
      s += b;
    }
    s += "\n";
  }
  std::snprintf(b, sizeof b,
                "accuracy %d/%d = %.1f%% (target >= 90%%), false alarms on none %d/%d (target <= 1), cases out of "
                "concealment spec %d\n",
                r.correct, r.cases, 100.0 * r.accuracy(), r.false_alarms, r.none_cases, r.out_of_spec);
  s += b;
  std::snprintf(b, sizeof b,
                "held-out RMSE fitted/nominal on correct effect cases: mean %.3f, worst %.3f (target <= 0.50)\n",
                r.mean_ratio, r.worst_ratio);
  s += b;
  std::snprintf(b, sizeof b, "diagnosis time per case: mean %.2f s, max %.2f s (target <= 30 s)\n", r.mean_case_s, r.max_case_s);
  s += b;
  return s;
}

}  // namespace pvcgel::tools

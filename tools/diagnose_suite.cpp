#include "tools/diagnose_suite.hpp"
#include "control/text_format.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <ostream>

#include "tools/diagnose_command.hpp"
#include "tools/parallel_for.hpp"
#include "tools/ident_command.hpp"

namespace pvcgel::tools {

using namespace control;
using namespace control::diagnosis;

namespace {

int label_index(const std::string& verdict) {
  if (verdict == "unexplained") return BlindSuiteResult::kLabels - 1;
  if (const auto k = parse_effect_kind(verdict)) return static_cast<int>(*k);
  return BlindSuiteResult::kLabels - 1;
}

std::string label_name(int i) {
  return i == BlindSuiteResult::kLabels - 1 ? "unexplained" : std::string(kEffectKindNames.names()[static_cast<size_t>(i)]);
}

}  // namespace

namespace {

/// The case's first recording as caseNN.csv in `save_dir`, and its label line (kept apart from it).
void save_case(const std::filesystem::path& save_dir, std::ofstream& labels, int number, EffectKind kind,
               const GeneratedCase& c) {
  const std::string name = format("case%02d.csv", number);
  control::identification::SineRecord rec;
  rec.sample_time_s = c.recordings[0].sample_time_s;
  rec.t_s = c.recordings[0].t_s;
  rec.u_V = c.recordings[0].u_V;
  rec.y_um = c.recordings[0].y_um;
  write_sine_recording(save_dir / name, rec, {{"source", "pvcgel bench diagnose (blind case; its label is in labels.csv)"}});
  labels << name << ',' << to_string(kind) << ',' << c.truth.magnitude << ',' << c.truth.effect_rms_um << ','
         << c.truth.effect_peak_um << ',' << c.truth.closed_loop << ",\"" << c.truth.input << "\"\n";
}

/// One case's line of the suite's log.
std::string case_line(int number, const DiagnosisResult& d, EffectKind kind, const GeneratedCase& c, bool ok, double secs) {
  return format("%3d verdict %-24s truth %-24s %s  effect RMS %.3f um (peak %.2f um)%s  held-out RMSE %.4f -> %.4f um  "
                "%.2f s  [%s%s]\n",
                number, d.verdict.c_str(), std::string(to_string(kind)).c_str(), ok ? "ok   " : "WRONG",
                c.truth.effect_rms_um, c.truth.effect_peak_um, c.truth.within_spec ? "" : " (out of spec)",
                d.baseline.rmse_validation_um, d.fitted.rmse_validation_um, secs, c.truth.closed_loop ? "closed loop: " : "",
                c.truth.input.c_str());
}

/// Counts the case in `r`: confusion, accuracy, false alarms; returns whether it is right.
bool tally(BlindSuiteResult& r, EffectKind kind, const DiagnosisResult& d, const GeneratedCase& c) {
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
  return ok;
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
    if (labels.is_open()) save_case(save_dir, labels, r.cases + 1, kind, c);
    // The diagnosis sees the recordings and the model only.
    const auto t0 = std::chrono::steady_clock::now();
    const DiagnosisResult d = diagnose(model, c.recordings);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const bool ok = tally(r, kind, d, c);
    if (ok && kind != EffectKind::none) {
      const double ratio = d.fitted.rmse_validation_um / d.baseline.rmse_validation_um;
      r.worst_ratio = std::max(r.worst_ratio, ratio);
      ratio_sum += ratio;
      ++ratio_n;
    }
    r.max_case_s = std::max(r.max_case_s, secs);
    time_sum += secs;
    log << case_line(r.cases, d, kind, c, ok, secs) << std::flush;
  }
  r.mean_ratio = ratio_n ? ratio_sum / ratio_n : NAN;
  r.mean_case_s = r.cases ? time_sum / r.cases : 0.0;
  return r;
}

std::string format_suite(const BlindSuiteResult& r) {
  std::string s = "confusion matrix (rows: truth, columns: verdict)\n";
  s += format("%-24s", "");
  for (int j = 0; j < BlindSuiteResult::kLabels; ++j) s += format(" %4.4s", label_name(j).c_str());
  s += "\n";
  for (int i = 0; i < BlindSuiteResult::kLabels - 1; ++i) {
    s += format("%-24s", label_name(i).c_str());
    for (int j = 0; j < BlindSuiteResult::kLabels; ++j)
      s += format(" %4d", r.confusion[static_cast<size_t>(i)][static_cast<size_t>(j)]);
    s += "\n";
  }
  s += format("accuracy %d/%d = %.1f%% (target >= 90%%), false alarms on none %d/%d (target <= 1), cases out of "
              "concealment spec %d\n",
              r.correct, r.cases, 100.0 * r.accuracy(), r.false_alarms, r.none_cases, r.out_of_spec);
  s += format("held-out RMSE fitted/nominal on correct effect cases: mean %.3f, worst %.3f (target <= 0.50)\n",
              r.mean_ratio, r.worst_ratio);
  s += format("diagnosis time per case: mean %.2f s, max %.2f s (target <= 30 s)\n", r.mean_case_s, r.max_case_s);
  return s;
}

}  // namespace pvcgel::tools

namespace pvcgel::tools {

namespace {

/// Splits one CSV line (double-quoted fields may hold commas and "" escapes).
std::vector<std::string> csv_fields(const std::string& line) {
  std::vector<std::string> out(1);
  bool quoted = false;
  for (size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted && c == '"' && i + 1 < line.size() && line[i + 1] == '"') out.back() += '"', ++i;
    else if (c == '"') quoted = !quoted;
    else if (c == ',' && !quoted) out.emplace_back();
    else if (c != '\r') out.back() += c;
  }
  return out;
}

struct LabelledCase {
  std::string name, effects, dominant;
  std::string form;  ///< the labels' form column (the generator's form of the effect), empty without one
  /// The smallest ratio_after_gain_offset_refit over its effects (the labels' params column); NaN without one.
  double weakest_after_refit = NAN;
};

/// The smallest `ratio_after_gain_offset_refit` of the '+'-separated `effects` in the labels' JSON `params`
/// (NaN when an effect has none); `where` names the row for the error on a params field that is not JSON.
double weakest_after_refit(const std::string& params, const std::string& effects, const std::string& where) {
  const auto j = nlohmann::json::parse(params, nullptr, false);
  if (j.is_discarded()) throw std::runtime_error(where + ": the params column is not JSON");
  double weakest = INFINITY;
  for (size_t b = 0; b <= effects.size();) {
    const size_t e = std::min(effects.find('+', b), effects.size());
    const std::string name = effects.substr(b, e - b);
    const auto it = j.is_object() ? j.find(name) : j.end();
    if (it == j.end() || !it->is_object()) return NAN;
    const auto ratio = it->find("ratio_after_gain_offset_refit");
    if (ratio == it->end() || !ratio->is_number()) return NAN;
    weakest = std::min(weakest, ratio->get<double>());
    b = e + 1;
  }
  return weakest;
}

std::vector<LabelledCase> read_labels(const std::filesystem::path& file) {
  std::ifstream f(file);
  if (!f) throw std::runtime_error(file.string() + ": cannot read the labels");
  std::string line;
  std::getline(f, line);
  const auto header = csv_fields(line);
  const auto optional_column = [&](const std::string& name) -> std::optional<size_t> {
    const auto it = std::find(header.begin(), header.end(), name);
    return it == header.end() ? std::nullopt : std::optional(static_cast<size_t>(it - header.begin()));
  };
  const auto column = [&](const std::string& name) {
    if (const auto at = optional_column(name)) return *at;
    throw std::runtime_error(file.string() + ":1: no column '" + name + "'");
  };
  const size_t c_case = column("case"), c_effects = column("effects"), c_dominant = column("dominant");
  // The independent generator's columns, which other labels may lack.
  const auto params = optional_column("params"), form = optional_column("form");
  std::vector<LabelledCase> cases;
  for (long n = 2; std::getline(f, line); ++n) {
    if (line.empty()) continue;
    const auto v = csv_fields(line);
    if (v.size() < header.size())
      throw std::runtime_error(file.string() + ":" + std::to_string(n) + ": " + std::to_string(v.size()) + " fields, expected " +
                               std::to_string(header.size()));
    cases.push_back({v[c_case], v[c_effects], v[c_dominant], form ? v[*form] : ""});
    if (params && v[c_effects] != "none")
      cases.back().weakest_after_refit = weakest_after_refit(v[*params], v[c_effects],
                                                             file.string() + ":" + std::to_string(n));
  }
  return cases;
}

struct CaseOutcome {
  std::string verdict, mixture, error;
  std::string leaders;  ///< the three best fitted candidates and the share of the excess each leaves
  std::string at_bounds;  ///< the nominal refit's parameters at their tolerance (NominalRefit::at_bounds), comma-separated
  std::string withheld;   ///< DiagnosisResult::withheld_second
  std::string ambiguous;  ///< DiagnosisResult::ambiguous_with, '+'-separated
  SecondEffectTest pair;  ///< DiagnosisResult::second_effect_test: the best pair fitted and its test
  bool widened = false;   ///< NominalRefit::widened
  double ratio = NAN, ratio_aligned = NAN, seconds = 0.0;
  double nominal_held_out_over_noise = NAN;  ///< the nominal's held-out RMSE over the estimated noise
};

/// "creep 0.21 hysteresis 0.35 ...": the three best fitted candidates, each with the share of the nuisance
/// refit's excess MSE it leaves (excess_share_left: the verdict's yardstick).
std::string leaders_text(const DiagnosisResult& d) {
  std::string text;
  for (size_t i = 0; i < d.candidates.size() && i < 3 && d.candidates[i].fitted; ++i) {
    text += format("%s%s %.2f", text.empty() ? "" : " ", std::string(to_string(d.candidates[i].effect.kind)).c_str(),
                   excess_share_left(d, d.candidates[i].errors));
  }
  return text;
}

CaseOutcome run_case(const std::filesystem::path& dir, int threads) {
  namespace fs = std::filesystem;
  CaseOutcome o;
  DiagnoseArgs a;
  a.model = (dir / "model.toml").string();
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".csv") a.recordings.push_back(e.path().string());
  std::sort(a.recordings.begin(), a.recordings.end());
  a.quiet = true;
  a.threads = threads;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    const auto d = run_diagnose(a).result;
    o.verdict = d.verdict;
    for (const auto& e : d.mixture) o.mixture += (o.mixture.empty() ? "" : "+") + std::string(to_string(e.kind));
    o.ratio = d.fitted.rmse_validation_um / d.baseline.rmse_validation_um;
    o.ratio_aligned = d.fitted.rmse_validation_um / d.aligned.rmse_validation_um;
    o.nominal_held_out_over_noise = d.baseline.rmse_validation_um / d.noise_sigma_um;
    o.leaders = leaders_text(d);
    o.at_bounds = join(d.nominal_refit.at_bounds, ",");
    o.withheld = d.withheld_second;
    o.ambiguous = join(d.ambiguous_with, "+");
    o.pair = d.second_effect_test;
    o.widened = d.nominal_refit.widened();
  } catch (const std::exception& e) {
    o.verdict = "error";
    o.error = e.what();
  }
  o.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return o;
}

/// Whether the '+'-separated list `names` holds `name`.
bool lists(const std::string& names, const std::string& name) {
  return ("+" + names + "+").find("+" + name + "+") != std::string::npos;
}

bool names_both(const std::string& mixture, const std::string& effects) {
  const auto plus = effects.find('+');
  return plus != std::string::npos && lists(mixture, effects.substr(0, plus)) && lists(mixture, effects.substr(plus + 1));
}

/// The case's score: the verdict for a single effect or none, both effects named for a mixture.
bool scored_right(const LabelledCase& c, const CaseOutcome& o) {
  return c.effects.find('+') == std::string::npos ? o.verdict == c.effects : names_both(o.mixture, c.effects);
}

/// "; beside LEADER: a, b, c; beside R: a": the second effects fitted beside each first effect, the best pair's
/// first (the leader, and a runner-up in its place when the exchange step fitted one; none fitted: "").
std::string seconds_tried(const SecondEffectTest& t) {
  std::vector<std::pair<std::string, std::vector<std::string>>> beside;
  for (const PairTried& p : t.tried) {
    auto at = std::find_if(beside.begin(), beside.end(), [&](const auto& b) { return b.first == p.effects[0]; });
    if (at == beside.end()) at = beside.insert(beside.end(), {p.effects[0], {}});
    at->second.push_back(p.effects[1]);
  }
  std::string out;
  for (const auto& [first, seconds] : beside) out += "; beside " + first + ": " + join(seconds, ", ");
  return out;
}

/// One case's line: the truth, the verdict and mixture, the score, the held-out ratio, the time, the
/// leading candidates and the marks (widened, refit at bound, withheld second, ambiguous, error).
std::string case_line(const LabelledCase& c, const CaseOutcome& o) {
  const bool missed_mixture = c.effects.find('+') != std::string::npos && !scored_right(c, o);
  const std::string pair = !missed_mixture         ? ""
                           : o.pair.effects.empty() ? "  no pair fitted"
                                                    : "  best pair: " + join(o.pair.effects, "+") + " (" +
                                                          join(second_effect_shortfalls(o.pair), ", ") + ")" +
                                                          seconds_tried(o.pair);
  return format("%s truth %-34s verdict %-24s mixture %-34s %s held-out ratio %.3f  %.1f s  [%s]%s%s%s%s%s%s%s%s%s%s\n",
                c.name.c_str(), c.effects.c_str(), o.verdict.c_str(), o.mixture.empty() ? "-" : o.mixture.c_str(),
                scored_right(c, o) ? "ok   " : "WRONG", o.ratio, o.seconds, o.leaders.c_str(), o.widened ? "  widened" : "",
                o.at_bounds.empty() ? "" : "  refit at bound: ", o.at_bounds.c_str(),
                o.withheld.empty() ? "" : "  withheld second: ", o.withheld.c_str(),
                o.ambiguous.empty() ? "" : "  ambiguous with: ", o.ambiguous.c_str(), pair.c_str(),
                o.error.empty() ? "" : "  error: ", o.error.c_str());
}

/// Adds a correct effect case's held-out ratios.
void add_ratios(DirectorySuiteResult& r, const CaseOutcome& o) {
  r.ratios.push_back(o.ratio);
  r.ratios_aligned.push_back(o.ratio_aligned);
  if (o.nominal_held_out_over_noise >= DirectorySuiteResult::kHeldOutShowsEffect)
    r.ratios_held_out_shows_effect.push_back(o.ratio);
}

/// Adds a single-effect or none case to the confusion matrix and its scores.
void tally_single(DirectorySuiteResult& r, const LabelledCase& c, const CaseOutcome& o) {
  ++r.confusion[static_cast<size_t>(label_index(c.effects))][static_cast<size_t>(label_index(o.verdict))];
  if (c.effects == "none") {
    ++r.none_cases;
    r.false_alarms += o.verdict != "none";
    return;
  }
  ++r.single_cases;
  if (!c.form.empty()) {
    auto& by_form = r.single_by_form[c.effects + "/" + c.form];
    by_form[0] += o.verdict == c.effects;
    ++by_form[1];
  }
  if (!o.ambiguous.empty()) {
    ++r.single_ambiguous;
    r.single_ambiguous_right += o.verdict == c.effects;
    r.single_truth_among_ambiguous += o.verdict != c.effects && lists(o.ambiguous, c.effects);
  }
  if (o.verdict == c.effects) {
    ++r.single_correct;
    add_ratios(r, o);
  }
}

/// Adds a mixture without both effects named to the breakdown by its best pair.
void tally_missed_mixture(DirectorySuiteResult& r, const LabelledCase& c, const CaseOutcome& o) {
  if (o.pair.effects.empty() || o.verdict == "error") {
    ++r.mixture_missed_no_pair;
    return;
  }
  r.mixture_missed_single_at_noise += o.pair.single_at_the_noise();
  if (!names_both(join(o.pair.effects, "+"), c.effects)) {
    ++r.mixture_missed_other_pair;
    r.mixture_other_pair_labels_fitted += std::any_of(o.pair.tried.begin(), o.pair.tried.end(), [&](const PairTried& p) {
      return names_both(join(p.effects, "+"), c.effects);
    });
  } else {
    ++r.mixture_missed_labels_pair;
    // A member not significant counts by which it is: the labels' dominant or the other.
    const auto role = [&](size_t i) { return o.pair.effects[i] == c.dominant ? "the dominant" : "the other"; };
    for (const auto& why : second_effect_shortfalls(o.pair, {role(0), role(1)})) ++r.mixture_labels_pair_shortfalls[why];
  }
}

/// Adds one case to the scores.
void tally(DirectorySuiteResult& r, const LabelledCase& c, const CaseOutcome& o) {
  ++r.cases;
  r.failed += o.verdict == "error";
  r.max_case_s = std::max(r.max_case_s, o.seconds);
  r.refit_at_bound += !o.at_bounds.empty();
  r.widened += o.widened;
  r.widened_right += o.widened && scored_right(c, o);
  (o.at_bounds.empty() ? r.refit_inside_right : r.refit_at_bound_right) += scored_right(c, o);
  const bool single_label = c.effects.find('+') == std::string::npos;
  r.false_second += single_label && o.mixture.find('+') != std::string::npos;
  r.withheld += !o.withheld.empty();
  r.withheld_true += !o.withheld.empty() && lists(c.effects, o.withheld);
  if (c.weakest_after_refit >= DirectorySuiteResult::kVisibleAfterRefit) {
    ++(single_label ? r.visible_single_cases : r.visible_mixture_cases);
    (single_label ? r.visible_single_correct : r.visible_mixture_both_named) += scored_right(c, o);
  }
  if (single_label) return tally_single(r, c, o);
  ++r.mixture_cases;
  r.mixture_both_named += names_both(o.mixture, c.effects);
  if (!names_both(o.mixture, c.effects)) tally_missed_mixture(r, c, o);
  r.mixture_dominant_correct += o.verdict == c.dominant;
  if (o.verdict == c.dominant) add_ratios(r, o);
}

/// The `count` slowest of `out` diagnosed again one at a time on every core (run_directory_suite).
void retime_alone(DirectorySuiteResult& r, const std::string& dir, const std::vector<LabelledCase>& cases,
                  const std::vector<CaseOutcome>& out, int count, std::ostream& log) {
  std::vector<size_t> order(out.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return out[a].seconds > out[b].seconds; });
  order.resize(std::min(order.size(), static_cast<size_t>(count)));
  r.alone_threads = threads_per_job(1);
  for (size_t i : order) {
    const CaseOutcome again = run_case(std::filesystem::path(dir) / cases[i].name, r.alone_threads);
    const bool changed = again.verdict != out[i].verdict || again.mixture != out[i].mixture;
    r.alone_answer_changed += changed;
    r.alone_s.emplace_back(cases[i].name, again.seconds);
    log << format("%s again alone on %d threads: %.1f s (%.1f s beside the other jobs)%s\n", cases[i].name.c_str(),
                  r.alone_threads, again.seconds, out[i].seconds, changed ? ", ANOTHER ANSWER: " : "")
        << (changed ? again.verdict + " / " + again.mixture + "\n" : "") << std::flush;
  }
}

}  // namespace

DirectorySuiteResult run_directory_suite(const std::string& dir, int jobs, std::ostream& log, int limit,
                                         int retime_slowest) {
  namespace fs = std::filesystem;
  auto cases = read_labels(fs::path(dir) / "labels.csv");
  if (limit > 0 && static_cast<size_t>(limit) < cases.size()) cases.resize(static_cast<size_t>(limit));
  std::vector<CaseOutcome> out(cases.size());
  std::mutex log_mutex;
  const int threads = threads_per_job(jobs);  // each case's fits share the cores the other jobs leave
  parallel_for(cases.size(), jobs, [&](size_t i) {
    out[i] = run_case(fs::path(dir) / cases[i].name, threads);
    const std::string line = case_line(cases[i], out[i]);
    const std::lock_guard lock(log_mutex);
    log << line << std::flush;
  });
  DirectorySuiteResult r;
  double time_sum = 0.0;
  for (size_t i = 0; i < cases.size(); ++i) {
    tally(r, cases[i], out[i]);
    time_sum += out[i].seconds;
  }
  r.mean_case_s = r.cases ? time_sum / r.cases : 0.0;
  r.jobs = jobs;
  r.threads_per_case = threads;
  if (jobs > 1 && retime_slowest > 0) retime_alone(r, dir, cases, out, retime_slowest, log);
  return r;
}

namespace {

/// The held-out RMSE ratios of the correct effect cases (two lines), or that there are none.
std::string held_out_ratios(const DirectorySuiteResult& r) {
  if (r.ratios.empty()) return "held-out RMSE fitted/nominal on correct cases: no such cases\n";
  double mean = 0.0, worst = 0.0, worst_aligned = 0.0;
  for (double x : r.ratios) mean += x / static_cast<double>(r.ratios.size()), worst = std::max(worst, x);
  for (double x : r.ratios_aligned) worst_aligned = std::max(worst_aligned, x);
  std::vector<double> sorted = r.ratios;
  std::sort(sorted.begin(), sorted.end());
  const auto& shown = r.ratios_held_out_shows_effect;
  const std::string shown_worst =
      shown.empty() ? "no such cases"
                    : format("worst %.3f, %td above 0.50", *std::max_element(shown.begin(), shown.end()),
                             std::count_if(shown.begin(), shown.end(), [](double x) { return x > 0.5; }));
  return format("held-out RMSE fitted/nominal on correct cases: mean %.3f, median %.3f, worst %.3f (target <= 0.50: worst/target %.2f);\n"
                "  against the nominal with offset and start state fitted: worst %.3f;\n"
                "  on the %zu whose held-out data show the effect (nominal held-out RMSE >= %.1fx the noise): %s; "
                "the other %zu: the held-out blocks fall where the effect does not act\n",
                mean, sorted[sorted.size() / 2], worst, worst / 0.5, worst_aligned, shown.size(),
                DirectorySuiteResult::kHeldOutShowsEffect, shown_worst.c_str(), r.ratios.size() - shown.size());
}

/// "single effects by the labels' form, those with a miss, the weakest first (right/cases): hysteresis/bouc_wen
/// 1/6, ...; 12 other forms all right (40 cases)", or nothing when the labels have no form column.
std::string forms_missed(const DirectorySuiteResult& r) {
  if (r.single_by_form.empty()) return "";
  std::vector<std::pair<std::string, std::array<int, 2>>> missed;
  int all_right = 0, all_right_cases = 0;
  for (const auto& [form, n] : r.single_by_form) {
    if (n[0] < n[1]) missed.emplace_back(form, n);
    else ++all_right, all_right_cases += n[1];
  }
  std::stable_sort(missed.begin(), missed.end(), [](const auto& a, const auto& b) {
    return a.second[0] * b.second[1] < b.second[0] * a.second[1];  // a's share right below b's
  });
  std::string s = "single effects by the labels' form, those with a miss, the weakest first (right/cases):";
  for (size_t i = 0; i < missed.size(); ++i)
    s += format("%s %s %d/%d", i ? "," : "", missed[i].first.c_str(), missed[i].second[0], missed[i].second[1]);
  if (missed.empty()) s += " none";
  return s + format("; %d other forms all right (%d cases)\n", all_right, all_right_cases);
}

/// "mixtures without both named, by the best pair fitted: ..." (nothing when every mixture was named).
std::string mixtures_missed(const DirectorySuiteResult& r) {
  const int missed = r.mixture_missed_no_pair + r.mixture_missed_other_pair + r.mixture_missed_labels_pair;
  if (missed == 0) return "";
  std::string why;
  for (const auto& [reason, n] : r.mixture_labels_pair_shortfalls) why += format("%s%s %d", why.empty() ? "" : ", ", reason.c_str(), n);
  return format("mixtures without both named (%d), by the best pair fitted: another pair %d (the labels' pair fitted too in %d), "
                "none fitted %d, the labels' pair %d%s%s%s; "
                "the best single effect alone at the noise (held-out RMSE within %.0f%% of it) in %d\n",
                missed, r.mixture_missed_other_pair, r.mixture_other_pair_labels_fitted, r.mixture_missed_no_pair,
                r.mixture_missed_labels_pair,
                why.empty() ? "" : " (", why.c_str(), why.empty() ? "" : ")", 100.0 * (kSingleAtTheNoise - 1.0),
                r.mixture_missed_single_at_noise);
}

/// The slowest cases' times alone (DirectorySuiteResult::alone_s) in the suite's order, or nothing when not
/// re-timed.
std::string alone_times(const DirectorySuiteResult& r) {
  if (r.alone_s.empty()) return "";
  std::string each;
  double max_s = 0.0;
  for (const auto& [name, s] : r.alone_s) {
    each += format("%s%s %.1f s", each.empty() ? "" : ", ", name.c_str(), s);
    max_s = std::max(max_s, s);
  }
  return format("  the %zu slowest again, one at a time on %d threads as `pvcgel diagnose` runs alone: max %.2f s "
                "(target <= 30 s: ratio %.2f; %s); another answer in %d\n",
                r.alone_s.size(), r.alone_threads, max_s, max_s / 30.0, each.c_str(), r.alone_answer_changed);
}

}  // namespace

std::string format_directory_suite(const DirectorySuiteResult& r) {
  BlindSuiteResult matrix;
  matrix.confusion = r.confusion;
  std::string s = format_suite(matrix);
  s = s.substr(0, s.find("accuracy"));  // the matrix only; the scores follow with the issue 11 targets
  // A score over no cases (a suite of `none` recordings has no single effects) says so instead of nan%.
  const auto score = [](const char* what, int a, int n, const char* target, double ratio_to_target) {
    if (n == 0) return format("%s: no such cases", what);
    return format("%s %d/%d = %.1f%% (target %s: ratio %.2f)", what, a, n, 100.0 * a / n, target,
                  100.0 * a / n / ratio_to_target);
  };
  s += format("cases %d (single effects %d, none %d, mixtures %d; %d stopped with an error)\n%s\n%s\n%s; dominant named %d/%d\n%s"
              "time per case (%d at once, each on %d thread%s): mean %.2f s, max %.2f s (target <= 30 s: ratio %.2f)\n%s"
              "nominal refit at a tolerance (with the named effects, else nuisance-only): %d cases, %d of them right; the other %d: %d right\n"
              "single-effect or none cases naming a false second effect: %d; second effect withheld (pair refit at a tolerance): %d cases, %d of them in the labels\n"
              "refit widened (not none at the ordinary tolerances; the gain stopped at its own, or f's shape did and "
              "the widened refit was none): %d cases, %d of them right\n"
              "single effects answered as ambiguous: %d (the verdict right in %d; the truth among the other names in %d)\n",
              r.cases, r.single_cases, r.none_cases, r.mixture_cases, r.failed,
              score("single-effect accuracy", r.single_correct, r.single_cases, ">= 95%", 95.0).c_str(),
              score("false alarms on none", r.false_alarms, r.none_cases, "<= 2%", 2.0).c_str(),
              score("mixtures with both effects named", r.mixture_both_named, r.mixture_cases, ">= 80%", 80.0).c_str(),
              r.mixture_dominant_correct, r.mixture_cases, held_out_ratios(r).c_str(), r.jobs, r.threads_per_case,
              r.threads_per_case == 1 ? "" : "s", r.mean_case_s, r.max_case_s, r.max_case_s / 30.0, alone_times(r).c_str(), r.refit_at_bound, r.refit_at_bound_right, r.cases - r.refit_at_bound,
              r.refit_inside_right, r.false_second, r.withheld, r.withheld_true, r.widened, r.widened_right,
              r.single_ambiguous, r.single_ambiguous_right, r.single_truth_among_ambiguous);
  if (r.visible_single_cases + r.visible_mixture_cases > 0)
    s += format("effects leaving at least %.1fx the noise RMS after a gain and offset refit (the labels' "
                "ratio_after_gain_offset_refit): single effects %d/%d, mixtures with both named %d/%d\n",
                DirectorySuiteResult::kVisibleAfterRefit, r.visible_single_correct, r.visible_single_cases,
                r.visible_mixture_both_named, r.visible_mixture_cases);
  return s + mixtures_missed(r) + forms_missed(r);
}

}  // namespace pvcgel::tools

#include "tools/diagnose_command.hpp"

#include <gtest/gtest.h>
#include <toml++/toml.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <sstream>

#include "control/config/config_parser.hpp"
#include "control/config/effect_config.hpp"
#include "control/diagnosis/candidates.hpp"
#include "control/diagnosis/generator.hpp"
#include "control/simulated_rig.hpp"
#include "control/text_format.hpp"
#include "daemon/daemon_config.hpp"
#include "tools/diagnose_suite.hpp"
#include "tools/parallel_for.hpp"
#include "tools/recording.hpp"

namespace pvcgel::tools {
namespace {

namespace fs = std::filesystem;
using namespace control;
using namespace control::diagnosis;

fs::path temp_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("pvcgel_diagnose_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

void write(const fs::path& p, const std::string& s) { std::ofstream(p) << s; }

std::string read(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

/// A recording in the daemon's format (with extra columns the tool ignores).
void write_recording(const fs::path& p, const Series& s, long nan_rows_at_end = 0) {
  std::ofstream f(p);
  f << "# pvcgel-recording: 1\n# source: test\nt_s,u_V,y_um,r_um,mode\n";
  char line[160];
  for (size_t k = 0; k < s.t_s.size(); ++k) {
    std::snprintf(line, sizeof line, "%.4f,%.6f,%.5f,nan,open_loop\n", s.t_s[k], s.u_V[k], s.y_um[k]);
    f << line;
  }
  for (long i = 0; i < nan_rows_at_end; ++i)
    f << s.t_s.back() + static_cast<double>(i + 1) * s.sample_time_s << ",nan,nan,nan,open_loop\n";
}

const char* kModelN3 = "[model]\npoly = [0.0721, 2.1307e-5, -1.7231e-11]\nG_num = [1.15, 1.03]\nG_den = [1.0, 17.11, 8.76]\n";

/// Quiet arguments for dir's model.toml and rec.csv, the JSON to dir/report.json.
DiagnoseArgs args_in(const fs::path& dir) {
  DiagnoseArgs a;
  a.model = (dir / "model.toml").string();
  a.recordings = {(dir / "rec.csv").string()};
  a.json = (dir / "report.json").string();
  a.quiet = true;
  return a;
}

/// How far the sim rig the augmented model configures runs from the diagnosed model (`nominal` with the
/// refit and the effects), and how far that model runs from the diagnosis's fitted prediction after 10 s
/// (the diagnosis starts from the rest state the first samples imply: equal after its transient).
std::pair<double, double> augmented_model_gaps(const DiagnoseOutcome& o, const control::SimRigConfig& sim_cfg,
                                               const control::HammersteinModel& nominal, const Series& s) {
  auto sim = sim_cfg;
  sim.noise_sigma_um = sim.quantization_um = 0.0;
  control::SimulatedRig rig(sim);
  // The truth it writes is the model with the nuisance refit (gain, G's time scale) plus the effects.
  const auto& nr = o.result.nominal_refit;
  auto truth = refit_model(nominal, nr.time_scale, nr.poly_shape, nr.poly_next);
  auto poly = truth.f.coefficients();
  for (double& coefficient : poly) coefficient *= nr.gain;
  truth.f = control::OddPolynomial(poly);
  EXPECT_EQ(sim_cfg.io_delay_samples, std::lround(o.result.alignment.used_samples));
  AugmentedPlant plant(truth, sim_cfg.io_delay_samples, s.sample_time_s, sim_cfg.added_effects);
  const auto y_model = plant.simulate(s.u_V, s.u_V[0]);
  const double offset_um = o.result.alignment.offset_um[0];  // the fitted prediction carries the sensor offset
  rig.reset_steady_state(s.u_V[0]);
  double worst_rig = 0.0, worst_prediction = 0.0;
  for (size_t k = 0; k < s.u_V.size(); ++k) {
    worst_rig = std::max(worst_rig, std::abs(rig.true_displacement_um() - y_model[k]));
    if (s.t_s[k] > 10.0)
      worst_prediction = std::max(worst_prediction, std::abs(y_model[k] + offset_um - o.result.y_fitted_um[0][k]));
    rig.apply(s.u_V[k]);
  }
  return {worst_rig, worst_prediction};
}

TEST(DiagnoseCommand, EndToEndJsonPredictionAndAnAugmentedModelTheSimRigRuns) {
  const auto dir = temp_dir("e2e");
  const auto c = generate_case(control::paper_model(3), EffectKind::creep, 5);
  write_recording(dir / "rec.csv", c.recordings[0], 3);
  write(dir / "model.toml", kModelN3);
  auto a = args_in(dir);
  a.predict = (dir / "pred").string();
  a.progress = true;
  testing::internal::CaptureStderr();
  const auto o = run_diagnose(a);
  const std::string progress = testing::internal::GetCapturedStderr();
  EXPECT_EQ(o.result.verdict, "creep") << o.summary;
  // Not a terminal: a line as each stage ends, with its task count and the seconds since the start.
  EXPECT_NE(progress.find("diagnose: coarse grids 10/10 ("), std::string::npos) << progress;
  EXPECT_NE(progress.find("diagnose: candidate fits "), std::string::npos) << progress;
  EXPECT_EQ(progress.find('\r'), std::string::npos) << progress;
  EXPECT_NE(o.summary.find("3 rows with non-finite t_s/u_V/y_um skipped"), std::string::npos) << o.summary;

  const auto json = read(a.json);
  for (const char* key : {"\"verdict\": \"creep\"", "\"effects\": [", "\"params\": {\"fraction\": ", "\"baseline\": {\"rmse_um\": ",
                          "\"fitted\": {\"rmse_um\": ", "\"mismatch\": [", "\"rmse_validation_um\": ", "\"skipped_rows\": 3",
                          "\"validation\": \"held out (never fitted), in each recording: the last 3 s of every 10 s block\""})
    EXPECT_NE(json.find(key), std::string::npos) << key << "\n" << json;

  std::ifstream pf(a.predict + "0.csv");
  std::string header;
  std::getline(pf, header);
  EXPECT_EQ(header, "t_s,y_um_baseline,y_um_fitted");

  // The augmented model: [model] + [[model.effect]] for the controller, and a sim rig that reproduces the fitted prediction.
  ASSERT_EQ(o.augmented_model_path, (dir / "predaugmented_model.toml").string());
  const auto root = toml::parse_file(o.augmented_model_path);
  const auto sim_cfg = control::parse_simulated_rig(root, o.augmented_model_path);
  ASSERT_EQ(sim_cfg.added_effects.size(), 1u);
  ASSERT_EQ(sim_cfg.added_effects[0].kind, EffectKind::creep);
  for (size_t i = 0; i < 3; ++i)
    EXPECT_NEAR(sim_cfg.added_effects[0].p[i], o.result.effect.p[i], 1e-7 * std::abs(o.result.effect.p[i]));
  // The controller's [model] is the refitted model (the effects hold only with it), its effects the same as the sim's,
  // read by the one effect-table parser.
  const auto controller_model = control::parse_model(root, o.augmented_model_path);
  control::TableReader model_table(root["model"].as_table(), "model");
  const auto controller_effects = control::read_effect_tables(model_table, "effect", 1e-3);
  ASSERT_EQ(controller_effects.size(), 1u);
  EXPECT_EQ(controller_effects[0].kind, EffectKind::creep);
  EXPECT_EQ(controller_effects[0].p, sim_cfg.added_effects[0].p);
  EXPECT_EQ(controller_model.f.coefficients(), sim_cfg.truth.f.coefficients());
  EXPECT_EQ(controller_model.G.den(), sim_cfg.truth.G.den());
  EXPECT_EQ(model_table.integer("io_delay_samples", -1), sim_cfg.io_delay_samples);
  const auto [worst_rig, worst_prediction] = augmented_model_gaps(o, sim_cfg, control::paper_model(3), c.recordings[0]);
  EXPECT_LT(worst_rig, 1e-5) << "the sim rig must run the diagnosed model (parameters written with 8 digits)";
  EXPECT_LT(worst_prediction, 0.03);
}

TEST(DiagnoseCommand, TheAugmentedModelScalesAnEffectInMicrometresWithTheGainItFoldsIntoF) {
  // The model file's f is 1.15x the rig's: the refit's gain (~0.87) goes into the augmented model's f, so a
  // saturation's knee, fitted on the nominal's displacement before that gain, must shrink with it. Written
  // as fitted, the augmented model ran 0.21 um from the fitted prediction here.
  const auto dir = temp_dir("gain");
  const auto c = generate_case(control::paper_model(3), EffectKind::saturation, 5);
  write_recording(dir / "rec.csv", c.recordings[0]);
  auto nominal = control::paper_model(3);
  auto poly = nominal.f.coefficients();
  for (double& coefficient : poly) coefficient *= 1.15;
  nominal.f = control::OddPolynomial(poly);
  write(dir / "model.toml", "[model]\npoly = " + format("[%.9g, %.9g, %.9g]", poly[0], poly[1], poly[2]) +
                                "\nG_num = [1.15, 1.03]\nG_den = [1.0, 17.11, 8.76]\n");
  const auto o = run_diagnose(args_in(dir));
  ASSERT_EQ(o.result.verdict, "saturation") << o.summary;
  const double gain = o.result.nominal_refit.gain;
  ASSERT_NEAR(gain, 1.0 / 1.15, 0.05);
  const auto sim_cfg = control::parse_simulated_rig(toml::parse_file(o.augmented_model_path), o.augmented_model_path);
  ASSERT_EQ(sim_cfg.added_effects.size(), 1u);
  const auto& written = sim_cfg.added_effects[0];
  EXPECT_NEAR(written.p[0], gain * o.result.effect.p[0], 1e-6 * written.p[0]);  // knee_um
  EXPECT_NEAR(written.p[1], gain * o.result.effect.p[1], 1e-6 * written.p[1]);  // softness_um
  EXPECT_EQ(written.p[2], o.result.effect.p[2]);                                  // on_drive: no unit
  const auto [worst_rig, worst_prediction] = augmented_model_gaps(o, sim_cfg, nominal, c.recordings[0]);
  EXPECT_LT(worst_rig, 1e-5);
  EXPECT_LT(worst_prediction, 0.03);
  // The report gives the parameters as the augmented model does: in the recordings' micrometres.
  const auto json = read(dir / "report.json");
  EXPECT_NE(json.find("\"knee_um\": " + format("%.6g", written.p[0])), std::string::npos) << json.substr(0, 2000);
}

TEST(DiagnoseCommand, ReportHasMarkdownAndPlots) {
  if (std::system("command -v gnuplot >/dev/null 2>&1") != 0) GTEST_SKIP() << "gnuplot not installed";
  const auto dir = temp_dir("report");
  const auto c = generate_case(control::paper_model(3), EffectKind::drift, 3);
  write_recording(dir / "rec.csv", c.recordings[0]);
  write(dir / "model.toml", kModelN3);
  DiagnoseArgs a;
  a.model = (dir / "model.toml").string();
  a.recordings = {(dir / "rec.csv").string()};
  a.report = (dir / "report").string();
  a.json = (dir / "report.json").string();
  a.quiet = true;
  const auto o = run_diagnose(a);
  for (const char* f : {"report.md", "measured_vs_simulated.png", "residual.png", "residual_vs_regime.png", "validation.png",
                        "candidates.png", "augmented_model.toml"})
    EXPECT_TRUE(fs::exists(dir / "report" / f)) << f;
  const auto md = read(dir / "report" / "report.md");
  EXPECT_NE(md.find("**Verdict: " + o.result.verdict + "**"), std::string::npos);
  // The candidates' yardstick, shown as the verdict judged it: the leader (drift, named) leaves at most the bar.
  ASSERT_EQ(o.result.verdict, "drift") << o.summary;
  const auto& leader = o.result.candidates.front();
  const double left = excess_share_left(o.result, leader.errors);
  EXPECT_LE(left, DiagnosisOptions{}.explained_excess);
  EXPECT_NE(md.find(" | " + format("%.3f", left) + " |\n"), std::string::npos) << md;
  EXPECT_NE(md.find("![candidates](candidates.png)"), std::string::npos);
  EXPECT_NE(read(dir / "report.json").find("\"excess_share_left\": " + format("%.6g", left)), std::string::npos);
  // One bar per fitted candidate, the leader's (in the mixture) marked.
  const auto bars = read(dir / "report" / "candidates.dat");
  EXPECT_NE(bars.find("\"drift\" " + format("%g", left) + " 1"), std::string::npos) << bars;
}

std::string error_of(const std::string& model_text, const std::string& recording_text) {
  const auto dir = temp_dir("bad");
  write(dir / "model.toml", model_text);
  write(dir / "rec.csv", recording_text);
  DiagnoseArgs a;
  a.model = (dir / "model.toml").string();
  a.recordings = {(dir / "rec.csv").string()};
  a.quiet = true;
  try {
    (void)run_diagnose(a);
  } catch (const std::exception& e) {
    std::string m = e.what();
    // Paths differ per run: report them relative to the directory.
    for (std::string p = dir.string() + "/"; m.find(p) != std::string::npos;) m.erase(m.find(p), p.size());
    return m;
  }
  return "no error";
}

std::string uniform_recording(size_t n, double Ts = 1e-3) {
  std::string s = "t_s,u_V,y_um\n";
  for (size_t k = 0; k < n; ++k) s += std::to_string(static_cast<double>(k) * Ts) + ",100,8.5\n";
  return s;
}

TEST(DiagnoseCommand, BadInputNamesFileLineAndReason) {
  EXPECT_EQ(error_of(kModelN3, "t_s,u_V\n0,1\n0.001,1\n"), "rec.csv:1: header lacks column 'y_um' (need at least t_s,u_V,y_um)");
  EXPECT_EQ(error_of(kModelN3, "t_s,u_V,y_um\n0,1,1\n0.001,1,1\n0.003,1,1\n0.004,1,1\n"),
            "rec.csv:3: non-uniform or non-monotone time (step 0.001000 s, expected 0.001333 s)");
  EXPECT_EQ(error_of(kModelN3, "t_s,u_V,y_um\n0,1,1\n0.001,1,1\n0.0005,1,1\n"), "rec.csv:3: non-uniform or non-monotone time (step 0.001000 s, expected 0.000250 s)");
  EXPECT_EQ(error_of(kModelN3, uniform_recording(1000)),
            "rec.csv: recording lasts 0.999 s, shorter than one time constant of G's slowest pole (1.89 s): the start "
            "state cannot be told from the response");
  // A NaN row inside a recording breaks the uniform time base once skipped.
  std::string nan_inside = "t_s,u_V,y_um\n0,1,1\n0.001,nan,1\n0.002,1,1\n0.003,1,1\n";
  EXPECT_EQ(error_of(kModelN3, nan_inside),
            "rec.csv:4: non-uniform or non-monotone time (step 0.002000 s, expected 0.001500 s) after skipping 1 invalid rows");
  EXPECT_EQ(error_of("[model]\npoly = [0.1]\nG_num = [1.0]\nG_den = [1.0, -2.0]\n", uniform_recording(10000)),
            "model.toml:4: model.G_den: G(s) = (1) / (s - 2) is unstable (a pole in the closed right half plane): an "
            "output-error simulation of it diverges");
  EXPECT_EQ(error_of("[model]\npoly = [0.1, -0.001]\nG_num = [1.0]\nG_den = [1.0, 2.0]\n", uniform_recording(10000)),
            "model.toml:2: model.poly: f is not monotone: f'(x) reaches 0 at x = 5.774 V, inside the recorded voltage range "
            "(|u| up to 100 V)");
  EXPECT_EQ(error_of("[model]\npoly = [0.1]\nG_num = [1.0]\n", uniform_recording(10000)),
            "model.toml: model.G_den: is required (in model.toml)");
}

TEST(DiagnoseCommand, APiezoLikeModelWithoutATunableControllerIsDiagnosedAndItsTablesKept) {
  // Issue 11's crash: a static gain with a fast first-order G (no PID reaches the default phase
  // margin), the user's [controller] table present, bipolar drive. Diagnosing needs no controller.
  const auto dir = temp_dir("piezo");
  const std::string model =
      "[model]\npoly = [0.05]\nG_num = [2000.0]\nG_den = [1.0, 2000.0]\n\n[controller]\nmode = \"pid\"\nperiod_s = 0.001\n";
  write(dir / "model.toml", model);
  Series s;
  s.sample_time_s = 1e-3;
  control::HammersteinModel truth{control::OddPolynomial({0.05}), control::TransferFunction({2000.0}, {1.0, 2000.0})};
  AugmentedPlant plant(truth, 1.0, s.sample_time_s, Effect{EffectKind::hysteresis, {0.15, 60.0}});
  for (int k = 0; k < 20000; ++k) {
    s.t_s.push_back(k * 1e-3);
    s.u_V.push_back(150.0 * std::sin(2.0 * M_PI * 1.0 * k * 1e-3) + 40.0 * std::sin(2.0 * M_PI * 3.3 * k * 1e-3));
  }
  s.y_um = plant.simulate(s.u_V, 0.0);
  std::mt19937_64 rng(4);
  std::normal_distribution<double> noise(0.0, 0.02);
  for (double& y : s.y_um) y += noise(rng);
  write_recording(dir / "rec.csv", s);
  const auto a = args_in(dir);
  const auto o = run_diagnose(a);
  EXPECT_EQ(o.result.verdict, "hysteresis") << o.summary;
  const auto json = read(a.json);
  for (const char* key : {"\"mixture\": [{\"name\": \"hysteresis\"", "\"ambiguous_with\": [", "\"alignment\": {\"io_delay_samples\": ",
                          "\"declared\": null", "\"offset_um\": ", "\"at_bounds\": [", "\"widened\": false",
                          "\"widened_from\": []", "\"withheld_second_effect\": ", "\"candidates_judged_on\": \"held_out\"",
                          "\"second_effect_test\": ", "\"declared_delay_excess_noise_variances\": 0,",
                          "\"longer_delay_pending\": false"})
    EXPECT_NE(json.find(key), std::string::npos) << key << "\n" << json;
  // The augmented model keeps the user's [controller] table and the sim backend accepts it.
  const auto text = read(o.augmented_model_path);
  EXPECT_NE(text.find("mode = 'pid'"), std::string::npos) << text;
  EXPECT_NO_THROW((void)control::parse_simulated_rig(toml::parse_file(o.augmented_model_path), o.augmented_model_path));
}

/// `pvcgel diagnose` on a committed case: tests/data/CASE/MODEL and its recordings FILES, quietly, the
/// augmented model in a temporary directory.
DiagnoseOutcome diagnose_data(const std::string& name, const std::string& model, const std::vector<std::string>& files) {
  const std::string dir = std::string(PVCGEL_SOURCE_DIR) + "/tests/data/" + name + "/";
  DiagnoseArgs a;
  a.model = dir + model;
  for (const auto& f : files) a.recordings.push_back(dir + f);
  std::string tmp = name;
  std::replace(tmp.begin(), tmp.end(), '/', '_');
  a.out = (temp_dir(tmp) / "augmented.toml").string();
  a.quiet = true;
  return run_diagnose(a);
}

/// Whether the verdict is `kind` and the augmented model's mixture is led by it (the summary on failure).
::testing::AssertionResult led_by(const DiagnoseOutcome& o, EffectKind kind) {
  const auto& r = o.result;
  if (r.verdict == to_string(kind) && !r.mixture.empty() && r.mixture[0].kind == kind) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "expected " << to_string(kind) << " to lead\n" << o.summary;
}

/// `pvcgel diagnose` on the committed real recordings tests/data/real/NAME/FILES against that directory's
/// best linear model (linear_model.toml).
DiagnoseOutcome diagnose_real_recordings(const std::string& name, const std::vector<std::string>& files) {
  return diagnose_data("real/" + name, "linear_model.toml", files);
}

/// A model file and its recordings loaded as `pvcgel diagnose` loads them, with its options, for
/// control::diagnosis::diagnose directly (options the command line does not expose).
struct LibraryCase {
  LoadedModel model;
  std::vector<control::diagnosis::Series> series;
  control::diagnosis::DiagnosisOptions options;
};

LibraryCase load_library_case(const std::string& model_path, const std::string& csv_path) {
  DiagnoseArgs a;
  a.model = model_path;
  a.recordings = {csv_path};
  LibraryCase c{load_model(model_path), {}, {}};
  c.series = load_recordings(a, c.model).data;
  c.options = diagnosis_options(a, c.model);
  return c;
}

TEST(DiagnoseRealRecordings, PiezoSmartHysteresisIsHysteresisAtUnderHalfTheLinearModelsError) {
  // A real piezo stack (tests/data/real/piezo_smarthysteresis, SOURCE.md: +-150 V, 1 Hz; the source documents
  // hysteresis) against its best linear model (fit_linear.py). Before the sine it rests 3 s at 0 V below the
  // loop's centre: remanence, which a loop explains and a lag cannot, so the verdict is not a forced pick.
  const auto o = diagnose_real_recordings("piezo_smarthysteresis", {"piezo_smarthysteresis.csv"});
  const auto& r = o.result;
  ASSERT_TRUE(led_by(o, EffectKind::hysteresis));
  EXPECT_TRUE(r.ambiguous_with.empty()) << o.summary;
  // The issue's target: held-out RMSE at most half the best linear model's (measured 0.30 against 0.94 um, the
  // recording held out in three stretches; 0.11 against 0.79 um at ce70c0d with its last 30% held out).
  EXPECT_LE(r.fitted.rmse_validation_um, 0.5 * r.aligned.rmse_validation_um) << o.summary;
  EXPECT_LE(r.fitted.rmse_validation_um, 0.5 * r.nominal_refit.errors.rmse_validation_um) << o.summary;
  // The diagnosed loop is one the controller can invert exactly (alpha below the compensator's limit).
  EXPECT_LT(r.mixture.front().p[0], kMaxCompensatedHysteresisAlpha);
}

TEST(DiagnoseRealRecordings, PiezoSmartHysteresisIsNotAmbiguousWithADriftStartedByThePairFits) {
  // With forward_pairs, the pair fits hand the drift a start from which, refitted alone, it steps after the
  // sine's onset. With the recording's last 30% held out (until 2026-11-27) that drift came within the
  // ambiguity margin of the loop on held-out data (0.232 against 0.203 um) and only the fitting segment, where
  // it left almost three times the loop's excess, kept it from being named as an equal explanation
  // (`ambiguity_fit_gain`). Held out in three stretches, neither end, it is clearly worse on both segments.
  const std::string dir = std::string(PVCGEL_SOURCE_DIR) + "/tests/data/real/piezo_smarthysteresis/";
  auto rig = load_library_case(dir + "linear_model.toml", dir + "piezo_smarthysteresis.csv");
  rig.options.forward_pairs = true;
  const auto r = control::diagnosis::diagnose(rig.model.model, rig.series, rig.options);
  ASSERT_EQ(r.verdict, "hysteresis") << r.explanation;
  const auto drift = std::find_if(r.candidates.begin(), r.candidates.end(),
                                  [](const auto& c) { return c.effect.kind == EffectKind::drift; });
  ASSERT_NE(drift, r.candidates.end());
  const double s2 = r.noise_sigma_um * r.noise_sigma_um, held_out_base = std::pow(r.nominal_refit.errors.rmse_validation_um, 2) - s2;
  EXPECT_GT(std::pow(drift->errors.rmse_validation_um, 2) - std::pow(r.candidates.front().errors.rmse_validation_um, 2),
            control::diagnosis::DiagnosisOptions{}.ambiguity_margin * held_out_base);
  EXPECT_GT(drift->errors.rmse_fit_um, 1.5 * r.candidates.front().errors.rmse_fit_um);
  EXPECT_TRUE(r.ambiguous_with.empty()) << r.explanation;
}

TEST(DiagnoseRealRecordings, PiezoP885IsHysteresisAtUnderHalfTheLinearModelsError) {
  // A second real piezo (tests/data/real/piezo_p885_dbo, SOURCE.md: PICMA P-885.91 at 0..3.6 V, 200 Hz, three
  // amplitude programmes; the source documents hysteresis) against its best linear model (fit_linear.py).
  // The nominal alone fits best half a sample late; with the loop the data take no delay, as an off-line fit
  // with free G found (measured 0.258 um held-out against 0.568 um, 0.45x, at this commit's parent).
  const auto o = diagnose_real_recordings("piezo_p885_dbo", {"piezo_p885_dbo_a.csv", "piezo_p885_dbo_b.csv", "piezo_p885_dbo_c.csv"});
  const auto& r = o.result;
  ASSERT_TRUE(led_by(o, EffectKind::hysteresis));
  EXPECT_TRUE(r.ambiguous_with.empty()) << o.summary;
  EXPECT_EQ(r.alignment.used_samples, 0.0) << r.alignment.note;
  EXPECT_LE(r.fitted.rmse_validation_um, 0.5 * r.aligned.rmse_validation_um) << o.summary;
  EXPECT_LT(r.mixture.front().p[0], kMaxCompensatedHysteresisAlpha);
}

TEST(DiagnoseRealRecordings, CascadedTanksIsNeverForcedIntoAPhysicsTheRigDoesNotHave) {
  // A real two-tank water rig (tests/data/real/cascaded_tanks, SOURCE.md: the Cascaded Tanks benchmark, time axis
  // scaled 1/400). The source documents square-root outflow (time constants that grow with the level) and overflow
  // saturation; against its best two-pole linear model the residual is ~30x the sensor noise, and no candidate
  // explains 30% of it on held-out data (measured: unexplained, dead_zone leading with 93% left). So the answer
  // may be `unexplained` or the documented physics, never `none` and never another effect.
  const auto o = diagnose_real_recordings("cascaded_tanks", {"cascaded_tanks_est.csv", "cascaded_tanks_val.csv"});
  const auto& r = o.result;
  EXPECT_NE(r.verdict, "none") << o.summary;
  EXPECT_GT(r.nominal_refit.errors.rmse_um, 10.0 * r.noise_sigma_um) << o.summary;
  if (r.verdict != "unexplained") {
    const std::set<std::string> documented{"saturation", "bias_dependent_dynamics", "asymmetric_dynamics"};
    for (const auto& e : r.mixture) EXPECT_TRUE(documented.count(std::string(to_string(e.kind)))) << o.summary;
  }
  // The source's convention: the pump voltage is held over each sample with no further delay, which the
  // model file does not declare and the alignment finds.
  EXPECT_EQ(r.alignment.used_samples, 0.0) << r.alignment.note;
}

TEST(DiagnoseRealRecordings, EmpsFrictionIsADeadZoneNearTheSourcesCoulombFriction) {
  // A real prismatic drive under position control (tests/data/real/emps_friction, SOURCE.md: the EMPS benchmark,
  // motor voltage in, the carriage's velocity out by central differences of the encoder). The source documents
  // viscous and Coulomb friction, F_c = 20.39 N identified by its own script. Against the best linear model (a
  // first-order G that takes the friction for damping) the friction is a dead zone on the drive: below the
  // breakaway force the carriage does not move. Measured: dead_zone, 0.690 V = 24.3 N, with a saturation beside
  // it (a slew limit before the pairs tried the static curves); held-out 3.83 against 15.0 mm/s (0.26x; the dead
  // zone alone 0.48x).
  const auto o = diagnose_real_recordings("emps_friction", {"emps_velocity.csv"});
  const auto& r = o.result;
  ASSERT_TRUE(led_by(o, EffectKind::dead_zone));
  EXPECT_TRUE(r.ambiguous_with.empty()) << o.summary;
  EXPECT_LE(r.fitted.rmse_validation_um, 0.5 * r.aligned.rmse_validation_um) << o.summary;
  // The threshold in newtons (gtau = 35.15 N/V) within a factor 1.5 of the source's Coulomb friction.
  constexpr double kGtau_N_per_V = 35.1507, kCoulomb_N = 20.3935;
  EXPECT_GT(r.mixture.front().p[0] * kGtau_N_per_V, kCoulomb_N / 1.5) << o.summary;
  EXPECT_LT(r.mixture.front().p[0] * kGtau_N_per_V, kCoulomb_N * 1.5) << o.summary;
}

TEST(DiagnoseAmbiguity, ALoopFromAChargedStartLeadsAndTheCreepThatDrawsTheSameLagStaysNamed) {
  // Case 58 of the closed-loop tuning set (tests/data/ambiguous_creep_loop/README.md): a Preisach loop under
  // closed loop from a charged start (a hold at another level before the recording). Started partway along
  // its rising branch, the loop explains the held-out data best; a slow creep draws the same lag at these
  // frequencies and fits the fitting segment as well, so it stays named with the experiment that separates them.
  const std::string dir = std::string(PVCGEL_SOURCE_DIR) + "/tests/data/ambiguous_creep_loop/";
  auto rig = load_library_case(dir + "model.toml", dir + "rec0.csv");
  const auto r = control::diagnosis::diagnose(rig.model.model, rig.series, rig.options);
  EXPECT_EQ(r.verdict, "hysteresis") << r.explanation;
  EXPECT_EQ(std::count(r.ambiguous_with.begin(), r.ambiguous_with.end(), "creep"), 1) << r.explanation;
  EXPECT_NE(r.separating_experiment.find("hold the voltage constant"), std::string::npos) << r.explanation;
  // The loop's start: neither virgin nor a whole branch (the hold before the recording was a single step away).
  ASSERT_EQ(r.candidates.front().loop_memory.size(), 1u);
  const double start = r.candidates.front().loop_memory[0];
  EXPECT_GT(std::abs(start), 0.0);
  EXPECT_LT(std::abs(start), 1.0);
  EXPECT_NE(r.explanation.find("partway ("), std::string::npos) << r.explanation;
}

TEST(DiagnoseWithheldSecond, ADeadZoneThatImitatesFsShapeAtItsBoundIsWithheldNotNamed) {
  // Case 209 of the evaluation set (tests/data/withheld_second/README.md): a loop alone, on the exact
  // nominal. A dead zone beside the loop is significant on held-out data (withheld_second is only set
  // once the pair test passed), but the pair's f shape stops at its tolerance and a dead zone can imitate
  // f's shape: it stays out of the augmented model, and the report says so.
  const std::string dir = std::string(PVCGEL_SOURCE_DIR) + "/tests/data/withheld_second/";
  const auto tmp = temp_dir("withheld");
  DiagnoseArgs a;
  a.model = dir + "model.toml";
  a.recordings = {dir + "rec0.csv", dir + "rec1.csv"};
  a.json = (tmp / "report.json").string();
  a.quiet = true;
  const auto o = run_diagnose(a);
  const auto& r = o.result;
  EXPECT_EQ(r.verdict, "hysteresis") << o.summary;
  ASSERT_EQ(r.mixture.size(), 1u) << o.summary;
  EXPECT_EQ(r.withheld_second, "dead_zone") << o.summary;
  EXPECT_EQ(r.withheld_at_bounds, std::vector<std::string>{"poly_shape"}) << o.summary;
  EXPECT_NE(o.summary.find("withheld second effect: dead_zone"), std::string::npos) << o.summary;
  EXPECT_NE(read(a.json).find("\"withheld_second_effect\": {\"name\": \"dead_zone\", \"refit_at_bounds\": [\"poly_shape\"]}"),
            std::string::npos);
  // The pair test passed (both members significant, material, the excess explained) and says so.
  const auto& t = r.second_effect_test;
  ASSERT_EQ(t.effects.size(), 2u) << o.summary;
  EXPECT_EQ(t.effects[0], "hysteresis") << o.summary;
  EXPECT_EQ(t.effects[1], "dead_zone") << o.summary;
  EXPECT_TRUE(t.member[0].significant && t.member[1].significant && t.explained && t.material) << o.summary;
  EXPECT_GT(t.member[0].mean_um2, t.member[1].mean_um2) << o.summary;
  EXPECT_FALSE(t.named) << o.summary;
  EXPECT_NE(o.summary.find("best pair: hysteresis + dead_zone"), std::string::npos) << o.summary;
  EXPECT_NE(o.summary.find("not named (withheld)"), std::string::npos) << o.summary;
  EXPECT_NE(read(a.json).find("\"second_effect_test\": {\"effects\": [\"hysteresis\", \"dead_zone\"]"), std::string::npos);
  // Every pair fitted, the best (the one tested) first: the leader beside each second effect tried, and the
  // exchange step's pairs, a runner-up in the leader's place beside the best pair's second effect.
  ASSERT_GE(t.tried.size(), 2u) << o.summary;
  EXPECT_EQ(t.tried.front().effects, (std::vector<std::string>{"hysteresis", "dead_zone"})) << o.summary;
  EXPECT_DOUBLE_EQ(t.tried.front().rmse_validation_um, t.rmse_validation_um) << o.summary;
  size_t exchanged = 0;
  for (size_t i = 1; i < t.tried.size(); ++i) {
    EXPECT_LE(t.tried[i - 1].score, t.tried[i].score) << o.summary;
    if (t.tried[i].effects[0] == "hysteresis") {
      EXPECT_NE(t.tried[i].effects[1], "dead_zone") << "each second effect once";
    } else {
      EXPECT_EQ(t.tried[i].effects[1], "dead_zone") << "an exchanged pair keeps the best pair's second effect";
      ++exchanged;
    }
  }
  EXPECT_EQ(exchanged, 2u) << "the two best runners-up in the leader's place\n" << o.summary;
  EXPECT_NE(read(a.json).find("\"pairs_tried\": [{\"effects\": [\"hysteresis\", \"dead_zone\"], \"rmse_fit_um\": "),
            std::string::npos);
  // The best single effect's held-out RMSE over the noise, in both.
  EXPECT_GT(t.single_over_noise, 0.0) << o.summary;
  EXPECT_NE(o.summary.find("the best single effect alone leaves " + control::format("%.3g", t.single_over_noise) + "x the noise"),
            std::string::npos) << o.summary;
  EXPECT_NE(read(a.json).find("\"single_over_noise\": "), std::string::npos);
}

/// Both effects of a pair named, dominant first, with its nominal refit stopped at f's shape and nothing withheld.
void expect_both_named_beside_fs_shape_bound(const DiagnoseOutcome& o, EffectKind dominant, EffectKind second) {
  const auto& r = o.result;
  ASSERT_EQ(r.mixture.size(), 2u) << o.summary;
  EXPECT_EQ(r.mixture[0].kind, dominant) << o.summary;
  EXPECT_EQ(r.mixture[1].kind, second) << o.summary;
  EXPECT_EQ(r.nominal_refit.at_bounds, std::vector<std::string>{"poly_shape"}) << o.summary;
  EXPECT_TRUE(r.withheld_second.empty()) << o.summary;
  const auto& t = r.second_effect_test;
  EXPECT_TRUE(t.named) << o.summary;
  EXPECT_EQ(t.effects, (std::vector<std::string>{std::string(to_string(dominant)), std::string(to_string(second))})) << o.summary;
  EXPECT_NEAR(t.member[0].mean_um2, r.contribution.at(0), 1e-12) << o.summary;
  EXPECT_NEAR(t.member[1].mean_um2, r.contribution.at(1), 1e-12) << o.summary;
  EXPECT_NE(o.summary.find("both named"), std::string::npos) << o.summary;
}

TEST(DiagnoseWithheldSecond, ADriftBesideFsShapeAtItsBoundIsStillNamed) {
  // Case 105 of the evaluation set (tests/data/named_beside_bound/README.md): a resonance and a drift.
  // The pair's f shape stops at its tolerance too, but a drift cannot imitate f's shape, so both are named.
  expect_both_named_beside_fs_shape_bound(diagnose_data("named_beside_bound", "model.toml", {"rec0.csv"}),
                                          EffectKind::resonance, EffectKind::drift);
}

TEST(DiagnoseWithheldSecond, ASaturationBesideFsShapeAtItsBoundIsNamedWhenAWiderNominalCannotDoItsPart) {
  // Case 214 of the evaluation set (tests/data/pair_beats_wider_nominal/README.md): a dead zone and a
  // saturation. The pair's f shape stops at its tolerance, where a saturation could imitate the nominal's
  // error; the dead zone alone with a wider nominal refit explains the held-out data clearly worse than the
  // pair, so the saturation is named, not withheld.
  expect_both_named_beside_fs_shape_bound(
      diagnose_data("pair_beats_wider_nominal", "model.toml", {"rec0.csv", "rec1.csv"}), EffectKind::dead_zone,
      EffectKind::saturation);
}

TEST(DiagnoseIndependentCases, AWiderCurveWhoseSingleEffectsCannotWinStopsBeforeItsPairsWithTheSameAnswer) {
  // Case 214 again: f's shape stops at its bound, so a second diagnosis runs with a wider curve. Its best
  // single effect is no better than the ordinary one's, so it stops before its pairs; with its pairs run
  // the ordinary diagnosis stood all the same, and the answer is the one it was.
  DiagnoseArgs a;
  const std::string dir = std::string(PVCGEL_SOURCE_DIR) + "/tests/data/pair_beats_wider_nominal/";
  a.model = dir + "model.toml";
  a.recordings = {dir + "rec0.csv", dir + "rec1.csv"};
  const auto model = load_model(a.model);
  const auto recordings = load_recordings(a, model);
  auto options = diagnosis_options(a, model);
  std::vector<std::string> stages;
  options.progress = [&stages](std::string_view stage, std::size_t done, std::size_t total) {
    if (done == total) stages.emplace_back(stage);
  };
  const auto stopped = control::diagnosis::diagnose(model.model, recordings.data, options);
  const auto joined = [&stages] { return join(stages, "; "); };
  EXPECT_NE(joined().find("with a wider curve: candidate fits"), std::string::npos) << joined();
  EXPECT_EQ(joined().find("with a wider curve: pair fits"), std::string::npos) << joined();
  stages.clear();
  options.stop_wide_without_better_single = false;
  const auto full = control::diagnosis::diagnose(model.model, recordings.data, options);
  EXPECT_NE(joined().find("with a wider curve: pair fits"), std::string::npos) << joined();
  EXPECT_FALSE(full.nominal_refit.widened());
  EXPECT_EQ(stopped.verdict, full.verdict);
  ASSERT_EQ(stopped.mixture.size(), full.mixture.size());
  for (size_t i = 0; i < full.mixture.size(); ++i) EXPECT_EQ(stopped.mixture[i].kind, full.mixture[i].kind);
  EXPECT_EQ(stopped.fitted.rmse_validation_um, full.fitted.rmse_validation_um);
  EXPECT_EQ(stopped.ambiguous_with, full.ambiguous_with);
  EXPECT_LT(stopped.simulations, full.simulations);
}

TEST(DiagnoseIndependentCases, AWidenedNuisanceRefitStartsFromTheOrdinaryOneToo) {
  // Case 95 of the evaluation set, cut to 20 s (tests/data/wide_refit_from_narrow/README.md): the static
  // curve is far off, so the tolerances widen. From the nominal alone the wide refit stepped f's shape to
  // its lower bound, where the start state lies beyond the recorded voltages, and stayed at 4.5x the noise.
  const auto o = diagnose_data("wide_refit_from_narrow", "model.toml", {"rec0.csv"});
  const auto& r = o.result;
  EXPECT_TRUE(r.nominal_refit.widened()) << o.summary;
  EXPECT_LT(r.nominal_refit.errors.rmse_um, 1.1 * r.noise_sigma_um) << o.summary;
}

TEST(DiagnoseIndependentCases, AsymmetricDynamicsOnTheSlowPoleAloneInClosedLoop) {
  // A case of the independent generator (tests/data/asymmetric_slow_pole/README.md): the slow mode alone
  // relaxes 8% slower than it contracts, tracked in closed loop. Scaling all of G's time constants by
  // direction cannot take it; bias-dependent dynamics on the slow pole alone took it before this form existed.
  const auto o = diagnose_data("asymmetric_slow_pole", "model.toml", {"rec0.csv", "rec1.csv"});
  const auto& r = o.result;
  ASSERT_TRUE(led_by(o, EffectKind::asymmetric_dynamics));
  EXPECT_EQ(r.mixture[0].p[1], 1.0) << "slow_pole_only\n" << o.summary;
  EXPECT_GT(r.mixture[0].p[0], 0.0) << "relaxation_slowdown: the relaxation is the slower\n" << o.summary;
}

TEST(DiagnoseIndependentCases, AsymmetricDynamicsWithTheRiseAloneOffTheNominal) {
  // A case of the independent generator (tests/data/asymmetric_rise_off_nominal/README.md): rising runs 1.86
  // times slower than the nominal, falling at it. With the nominal held on the rising direction that was
  // beyond the refit's tolerance on G's time scale, and the verdict was `unexplained`.
  const auto o = diagnose_data("asymmetric_rise_off_nominal", "model.toml", {"rec0.csv", "rec1.csv", "rec2.csv"});
  const auto& r = o.result;
  ASSERT_TRUE(led_by(o, EffectKind::asymmetric_dynamics));
  EXPECT_NEAR(r.mixture[0].p[0], 0.537 - 1.0, 0.05) << "relaxation_slowdown: the label's ratio of speeds\n" << o.summary;
  EXPECT_GT(r.mixture[0].p[2], 0.5) << "rise_share: the nominal nearer the relaxation's speed\n" << o.summary;
  EXPECT_LT(r.fitted.rmse_validation_um, 1.1 * r.noise_sigma_um) << o.summary;
}

TEST(DiagnoseIndependentCases, ASaturationOnTheDriveIsNotPenalisedForItsFormChoice) {
  // A case of the independent generator (tests/data/saturation_on_the_drive/README.md): a saturation and a
  // dead zone both reach the noise, the saturation a little closer on both segments. Its placement flag
  // (on_drive), a choice between two fitted forms, was counted as a parameter, and the dead zone won.
  const auto o = diagnose_data("saturation_on_the_drive", "model.toml", {"rec0.csv", "rec1.csv"});
  const auto& r = o.result;
  ASSERT_TRUE(led_by(o, EffectKind::saturation));
  EXPECT_EQ(r.mixture[0].p[*form_flag_index(EffectKind::saturation)], 1.0) << "on the drive, as labelled\n" << o.summary;
  EXPECT_LT(r.fitted.rmse_validation_um, 1.05 * r.noise_sigma_um) << o.summary;
}

TEST(DiagnoseIndependentCases, ANoneWhoseNuisanceRefitACandidateImprovedIsNone) {
  // A `none` of the independent generator (tests/data/none_from_leader/README.md): the nuisance-only refit
  // stopped at 1.6x the noise; the delay candidate, its delay at 0, reached the noise with its own refit and
  // was the verdict. Made again from the leader's nominal, the nuisance-only refit passes the `none` test.
  const auto o = diagnose_data("none_from_leader", "model.toml", {"rec0.csv"});
  const auto& r = o.result;
  EXPECT_EQ(r.verdict, "none") << o.summary;
  EXPECT_TRUE(r.mixture.empty()) << o.summary;
  EXPECT_LT(r.nominal_refit.errors.rmse_um, 1.1 * r.noise_sigma_um) << o.summary;
  EXPECT_NE(r.explanation.find("started from delay's joint fit"), std::string::npos) << r.explanation;
}

TEST(DiagnoseIndependentCases, ADelayBeyondTheDeclaredThatGsTimeScaleAbsorbsIsNamed) {
  // A delay of the independent generator (tests/data/longer_delay_than_declared/README.md): 1.1 ms beyond
  // the declared 2 samples at 1 kHz. The nuisance-only refit passes the `none` test with G 12% slower, but
  // the delay search fits clearly better at 3 samples over both recordings, so the candidates judge it.
  const auto o = diagnose_data("longer_delay_than_declared", "model.toml", {"rec0.csv", "rec1.csv"});
  const auto& r = o.result;
  EXPECT_TRUE(r.none_test.level_ok) << o.summary;
  EXPECT_TRUE(r.none_test.longer_delay_pending) << o.summary;
  EXPECT_GT(r.alignment.declared_delay_excess_noise_variances, 25.0) << o.summary;
  EXPECT_EQ(r.verdict, "delay") << o.summary;
  ASSERT_EQ(r.mixture.size(), 1U) << o.summary;
  EXPECT_NEAR(r.mixture[0].p[0], 1.1e-3, 0.3e-3) << "extra_delay_s: the label's\n" << o.summary;
  EXPECT_NE(r.explanation.find("noise variances less squared error"), std::string::npos) << r.explanation;
  // One sine alone cannot tell the delay from a slower G: the search's gain stays under the bar.
  const auto alone = diagnose_data("longer_delay_than_declared", "model.toml", {"rec0.csv"});
  EXPECT_EQ(alone.result.verdict, "none") << alone.summary;
  EXPECT_FALSE(alone.result.none_test.longer_delay_pending) << alone.summary;
  EXPECT_LT(alone.result.alignment.declared_delay_excess_noise_variances, 25.0) << alone.summary;
}

TEST(DiagnoseIndependentCases, ASecondEffectBehindAlternativesToTheLeaderIsFittedBesideIt) {
  // A mixture of the independent generator (tests/data/alternatives_beside_leader/README.md): a 3 ms delay
  // and falling 7% faster than rising. A creep and a mode, alternatives to the delay, took the runners-up's
  // places, and the asymmetric dynamics was never fitted beside it: the verdict was the delay alone.
  const auto o = diagnose_data("alternatives_beside_leader", "model.toml", {"rec0.csv", "rec1.csv", "rec2.csv"});
  const auto& r = o.result;
  EXPECT_EQ(r.verdict, "delay") << o.summary;
  ASSERT_EQ(r.mixture.size(), 2U) << o.summary;
  EXPECT_EQ(r.mixture[0].kind, EffectKind::delay) << o.summary;
  EXPECT_NEAR(r.mixture[0].p[0], 3e-3, 1e-3) << "extra_delay_s: the label's\n" << o.summary;
  ASSERT_EQ(r.mixture[1].kind, EffectKind::asymmetric_dynamics) << o.summary;
  EXPECT_LT(r.mixture[1].p[0], 0.0) << "relaxation_slowdown: falling is the faster\n" << o.summary;
  EXPECT_LT(r.fitted.rmse_validation_um, 1.1 * r.noise_sigma_um) << o.summary;
}

TEST(DiagnoseIndependentCases, ALeaderThatStoodInForBothIsExchanged) {
  // A mixture of the independent generator (tests/data/exchanged_leader/README.md): a 355 V/s slew limit and
  // bias-dependent dynamics. A creep led alone, standing in for part of both, and the pair named was creep +
  // slew limit; the bias-dependent dynamics was never fitted beside the slew limit until the exchange step.
  const auto o = diagnose_data("exchanged_leader", "model.toml", {"rec0.csv", "rec1.csv", "rec2.csv"});
  const auto& r = o.result;
  ASSERT_EQ(r.mixture.size(), 2U) << o.summary;
  const auto named = [&](EffectKind k) {
    return std::find_if(r.mixture.begin(), r.mixture.end(), [&](const Effect& e) { return e.kind == k; });
  };
  EXPECT_NE(named(EffectKind::bias_dependent_dynamics), r.mixture.end()) << o.summary;
  const auto slew = named(EffectKind::slew_limit);
  ASSERT_NE(slew, r.mixture.end()) << o.summary;
  EXPECT_NEAR(slew->p[0], 355.0, 0.1 * 355.0) << "slew_rate_V_per_s: the label's\n" << o.summary;
  EXPECT_LT(r.fitted.rmse_validation_um, 1.3 * r.noise_sigma_um) << o.summary;
}

TEST(DiagnoseIndependentCases, ASecondStateTimeScaleTakesNoRunnerUpsPlace) {
  // A mixture of the independent generator (tests/data/state_time_scales_placeless/README.md): a 1.3 ms delay
  // and a 2705 V/s slew limit. Bias-dependent dynamics leads alone, asymmetric dynamics fifth; taking a
  // runner-up's place beside it, the asymmetry kept the slew limit out of the pairs and the answer was delay
  // + a mode.
  const auto o = diagnose_data("state_time_scales_placeless", "model.toml", {"rec0.csv"});
  const auto& r = o.result;
  const auto& tried = r.second_effect_test.tried;
  const auto was_tried = [&](const std::vector<std::string>& pair) {
    return std::any_of(tried.begin(), tried.end(), [&](const PairTried& t) { return t.effects == pair; });
  };
  EXPECT_TRUE(was_tried({"bias_dependent_dynamics", "slew_limit"})) << o.summary;
  EXPECT_TRUE(was_tried({"bias_dependent_dynamics", "asymmetric_dynamics"})) << o.summary;
  ASSERT_EQ(r.mixture.size(), 2U) << o.summary;
  const auto named = [&](EffectKind k) {
    return std::find_if(r.mixture.begin(), r.mixture.end(), [&](const Effect& e) { return e.kind == k; });
  };
  const auto delay = named(EffectKind::delay), slew = named(EffectKind::slew_limit);
  ASSERT_NE(delay, r.mixture.end()) << o.summary;
  ASSERT_NE(slew, r.mixture.end()) << o.summary;
  EXPECT_NEAR(delay->p[0], 1.3e-3, 0.2 * 1.3e-3) << "extra_delay_s: the label's\n" << o.summary;
  EXPECT_NEAR(slew->p[0], 2705.0, 0.1 * 2705.0) << "slew_rate_V_per_s: the label's\n" << o.summary;
  EXPECT_LT(r.fitted.rmse_validation_um, 1.1 * r.noise_sigma_um) << o.summary;
}

TEST(DiagnoseIndependentCases, BiasDependentDynamicsAboutTheRecordedRangeAreCentredThere) {
  // A case of the independent generator (tests/data/bias_about_a_centre/README.md): the slow pole moves with
  // the displacement, recorded between about 75 and 125 um. Centred at zero, the form needed G's time
  // constants there beyond the refit's tolerance and the verdict was `unexplained`.
  const auto o = diagnose_data("bias_about_a_centre", "model.toml", {"rec0.csv"});
  const auto& r = o.result;
  EXPECT_EQ(r.verdict, "bias_dependent_dynamics") << o.summary;
  ASSERT_FALSE(r.mixture.empty()) << o.summary;
  const auto& e = r.mixture[0];
  ASSERT_EQ(e.kind, EffectKind::bias_dependent_dynamics) << o.summary;
  EXPECT_GT(e.p[5], 50.0) << "centre_um: within the recorded range, not at zero\n" << o.summary;
  EXPECT_LT(e.p[5], 150.0) << "centre_um\n" << o.summary;
  EXPECT_LT(r.fitted.rmse_validation_um, 1.1 * r.noise_sigma_um) << o.summary;
  EXPECT_LT(r.fitted.rmse_validation_um, 0.7 * r.nominal_refit.errors.rmse_validation_um) << o.summary;
}

TEST(DiagnoseIndependentCases, ACandidateThatExplainsTheExcessLeadsOneThatDoesNot) {
  // A case of the independent generator (tests/data/explained_below_a_penalised_leader/README.md): judged on
  // the fitting segment at the noise floor, the penalised ranking put a delay that explains nothing above
  // the bias-dependent dynamics that explain most of the excess, and the verdict was `unexplained`.
  const auto o = diagnose_data("explained_below_a_penalised_leader", "model.toml", {"rec0.csv"});
  const auto& r = o.result;
  EXPECT_EQ(r.candidates_judged_on, "fitting_segment") << o.summary;
  EXPECT_EQ(r.verdict, "bias_dependent_dynamics") << o.summary;
  ASSERT_FALSE(r.candidates.empty());
  EXPECT_LE(control::diagnosis::excess_share_left(r, r.candidates.front().errors), 0.5) << o.summary;
}

TEST(DiagnoseIndependentCases, ADeadZoneTheCommandsNeverComeNearIsNotNamedInPlaceOfALoop) {
  // Evaluation case134 (tests/data/dead_zone_never_reached/README.md): a small loop in closed loop about
  // 390 V, no command below 323 V. A dead zone at 10.6 V, whose catch-up to 432 V put a corner in the
  // static curve, led the loop by its penalty alone and was the verdict.
  const auto o = diagnose_data("dead_zone_never_reached", "model.toml", {"rec0.csv", "rec1.csv"});
  const auto& r = o.result;
  EXPECT_EQ(r.verdict, "hysteresis") << o.summary;
  for (const auto& e : r.mixture) EXPECT_NE(e.kind, EffectKind::dead_zone) << o.summary;
  EXPECT_EQ(std::find(r.ambiguous_with.begin(), r.ambiguous_with.end(), "dead_zone"), r.ambiguous_with.end()) << o.summary;
  const auto dead_zone = std::find_if(r.candidates.begin(), r.candidates.end(),
                                      [](const auto& c) { return c.effect.kind == EffectKind::dead_zone; });
  ASSERT_NE(dead_zone, r.candidates.end());
  ASSERT_TRUE(dead_zone->fitted) << o.summary;
  EXPECT_LT(dead_zone->effect.p[0], 32.0) << "threshold_V\n" << o.summary;
  EXPECT_NE(dead_zone->explanation.find("; not named: its threshold"), std::string::npos) << dead_zone->explanation;
}

TEST(DiagnoseIndependentCases, ASmoothDeadZoneBendingOneStepLevelIsADeadZone) {
  // A fresh case of the independent generator (tests/data/dead_zone_wide_catch_up/README.md): a smooth
  // 1.35 V dead zone on a 0-10 V input, seen at one step level (2.6 V) above every catch-up the grid
  // started from; the dead-zone fit stopped at no dead zone and the verdict was drift.
  const auto o = diagnose_data("dead_zone_wide_catch_up", "model.toml", {"rec0.csv"});
  const auto& r = o.result;
  EXPECT_EQ(r.verdict, "dead_zone") << o.summary;
  ASSERT_EQ(r.mixture.size(), 1u) << o.summary;
  EXPECT_EQ(r.mixture[0].kind, EffectKind::dead_zone) << o.summary;
  // The curve rejoins the nominal above 2.6 V and below 4.1 V: threshold plus catch-up between them.
  const double rejoins_V = r.mixture[0].p[0] + r.mixture[0].p[1];
  EXPECT_GT(rejoins_V, 2.6) << o.summary;
  EXPECT_LT(rejoins_V, 4.1) << o.summary;
  EXPECT_LE(r.fitted.rmse_validation_um, 1.1 * r.noise_sigma_um) << o.summary;
}

TEST(DiagnoseIndependentCases, APairStartThePlantCannotSimulateIsAFailedFitNotAnError) {
  // A fresh case of the independent generator (tests/data/nan_pair_start/README.md): a 313 Hz mode on a
  // 10 kHz piezo. A pair fit started where the simulation is not finite; its NaN step put f's shape at NaN
  // and the model check threw, so the diagnosis stopped and wrote nothing.
  const auto o = diagnose_data("nan_pair_start", "model.toml", {"rec0.csv", "rec1.csv"});
  const auto& r = o.result;
  ASSERT_TRUE(led_by(o, EffectKind::resonance));
  EXPECT_LE(r.fitted.rmse_validation_um, 0.5 * r.baseline.rmse_validation_um) << o.summary;
  for (const auto& tried : r.second_effect_test.tried)
    EXPECT_FALSE(std::isnan(tried.score)) << tried.effects[0] << "+" << tried.effects[1] << "\n" << o.summary;
}

TEST(DiagnoseIndependentCases, AnUnexplainedDriftSaysADriftOfEachRecordingsOwnIsNotModelled) {
  // A fresh case of the independent generator (tests/data/drift_of_its_own/README.md): a thermal drift whose
  // rate and settling differ between the two recordings. The drift candidate, shared by them, leaves 53% of
  // the excess: `unexplained`, and the explanation says what the drift cannot fit. Its label, `drift`, is
  // accepted too.
  const auto o = diagnose_data("drift_of_its_own", "model.toml", {"rec0.csv", "rec1.csv"});
  const auto& r = o.result;
  if (r.verdict == "drift") return;
  ASSERT_EQ(r.verdict, "unexplained") << o.summary;
  EXPECT_EQ(r.candidates.front().effect.kind, EffectKind::drift) << o.summary;
  EXPECT_NE(r.explanation.find("shared by the 2 recordings"), std::string::npos) << r.explanation;
  EXPECT_NE(r.explanation.find("Diagnose each recording alone"), std::string::npos) << r.explanation;
}

TEST(DiagnoseIndependentCases, AnUnexplainedVerdictWhoseRefitReachesTheNoiseSaysTheNominalIsOff) {
  // A fresh case of the independent generator (tests/data/bias_at_one_operating_point/README.md):
  // bias-dependent dynamics over one operating point, which the nuisance-only refit's time scale takes.
  const auto o = diagnose_data("bias_at_one_operating_point", "model.toml", {"rec0.csv"});
  const auto& r = o.result;
  const double refit_um = r.nominal_refit.errors.rmse_um;
  ASSERT_LT(refit_um * refit_um, 1.1 * r.noise_sigma_um * r.noise_sigma_um) << o.summary;  // the premise
  EXPECT_TRUE(r.mixture.empty()) << o.summary;  // nothing beats the refit, so nothing is named
  if (r.verdict == "none") return;  // the `none` test's one failing window is a near thing
  ASSERT_EQ(r.verdict, "unexplained") << o.summary;
  EXPECT_NE(r.explanation.find("The nuisance-only refit alone comes within 10% of the noise variance"), std::string::npos)
      << r.explanation;
  EXPECT_NE(r.explanation.find("record at a second one"), std::string::npos) << r.explanation;
}

TEST(DiagnoseIndependentCases, ALoopThatDoesNoWorkDoesNotBuyAFasterG) {
  // A fresh case of the independent generator (tests/data/idle_loop_faster_g/README.md): an 87 Hz mode
  // beside a piezo's dynamics. The loop fit took G 0.65x as fast, beyond the nuisance refit's tolerance, at
  // alpha -1.2e-4 (the loop itself did nothing), and the faster G made hysteresis the verdict.
  const auto o = diagnose_data("idle_loop_faster_g", "model.toml", {"rec0.csv", "rec1.csv"});
  const auto& r = o.result;
  // Cut to 1 s, the mode and creep both reach the noise held out (0.0050 um): either may lead, the other
  // named as equally good (with the exact exponential since 7fdcb00, creep leads here by the fourth digit;
  // the whole recordings give `resonance`).
  const auto& named = r.ambiguous_with;
  EXPECT_TRUE(r.verdict == "resonance" || std::find(named.begin(), named.end(), "resonance") != named.end()) << o.summary;
  EXPECT_NE(r.verdict, "hysteresis") << o.summary;
  for (const auto& e : r.mixture) EXPECT_NE(e.kind, EffectKind::hysteresis) << o.summary;
  using control::diagnosis::detail::fitted_candidate;
  const auto* loop = fitted_candidate(r, EffectKind::hysteresis);
  ASSERT_NE(loop, nullptr) << o.summary;
  const control::diagnosis::DiagnosisOptions defaults;
  EXPECT_GE(loop->time_scale, 1.0 / (1.0 + defaults.time_scale_tolerance) - 1e-9) << o.summary;
  // The fitted mode lies above 400 Hz: where it leads, the augmented model's sim runs it at the recordings'
  // 10 kHz, not the default 1 kHz, at which its file was refused and not written.
  const auto* mode = fitted_candidate(r, EffectKind::resonance);
  ASSERT_NE(mode, nullptr) << o.summary;
  EXPECT_GT(mode->effect.p[0], 400.0) << o.summary;
  EXPECT_NE(read(o.augmented_model_path).find("[controller]\nperiod_s = 0.0001\n"), std::string::npos);
}

TEST(DiagnoseIndependentCases, ASlewLimitSlewsFromWhereTheActuatorWasLeft) {
  // A fresh case of the independent generator (tests/data/slew_from_charged_start/README.md): an analog slew
  // limit at 294 V/s under closed loop from a charged start at 100 Hz. Started at rest at the first command,
  // the slew candidate bent its rate to the start (243 V/s), did worse than the nuisance-only refit held out,
  // and a delay led.
  const auto o = diagnose_data("slew_from_charged_start", "model.toml", {"rec0.csv"});
  const auto& r = o.result;
  ASSERT_TRUE(led_by(o, EffectKind::slew_limit));
  EXPECT_NEAR(r.mixture[0].p[0], 294.0, 0.05 * 294.0) << "slew_rate_V_per_s: the label's\n" << o.summary;
  EXPECT_NE(r.explanation.find("the drive slews from where the actuator rests in recording 0"), std::string::npos)
      << r.explanation;
  EXPECT_LT(r.fitted.rmse_validation_um, 1.05 * r.noise_sigma_um) << o.summary;
}

TEST(DiagnoseIndependentCases, ADigitalSlewLimitIsFittedAsOne) {
  // A fresh case of the independent generator (tests/data/digital_slew_limit/README.md): a digital limiter
  // at 1455 V/s on the held command at 100 Hz. The analog form alone left 88% of the excess and a mode led.
  const auto o = diagnose_data("digital_slew_limit", "model.toml", {"rec0.csv"});
  const auto& r = o.result;
  ASSERT_TRUE(led_by(o, EffectKind::slew_limit));
  EXPECT_EQ(r.mixture[0].p[1], 1.0) << "digital\n" << o.summary;
  EXPECT_NEAR(r.mixture[0].p[0], 1455.0, 0.05 * 1455.0) << "slew_rate_V_per_s\n" << o.summary;
  EXPECT_LE(r.fitted.rmse_validation_um, 1.1 * r.noise_sigma_um) << o.summary;
}

TEST(DiagnoseIndependentCases, HalfASampleOfDelayIsADelayAt100Hz) {
  // A case of the independent generator (tests/data/fractional_delay/README.md): 0.5 samples of transport
  // delay at 100 Hz. With the held command interpolated linearly between samples, a 35 Hz mode led.
  const auto o = diagnose_data("fractional_delay", "model.toml", {"rec0.csv", "rec1.csv", "rec2.csv", "rec3.csv"});
  const auto& r = o.result;
  ASSERT_TRUE(led_by(o, EffectKind::delay));
  EXPECT_NEAR(r.mixture[0].p[0], 0.005, 0.001) << "extra_delay_s: half a sample, beyond the declared one\n" << o.summary;
}

TEST(DiagnoseBlindSuite, FixedSubsetMeetsTheIssueThresholds) {
  // 11 cases: every effect once and none once (seed fixed); the full suite is `pvcgel bench diagnose`.
  std::ostringstream log;
  const auto r = run_blind_suite(11, 7, log);
  std::cout << log.str() << format_suite(r);
  EXPECT_EQ(r.cases, 11);
  EXPECT_GE(r.accuracy(), 0.9);
  EXPECT_LE(r.false_alarms, 1);
  EXPECT_LE(r.worst_ratio, 0.5);
  EXPECT_EQ(r.out_of_spec, 0);
}

TEST(DiagnoseIndependentSuite, AScoreOverNoCasesSaysSoInsteadOfNan) {
  // A suite of `none` recordings only (generate.py --only none) has no single effects and no mixtures.
  DirectorySuiteResult r;
  r.cases = r.none_cases = 100;
  r.false_alarms = 1;
  const auto text = format_directory_suite(r);
  EXPECT_EQ(text.find(" nan"), std::string::npos) << text;  // ("dominant" holds the letters)
  EXPECT_NE(text.find("single-effect accuracy: no such cases"), std::string::npos) << text;
  EXPECT_NE(text.find("mixtures with both effects named: no such cases"), std::string::npos) << text;
  EXPECT_NE(text.find("held-out RMSE fitted/nominal on correct cases: no such cases"), std::string::npos) << text;
  EXPECT_NE(text.find("false alarms on none 1/100 = 1.0% (target <= 2%: ratio 0.50)"), std::string::npos) << text;
}

TEST(DiagnoseIndependentSuite, TheHeldOutRatioIsAlsoGivenWhereTheHeldOutDataShowTheEffect) {
  // Evaluation case234: a dead zone seen only in the step from rest (fitting segment); the nominal's held-out
  // RMSE is the noise, so its ratio stays 1.003 however right the verdict. It is counted, and shown apart.
  DirectorySuiteResult r;
  r.cases = r.single_cases = r.single_correct = 3;
  r.ratios = {0.1, 0.3, 1.003};
  r.ratios_aligned = {0.1, 0.3, 0.96};
  r.ratios_held_out_shows_effect = {0.1, 0.3};
  const auto text = format_directory_suite(r);
  EXPECT_NE(text.find("worst 1.003 (target <= 0.50: worst/target 2.01)"), std::string::npos) << text;
  EXPECT_NE(text.find("on the 2 whose held-out data show the effect (nominal held-out RMSE >= 1.5x the noise): worst "
                      "0.300, 0 above 0.50; the other 1: the held-out blocks fall where the effect does not act"),
            std::string::npos)
      << text;
  r.ratios_held_out_shows_effect.clear();  // every correct case's held-out data at the noise: no worst to give
  const auto none_shown = format_directory_suite(r);
  EXPECT_NE(none_shown.find("on the 0 whose held-out data show the effect (nominal held-out RMSE >= 1.5x the noise): "
                            "no such cases; the other 3"),
            std::string::npos)
      << none_shown;
  EXPECT_EQ(none_shown.find(" nan"), std::string::npos) << none_shown;
}

TEST(DiagnoseIndependentSuite, MixturesLeftUnnamedAreCountedByTheBestPairAndWhatKeptItsSecondOut) {
  DirectorySuiteResult r;
  r.cases = r.mixture_cases = 10;
  r.mixture_both_named = 4;
  r.mixture_missed_other_pair = 3;
  r.mixture_other_pair_labels_fitted = 1;
  r.mixture_missed_no_pair = 1;
  r.mixture_missed_labels_pair = 2;
  r.mixture_labels_pair_shortfalls = {{"the other not significant", 2}, {"not material", 1}};
  r.mixture_missed_single_at_noise = 2;
  const auto text = format_directory_suite(r);
  EXPECT_NE(text.find("mixtures without both named (6), by the best pair fitted: another pair 3 (the labels' pair fitted "
                      "too in 1), none fitted 1, the labels' "
                      "pair 2 (not material 1, the other not significant 2); the best single effect alone at the noise "
                      "(held-out RMSE within 5% of it) in 2"),
            std::string::npos)
      << text;
  r.mixture_missed_other_pair = r.mixture_missed_no_pair = r.mixture_missed_labels_pair = 0;  // all named: no line
  EXPECT_EQ(format_directory_suite(r).find("mixtures without both named"), std::string::npos);
}

TEST(DiagnoseIndependentSuite, SingleEffectsAreCountedByTheLabelsFormTheWeakestFirst) {
  DirectorySuiteResult r;
  r.cases = r.single_cases = 14;
  r.single_by_form = {{"hysteresis/bouc_wen", {1, 6}}, {"hysteresis/duhem", {1, 4}}, {"delay/transport", {3, 3}},
                      {"creep/add_log", {1, 1}}};
  const auto text = format_directory_suite(r);
  EXPECT_NE(text.find("single effects by the labels' form, those with a miss, the weakest first (right/cases): "
                      "hysteresis/bouc_wen 1/6, hysteresis/duhem 1/4; 2 other forms all right (4 cases)"),
            std::string::npos)
      << text;
  r.single_by_form.clear();  // labels without a form column: no line
  EXPECT_EQ(format_directory_suite(r).find("labels' form"), std::string::npos);
}

TEST(DiagnoseIndependentSuite, AnAmbiguousAnswerHoldingTheTruthIsCountedAsSuch) {
  // The closed-loop Preisach case (tests/data/ambiguous_creep_loop) as a one-case suite labelled creep (the
  // generator labelled it hysteresis): the verdict (the loop) is then wrong, the creep among the ambiguous names.
  namespace fs = std::filesystem;
  const auto suite = temp_dir("ambiguous_suite");
  fs::create_directories(suite / "case000");
  for (const char* f : {"model.toml", "rec0.csv"})
    fs::copy_file(fs::path(PVCGEL_SOURCE_DIR) / "tests/data/ambiguous_creep_loop" / f, suite / "case000" / f,
                  fs::copy_options::overwrite_existing);
  // With a params column as the generator writes it: the effect leaves 2x the noise after a gain and offset refit.
  std::ofstream(suite / "labels.csv")
      << "case,effects,dominant,params\n"
         "case000,creep,creep,\"{\"\"creep\"\":{\"\"ratio_after_gain_offset_refit\"\":2.0}}\"\n";
  std::ostringstream log;
  const auto r = run_directory_suite(suite.string(), 1, log);
  const auto text = format_directory_suite(r);
  ASSERT_EQ(r.single_cases, 1) << log.str();
  EXPECT_EQ(r.visible_single_cases, 1);
  EXPECT_EQ(r.visible_single_correct, 0);
  EXPECT_NE(text.find("ratio_after_gain_offset_refit): single effects 0/1, mixtures with both named 0/0"), std::string::npos)
      << text;
  EXPECT_EQ(r.single_correct, 0) << log.str();
  EXPECT_EQ(r.single_ambiguous, 1) << log.str();
  EXPECT_EQ(r.single_ambiguous_right, 0);
  EXPECT_EQ(r.single_truth_among_ambiguous, 1);
  EXPECT_NE(log.str().find("ambiguous with: creep"), std::string::npos) << log.str();
  EXPECT_NE(text.find("single effects answered as ambiguous: 1 (the verdict right in 0; the truth among the other names in 1)"),
            std::string::npos) << text;
}

TEST(DiagnoseIndependentSuite, TheSlowestCasesAreTimedAgainAloneOnEveryCore) {
  // Two jobs share the cores, so each case fits on a share of them; the slowest case is diagnosed again
  // alone, on every core, with the same answer. One job: the suite's times are already alone.
  namespace fs = std::filesystem;
  const auto suite = temp_dir("retime_suite");
  for (const char* c : {"case000", "case001"}) {
    fs::create_directories(suite / c);
    for (const char* f : {"model.toml", "rec0.csv"})
      fs::copy_file(fs::path(PVCGEL_SOURCE_DIR) / "tests/data/ambiguous_creep_loop" / f, suite / c / f,
                    fs::copy_options::overwrite_existing);
  }
  std::ofstream(suite / "labels.csv") << "case,effects,dominant\ncase000,hysteresis,hysteresis\ncase001,hysteresis,hysteresis\n";
  std::ostringstream log;
  const auto r = run_directory_suite(suite.string(), 2, log, 0, 1);
  const auto text = format_directory_suite(r);
  ASSERT_EQ(r.alone_s.size(), 1u) << log.str();
  EXPECT_EQ(r.alone_threads, threads_per_job(1));
  EXPECT_EQ(r.threads_per_case, threads_per_job(2));
  EXPECT_EQ(r.alone_answer_changed, 0) << log.str();
  EXPECT_GT(r.alone_s.front().second, 0.0);
  EXPECT_NE(log.str().find(r.alone_s.front().first + " again alone on"), std::string::npos) << log.str();
  EXPECT_NE(text.find("time per case (2 at once, each on"), std::string::npos) << text;
  EXPECT_NE(text.find("the 1 slowest again, one at a time on"), std::string::npos) << text;
  std::ostringstream alone_log;
  const auto one_job = run_directory_suite(suite.string(), 1, alone_log, 0, 1);
  EXPECT_TRUE(one_job.alone_s.empty());
  EXPECT_EQ(format_directory_suite(one_job).find("slowest again"), std::string::npos);
}

TEST(DiagnoseIndependentSuite, AParamsFieldThatIsNotJsonIsRefusedNamingTheRow) {
  const auto suite = temp_dir("bad_params_suite");
  std::ofstream(suite / "labels.csv") << "case,effects,dominant,params\ncase000,creep,creep,{\"\"creep\"\":\n";
  std::ostringstream log;
  try {
    (void)run_directory_suite(suite.string(), 1, log);
    FAIL() << "a params field that is not JSON was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("labels.csv:2: the params column is not JSON"), std::string::npos) << e.what();
  }
}

TEST(DiagnoseIndependentSuite, FixedSubsetRegressionFloor) {
  // The first 12 cases of tests/data/independent (made by a separate Python generator,
  // tests/data/independent/generate.py, from physical descriptions only; labels in labels.csv).
  // The issue's targets (>= 95% single effects, <= 2% false alarms, >= 80% mixtures named) are NOT
  // met yet: this asserts today's level so it cannot silently get worse; the report prints the targets.
  std::ostringstream log;
  const auto r = run_directory_suite(std::string(PVCGEL_SOURCE_DIR) + "/tests/data/independent", 2, log, 12);
  std::cout << log.str() << format_directory_suite(r);
  EXPECT_EQ(r.cases, 12);
  EXPECT_EQ(r.failed, 0);
  EXPECT_EQ(r.false_alarms, 0);
  EXPECT_GE(r.single_correct, 5);
  for (double ratio : r.ratios) EXPECT_LE(ratio, 0.5);
  EXPECT_LE(r.ratios_held_out_shows_effect.size(), r.ratios.size());
  // The labels have a form column: every single effect is counted under its form, once.
  int by_form = 0, by_form_right = 0;
  for (const auto& [form, n] : r.single_by_form) by_form_right += n[0], by_form += n[1];
  EXPECT_EQ(by_form, r.single_cases);
  EXPECT_EQ(by_form_right, r.single_correct);
  // The split by the nuisance refit's bounds counts every right case once, on one side.
  EXPECT_LE(r.refit_at_bound_right, r.refit_at_bound);
  EXPECT_EQ(r.refit_at_bound_right + r.refit_inside_right,
            r.single_correct + (r.none_cases - r.false_alarms) + r.mixture_both_named);
  // No single-effect or none case of the subset names a false second effect (measured at this level).
  EXPECT_EQ(r.false_second, 0);
  EXPECT_LE(r.single_ambiguous_right + r.single_truth_among_ambiguous, r.single_ambiguous);
  // The subset's labels carry the generator's after-refit ratios: the split covers part of the effect cases.
  EXPECT_GT(r.visible_single_cases + r.visible_mixture_cases, 0);
  EXPECT_LE(r.visible_single_cases, r.single_cases);
  EXPECT_LE(r.visible_single_correct, std::min(r.visible_single_cases, r.single_correct));
  EXPECT_LE(r.visible_mixture_both_named, std::min(r.visible_mixture_cases, r.mixture_both_named));
  // Every mixture left unnamed is counted once under its best pair.
  EXPECT_EQ(r.mixture_missed_no_pair + r.mixture_missed_other_pair + r.mixture_missed_labels_pair,
            r.mixture_cases - r.mixture_both_named);
  EXPECT_LE(r.mixture_other_pair_labels_fitted, r.mixture_missed_other_pair);
}

}  // namespace
}  // namespace pvcgel::tools

#include "control/config/config_parser.hpp"

#include <gtest/gtest.h>

#include <string>

#include "control/config_error.hpp"

namespace pvcgel::control {
namespace {

RigConfiguration parse(const std::string& text) { return parse_configuration(toml::parse(text), "test.toml"); }

// Parses `text` and expects a ConfigError naming `key`, with the source file in the message.
void expect_key(const std::string& text, const std::string& key) {
  try {
    (void)parse(text);
    ADD_FAILURE() << "accepted:\n" << text;
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), key) << e.what() << "\nfor:\n" << text;
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind(key + ": ", 0), 0u) << msg;
    EXPECT_NE(msg.find("(in test.toml)"), std::string::npos) << msg;
  }
}

TEST(ConfigParser, ShippedPaperRigFileMatchesThePaperModels) {
  const std::string path = std::string(PVCGEL_SOURCE_DIR) + "/config/paper-rig.toml";
  const auto cfg = parse_configuration(toml::parse_file(path), path);
  EXPECT_EQ(cfg.model.f.coefficients(), paper_model(2).f.coefficients());
  EXPECT_EQ(cfg.model.G.num(), paper_model(2).G.num());
  EXPECT_EQ(cfg.model.G.den(), paper_model(2).G.den());
  EXPECT_EQ(cfg.sim.truth.f.coefficients(), paper_model(3).f.coefficients());
  EXPECT_EQ(cfg.controller.mode, ControllerMode::inverse_pid_dob);
  EXPECT_EQ(cfg.controller.sample_time_s, 1e-3);
  EXPECT_EQ(cfg.controller.io_delay_samples, 1);
  ASSERT_TRUE(cfg.controller.tuning.has_value());
  EXPECT_EQ(cfg.controller.tuning->crossover_rad_s, 45.0);
  EXPECT_EQ(cfg.controller.tuning->phase_margin_deg, 60.0);
  EXPECT_EQ(cfg.controller.dob_lambda_s, 0.1);
  EXPECT_EQ(cfg.sim.noise_sigma_um, 0.05);
  EXPECT_EQ(cfg.sim.quantization_um, 0.01);
  EXPECT_TRUE(cfg.sim.hysteresis.enabled);
  EXPECT_EQ(cfg.sim.hysteresis.alpha, 0.05);
  EXPECT_EQ(cfg.sim.creep.time_constant_s, 20.0);
  EXPECT_EQ(cfg.sim.sample_time_s, cfg.controller.sample_time_s);
}

TEST(ConfigParser, EmptyFileGivesTheDefaults) {
  const auto cfg = parse("");
  EXPECT_EQ(cfg.model.f.coefficients(), paper_model(2).f.coefficients());
  EXPECT_EQ(cfg.controller.mode, ControllerConfig{}.mode);
  ASSERT_TRUE(cfg.controller.tuning.has_value());
  EXPECT_EQ(cfg.controller.tuning->crossover_rad_s, TuningTarget{}.crossover_rad_s);
  EXPECT_EQ(cfg.sim.truth.f.coefficients(), paper_model(3).f.coefficients());
}

TEST(ConfigParser, ReadsValuesIntoTheStructures) {
  const auto cfg = parse(R"(
[model]
poly = [1.3664]
G_num = [1.15, 1.03]
G_den = [1.0, 17.11, 8.76]
io_delay_samples = 2
[controller]
mode = "inverse_pid_dob_ff"
voltage_max_V = 800
slew_limit_V_per_s = 5000.0
[controller.dob]
lambda_s = 0.05
[controller.tuning]
crossover_rad_s = 30.0
[sim]
seed = 7
noise_sigma_um = 0.0
[sim.creep]
enabled = false
)");
  EXPECT_EQ(cfg.model.f.coefficients(), std::vector<double>{1.3664});
  EXPECT_EQ(cfg.controller.io_delay_samples, 2);
  EXPECT_EQ(cfg.controller.mode, ControllerMode::inverse_pid_dob_ff);
  EXPECT_EQ(cfg.controller.voltage_max_V, 800.0);  // integers are accepted as numbers
  EXPECT_EQ(cfg.controller.slew_limit_V_per_s, 5000.0);
  EXPECT_EQ(cfg.controller.dob_lambda_s, 0.05);
  ASSERT_TRUE(cfg.controller.tuning.has_value());
  EXPECT_EQ(cfg.controller.tuning->crossover_rad_s, 30.0);
  EXPECT_EQ(cfg.sim.seed, 7u);
  EXPECT_EQ(cfg.sim.noise_sigma_um, 0.0);
  EXPECT_FALSE(cfg.sim.creep.enabled);
  EXPECT_TRUE(cfg.sim.hysteresis.enabled);  // untouched default
}

TEST(ConfigParser, ManualGainsForEveryMode) {
  // Take tuned gains (known to be stable) and feed them back as manual tables.
  const Controller tuned(paper_model(2), ControllerConfig{});
  std::string text = "[controller.pid]\n";
  for (auto m : kAllModes) {
    const auto& g = tuned.gains(m);
    char buf[256];
    std::snprintf(buf, sizeof buf, "%s = { kp = %.17g, ki = %.17g, kd = %.17g, tf_s = %.17g }\n",
                  std::string(to_string(m)).c_str(), g.kp, g.ki, g.kd, g.tf_s);
    text += buf;
  }
  const auto cfg = parse(text);
  EXPECT_FALSE(cfg.controller.tuning.has_value());
  for (auto m : kAllModes) EXPECT_EQ(cfg.controller.gains[static_cast<size_t>(m)].kp, tuned.gains(m).kp);
}

TEST(ConfigParser, ErrorsNameTheDottedKey) {
  expect_key("[controller]\nvoltage_max_V = 1200.0\n", "controller.voltage_max_V");
  expect_key("[controller]\nvoltage_min_V = -5.0\n", "controller.voltage_min_V");
  expect_key("[controller]\nvoltage_max_V = \"high\"\n", "controller.voltage_max_V");
  expect_key("[controller]\nvoltage_max_V = nan\n", "controller.voltage_max_V");
  expect_key("[controller]\nmode = \"fast\"\n", "controller.mode");
  expect_key("[controller]\nperiod = 0.001\n", "controller.period");  // typo: unknown key
  expect_key("[controller.dob]\nq_order = 1.5\n", "controller.dob.q_order");
  expect_key("[controller.dob]\nlambda_s = 0.0\n", "controller.dob.lambda_s");
  expect_key("[controller.tuning]\ncrossover_rad_s = 1500.0\nphase_margin_deg = 80.0\n", "controller.tuning");
  expect_key("[controller.tuning]\n[controller.pid]\n", "controller.pid");
  expect_key("[sim]\nnoise_sigma_um = -1.0\n", "sim.noise_sigma_um");
  expect_key("[sim.hysteresis]\nenabled = 1\n", "sim.hysteresis.enabled");
  expect_key("[sim.truth]\npoly = [0.1]\nG_num = [1.0]\n", "sim.truth.G_den");
  expect_key("unknown = 3\n", "unknown");
  expect_key("[model]\npoly = [0.0721, 2.1307e-5, -1.7231e-11]\nG_num = [1.15, 1.03]\nG_den = [1.0, 17.11, 8.76]\n",
             "model.poly");  // non-monotone on 0..1000 V
  expect_key("[model]\npoly = [0.127, \"x\"]\nG_num = [1.0]\nG_den = [1.0, 1.0]\n", "model.poly[1]");
  expect_key("[model]\npoly = []\nG_num = [1.0]\nG_den = [1.0, 1.0]\n", "model.poly");
  expect_key("[model]\npoly = [0.127]\nG_num = [-1.15, 1.03]\nG_den = [1.0, 17.11, 8.76]\n", "model.G");  // RHP zero
}

TEST(ConfigParser, ModelEffectsReachTheController) {
  const std::string model = "[model]\npoly = [0.1270, 1.3057e-5]\nG_num = [1.15, 1.03]\nG_den = [1.0, 17.11, 8.76]\n";
  const auto cfg = parse(model + "[[model.effect]]\nname = \"hysteresis\"\nalpha = 0.1\nthreshold_scale_V = 30.0\n"
                                 "[[model.effect]]\nname = \"creep\"\nfraction = 0.05\ntime_constant_s = 10.0\n");
  ASSERT_EQ(cfg.controller.effects.size(), 2u);
  EXPECT_EQ(cfg.controller.effects[0].kind, EffectKind::hysteresis);
  EXPECT_DOUBLE_EQ(cfg.controller.effects[0].p[1], 30.0);
  EXPECT_EQ(cfg.controller.effects[1].kind, EffectKind::creep);
  EXPECT_DOUBLE_EQ(cfg.controller.effects[1].p[2], 0.0);  // spread_decades' default
  // Bad tables and refused effects name the table.
  expect_key(model + "[[model.effect]]\nname = \"hysteresis\"\nalpha = 0.1\n", "model.effect[0].threshold_scale_V");
  expect_key(model + "[[model.effect]]\nname = \"backlash\"\n", "model.effect[0].name");
  expect_key(model + "[[model.effect]]\nname = \"asymmetric_dynamics\"\nrelaxation_slowdown = 0.3\n", "model.effect[0]");
  expect_key(model + "[[model.effect]]\nname = \"hysteresis\"\nalpha = 0.95\nthreshold_scale_V = 30.0\n",
             "model.effect[0].alpha");
}

TEST(ConfigParser, OutOfRangeIntegersAreRejected) {
  expect_key("[controller.dob]\nq_order = 4294967297\n", "controller.dob.q_order");
  expect_key("[model]\npoly = [0.127, 1.3057e-5]\nG_num = [1.15, 1.03]\nG_den = [1.0, 17.11, 8.76]\n"
             "io_delay_samples = 4294967297\n",
             "model.io_delay_samples");
}

TEST(ConfigParser, MissingManualGainTableNamesTheTable) {
  expect_key("[controller.pid]\npid = { kp = 1.0, ki = 10.0, kd = 0.0, tf_s = 0.0 }\n", "controller.pid.inverse_pid");
}

}  // namespace
}  // namespace pvcgel::control

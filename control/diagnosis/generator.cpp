#include "control/diagnosis/generator.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <optional>
#include <random>

#include "control/controller.hpp"
#include "control/reference_signal.hpp"
#include "control/simulated_rig.hpp"
#include "control/state_space.hpp"

namespace pvcgel::control::diagnosis {

namespace {

constexpr double kPi = std::numbers::pi;

/// The generator's effect: its own magnitude and shape parameters.
struct TruthEffect {
  EffectKind kind = EffectKind::none;
  double m = 0.0;       ///< magnitude (monotone in the effect size)
  double a = 0.0, b = 0.0, c = 0.0;  ///< shape parameters (per kind)
};

/// The truth a case is generated on. Hysteresis, delay and the baseline use
/// SimulatedRig; the other effects a continuous-time model integrated by RK4.
class TruthPlant {
 public:
  TruthPlant(const HammersteinModel& model, const GeneratorOptions& o, const TruthEffect& e, std::uint64_t seed)
      : e_(e), f_(model.f), Ts_(o.sample_time_s), io_(o.io_delay_samples), noise_(o.noise_sigma_um),
        quant_(o.quantization_um), rng_(seed) {
    if (e.kind == EffectKind::none || e.kind == EffectKind::hysteresis || e.kind == EffectKind::delay) {
      SimRigConfig c = SimRigConfig{}.exactly(model);
      c.sample_time_s = Ts_;
      c.io_delay_samples = io_ + (e.kind == EffectKind::delay ? static_cast<int>(e.m) : 0);
      c.noise_sigma_um = noise_;
      c.quantization_um = quant_;
      c.seed = seed;
      if (e.kind == EffectKind::hysteresis) {
        c.hysteresis.enabled = true;
        c.hysteresis.alpha = e.m;
        c.hysteresis.saturation_V = e.a;
      }
      rig_ = std::make_unique<SimulatedRig>(c);
      return;
    }
    const auto ss = realize(model.G);
    A_ = ss.A;
    B_ = ss.B;
    C_ = ss.C;
    D_ = ss.D;
    G0_ = model.G.dc_gain();
    n_ = ss.order();
    if (const auto turn = f_.first_turnover(1000.0)) x_sat_ = *turn;
    X_ = Eigen::VectorXd::Zero(n_ + 7);
  }

  void reset_steady_state(double u) {
    if (rig_) return rig_->reset_steady_state(u);
    line_.assign(static_cast<size_t>(io_), u);
    t_ = 0.0;
    const double w = static_input(u);
    X_.head(n_) = -A_.partialPivLu().solve(B_ * w);
    const double y = C_.dot(X_.head(n_)) + D_ * w;
    X_(n_) = 0.6 * e_.m * G0_ * w;  // creep elements
    X_(n_ + 1) = 0.4 * e_.m * G0_ * w;
    amplifier_start_ = u;
    X_(n_ + 6) = y;  // low-passed displacement (operating point)
    X_(n_ + 4) = y;  // mode position and velocity
    X_(n_ + 5) = 0.0;
    u_held_ = u;
  }

  [[nodiscard]] double true_output() const {
    if (rig_) return rig_->true_displacement_um();
    const double w = static_input(amplifier_start_);
    double y = C_.dot(X_.head(n_)) + D_ * w;
    switch (e_.kind) {
      case EffectKind::creep: y += X_(n_) + X_(n_ + 1); break;
      case EffectKind::resonance: y = X_(n_ + 4); break;
      case EffectKind::saturation: y = std::tanh(e_.m * y) / e_.m; break;
      case EffectKind::drift:
        if (t_ > e_.a) y += e_.m * (1.0 - std::exp(-(t_ - e_.a) / e_.b));
        break;
      default: break;
    }
    return y;
  }

  double measure() {
    if (rig_) return rig_->measure();
    double y = true_output() + noise_ * normal_(rng_);
    if (quant_ > 0) y = std::round(y / quant_) * quant_;
    return y;
  }

  void apply(double u) {
    if (rig_) return rig_->apply(u);
    line_.push_back(u);
    u_held_ = line_.front();
    line_.erase(line_.begin());
    constexpr int kSub = 4;
    const double h = Ts_ / kSub;
    for (int i = 0; i < kSub; ++i) {
      const double tau = i * h;
      const Eigen::VectorXd k1 = derivative(X_, tau);
      const Eigen::VectorXd k2 = derivative(X_ + 0.5 * h * k1, tau + 0.5 * h);
      const Eigen::VectorXd k3 = derivative(X_ + 0.5 * h * k2, tau + 0.5 * h);
      const Eigen::VectorXd k4 = derivative(X_ + h * k3, tau + h);
      X_ += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
    amplifier_start_ = amplifier(Ts_);
    t_ += Ts_;
  }

 private:
  [[nodiscard]] double static_input(double u) const {
    double x = u;
    if (e_.kind == EffectKind::dead_zone) x = u * (1.0 - std::exp(-std::pow(u / e_.m, 4)));
    return f_(std::min(x, x_sat_));
  }

  /// Amplifier voltage tau into the sample: a continuous ramp at the slew rate toward the command.
  [[nodiscard]] double amplifier(double tau) const {
    if (e_.kind != EffectKind::slew_limit) return u_held_;
    const double e = u_held_ - amplifier_start_;
    return amplifier_start_ + std::copysign(std::min(std::abs(e), tau / e_.m), e);
  }

  [[nodiscard]] Eigen::VectorXd derivative(const Eigen::VectorXd& X, double tau) const {
    Eigen::VectorXd d = Eigen::VectorXd::Zero(X.size());
    const double ua = amplifier(tau);
    const double w = static_input(ua);
    const auto xg = X.head(n_);
    const double y_lin = C_.dot(xg) + D_ * w;
    double scale = 1.0;
    if (e_.kind == EffectKind::asymmetric_dynamics)
      scale = 1.0 + e_.m * 0.5 * (1.0 + std::tanh((y_lin - G0_ * w) / 0.2));
    if (e_.kind == EffectKind::bias_dependent_dynamics) scale = 1.0 + e_.m * X(n_ + 6) / 100.0;
    d.head(n_) = (A_ * xg + B_ * w) / scale;
    const double tau1 = e_.a, tau2 = 5.0 * e_.a;
    if (e_.kind == EffectKind::creep) {
      d(n_) = (0.6 * e_.m * G0_ * w - X(n_)) / tau1;
      d(n_ + 1) = (0.4 * e_.m * G0_ * w - X(n_ + 1)) / tau2;
    }
    d(n_ + 6) = (y_lin - X(n_ + 6)) / 0.5;
    if (e_.kind == EffectKind::resonance) {
      const double wn = 2.0 * kPi / e_.m, zeta = e_.a;
      d(n_ + 4) = X(n_ + 5);
      d(n_ + 5) = wn * wn * (y_lin - X(n_ + 4)) - 2.0 * zeta * wn * X(n_ + 5);
    }
    return d;
  }

  TruthEffect e_;
  OddPolynomial f_;
  double Ts_;
  int io_;
  double noise_, quant_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::unique_ptr<SimulatedRig> rig_;
  Eigen::MatrixXd A_;
  Eigen::VectorXd B_;
  Eigen::RowVectorXd C_;
  double D_ = 0.0, G0_ = 0.0, x_sat_ = 1000.0;
  int n_ = 0;
  Eigen::VectorXd X_;
  std::vector<double> line_;
  double u_held_ = 0.0, t_ = 0.0;
  double amplifier_start_ = 0.0;  ///< amplifier voltage at the start of this sample
};

/// An excitation: open-loop voltage u(t) or a closed-loop reference r(t).
struct Excitation {
  bool closed_loop = false;
  std::vector<double> u_V;  ///< open loop
  MultiSine reference;      ///< closed loop
  std::string description;
};

double log_uniform(std::mt19937_64& rng, double lo, double hi) {
  return std::exp(std::uniform_real_distribution<double>(std::log(lo), std::log(hi))(rng));
}

/// A closed-loop reference: one of the paper's, or a sine around a random level.
MultiSine draw_reference(std::mt19937_64& rng, std::string& description) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  if (U(rng) < 0.5) {
    const auto& name = kPaperReferenceNames[static_cast<size_t>(U(rng) * 3.999)];
    description = "closed loop, paper reference " + name;
    return *paper_reference(name);
  }
  MultiSine r;
  r.offset_um = 40.0 + 200.0 * U(rng);
  r.n_tones = 1;
  r.tones[0] = {std::min(10.0 + 50.0 * U(rng), 0.8 * r.offset_um), log_uniform(rng, 0.1, 1.0), 0.0};
  description = "closed loop, sine reference " + std::to_string(std::lround(r.tones[0].amplitude_um)) + " um around " +
                std::to_string(std::lround(r.offset_um)) + " um";
  return r;
}

/// The bias range of an open-loop excitation: low-voltage ones (for effects that only show there) 40..150 V.
struct BiasRange {
  double lo, span;
};

/// Sines at several amplitudes and biases, one per third of the recording.
void draw_sines(std::mt19937_64& rng, BiasRange b, double Ts, Excitation& ex) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const size_t n = ex.u_V.size();
  ex.description = "sines";
  for (size_t seg = 0; seg < 3; ++seg) {
    const double bias = b.lo + b.span * U(rng);
    const double amp = (0.3 + 0.65 * U(rng)) * std::min(bias, 780.0 - bias);
    const double f = log_uniform(rng, 0.1, 2.0);
    // Appended piece by piece: GCC 12 warns (-Wrestrict, a false positive) on " " + std::to_string(...) here.
    ex.description.append(" ").append(std::to_string(std::lround(amp))).append("V@").append(std::to_string(std::lround(bias))).append("V");
    for (size_t k = seg * n / 3; k < (seg + 1) * n / 3; ++k)
      ex.u_V[k] = bias + amp * std::sin(2 * kPi * f * static_cast<double>(k - seg * n / 3) * Ts);
  }
}

/// Steps to random levels, held 1..4 s each.
void draw_steps(std::mt19937_64& rng, bool low_voltage, double Ts, Excitation& ex) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  ex.description = "steps";
  double level = 0.0;
  size_t next = 0;
  for (size_t k = 0; k < ex.u_V.size(); ++k) {
    if (k == next) {
      level = low_voltage ? 10.0 + 200.0 * U(rng) : 20.0 + 730.0 * U(rng);
      next = k + static_cast<size_t>((1.0 + 3.0 * U(rng)) / Ts);
    }
    ex.u_V[k] = level;
  }
}

/// Four sines of random frequency and phase around one bias.
void draw_multisine(std::mt19937_64& rng, bool low_voltage, BiasRange b, double Ts, Excitation& ex) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const double bias = low_voltage ? b.lo + b.span * U(rng) : 150.0 + 300.0 * U(rng);
  const double room = std::min(bias, 780.0 - bias);
  ex.description = "multisine around " + std::to_string(std::lround(bias)) + " V";
  std::array<double, 4> f{}, ph{};
  for (size_t i = 0; i < 4; ++i) {
    f[i] = log_uniform(rng, 0.05, 5.0);
    ph[i] = 2 * kPi * U(rng);
  }
  for (size_t k = 0; k < ex.u_V.size(); ++k) {
    double v = 0.0;
    for (size_t i = 0; i < 4; ++i) v += std::sin(2 * kPi * f[i] * static_cast<double>(k) * Ts + ph[i]);
    ex.u_V[k] = bias + 0.24 * room * v;
  }
}

/// An exponential chirp from 0.05 Hz to 1..6 Hz over the recording.
void draw_chirp(std::mt19937_64& rng, bool low_voltage, BiasRange b, double Ts, double T, Excitation& ex) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const double bias = low_voltage ? b.lo + b.span * U(rng) : 100.0 + 350.0 * U(rng);
  const double amp = (0.4 + 0.5 * U(rng)) * std::min(bias, 780.0 - bias);
  const double f0 = 0.05, f1 = log_uniform(rng, 1.0, 6.0);
  ex.description = "chirp 0.05.." + std::to_string(std::lround(f1)) + " Hz around " + std::to_string(std::lround(bias)) + " V";
  for (size_t k = 0; k < ex.u_V.size(); ++k) {
    const double t = static_cast<double>(k) * Ts;
    const double phase = 2 * kPi * f0 * T / std::log(f1 / f0) * (std::pow(f1 / f0, t / T) - 1.0);
    ex.u_V[k] = bias + amp * std::sin(phase);
  }
}

Excitation draw_excitation(std::mt19937_64& rng, const GeneratorOptions& o, bool low_voltage, bool no_steps) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  Excitation ex;
  if (!low_voltage && U(rng) < o.closed_loop_probability) {
    ex.closed_loop = true;
    ex.reference = draw_reference(rng, ex.description);
    return ex;
  }
  ex.u_V.resize(static_cast<size_t>(std::lround(o.duration_s / o.sample_time_s)));
  const double Ts = o.sample_time_s;
  int type = static_cast<int>(U(rng) * 4.0);
  if (no_steps && type == 1) type = 2;
  const BiasRange bias{low_voltage ? 40.0 : 60.0, low_voltage ? 110.0 : 440.0};
  if (type == 0) draw_sines(rng, bias, Ts, ex);
  else if (type == 1) draw_steps(rng, low_voltage, Ts, ex);
  else if (type == 2) draw_multisine(rng, low_voltage, bias, Ts, ex);
  else draw_chirp(rng, low_voltage, bias, Ts, o.duration_s, ex);
  for (double& u : ex.u_V) u = std::clamp(u, 0.0, 800.0);
  return ex;
}

struct Run {
  Series series;
  double initial_V = 0.0;  ///< the truth's rest voltage before the first sample
  std::vector<double> y_true;
};

Run run_case(const HammersteinModel& model, const GeneratorOptions& o, const TruthEffect& e, const Excitation& ex,
             std::uint64_t seed) {
  TruthPlant plant(model, o, e, seed);
  const auto n = static_cast<size_t>(std::lround(o.duration_s / o.sample_time_s));
  Run run;
  auto& s = run.series;
  s.sample_time_s = o.sample_time_s;
  s.t_s.resize(n);
  s.u_V.resize(n);
  s.y_um.resize(n);
  run.y_true.resize(n);
  std::optional<Controller> ctl;
  std::vector<double> window;
  if (ex.closed_loop) {
    ControllerConfig cc;
    cc.sample_time_s = o.sample_time_s;
    cc.io_delay_samples = o.io_delay_samples;
    cc.voltage_max_V = 800.0;
    ctl.emplace(model, cc);
    window.resize(static_cast<size_t>(ctl->preview_samples() + 1));
    for (size_t i = 0; i < window.size(); ++i) window[i] = ex.reference(static_cast<double>(i) * o.sample_time_s);
    ctl->reset_steady_state(window[0]);
    run.initial_V = ctl->last_voltage_V();
  } else {
    run.initial_V = ex.u_V[0];
  }
  plant.reset_steady_state(run.initial_V);
  for (size_t k = 0; k < n; ++k) {
    s.t_s[k] = static_cast<double>(k) * o.sample_time_s;
    run.y_true[k] = plant.true_output();
    s.y_um[k] = plant.measure();
    if (ctl) {
      s.u_V[k] = ctl->step(window, s.y_um[k]).voltage_V;
      std::rotate(window.begin(), window.begin() + 1, window.end());
      window.back() = ex.reference(static_cast<double>(k + window.size()) * o.sample_time_s);
    } else {
      s.u_V[k] = ex.u_V[k];
    }
    plant.apply(s.u_V[k]);
  }
  return run;
}

/// RMS on the held-out segment and peak of (true output - nominal model from the recorded u).
std::pair<double, double> effect_size(const HammersteinModel& model, const GeneratorOptions& o, const Run& run) {
  AugmentedPlant nominal(model, o.io_delay_samples, o.sample_time_s, Effect{});
  const auto y0 = nominal.simulate(run.series.u_V, run.initial_V);
  const auto held_out = held_out_mask(y0.size(), o.sample_time_s);
  double sum = 0.0, peak = 0.0, n = 0.0;
  for (size_t k = 0; k < y0.size(); ++k) {
    const double d = run.y_true[k] - y0[k];
    peak = std::max(peak, std::abs(d));
    if (held_out[k]) sum += d * d, n += 1.0;
  }
  return {std::sqrt(sum / std::max(n, 1.0)), peak};
}

TruthEffect draw_shape(EffectKind kind, std::mt19937_64& rng, double duration_s) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const double sign = U(rng) < 0.5 ? -1.0 : 1.0;
  TruthEffect e{kind, 0.0, 0.0, 0.0, 0.0};
  switch (kind) {
    case EffectKind::hysteresis: e = {kind, 0.01, 10.0 + 70.0 * U(rng)}; break;
    case EffectKind::creep: e = {kind, 0.003, 1.0 + 5.0 * U(rng)}; break;
    case EffectKind::dead_zone: e = {kind, 30.0}; break;
    case EffectKind::saturation: e = {kind, 5e-4}; break;
    case EffectKind::delay: e = {kind, 1.0}; break;
    case EffectKind::asymmetric_dynamics: e = {kind, sign * 0.1}; break;
    case EffectKind::slew_limit: e = {kind, 1.0 / 3000.0}; break;
    case EffectKind::resonance: e = {kind, 1.0 / 40.0, 0.03 + 0.25 * U(rng)}; break;
    case EffectKind::drift:
      e = {kind, sign * 0.3, 0.4 * duration_s * U(rng), duration_s * (0.5 + 1.5 * U(rng))};
      break;
    case EffectKind::bias_dependent_dynamics: e = {kind, sign * 0.05}; break;
    case EffectKind::none: break;
  }
  return e;
}

/// Lower bound of the magnitude: below it the effect is indistinguishable
/// from another one (a slew limit of a few samples or a mode far above the
/// gel's bandwidth is a delay), so such a case is redrawn instead.
double magnitude_floor(EffectKind kind) {
  switch (kind) {
    case EffectKind::slew_limit: return 1.0 / 20000.0;  // S <= 20 kV/s
    case EffectKind::resonance: return 1.0 / 60.0;      // f_n <= 60 Hz
    default: return 0.0;
  }
}

/// Upper bound of the magnitude (physically sensible range of the generator's form).
double magnitude_cap(EffectKind kind) {
  switch (kind) {
    case EffectKind::hysteresis: return 0.5;
    case EffectKind::creep: return 0.2;
    case EffectKind::dead_zone: return 150.0;
    case EffectKind::saturation: return 2e-2;
    case EffectKind::delay: return 12.0;  // the rig's delay line holds 15 samples
    case EffectKind::asymmetric_dynamics: return 2.0;
    case EffectKind::slew_limit: return 1.0 / 50.0;
    case EffectKind::resonance: return 1.0 / 3.0;  // f_n >= 3 Hz
    case EffectKind::drift: return 20.0;
    case EffectKind::bias_dependent_dynamics: return 1.5;
    case EffectKind::none: return 0.0;
  }
  return 0.0;
}

/// A run at the magnitude found for the target, with its effect's RMS and peak (0 for `none`).
struct SizedRun {
  Run run;
  double rms = 0.0, peak = 0.0;
};

/// Whole samples: the smallest delay that reaches 0.85 of the target RMS (sets e.m).
SizedRun size_delay(const HammersteinModel& model, const GeneratorOptions& o, TruthEffect& e, const Excitation& ex,
                    std::uint64_t seed, double target) {
  SizedRun s;
  for (int d = 1; d <= static_cast<int>(magnitude_cap(EffectKind::delay)); ++d) {
    e.m = d;
    s.run = run_case(model, o, e, ex, seed);
    std::tie(s.rms, s.peak) = effect_size(model, o, s.run);
    if (s.rms >= 0.85 * target) break;
  }
  return s;
}

/// Secant on log(magnitude) toward the target RMS, within the kind's floor and cap (sets e.m).
SizedRun size_by_secant(const HammersteinModel& model, const GeneratorOptions& o, EffectKind kind, TruthEffect& e,
                        const Excitation& ex, std::uint64_t seed, double target) {
  SizedRun s;
  const double sign = e.m < 0 ? -1.0 : 1.0;
  double lm = std::log(std::abs(e.m)), lr_prev = 0.0, lm_prev = 0.0;
  for (int it = 0; it < 10; ++it) {
    e.m = sign * std::clamp(std::exp(lm), magnitude_floor(kind), magnitude_cap(kind));
    s.run = run_case(model, o, e, ex, seed);
    std::tie(s.rms, s.peak) = effect_size(model, o, s.run);
    const double lr = std::log(std::max(s.rms, 1e-12));
    if (std::abs(lr - std::log(target)) < 0.08 || (std::abs(e.m) >= magnitude_cap(kind) && s.rms < target) ||
        (std::abs(e.m) <= magnitude_floor(kind) && s.rms > target))
      break;
    double slope = 1.0;
    if (it > 0 && std::abs(lm - lm_prev) > 1e-9) slope = std::clamp((lr - lr_prev) / (lm - lm_prev), 0.2, 5.0);
    lm_prev = lm;
    lr_prev = lr;
    lm += std::clamp((std::log(target) - lr) / slope, -3.0, 3.0);
  }
  return s;
}

}  // namespace

GeneratedCase generate_case(const HammersteinModel& model, EffectKind kind, std::uint64_t seed,
                            const GeneratorOptions& o) {
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ULL + 17);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  GeneratedCase out;
  out.truth.effect = kind;
  double x_top = 800.0;
  if (const auto turn = model.f.first_turnover(800.0)) x_top = *turn;
  out.truth.stroke_um = model.G.dc_gain() * model.f(x_top);
  const double target = o.noise_sigma_um * (o.effect_rms_min + (o.effect_rms_max - o.effect_rms_min) * U(rng));
  for (int attempt = 0; attempt < 12; ++attempt) {
    // A dead zone only shows near 0 V: after two misses, excite there.
    // The rig's Bouc-Wen update is explicit: jumps of many h_sat in one sample
    // are outside its validity, so hysteresis cases get no steps.
    const Excitation ex =
        draw_excitation(rng, o, kind == EffectKind::dead_zone && attempt >= 2, kind == EffectKind::hysteresis);
    TruthEffect e = draw_shape(kind, rng, o.duration_s);
    const SizedRun sized = kind == EffectKind::none    ? SizedRun{run_case(model, o, e, ex, seed)}
                           : kind == EffectKind::delay ? size_delay(model, o, e, ex, seed, target)
                                                       : size_by_secant(model, o, kind, e, ex, seed, target);
    const double rms = sized.rms, peak = sized.peak;
    out.recordings = {sized.run.series};
    out.truth.magnitude = e.m;
    out.truth.effect_rms_um = rms;
    out.truth.effect_peak_um = peak;
    out.truth.closed_loop = ex.closed_loop;
    out.truth.input = ex.description;
    // Concealed: a few noise sigmas, well under 1% of the stroke.
    out.truth.within_spec =
        kind == EffectKind::none ||
        (rms >= 0.8 * target && rms <= 1.5 * o.effect_rms_max * o.noise_sigma_um && peak < 0.01 * out.truth.stroke_um);
    if (out.truth.within_spec) return out;
  }
  return out;
}

std::vector<std::pair<EffectKind, std::uint64_t>> blind_suite_plan(int cases, std::uint64_t seed) {
  std::vector<EffectKind> labels;
  const auto kinds = kEffectKindNames.enumerators();  // none and the ten effects in turn
  for (int i = 0; i < cases; ++i) labels.push_back(kinds[static_cast<size_t>(i) % kinds.size()]);
  std::mt19937_64 rng(seed);
  std::shuffle(labels.begin(), labels.end(), rng);
  std::vector<std::pair<EffectKind, std::uint64_t>> plan;
  for (int i = 0; i < cases; ++i) plan.emplace_back(labels[static_cast<size_t>(i)], seed * 1000 + static_cast<std::uint64_t>(i));
  return plan;
}

}  // namespace pvcgel::control::diagnosis

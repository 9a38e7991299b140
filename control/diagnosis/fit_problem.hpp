#pragma once
/// @file
/// The fitting machinery of the diagnosis (internal): a candidate's parameter space (`FitSpace`), the
/// simulation of a model with effects and the projection of the linear nuisance parameters (`Problem`),
/// bounded Levenberg-Marquardt over the rest, and `run_each` for fits on the caller's threads.

#include <Eigen/Dense>
#include <array>
#include <atomic>
#include <cmath>
#include <functional>
#include <numeric>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "control/diagnosis/diagnosis.hpp"
#include "control/effect.hpp"

namespace pvcgel::control::diagnosis::detail {

/// Sum of squared residuals over [begin, end) and the count.
struct SquaredError {
  double sum = 0.0;
  double n = 0.0;
  void add(double r) {
    sum += r * r;
    n += 1.0;
  }
  [[nodiscard]] double mse() const { return n > 0 ? sum / n : 0.0; }
};

/// The bounded refit of the nominal model that is fitted as a nonlinear nuisance:
/// G's time constants scaled by time_scale, f's coefficients above the linear one by shape,
/// and one odd term of the next order added to f (`next`: its slope at the largest recorded |u| over
/// f's mean slope f(u)/u there).
struct Nominal {
  Nominal(double ts = 1.0, double sh = 1.0, double nx = 0.0) : time_scale(ts), shape(sh), next(nx) {}  // NOLINT: a bare time scale converts
  double time_scale, shape, next;
};

constexpr Eigen::Index kNominalParams = 3;

/// Internal (fit) coordinates of a joint fit: the effects' parameters, then
/// (optionally) G's time scale; log for scale parameters, range-normalised otherwise.
struct FitSpace {
  std::vector<EffectKind> kinds;
  std::vector<ParameterSpec> specs;
  std::vector<size_t> first;  ///< index of each kind's first parameter in specs
  bool time_scale = false;    ///< the last three specs are the nominal refit (G's time scale, f's shape, f's next term)

  FitSpace(std::vector<EffectKind> k, const DataScale& d, bool with_nominal, const DiagnosisOptions& o,
           const std::vector<Series>* data = nullptr);
  [[nodiscard]] double scale(size_t i) const { return (specs[i].upper - specs[i].lower) / 100.0; }
  [[nodiscard]] double to_z(size_t i, double p) const {
    if (specs[i].fixed) return 0.0;
    return specs[i].log_scale ? std::log(p) : p / scale(i);
  }
  [[nodiscard]] double to_p(size_t i, double z) const {
    if (specs[i].fixed) return specs[i].lower;
    const double p = specs[i].log_scale ? std::exp(z) : z * scale(i);
    return std::clamp(p, specs[i].lower, specs[i].upper);
  }
  [[nodiscard]] size_t end_of(size_t e) const {
    return e + 1 < kinds.size() ? first[e + 1] : specs.size() - (time_scale ? kNominalParams : 0);
  }
  [[nodiscard]] std::vector<Effect> effects(const Eigen::VectorXd& z) const {
    std::vector<Effect> out;
    for (size_t e = 0; e < kinds.size(); ++e) {
      Effect x{kinds[e], {}};
      for (size_t i = first[e]; i < end_of(e); ++i) x.p[i - first[e]] = to_p(i, z(static_cast<Eigen::Index>(i)));
      out.push_back(x);
    }
    return out;
  }
  [[nodiscard]] Nominal g_scale(const Eigen::VectorXd& z) const {
    if (!time_scale) return {};
    const size_t n = specs.size();
    return {to_p(n - 3, z(z.size() - 3)), to_p(n - 2, z(z.size() - 2)), to_p(n - 1, z(z.size() - 1))};
  }
  /// Holds parameter i of `kind` at `value` (a choice fitted space by space: the saturation's placement).
  void hold(EffectKind kind, size_t i, double value) {
    for (size_t e = 0; e < kinds.size(); ++e)
      if (kinds[e] == kind) {
        auto& spec = specs[first[e] + i];
        spec.lower = spec.upper = value;
        spec.fixed = true;
      }
  }
  /// z of given effects (kinds in this order) and nominal refit, each parameter clamped into its bounds: a
  /// start from another space (a loop's faster G, a wider pass's f) beyond them would sit where to_p's clamp
  /// is flat, and the fit could not move it.
  [[nodiscard]] Eigen::VectorXd z_of(const std::vector<Effect>& e, Nominal k) const {
    Eigen::VectorXd z(static_cast<Eigen::Index>(specs.size()));
    const auto inside = [&](size_t i, double p) { return to_z(i, std::clamp(p, specs[i].lower, specs[i].upper)); };
    for (size_t n = 0; n < kinds.size(); ++n)
      for (size_t i = first[n]; i < end_of(n); ++i) z(static_cast<Eigen::Index>(i)) = inside(i, e[n].p[i - first[n]]);
    if (time_scale) {
      const size_t n = specs.size();
      z(z.size() - 3) = inside(n - 3, k.time_scale);
      z(z.size() - 2) = inside(n - 2, k.shape);
      z(z.size() - 1) = inside(n - 1, k.next);
    }
    return z;
  }
};

/// The smallest and largest recorded voltage.
std::pair<double, double> voltage_range(const Series& s);
/// The rest voltage (steady state) whose output matches the first measured samples, searched over the
/// recorded voltages (`u_range_V`: voltage_range(s), given when known) and a fifth of their span beyond.
double rest_from_output(AugmentedPlant& plant, const Series& s);
double rest_from_output(AugmentedPlant& plant, const Series& s, std::pair<double, double> u_range_V);

/// The fit samples of a held-out mask as [begin, end) ranges, so sums over them run on contiguous memory.
std::vector<std::pair<size_t, size_t>> fit_ranges(const std::vector<char>& held_out);

/// Samples [first, last) of a series as an Eigen vector view.
inline Eigen::Map<const Eigen::VectorXd> segment(const std::vector<double>& v, size_t first, size_t last) {
  return {v.data() + first, static_cast<Eigen::Index>(last - first)};
}

/// A model's prediction after the nuisance projection.
struct Prediction {
  std::vector<std::vector<double>> y;  ///< per recording, all simulated samples
  double gain = 1.0;
  std::vector<double> offset_um;
  /// A wandering drift's size from its fitted curves (their RMS change from knot to knot over the
  /// knot spacing's square root); 0 when the model has no such drift.
  double wander_um_per_sqrt_s = 0.0;
};

/// Whether `e` holds a drift that wanders: the projection then also fits a smooth curve per recording.
bool wanders(std::span<const Effect> e);

/// Whether `e` holds a slew limit: its state is the drive the actuator sees (Problem::set_drive_at_rest).
bool slews(std::span<const Effect> e);

/// Simulates candidate models and fits the nuisance parameters that enter
/// linearly by least squares on the fit samples (variable projection): the
/// overall gain (bounded), a sensor offset per recording and the initial
/// state of G per recording (G's free-response modes), so no candidate is
/// blamed for a start not at rest, an offset or a gain error. A drift that wanders adds a cubic spline
/// per recording to those, knotted at its held-out blocks, so every held-out stretch lies between
/// fitted data the curve passes through.
class Problem {
 public:
  /// The refit's gain bounds and how far f must stay increasing come from `o`.
  Problem(const HammersteinModel& m, const std::vector<Series>& d, const std::vector<std::vector<char>>& held_out,
          const DiagnosisOptions& o)
      : model_(m), data_(d), gain_(gain_bounds(o)) {
    for (const auto& mask : held_out) {
      n_fit_ += static_cast<size_t>(std::count(mask.begin(), mask.end(), 0));
      fit_ranges_.push_back(fit_ranges(mask));
      end_.push_back(fit_ranges_.back().empty() ? 0 : fit_ranges_.back().back().second);
      block_.push_back(block_length(mask));
    }
    initial_V_.assign(d.size(), NAN);
    for (const auto& s : d) {
      u_range_.push_back(voltage_range(s));
      u_ref_ = std::max({u_ref_, std::abs(u_range_.back().first), std::abs(u_range_.back().second)});
    }
    u_keep_ = std::max(o.f_increasing_margin * u_ref_, o.f_increasing_up_to_V);
  }
  /// The nominal model, as given (before any refit).
  [[nodiscard]] const HammersteinModel& model() const noexcept { return model_; }
  void set_delay(double io) { io_ = io; }
  [[nodiscard]] double delay() const { return io_; }
  void set_initial(std::vector<double> v) { initial_V_ = std::move(v); }
  /// The branch each recording's loop starts on (AugmentedPlant::set_loop_memory); only plants with
  /// hysteresis see it. Empty: virgin.
  void set_loop_memory(std::vector<double> m) { loop_memory_ = std::move(m); }
  /// Per recording, whether a slew limit's drive starts where the actuator rests, at the voltage the first
  /// samples imply, instead of at the analysis's start (a closed loop from a charged start: the first
  /// command is not where the actuator was left, and the drive slews from there). Empty: nowhere.
  void set_drive_at_rest(std::vector<char> at_rest) { drive_at_rest_ = std::move(at_rest); }
  [[nodiscard]] const std::vector<char>& drive_at_rest() const { return drive_at_rest_; }
  /// A candidate's start states (its own fit's choice): a loop's branches, a slew limit's drive; a candidate
  /// of another kind leaves them.
  void use_start_states_of(const CandidateResult& c) {
    if (c.effect.kind == EffectKind::hysteresis) loop_memory_ = c.loop_memory;
    if (c.effect.kind == EffectKind::slew_limit) drive_at_rest_ = c.drive_at_rest;
  }
  [[nodiscard]] const std::vector<double>& loop_memory() const { return loop_memory_; }
  [[nodiscard]] const std::vector<double>& initial() const { return initial_V_; }

  /// Raw simulation (no projection) of every recording up to its fit end, or all of it.
  std::vector<std::vector<double>> raw(std::span<const Effect> e, Nominal k, bool all) {
    ++simulations_;
    const HammersteinModel mk = refit_model(model_, k.time_scale, k.shape, next_coefficient(k.next, k.shape));
    std::vector<std::vector<double>> out;
    for (size_t r = 0; r < data_.size(); ++r) {
      const auto& s = data_[r];
      AugmentedPlant plant(mk, io_, s.sample_time_s, e);
      if (r < loop_memory_.size()) plant.set_loop_memory(loop_memory_[r]);
      const bool from_output = std::isnan(initial_V_[r]) || (r < drive_at_rest_.size() && drive_at_rest_[r] && slews(e));
      const double v0 = from_output ? rest_from_output(plant, s, u_range_[r]) : initial_V_[r];
      const size_t n = all ? s.u_V.size() : end_[r];
      out.push_back(plant.simulate(std::span<const double>(s.u_V).first(n), v0));
    }
    return out;
  }

  /// Projects a raw simulation: gain (fitted or 1), offset and initial-state modes per recording, and
  /// with `wander` a drift's spline.
  Prediction project(std::vector<std::vector<double>> yhat, double time_scale, bool fit_gain, bool wander = false);

  Prediction predict(std::span<const Effect> e, Nominal k, bool fit_gain, bool all = true) {
    return project(raw(e, k, all), k.time_scale, fit_gain, wanders(e));
  }

  /// Fit-segment residual after the projection.
  Eigen::VectorXd residual(std::span<const Effect> e, Nominal k);
  /// residual(e, k)'s squared norm from predict(e, k, ...)'s prediction `y` (the same numbers, no simulation).
  [[nodiscard]] double fit_sse_um2(const std::vector<std::vector<double>>& y) const;
  [[nodiscard]] int simulations() const { return simulations_; }
  void add_simulations(int n) { simulations_ += n; }
  /// The coefficient c of f's added odd term c x^(2n+1) from its slope at the largest recorded |u|
  /// as a share of f's mean slope there: c (2n+1) u^(2n) = slope_share f(u) / u.
  /// A negative term is limited so that f (with `shape`) stays increasing up to the controller's range (at
  /// least twice the largest recorded |u|): the augmented model must run in that controller. With 1% to
  /// spare: a fit that converges onto that limit put f's turnover on the controller's maximum itself, and the
  /// file's ten digits then moved it inside (pvcgeld refused an augmented model turning at 845.0 V of 845 V).
  [[nodiscard]] double next_coefficient(double slope_share, double shape = 1.0) const {
    const int n = model_.f.terms();
    if (slope_share == 0.0 || n >= OddPolynomial::kMaxTerms) return 0.0;
    const double unit = model_.f(u_ref_) / u_ref_ / ((2.0 * n + 1.0) * std::pow(u_ref_, 2.0 * n));
    const auto turns = [&](double share) {
      return refit_model(model_, 1.0, shape, share * unit).f.first_turnover(1.01 * u_keep_).has_value();
    };
    if (slope_share > 0.0 || !turns(slope_share)) return slope_share * unit;
    double ok = 0.0, bad = slope_share;  // bisection on the share: `ok` keeps f increasing
    for (int i = 0; i < 30; ++i) (turns(0.5 * (ok + bad)) ? bad : ok) = 0.5 * (ok + bad);
    return ok * unit;
  }

 private:
  /// Per recording: G's free response (time-scaled by k) from each unit state, and the least-squares
  /// pieces of the projection that do not depend on the simulation, so each projection is one pass.
  struct Basis {
    std::vector<Eigen::VectorXd> modes;   ///< free response from each unit state, then the spline's columns
    /// Per mode, the samples [first, second) outside which it is zero (a spline) or below 1e-15 of its peak
    /// (a decayed free response): products with it need only these.
    std::vector<std::pair<size_t, size_t>> support;
    size_t free_modes = 0;                ///< how many of `modes` are G's free response
    Eigen::LDLT<Eigen::MatrixXd> gram;    ///< of psi = (1, modes) over the fit samples
    Eigen::VectorXd data_coefficients;    ///< gram^-1 sum psi y: offset and modes that fit the data alone
    /// Mode m over the samples [at.first, at.second).
    [[nodiscard]] auto on(size_t m, std::pair<size_t, size_t> at) const {
      return modes[m].segment(static_cast<Eigen::Index>(at.first), static_cast<Eigen::Index>(at.second - at.first));
    }
    /// Turns y, a simulation's samples [first, first + y.size()), into the projection's prediction:
    /// gain y + c(0) (the offset) + the modes weighted by c(1), c(2), ...
    void predict_in_place(Eigen::Ref<Eigen::VectorXd> y, size_t first, double gain, const Eigen::VectorXd& c) const;
  };
  /// The projection's least-squares solution: the gain and, per recording, the offset then the modes' weights.
  struct Projection {
    double gain = 1.0;
    std::vector<Eigen::VectorXd> coefficients;
  };
  [[nodiscard]] Projection fit_projection(const std::vector<std::vector<double>>& yhat, const std::vector<Basis>& basis_r,
                                          bool fit_gain) const;
  /// Fills `b`'s Gram matrix of (1, modes) over `fit_ranges` and the coefficients that fit y_um alone.
  static void solve_gram(Basis& b, const std::vector<double>& y_um, const std::vector<std::pair<size_t, size_t>>& fit_ranges);
  const std::vector<Basis>& basis(double k, bool wander);
  /// The length of a held-out mask's blocks (held_out_mask), in samples.
  static size_t block_length(const std::vector<char>& mask);
  /// The wander of a projection's splines (Prediction::wander_um_per_sqrt_s), from their coefficients.
  [[nodiscard]] double wander_size(const std::vector<Basis>& basis, const std::vector<Eigen::VectorXd>& coefficients) const;

  const HammersteinModel& model_;
  const std::vector<Series>& data_;
  std::vector<std::vector<std::pair<size_t, size_t>>> fit_ranges_;  ///< per recording: [begin, end) of fit samples
  std::vector<size_t> end_;  ///< one past the last fitted sample, per recording
  std::vector<size_t> block_;  ///< the held-out block length, per recording (a wandering drift's knot spacing)
  std::vector<double> initial_V_;
  std::vector<double> loop_memory_;
  std::vector<char> drive_at_rest_;
  double io_ = 1.0;
  std::vector<std::pair<double, double>> u_range_;  ///< per recording, voltage_range
  double u_ref_ = 1e-9;  ///< largest recorded |u| (V)
  double u_keep_ = 0.0;  ///< f stays increasing up to here (V)
  std::pair<double, double> gain_;  ///< the refit's gain bounds
  size_t n_fit_ = 0;
  int simulations_ = 0;
  // Two time scales cached: a Jacobian's time-scale column alternates with its base point.
  std::array<std::pair<double, bool>, 2> basis_k_{{{NAN, false}, {NAN, false}}};
  std::array<std::vector<Basis>, 2> basis_;
  size_t basis_next_ = 0;  ///< the slot the next new time scale replaces
};

/// Runs task(i, own) for every i below `count`, `own` a copy of `problem` for task i alone (a fit changes
/// the loop memory and the caches of the problem it runs on), at once through o.run_tasks when given;
/// counts their simulations in `problem` and tells o.progress of each task done in `stage`. A copy lives
/// only while its task runs (each holds G's free-response modes of every recording).
template <class Task>
void run_each(std::string_view stage, size_t count, Problem& problem, const DiagnosisOptions& o, Task&& task) {
  std::vector<int> added(count, 0);
  std::atomic<size_t> done{0};
  const std::function<void(size_t)> one = [&](size_t i) {
    Problem own = problem;
    task(i, own);
    added[i] = own.simulations() - problem.simulations();
    const size_t d = ++done;
    if (o.progress) o.progress(stage, d, count);
  };
  if (o.run_tasks && count > 1) {
    o.run_tasks(count, one);
  } else {
    for (size_t i = 0; i < count; ++i) one(i);
  }
  problem.add_simulations(std::accumulate(added.begin(), added.end(), 0));
}

/// Levenberg-Marquardt stops when a step lowers the fit's cost by less than this share of it.
constexpr double kFitTolerance = 1e-4;
/// ... and fit_staged's first stage, which only prepares the second, at this share.
constexpr double kBasinTolerance = 1e-3;

/// Bounded Levenberg-Marquardt on the simulated output from z (fit coordinates); sets `cost` to the
/// fit-segment sum of squares it reaches.
Eigen::VectorXd levenberg_marquardt(Problem& problem, const FitSpace& c, Eigen::VectorXd z, double& cost,
                                    double relative_tolerance = kFitTolerance);

/// Levenberg-Marquardt with f's added term held first (to kBasinTolerance), then everything free.
Eigen::VectorXd fit_staged(Problem& problem, const FitSpace& c, Eigen::VectorXd z, double& cost);

/// RMSE over all samples, over the fit segment and over the held-out data.
ModelErrors errors_of(const std::vector<Series>& data, const std::vector<std::vector<double>>& yhat,
                      const std::vector<std::vector<char>>& held_out);

/// Sets `d`'s model_y range: the nominal's own displacement under the nuisance refit `refit`,
/// (y - offset) / gain, where a saturation's knee acts, before the refit's gain. A widened gain of 0.27 put it
/// at 3.7x the recorded displacement, past every knee the recorded range allowed (the knee stopped at its
/// bound and a dead zone's catch-up took the corner: independent seed 137's case043).
void cover_model_displacement(DataScale& d, const Prediction& refit);

/// Largest |y| the nominal model reaches on these recordings, and the recorded command range.
DataScale data_scale(const std::vector<Series>& data, const std::vector<std::vector<double>>& y_nominal,
                     const std::vector<std::vector<char>>& held_out);

/// Fit-segment MSE of effects `e` with the nominal refitted as `k`.
double fit_mse(Problem& p, std::span<const Effect> e, Nominal k);

/// The nuisance-only refit: G's time scale and f's shape by least squares (gain, offset, start by projection),
/// from the nominal and, when given, from `also_from` (the lower cost wins).
Nominal refit_nominal(Problem& p, const DiagnosisOptions& o, std::optional<Nominal> also_from = std::nullopt);

/// The nominal refit a candidate was fitted jointly with.
inline Nominal nominal_of(const CandidateResult& c) { return {c.time_scale, c.poly_shape, c.poly_next}; }
/// The nuisance-only refit's nominal.
inline Nominal nominal_of(const NominalRefit& r) { return {r.time_scale, r.poly_shape, r.poly_next_slope}; }

}  // namespace pvcgel::control::diagnosis::detail

#include "control/identification/transfer_function_fit.hpp"

#include <Eigen/Dense>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <unsupported/Eigen/LevenbergMarquardt>

namespace pvcgel::control::identification {

namespace {

using cd = std::complex<double>;

/// theta = [b_0..b_nb, a_0..a_{na-1}] in ascending powers of the scaled s' = s / w0;
/// den is monic: D(s') = s'^na + sum a_i s'^i.
struct Rational {
  int nb, na;
  [[nodiscard]] cd num(const Eigen::VectorXd& th, cd s) const {
    cd v = 0.0;
    for (int i = nb; i >= 0; --i) v = v * s + th(i);
    return v;
  }
  [[nodiscard]] cd den(const Eigen::VectorXd& th, cd s) const {
    cd v = 1.0;
    for (int i = na - 1; i >= 0; --i) v = v * s + th(nb + 1 + i);
    return v;
  }
};

/// Weighted complex error of the rational model, split into real and imaginary parts.
struct ComplexErrorFunctor : Eigen::DenseFunctor<double> {
  Rational R;
  Eigen::VectorXcd s, H;
  Eigen::VectorXd w;
  ComplexErrorFunctor(Rational r, Eigen::VectorXcd s_, Eigen::VectorXcd H_, Eigen::VectorXd w_)
      : DenseFunctor<double>(r.nb + 1 + r.na, static_cast<int>(2 * s_.size())),
        R(r), s(std::move(s_)), H(std::move(H_)), w(std::move(w_)) {}
  int operator()(const Eigen::VectorXd& th, Eigen::VectorXd& f) const {
    for (Eigen::Index k = 0; k < s.size(); ++k) {
      const cd e = w(k) * (R.num(th, s(k)) / R.den(th, s(k)) - H(k));
      f(2 * k) = e.real();
      f(2 * k + 1) = e.imag();
    }
    return 0;
  }
  int df(const Eigen::VectorXd& th, Eigen::MatrixXd& J) const {
    for (Eigen::Index k = 0; k < s.size(); ++k) {
      const cd N = R.num(th, s(k)), D = R.den(th, s(k));
      cd p = 1.0;
      for (int i = 0; i <= std::max(R.nb, R.na - 1); ++i) {
        if (i <= R.nb) {
          const cd d = w(k) * p / D;
          J(2 * k, i) = d.real();
          J(2 * k + 1, i) = d.imag();
        }
        if (i <= R.na - 1) {
          const cd d = -w(k) * N * p / (D * D);
          J(2 * k, R.nb + 1 + i) = d.real();
          J(2 * k + 1, R.nb + 1 + i) = d.imag();
        }
        p *= s(k);
      }
    }
    return 0;
  }
};

double fit_percent(const Eigen::VectorXcd& H, const Eigen::VectorXcd& G) {
  const cd mean = H.mean();
  const double den = (H.array() - mean).matrix().norm();
  return 100.0 * (1.0 - (H - G).norm() / den);
}

const char* lm_status_text(Eigen::LevenbergMarquardtSpace::Status st) {
  using namespace Eigen::LevenbergMarquardtSpace;
  switch (st) {
    case RelativeReductionTooSmall: return "converged (relative reduction of the error)";
    case RelativeErrorTooSmall: return "converged (relative change of the parameters)";
    case RelativeErrorAndReductionTooSmall: return "converged (error and parameters)";
    case CosinusTooSmall: return "converged (gradient orthogonal to the error)";
    case TooManyFunctionEvaluation: return "stopped: too many function evaluations";
    case FtolTooSmall: case XtolTooSmall: case GtolTooSmall: return "stopped: tolerance too small";
    case ImproperInputParameters: return "improper input parameters";
    default: return "not started";
  }
}

}  // namespace

std::string TransferFunctionFit::control_problem() const {
  std::ostringstream os;
  if (!stable) os << "G(s) = " << G.to_string() << " is unstable (a pole in the right half plane): refused for control";
  else if (!minimum_phase)
    os << "G(s) = " << G.to_string()
       << " is non-minimum phase (a zero in the right half plane): its inverse, used by the inverse controller, "
          "the disturbance observer and the feedforward, would be unstable; refused for control (try other orders "
          "or check the data)";
  return os.str();
}

namespace {

/// Throws std::invalid_argument naming what is wrong with the orders or the points.
void check_points(const Eigen::VectorXd& omega, const Eigen::VectorXcd& H, int nb, int na) {
  if (nb < 0 || na < 1 || nb > na) throw std::invalid_argument("need 0 <= numerator order <= denominator order, >= 1");
  const Eigen::Index K = omega.size();
  const int np = nb + 1 + na;
  if (H.size() != K) throw std::invalid_argument("omega and response sizes differ");
  if (2 * K < np)
    throw std::invalid_argument("too few frequency points (" + std::to_string(K) + ") for " + std::to_string(np) +
                                " parameters");
  for (Eigen::Index k = 0; k < K; ++k)
    if (!(omega(k) > 0.0) || !std::isfinite(H(k).real()) || !std::isfinite(H(k).imag()) || std::abs(H(k)) == 0.0)
      throw std::invalid_argument("frequency point " + std::to_string(k) + " is not finite, positive and non-zero");
}

/// One weighted linear least-squares problem N(s') - H D(s') = 0 in theta (D's leading 1 to the right side),
/// each point weighted by `weight` / |D_prev|.
Eigen::VectorXd linearised_solve(const Rational& R, const Eigen::VectorXcd& s, const Eigen::VectorXcd& H,
                                 const Eigen::VectorXd& weight, const Eigen::VectorXd& Dw) {
  const Eigen::Index K = s.size();
  const int nb = R.nb, na = R.na;
  Eigen::MatrixXd A(2 * K, nb + 1 + na);
  Eigen::VectorXd b(2 * K);
  for (Eigen::Index k = 0; k < K; ++k) {
    const double wk = weight(k) / Dw(k);
    cd p = 1.0;
    for (int i = 0; i <= std::max(nb, na); ++i) {
      if (i <= nb) {
        A(2 * k, i) = (wk * p).real();
        A(2 * k + 1, i) = (wk * p).imag();
      }
      if (i < na) {
        const cd v = -wk * H(k) * p;
        A(2 * k, nb + 1 + i) = v.real();
        A(2 * k + 1, nb + 1 + i) = v.imag();
      }
      if (i == na) {
        const cd v = wk * H(k) * p;
        b(2 * k) = v.real();
        b(2 * k + 1) = v.imag();
      }
      p *= s(k);
    }
  }
  return A.colPivHouseholderQr().solve(b);
}

/// Linear stage: Levy (first pass, D_prev = 1), then Sanathanan-Koerner reweighting by 1/|D_prev|.
/// Counts its iterations in `out`.
Eigen::VectorXd sanathanan_koerner(const Rational& R, const Eigen::VectorXcd& s, const Eigen::VectorXcd& H,
                                   const Eigen::VectorXd& weight, int iterations, TransferFunctionFit& out) {
  Eigen::VectorXd th = Eigen::VectorXd::Zero(R.nb + 1 + R.na);
  th(R.nb + 1) = 1.0;  // D = s'^na + 1 to start; overwritten by the first solve
  Eigen::VectorXd Dw = Eigen::VectorXd::Ones(s.size());
  for (int it = 0; it < iterations; ++it) {
    const Eigen::VectorXd next = linearised_solve(R, s, H, weight, Dw);
    const double change = (next - th).norm() / std::max(next.norm(), 1e-300);
    th = next;
    out.sk_iterations = it + 1;
    for (Eigen::Index k = 0; k < s.size(); ++k) Dw(k) = std::abs(R.den(th, s(k)));
    if (change < 1e-12) break;
  }
  return th;
}

/// Back to s: num and den multiplied by w0^na so den is monic in s.
TransferFunction unscaled(const Rational& R, const Eigen::VectorXd& th, double w0) {
  const int nb = R.nb, na = R.na;
  std::vector<double> num(static_cast<size_t>(nb + 1)), den(static_cast<size_t>(na + 1));
  for (int i = 0; i <= nb; ++i) num[static_cast<size_t>(nb - i)] = th(i) * std::pow(w0, na - i);
  den[0] = 1.0;
  for (int i = 0; i < na; ++i) den[static_cast<size_t>(na - i)] = th(nb + 1 + i) * std::pow(w0, na - i);
  return TransferFunction(num, den, "ident.G");
}

}  // namespace

TransferFunctionFit fit_transfer_function(const Eigen::VectorXd& omega, const Eigen::VectorXcd& H,
                                          const TransferFunctionFitOptions& o) {
  const int nb = o.numerator_order, na = o.denominator_order;
  check_points(omega, H, nb, na);
  const Eigen::Index K = omega.size();

  // Scale s so the powers of s'^i stay near 1 (conditioning of both stages).
  const double w0 = std::exp(omega.array().log().mean());
  Eigen::VectorXcd s(K);
  for (Eigen::Index k = 0; k < K; ++k) s(k) = cd(0.0, omega(k) / w0);
  const Eigen::VectorXd weight = H.cwiseAbs().cwiseInverse();  // relative error
  const Rational R{nb, na};

  TransferFunctionFit out{TransferFunction({1.0}, {1.0}), 0, 0, 0, 0, {}, 0, {}, {}, false, false};
  Eigen::VectorXd th = sanathanan_koerner(R, s, H, weight, o.sk_iterations, out);
  Eigen::VectorXcd G(K);
  for (Eigen::Index k = 0; k < K; ++k) G(k) = R.num(th, s(k)) / R.den(th, s(k));
  out.sk_fit_percent = fit_percent(H, G);

  // Nonlinear stage: the complex error itself (SK only approximates it).
  ComplexErrorFunctor f(R, s, H, weight);
  Eigen::LevenbergMarquardt<ComplexErrorFunctor> lm(f);
  lm.setMaxfev(o.lm_max_evaluations);
  lm.setXtol(1e-14);
  lm.setFtol(1e-14);
  Eigen::VectorXd th_lm = th;
  out.lm_status = lm_status_text(lm.minimize(th_lm));
  out.lm_iterations = static_cast<int>(lm.iterations());
  if (th_lm.allFinite()) th = th_lm;

  out.G = unscaled(R, th, w0);
  for (Eigen::Index k = 0; k < K; ++k) G(k) = out.G(cd(0.0, omega(k)));
  out.fit_percent = fit_percent(H, G);
  out.max_relative_error = ((G - H).cwiseAbs().array() / H.cwiseAbs().array()).maxCoeff();
  out.poles = out.G.poles();
  out.zeros = out.G.zeros();
  out.stable = out.G.is_stable();
  out.minimum_phase = out.G.is_minimum_phase();
  return out;
}

}  // namespace pvcgel::control::identification

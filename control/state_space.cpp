#include "control/state_space.hpp"

#include <Eigen/Dense>
#include <unsupported/Eigen/MatrixFunctions>
#include <cmath>

#include "control/config_error.hpp"

namespace pvcgel::control {

namespace {
Eigen::VectorXd characteristic_polynomial(const Eigen::MatrixXd& A) {
  // Monic, descending powers of z == ascending powers of z^-1.
  if (A.rows() == 0) return Eigen::VectorXd::Ones(1);
  const Eigen::VectorXcd eig = A.eigenvalues();
  const auto p = polynomial_from_roots(eig);
  return Eigen::Map<const Eigen::VectorXd>(p.data(), static_cast<Eigen::Index>(p.size()));
}
Eigen::VectorXcd roots_in_z(const Eigen::VectorXd& ascending_in_zinv) {
  // Coefficients of z^-k ascending are the z-polynomial's in descending order.
  std::vector<double> desc(ascending_in_zinv.data(), ascending_in_zinv.data() + ascending_in_zinv.size());
  while (desc.size() > 1 && desc.back() == 0.0) desc.pop_back();  // factors of z^-1 are delays
  return polynomial_roots(desc);
}
}  // namespace

Eigen::VectorXd balance(Eigen::MatrixXd& M) {
  const Eigen::Index n = M.rows();
  Eigen::VectorXd d = Eigen::VectorXd::Ones(n);
  for (bool changed = true; changed;) {
    changed = false;
    for (Eigen::Index i = 0; i < n; ++i) {
      const double column = M.col(i).lpNorm<1>() - std::abs(M(i, i)), row = M.row(i).lpNorm<1>() - std::abs(M(i, i));
      if (column == 0.0 || row == 0.0) continue;  // an input's row of zeros: nothing to balance against
      double c = column, r = row, f = 1.0;
      while (c < r / 2.0) c *= 2.0, r /= 2.0, f *= 2.0;
      while (c >= 2.0 * r) c /= 2.0, r *= 2.0, f /= 2.0;
      if (c + r >= 0.95 * (column + row)) continue;
      changed = true;
      d(i) *= f;
      M.col(i) *= f;
      M.row(i) /= f;
    }
  }
  return d;
}

std::complex<double> DiscreteTransferFunction::frequency_response(double omega, double Ts) const {
  const std::complex<double> zinv = std::polar(1.0, -omega * Ts);
  std::complex<double> n = 0.0, d = 0.0;
  for (Eigen::Index i = b.size() - 1; i >= 0; --i) n = n * zinv + b(i);
  for (Eigen::Index i = a.size() - 1; i >= 0; --i) d = d * zinv + a(i);
  return n / d;
}

double DiscreteTransferFunction::dc_gain() const { return b.sum() / a.sum(); }
Eigen::VectorXcd DiscreteTransferFunction::poles() const { return roots_in_z(a); }

Eigen::VectorXcd DiscreteTransferFunction::zeros() const {
  const int d = delay_samples();
  return roots_in_z(b.tail(b.size() - d));
}

int DiscreteTransferFunction::delay_samples(double tol) const {
  int d = 0;
  const double scale = b.cwiseAbs().maxCoeff();
  while (d < b.size() - 1 && std::abs(b(d)) <= tol * scale) ++d;
  return d;
}

DiscreteTransferFunction DiscreteTransferFunction::delayed(int n) const {
  DiscreteTransferFunction r{Eigen::VectorXd::Zero(b.size() + n), a};
  r.b.tail(b.size()) = b;
  return r;
}

DiscreteTransferFunction operator*(const DiscreteTransferFunction& x, const DiscreteTransferFunction& y) {
  auto conv = [](const Eigen::VectorXd& p, const Eigen::VectorXd& q) {
    const auto r = polynomial_multiply({p.data(), p.data() + p.size()}, {q.data(), q.data() + q.size()});
    return Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(r.data(), static_cast<Eigen::Index>(r.size())));
  };
  return {conv(x.b, y.b), conv(x.a, y.a)};
}

StateSpace realize(const TransferFunction& g, const std::string& key) {
  if (g.relative_degree() < 0)
    throw ConfigError(key, "transfer function " + g.to_string() + " is improper (numerator degree above denominator degree)");
  const int n = g.order();
  const double a0 = g.den()[0];
  std::vector<double> b(static_cast<size_t>(n + 1), 0.0);
  std::copy(g.num().begin(), g.num().end(), b.begin() + (n + 1 - static_cast<int>(g.num().size())));
  StateSpace ss;
  ss.A = Eigen::MatrixXd::Zero(n, n);
  ss.B = Eigen::VectorXd::Zero(n);
  ss.C = Eigen::RowVectorXd::Zero(n);
  ss.D = b[0] / a0;
  for (int i = 0; i < n; ++i) {
    const double ai = g.den()[static_cast<size_t>(i + 1)] / a0;
    ss.A(0, i) = -ai;
    ss.C(i) = b[static_cast<size_t>(i + 1)] / a0 - ai * ss.D;
    if (i + 1 < n) ss.A(i + 1, i) = 1.0;
  }
  if (n > 0) ss.B(0) = 1.0;
  return ss;
}

StateSpace realize(const DiscreteTransferFunction& h) {
  const Eigen::Index n = std::max(h.a.size(), h.b.size()) - 1;
  Eigen::VectorXd a = Eigen::VectorXd::Zero(n + 1), b = Eigen::VectorXd::Zero(n + 1);
  a.head(h.a.size()) = h.a / h.a(0);
  b.head(h.b.size()) = h.b / h.a(0);
  StateSpace ss;
  ss.D = b(0);
  ss.A = Eigen::MatrixXd::Zero(n, n);
  ss.B = b.tail(n) - a.tail(n) * b(0);
  ss.C = Eigen::RowVectorXd::Zero(n);
  if (n > 0) {
    ss.A.col(0) = -a.tail(n);
    ss.A.topRightCorner(n - 1, n - 1).setIdentity();
    ss.C(0) = 1.0;
  }
  return ss;
}

StateSpace discretize_zoh(const StateSpace& c, double Ts) {
  const Eigen::Index n = c.A.rows();
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(n + 1, n + 1);
  M.topLeftCorner(n, n) = c.A * Ts;
  M.topRightCorner(n, 1) = c.B * Ts;
  // exp(D^-1 M D) = D^-1 exp(M) D. A badly scaled realisation (a fast G's numerator, 1e6, times a mode's
  // wn^2, 4e6, in one entry) otherwise gave an unstable exponential of a stable block: |eigenvalue| 8.2
  // where exp(lambda Ts) is 0.998 (seed 117's case011, a mode on a 10 kHz piezo beside G's slow pole moved
  // alone), and the simulation ran to infinity.
  const Eigen::VectorXd d = balance(M);
  const Eigen::MatrixXd E = d.asDiagonal() * Eigen::MatrixXd(M.exp()) * d.cwiseInverse().asDiagonal();
  return {E.topLeftCorner(n, n), E.topRightCorner(n, 1), c.C, c.D};
}

StateSpace discretize_tustin(const StateSpace& c, double Ts) {
  const Eigen::Index n = c.A.rows();
  const Eigen::MatrixXd I = Eigen::MatrixXd::Identity(n, n);
  const Eigen::MatrixXd M = (I - c.A * (Ts / 2.0)).inverse();
  StateSpace d;
  d.A = M * (I + c.A * (Ts / 2.0));
  d.B = M * c.B * Ts;
  d.C = c.C * M;
  d.D = c.D + (c.C * M * c.B)(0) * Ts / 2.0;
  return d;
}

DiscreteTransferFunction to_transfer_function(const StateSpace& d) {
  // det(zI - A + B C) = det(zI - A) (1 + C (zI - A)^-1 B) gives the numerator.
  const Eigen::VectorXd den = characteristic_polynomial(d.A);
  const Eigen::VectorXd num = characteristic_polynomial(d.A - d.B * d.C) - den + d.D * den;
  return {num, den};
}

}  // namespace pvcgel::control

#include "control/identification/identification.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace pvcgel::control::identification {

std::complex<double> remove_sampling_delay(std::complex<double> H, double w, double Ts, int d) {
  const double x = 0.5 * w * Ts;
  const double sinc = x == 0.0 ? 1.0 : std::sin(x) / x;
  return H * std::polar(1.0 / sinc, w * Ts * (d + 0.5));
}

double overall_gain(const HammersteinModel& m, double A, double B, double w) {
  return m.f.describing_function(A, B) * std::abs(m.G(std::complex<double>(0.0, w)));
}

HammersteinModel IdentificationResult::model(int n) const {
  return {OddPolynomial(f_fit.candidate(n).c, "ident.poly"), G_fit.G};
}

IdentificationResult identify(std::vector<FrequencyResponsePoint> points, const IdentificationOptions& o) {
  std::vector<std::complex<double>> cont(points.size());
  std::vector<size_t> used, ref;
  for (size_t i = 0; i < points.size(); ++i) {
    const auto& p = points[i];
    cont[i] = remove_sampling_delay(p.response, p.omega_rad_s(), o.sample_time_s, o.io_delay_samples);
    if (!p.valid) continue;
    used.push_back(i);
    if (std::abs(p.amplitude_V - o.reference_amplitude_V) <= o.regime_tolerance_V &&
        std::abs(p.bias_V - o.reference_bias_V) <= o.regime_tolerance_V)
      ref.push_back(i);
  }
  const int params = o.G.numerator_order + 1 + o.G.denominator_order;
  if (2 * static_cast<int>(ref.size()) < params) {
    std::ostringstream os;
    os << "only " << ref.size() << " valid point(s) at the reference regime A = " << o.reference_amplitude_V
       << " V, B = " << o.reference_bias_V << " V (+-" << o.regime_tolerance_V << " V); G with numerator order "
       << o.G.numerator_order << " and denominator order " << o.G.denominator_order << " needs at least "
       << (params + 1) / 2;
    throw std::invalid_argument(os.str());
  }
  Eigen::VectorXd w(static_cast<Eigen::Index>(ref.size()));
  Eigen::VectorXcd H(w.size());
  for (size_t j = 0; j < ref.size(); ++j) {
    w(static_cast<Eigen::Index>(j)) = points[ref[j]].omega_rad_s();
    H(static_cast<Eigen::Index>(j)) = cont[ref[j]];
  }
  TransferFunctionFit G_fit = fit_transfer_function(w, H, o.G);

  DescribingFunctionData d;
  const auto K = static_cast<Eigen::Index>(used.size());
  d.amplitude_V.resize(K);
  d.bias_V.resize(K);
  d.gain.resize(K);
  for (Eigen::Index k = 0; k < K; ++k) {
    const auto& p = points[used[static_cast<size_t>(k)]];
    d.amplitude_V(k) = p.amplitude_V;
    d.bias_V(k) = p.bias_V;
    d.gain(k) = std::abs(cont[used[static_cast<size_t>(k)]]) /
                std::abs(G_fit.G(std::complex<double>(0.0, p.omega_rad_s())));
  }
  NonlinearityFit f_fit = fit_nonlinearity(d, o.f);
  return IdentificationResult{std::move(points), std::move(cont), std::move(used), std::move(ref), std::move(G_fit),
                              std::move(f_fit)};
}

}  // namespace pvcgel::control::identification

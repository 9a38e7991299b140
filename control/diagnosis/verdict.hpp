#pragma once
/// @file
/// The verdict (internal): `none` from the nuisance-only refit, else a single effect (with the equally
/// good explanations and the experiment that separates them), a mixture of two, or `unexplained`, and the
/// text that says why.

#include <vector>

#include "control/diagnosis/diagnosis.hpp"
#include "control/diagnosis/fit_problem.hpp"

namespace pvcgel::control::diagnosis::detail {

/// `none` when the nuisance-only refit passes the `none` test and no longer I/O delay than the file's
/// fits clearly better; fills the verdict if so.
bool decide_none(DiagnosisResult& res, Prediction& refit, const DiagnosisOptions& o);

/// The verdict from the fitted candidates, judged against the nuisance-only refit.
void decide(DiagnosisResult& res, Problem& problem, const std::vector<Series>& data, const DataScale& scale,
            const DiagnosisOptions& o);

}  // namespace pvcgel::control::diagnosis::detail

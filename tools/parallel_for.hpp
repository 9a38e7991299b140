#pragma once
/// @file
/// The one thread pool of the `pvcgel` command: independent tasks (suite cases, a diagnosis's candidate
/// fits) on a few threads.

#include <cstddef>
#include <functional>

namespace pvcgel::tools {

/// Runs task(i) for every i below `count` on up to `threads` threads (the calling one among them) and
/// returns when all are done. If tasks throw, the rest still run and the first exception is rethrown here.
void parallel_for(std::size_t count, int threads, const std::function<void(std::size_t)>& task);

/// The threads a job gets when `jobs` run side by side on this machine's cores (at least 1).
int threads_per_job(int jobs);

}  // namespace pvcgel::tools

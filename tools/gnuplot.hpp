#pragma once
/// @file
/// Plots through gnuplot (Debian gnuplot-nox): data files plus a script, run once.

#include <filesystem>
#include <string>

namespace pvcgel::tools {

/// Runs `gnuplot script_path`. @throws std::runtime_error with an actionable
/// message when gnuplot is missing or fails.
void run_gnuplot(const std::filesystem::path& script_path);

/// A private temporary directory for a plot's data and script when only the
/// image is wanted (`show --plot`); removed with everything in it on destruction.
class ScratchDirectory final {
 public:
  /// @throws std::runtime_error when no directory can be created in the system's temp path.
  explicit ScratchDirectory(const std::string& prefix);
  ~ScratchDirectory();
  ScratchDirectory(const ScratchDirectory&) = delete;
  ScratchDirectory& operator=(const ScratchDirectory&) = delete;
  [[nodiscard]] const std::filesystem::path& path() const noexcept { return path_; }

 private:
  std::filesystem::path path_;
};

}  // namespace pvcgel::tools

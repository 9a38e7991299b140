#include "daemon/recorder.hpp"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>

namespace pvcgel::daemon {

namespace {

/// Creates the missing parents of `path`; returns the directory created ("" when none was missing).
std::string create_parent_directories(const std::string& path) {
  const auto parent = std::filesystem::path(path).parent_path();
  std::error_code ec;
  if (parent.empty() || std::filesystem::is_directory(parent, ec)) return "";
  if (!std::filesystem::create_directories(parent, ec) && ec)
    throw std::runtime_error("cannot create directory '" + parent.string() + "' for recording '" + path +
                             "': " + ec.message());
  return parent.string();
}

}  // namespace

Recorder::Recorder(const std::string& path, const RecordingHeader& header)
    : path_(path), created_directory_(create_parent_directories(path)) {
  file_ = std::fopen(path.c_str(), "w");
  if (!file_) throw std::runtime_error("cannot open recording '" + path + "': " + std::strerror(errno));
  std::fprintf(file_, "%s\n", kRecordingMagic.data());
  for (const auto& [k, v] : header) std::fprintf(file_, "# %s: %s\n", k.c_str(), v.c_str());
  std::fprintf(file_, "%s\n%s\n", kRecordingConvention.data(), kRecordingColumns.data());
}

Recorder::~Recorder() {
  if (file_) std::fclose(file_);
}

void Recorder::write(const CycleRecord& r) {
  // A late joiner (pvcgel record) starts wherever the stream is; gaps count from there.
  if (rows_ > 0 && r.seq != next_seq_) gaps_ += r.seq > next_seq_ ? r.seq - next_seq_ : 1;
  next_seq_ = r.seq + 1;
  const std::string_view mode = r.target == LoopTarget::voltage ? "open_loop" : control::to_string(r.mode);
  std::fprintf(file_, "%.4f,%.6f,%.4f,%.4f,%.4f,%.5g,%s,%s,%s,%d,%.1f\n", r.t_s, r.u_V, r.y_um, r.r_um, r.e_um,
               r.d_hat, mode.data(), to_string(r.state).data(), to_string(r.fault).data(), r.high_voltage ? 1 : 0,
               static_cast<double>(r.latency_us));
  ++rows_;
}

void Recorder::flush_if_due() {
  const auto now = std::chrono::steady_clock::now();
  if (now - last_flush_ > std::chrono::milliseconds(100)) {
    std::fflush(file_);
    last_flush_ = now;
  }
}

void Recorder::finish() {
  if (std::fflush(file_) != 0 || std::ferror(file_))
    throw std::runtime_error("writing recording '" + path_ + "' failed: " + std::strerror(errno));
}

}  // namespace pvcgel::daemon

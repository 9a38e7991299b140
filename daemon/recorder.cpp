#include "daemon/recorder.hpp"

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <thread>

namespace pvcgel::daemon {

Recorder::Recorder(const std::string& path, const std::vector<std::pair<std::string, std::string>>& header)
    : path_(path) {
  const auto parent = std::filesystem::path(path).parent_path();
  std::error_code ec;
  if (!parent.empty()) std::filesystem::create_directories(parent, ec);
  file_ = std::fopen(path.c_str(), "w");
  if (!file_) throw std::runtime_error("cannot open recording '" + path + "': " + std::strerror(errno));
  std::fprintf(file_, "# pvcgel-recording: 1\n");
  for (const auto& [k, v] : header) std::fprintf(file_, "# %s: %s\n", k.c_str(), v.c_str());
  std::fprintf(file_,
               "# convention: row k holds y_um measured at the start of cycle k (t_s) and the u_V then "
               "applied and held until cycle k+1 (zero-order hold)\n");
  std::fprintf(file_, "t_s,u_V,y_um,r_um,e_um,d_hat,mode,state,fault,hv,latency_us\n");
}

Recorder::~Recorder() {
  if (file_) std::fclose(file_);
}

void Recorder::write(const CycleRecord& r) {
  if (r.seq != next_seq_) gaps_ += r.seq > next_seq_ ? r.seq - next_seq_ : 1;
  next_seq_ = r.seq + 1;
  std::fprintf(file_, "%.4f,%.6f,%.4f,%.4f,%.4f,%.5g,%s,%s,%s,%d,%.1f\n", r.t_s, r.u_V, r.y_um, r.r_um, r.e_um,
               r.d_hat, control::to_string(r.mode).data(), to_string(r.state).data(), to_string(r.fault).data(),
               r.high_voltage ? 1 : 0, static_cast<double>(r.latency_us));
  ++rows_;
}

void Recorder::run(RecordRing& ring, const std::atomic<bool>& done) {
  auto last_flush = std::chrono::steady_clock::now();
  for (;;) {
    bool any = false;
    while (auto r = ring.pop()) {
      write(*r);
      any = true;
    }
    const auto now = std::chrono::steady_clock::now();
    if (now - last_flush > std::chrono::milliseconds(100)) {
      std::fflush(file_);
      last_flush = now;
    }
    if (!any) {
      if (done.load(std::memory_order_acquire) && ring.size() == 0) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }
  if (std::fflush(file_) != 0) throw std::runtime_error("writing recording '" + path_ + "' failed: " + std::strerror(errno));
}

}  // namespace pvcgel::daemon

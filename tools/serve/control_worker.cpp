#include "tools/serve/control_worker.hpp"

#include <stdexcept>

#include "control/controller.hpp"
#include "control/reference_signal.hpp"
#include "daemon/input_validation.hpp"

namespace pvcgel::tools::serve {

namespace {

using nlohmann::json;
using daemon::CommandKind;

std::string string_field(const json& request, const char* key) {
  const auto it = request.find(key);
  if (it == request.end() || !it->is_string())
    throw std::invalid_argument(std::string("request needs a string \"") + key + "\"");
  return it->get<std::string>();
}

json reply_json(const Reply& r) {
  return json{{"accepted", r.accepted}, {"reason", std::string(daemon::to_string(r.reason))}, {"detail", r.detail}};
}

Reply run_command(DdsClient& c, const json& request) {
  static const std::map<std::string, CommandKind> kPlain{{"arm", CommandKind::arm},     {"start", CommandKind::start},
                                                         {"stop", CommandKind::stop},   {"reset", CommandKind::reset},
                                                         {"clear", CommandKind::clear}};
  const std::string name = string_field(request, "command");
  if (const auto it = kPlain.find(name); it != kPlain.end()) return c.command(it->second, 0, false);
  if (name == "mode") {
    const std::string arg = string_field(request, "argument");
    const auto mode = control::parse_mode(arg);
    if (!mode) throw std::invalid_argument("unknown mode '" + arg + "' (pid, inverse_pid, inverse_pid_dob, inverse_pid_dob_ff)");
    return c.command(CommandKind::set_mode, static_cast<std::uint8_t>(*mode), false);
  }
  if (name == "target") {
    const std::string arg = string_field(request, "argument");
    if (arg != "displacement" && arg != "voltage")
      throw std::invalid_argument("unknown target '" + arg + "' (displacement or voltage)");
    return c.command(CommandKind::set_target, arg == "voltage" ? 1 : 0, false);
  }
  throw std::invalid_argument("unknown command '" + name + "' (arm, start, stop, reset, clear, mode, target)");
}

/// One of the paper's references as a parametric segment the daemon expands.
Reply run_reference(DdsClient& c, const json& request) {
  const std::string name = string_field(request, "reference");
  const auto ref = control::paper_reference(name);
  if (!ref) throw std::invalid_argument("unknown reference '" + name + "' (0.1Hz, 0.5Hz, 1Hz, multi)");
  double blend_s = 1.0;
  if (const auto it = request.find("blend_s"); it != request.end()) {
    if (!it->is_number()) throw std::invalid_argument("\"blend_s\" must be a number (s)");
    blend_s = it->get<double>();
  }
  std::vector<double> values = control::multisine_segment_values(*ref);
  pvcgel_v1_Trajectory t{};
  t.target = 0;
  t.kind = 4;  // multisine: [offset, a1, f1, phi1, ...]
  t.timing = 0;
  t.start_time_s = -1.0;
  t.blend_s = blend_s;
  t.values._buffer = values.data();
  t.values._length = static_cast<std::uint32_t>(values.size());
  t.values._maximum = t.values._length;
  t.values._release = false;
  return c.send(t, false);
}

}  // namespace

ControlWorker::ControlWorker(ClientOptions base) : base_(std::move(base)), thread_([this] { loop(); }) {}

ControlWorker::~ControlWorker() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

bool ControlWorker::submit(const std::string& rig, Kind kind, nlohmann::json request, Done done) {
  {
    std::lock_guard lock(mutex_);
    if (jobs_.size() >= 8) return false;
    jobs_.push_back(Job{rig, kind, std::move(request), std::move(done)});
  }
  wake_.notify_one();
  return true;
}

nlohmann::json ControlWorker::execute(DdsClient& c, Kind kind, const nlohmann::json& request) {
  if (!request.is_object()) throw std::invalid_argument("request must be a JSON object");
  return reply_json(kind == Kind::command ? run_command(c, request) : run_reference(c, request));
}

void ControlWorker::loop() {
  for (;;) {
    Job job;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [this] { return stop_ || !jobs_.empty(); });
      if (stop_) return;
      job = std::move(jobs_.front());
      jobs_.pop_front();
    }
    try {
      auto& client = clients_[job.rig];
      if (!client) {
        ClientOptions o = base_;
        o.rig = job.rig;
        client = std::make_unique<DdsClient>(o);
      }
      const json result = execute(*client, job.kind, job.request);
      job.done(true, result.dump());
    } catch (const std::invalid_argument& e) {
      job.done(false, std::string("bad request: ") + e.what());
    } catch (const std::exception& e) {
      clients_.erase(job.rig);  // a daemon that went away: join afresh next time
      job.done(false, e.what());
    }
  }
}

}  // namespace pvcgel::tools::serve

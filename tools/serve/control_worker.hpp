#pragma once
/// @file
/// Control from the live view (`pvcgel serve --allow-control`): requests from
/// WebSocket clients run on this worker's thread as real DDS Commands and
/// Trajectories through the project's client (DdsClient), so every action
/// passes the daemon's own validation and is answered by its CommandReply.
/// Neither the DDS reader nor the WebSocket thread ever waits for a reply.

#include <nlohmann/json.hpp>

#include <condition_variable>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "tools/dds_client.hpp"

namespace pvcgel::tools::serve {

class ControlWorker final {
 public:
  /// `ok` true: `result` is the response JSON {accepted, reason, detail}; false: why it failed.
  using Done = std::function<void(bool ok, const std::string& result)>;
  enum class Kind { command, reference };

  /// `base` gives the domain, DDS configuration and reply timeout (its rig is replaced per request).
  explicit ControlWorker(ClientOptions base);
  ~ControlWorker();
  ControlWorker(const ControlWorker&) = delete;
  ControlWorker& operator=(const ControlWorker&) = delete;

  /// Queues a request; false when 8 are already waiting (the caller answers "busy").
  bool submit(const std::string& rig, Kind kind, nlohmann::json request, Done done);

  /// Runs one request on `c` (throws std::invalid_argument for a malformed request). Public for tests.
  static nlohmann::json execute(DdsClient& c, Kind kind, const nlohmann::json& request);

 private:
  struct Job {
    std::string rig;
    Kind kind;
    nlohmann::json request;
    Done done;
  };
  void loop();

  ClientOptions base_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Job> jobs_;
  bool stop_ = false;
  std::map<std::string, std::unique_ptr<DdsClient>> clients_;  // only touched by the worker thread
  std::thread thread_;
};

}  // namespace pvcgel::tools::serve

#pragma once
/// @file
/// `pvcgel serve`: one port with the Foxglove WebSocket protocol v1 and the
/// live page over HTTP (websocketpp on standalone asio, one network thread),
/// fed by a RigWatcher on its own thread through bounded per-client queues.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "tools/dds_client.hpp"
#include "tools/serve/live_messages.hpp"
#include "tools/serve/rig_watcher.hpp"

namespace pvcgel::tools::serve {

struct ServeOptions {
  ClientOptions dds;
  int port = 8765;  ///< 0: any free port (printed at start)
  std::string bind = "127.0.0.1";
  bool allow_control = false;
  bool reliable_telemetry = false;
  /// Folder with index.html, app.js, style.css and node_modules/uplot/dist.
  std::string web_root;
  int page_decimation = 10;       ///< the page plots every n-th sample (exact statistics use all)
  /// The page draws its plots once per batch and scrolls them between batches
  /// (it runs 0.25 s behind the newest sample): 10 draws a second instead of 32
  /// is most of what the page costs a browser without a GPU.
  double page_batch_period_s = 0.1;
  int foxglove_decimation = 10;   ///< the decimated Foxglove channel: every n-th sample
};

/// Runs the server until SIGINT or SIGTERM; returns the exit code (0).
/// @throws std::runtime_error for a missing page file, a bad address or a port in use.
int run_live_server(const ServeOptions& o);

}  // namespace pvcgel::tools::serve

#include "tools/serve/serve_command.hpp"

#include <unistd.h>

#include <filesystem>

#include "tools/serve/live_server.hpp"

namespace pvcgel::tools {

namespace {

/// The page: --web-root, else the installed one (<prefix>/share/pvcgel/web beside
/// <prefix>/bin/pvcgel), else the source tree's (a binary in the build tree).
std::string default_web_root() {
  std::error_code ec;
  const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  const auto installed = exe.parent_path().parent_path() / "share" / "pvcgel" / "web";
  if (!ec && std::filesystem::exists(installed / "index.html")) return installed.string();
  return PVCGEL_SERVE_WEB_DIR;
}

}  // namespace

void add_serve_command(CLI::App& app) {
  auto opt = std::make_shared<serve::ServeOptions>();
  auto* cmd = app.add_subcommand(
      "serve", "Live view in the browser (http://HOST:PORT/) and in Foxglove (ws://HOST:PORT, foxglove.websocket.v1)");
  add_client_options(*cmd, opt->dds);
  cmd->add_option("--port", opt->port, "HTTP and WebSocket port (0: any free port, printed)")->capture_default_str();
  cmd->add_option("--bind", opt->bind, "address to listen on (0.0.0.0: every interface; the lab network)")
      ->capture_default_str();
  cmd->add_flag("--allow-control", opt->allow_control,
                "let the page and Foxglove arm/start/stop/reset, change mode and send references (default: watch only)");
  cmd->add_flag("--reliable-telemetry", opt->reliable_telemetry,
                "read Telemetry reliably (the daemon needs [dds] reliable_telemetry = true); default best-effort, "
                "which matches any daemon");
  cmd->add_option("--web-root", opt->web_root, "folder of the page (default: the build's or the installed one)");
  cmd->add_option("--page-decimation", opt->page_decimation, "the page plots every n-th sample")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000));
  cmd->add_option("--foxglove-decimation", opt->foxglove_decimation,
                  "the /RIG/telemetry_decimated channel carries every n-th sample")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000));
  cmd->callback([opt] {
    if (opt->port < 0 || opt->port > 65535) throw CLI::ValidationError("--port", "must be 0..65535");
    if (opt->web_root.empty()) opt->web_root = default_web_root();
    if (const int rc = serve::run_live_server(*opt); rc != 0) throw CLI::RuntimeError(rc);
  });
}

}  // namespace pvcgel::tools

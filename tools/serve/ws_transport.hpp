#pragma once
/// @file
/// The network side of `pvcgel serve`: one port serving a fixed set of files
/// over HTTP and WebSocket connections of one subprotocol, on one thread.
/// websocketpp 0.8 (Debian 12) does not compile as C++20, so it lives behind
/// this interface in a C++17 translation unit (ws_transport.cpp); this header
/// uses only the standard library.

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>

namespace pvcgel::tools::serve {

/// WebSocket close codes (RFC 6455) used here.
enum CloseCode : std::uint16_t {
  kGoingAway = 1001,
  kUnsupportedData = 1003,
  kPolicyViolation = 1008,
  kTryAgainLater = 1013,
};

class WsTransport final {
 public:
  using ConnectionId = std::uint64_t;
  struct Handlers {
    std::function<void(ConnectionId)> on_open;
    std::function<void(ConnectionId)> on_close;
    std::function<void(ConnectionId, const std::string& data, bool binary)> on_message;
  };
  /// URL path -> (content, content type).
  using Files = std::map<std::string, std::pair<std::string, std::string>>;

  /// Listens on bind:port (0: any free port). Messages above `max_message` bytes
  /// close the connection (1009). @throws std::runtime_error naming the address.
  WsTransport(const std::string& bind, int port, Files files, std::string subprotocol, std::size_t max_message,
              Handlers handlers);
  ~WsTransport();
  WsTransport(const WsTransport&) = delete;
  WsTransport& operator=(const WsTransport&) = delete;

  [[nodiscard]] int port() const;

  // On the network thread only (handlers, posted functions, timers):
  void send(ConnectionId c, const std::string& data, bool binary);
  /// Bytes handed to the connection and not yet written to its socket (0 when gone).
  std::size_t buffered(ConnectionId c);
  /// False once the connection is closing or gone.
  bool is_open(ConnectionId c);
  void close(ConnectionId c, CloseCode code, const std::string& reason);
  std::string peer(ConnectionId c);

  /// Runs `f` on the network thread. Thread-safe.
  void post(std::function<void()> f);
  /// Runs `f` on the network thread every `period` until shutdown.
  void every(std::chrono::milliseconds period, std::function<void()> f);
  /// Calls `f` on the network thread at SIGINT or SIGTERM.
  void on_signal(std::function<void()> f);
  /// Serves until shutdown() has finished.
  void run();
  /// Stops listening, closes every connection (1001), returns from run() shortly after.
  void shutdown();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace pvcgel::tools::serve

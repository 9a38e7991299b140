// Compiled as C++17: websocketpp 0.8.2's headers are not valid C++20.
#include "tools/serve/ws_transport.hpp"

#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

#include <csignal>
#include <stdexcept>

namespace pvcgel::tools::serve {

using Server = websocketpp::server<websocketpp::config::asio>;
using Hdl = websocketpp::connection_hdl;

struct WsTransport::Impl {
  asio::io_context io;
  Server server;
  Files files;
  std::string subprotocol;
  Handlers handlers;
  std::map<ConnectionId, Hdl> hdls;
  std::map<Hdl, ConnectionId, std::owner_less<Hdl>> ids;
  ConnectionId next = 1;
  bool stopping = false;
  asio::signal_set signals{io, SIGINT, SIGTERM};
  std::vector<std::unique_ptr<asio::steady_timer>> timers;
  std::vector<std::shared_ptr<std::function<void()>>> timers_keepalive;

  Server::connection_ptr con(ConnectionId c) {
    const auto it = hdls.find(c);
    if (it == hdls.end()) return nullptr;
    std::error_code ec;
    auto p = server.get_con_from_hdl(it->second, ec);
    return ec ? nullptr : p;
  }

  void http(Hdl h) {
    auto c = server.get_con_from_hdl(h);
    std::string resource = c->get_resource();
    resource = resource.substr(0, resource.find('?'));
    const auto it = files.find(resource);
    if (c->get_request().get_method() != "GET" || it == files.end()) {
      c->set_status(websocketpp::http::status_code::not_found);
      c->set_body("not found: " + resource.substr(0, 200) + "\n");
      return;
    }
    c->set_status(websocketpp::http::status_code::ok);
    c->append_header("Content-Type", it->second.second);
    c->append_header("Cache-Control", "no-cache");
    c->set_body(it->second.first);
  }

  bool validate(Hdl h) {
    auto c = server.get_con_from_hdl(h);
    for (const auto& p : c->get_requested_subprotocols()) {
      if (p == subprotocol) {
        c->select_subprotocol(p);
        return true;
      }
    }
    c->set_status(websocketpp::http::status_code::bad_request);
    c->set_body("this server speaks only the WebSocket subprotocol " + subprotocol + "\n");
    return false;
  }

  void closed(Hdl h) {
    const auto it = ids.find(h);
    if (it == ids.end()) return;
    const ConnectionId c = it->second;
    ids.erase(it);
    hdls.erase(c);
    handlers.on_close(c);
  }
};

WsTransport::WsTransport(const std::string& bind, int port, Files files, std::string subprotocol,
                         std::size_t max_message, Handlers handlers)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.files = std::move(files);
  m.subprotocol = std::move(subprotocol);
  m.handlers = std::move(handlers);
  m.server.clear_access_channels(websocketpp::log::alevel::all);
  m.server.clear_error_channels(websocketpp::log::elevel::all);
  m.server.init_asio(&m.io);
  m.server.set_reuse_addr(true);
  m.server.set_max_message_size(max_message);
  m.server.set_max_http_body_size(max_message);
  m.server.set_http_handler([&m](Hdl h) { m.http(h); });
  m.server.set_validate_handler([&m](Hdl h) { return m.validate(h); });
  m.server.set_open_handler([&m](Hdl h) {
    const ConnectionId c = m.next++;
    m.hdls[c] = h;
    m.ids[h] = c;
    m.handlers.on_open(c);
  });
  m.server.set_close_handler([&m](Hdl h) { m.closed(h); });
  m.server.set_fail_handler([&m](Hdl h) { m.closed(h); });
  m.server.set_message_handler([&m](Hdl h, Server::message_ptr msg) {
    const auto it = m.ids.find(h);
    if (it != m.ids.end())
      m.handlers.on_message(it->second, msg->get_payload(), msg->get_opcode() == websocketpp::frame::opcode::binary);
  });
  std::error_code ec;
  const auto address = asio::ip::make_address(bind, ec);
  if (ec) throw std::runtime_error("--bind '" + bind + "' is not an IP address");
  m.server.listen(asio::ip::tcp::endpoint(address, static_cast<unsigned short>(port)), ec);
  if (ec) throw std::runtime_error("cannot listen on " + bind + ":" + std::to_string(port) + ": " + ec.message());
  m.server.start_accept(ec);
  if (ec) throw std::runtime_error("cannot accept on " + bind + ":" + std::to_string(port) + ": " + ec.message());
}

WsTransport::~WsTransport() = default;

int WsTransport::port() const {
  std::error_code ec;
  return impl_->server.get_local_endpoint(ec).port();
}

void WsTransport::send(ConnectionId c, const std::string& data, bool binary) {
  auto p = impl_->con(c);
  if (!p) return;
  p->send(data, binary ? websocketpp::frame::opcode::binary : websocketpp::frame::opcode::text);
}

std::size_t WsTransport::buffered(ConnectionId c) {
  auto p = impl_->con(c);
  return p ? p->get_buffered_amount() : 0;
}

bool WsTransport::is_open(ConnectionId c) {
  auto p = impl_->con(c);
  return p && p->get_state() == websocketpp::session::state::open;
}

void WsTransport::close(ConnectionId c, CloseCode code, const std::string& reason) {
  auto p = impl_->con(c);
  if (!p) return;
  std::error_code ec;
  p->close(code, reason.substr(0, 120), ec);  // a close reason is at most 123 bytes
}

std::string WsTransport::peer(ConnectionId c) {
  auto p = impl_->con(c);
  return p ? p->get_remote_endpoint() : std::string("?");
}

void WsTransport::post(std::function<void()> f) { asio::post(impl_->io, std::move(f)); }

void WsTransport::every(std::chrono::milliseconds period, std::function<void()> f) {
  auto& timer = impl_->timers.emplace_back(std::make_unique<asio::steady_timer>(impl_->io));
  auto tick = std::make_shared<std::function<void()>>();
  *tick = [this, t = timer.get(), period, f = std::move(f), tick_weak = std::weak_ptr(tick)] {
    t->expires_after(period);
    t->async_wait([this, f, tick_weak](const std::error_code& ec) {
      if (ec || impl_->stopping) return;
      f();
      if (auto next = tick_weak.lock()) (*next)();
    });
  };
  impl_->timers_keepalive.push_back(tick);
  (*tick)();
}

void WsTransport::on_signal(std::function<void()> f) {
  impl_->signals.async_wait([f = std::move(f)](const std::error_code& ec, int) {
    if (!ec) f();
  });
}

void WsTransport::run() { impl_->io.run(); }

void WsTransport::shutdown() {
  Impl& m = *impl_;
  m.stopping = true;
  std::error_code ec;
  m.server.stop_listening(ec);
  for (auto& [id, h] : m.hdls) m.server.close(h, websocketpp::close::status::going_away, "pvcgel serve is shutting down", ec);
  for (auto& t : m.timers) t->cancel();
  m.signals.cancel();
  // Give the close handshakes a moment, then leave whatever is still open.
  auto& last = m.timers.emplace_back(std::make_unique<asio::steady_timer>(m.io));
  last->expires_after(std::chrono::milliseconds(300));
  last->async_wait([&m](const std::error_code&) { m.io.stop(); });
}

}  // namespace pvcgel::tools::serve

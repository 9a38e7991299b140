#pragma once
// A minimal Modbus TCP responder on a raw socket, written for the tests that
// need replies no real server sends: it answers correctly, with malformed
// frames (wrong transaction id, wrong function, wrong byte count), or with
// protocol exceptions, as the test switches it. Its serving thread never
// allocates, so it can share a process with the allocation-counting tests.

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <initializer_list>
#include <cstdint>
#include <stdexcept>
#include <thread>

namespace pvcgel::test {

class RawModbusServer {
 public:
  /// correct; garbage (malformed frames); exception (server device failure);
  /// late_once (the next reply correct but held back until the request after it arrives, then sent
  /// together with that request's own reply in one segment, then correct: a late reply that lands
  /// inside the next transaction, however the threads are scheduled); one_behind (every reply held
  /// back until the next request arrives, then sent alone: each transaction receives the answer to
  /// the one before it, as from a server that has fallen behind and stays behind).
  enum class Mode : int { correct, garbage, exception, late_once, one_behind };

  RawModbusServer() {
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    const int one = 1;
    ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t len = sizeof a;
    if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::listen(listen_fd_, 4) != 0 ||
        ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len) != 0)
      throw std::runtime_error("RawModbusServer: cannot listen");
    port_ = ntohs(a.sin_port);
    thread_ = std::thread([this] { serve(); });
  }
  ~RawModbusServer() {
    stop_ = true;
    thread_.join();
    ::close(listen_fd_);
  }
  [[nodiscard]] int port() const { return port_; }
  void set_mode(Mode m) { mode_.store(m); }
  /// Requests answered with a malformed frame or an exception so far.
  [[nodiscard]] int bad_replies() const { return bad_replies_.load(); }
  /// Requests received so far.
  [[nodiscard]] int requests() const { return requests_.load(); }

 private:
  bool wait_readable(int fd) const {
    pollfd p{fd, POLLIN, 0};
    while (!stop_) {
      const int rc = ::poll(&p, 1, 20);
      if (rc > 0) return true;
      if (rc < 0) return false;
    }
    return false;
  }
  bool read_exact(int fd, std::uint8_t* buf, size_t n) const {
    size_t got = 0;
    while (got < n) {
      if (!wait_readable(fd)) return false;
      const ssize_t r = ::recv(fd, buf + got, n - got, 0);
      if (r <= 0) return false;
      got += static_cast<size_t>(r);
    }
    return true;
  }
  void serve() {
    while (!stop_) {
      if (!wait_readable(listen_fd_)) continue;
      const int fd = ::accept(listen_fd_, nullptr, nullptr);
      if (fd < 0) continue;
      const int one = 1;  // as any Modbus server: no Nagle delay on small replies
      ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
      std::uint8_t hdr[7], pdu[260];
      std::array<std::uint8_t, 600> held{};  // a late_once reply not yet sent
      size_t held_size = 0;
      unsigned variant = 0;
      while (!stop_ && read_exact(fd, hdr, 7)) {
        const size_t len = static_cast<size_t>(hdr[4] << 8 | hdr[5]);
        if (len < 2 || len > 254 || !read_exact(fd, pdu, len - 1)) break;
        ++requests_;
        const std::uint8_t fc = pdu[0];
        Frame body;  // unit id onwards
        const Mode mode = mode_.load();
        if (mode == Mode::exception) {
          body.set({hdr[6], static_cast<std::uint8_t>(fc | 0x80), 0x04});  // server device failure
          ++bad_replies_;
        } else if (mode == Mode::garbage) {
          ++bad_replies_;
          switch (variant++ % 3) {
            case 0:  // a well-formed reply to another transaction
              hdr[1] = static_cast<std::uint8_t>(hdr[1] + 1);
              reply(hdr[6], fc, pdu, body);
              break;
            case 1:  // the wrong function code
              body.set({hdr[6], static_cast<std::uint8_t>(fc == 5 ? 6 : 5), 0, 10, 0, 0});
              break;
            default:  // a byte count that does not match the request
              body.set({hdr[6], fc, 2, 0, 1});
              break;
          }
        } else {
          reply(hdr[6], fc, pdu, body);
        }
        // Room for a held reply and this one: both go out in one send.
        std::array<std::uint8_t, 600> frame;
        size_t at = held_size;
        for (size_t i = 0; i < 4; ++i) frame[at + i] = hdr[i];
        frame[at + 4] = static_cast<std::uint8_t>(body.size >> 8);
        frame[at + 5] = static_cast<std::uint8_t>(body.size & 0xFF);
        for (size_t i = 0; i < body.size; ++i) frame[at + 6 + i] = body.bytes[i];
        at += 6 + body.size;
        if (mode == Mode::late_once && held_size == 0) {
          held = frame;  // sent with the next request's reply
          held_size = at;
          continue;
        }
        if (mode == Mode::one_behind) {  // send the held reply alone, hold this one
          if (held_size > 0 && ::send(fd, held.data(), held_size, MSG_NOSIGNAL) < 0) break;
          std::copy(frame.begin() + static_cast<std::ptrdiff_t>(held_size), frame.begin() + static_cast<std::ptrdiff_t>(at),
                    held.begin());
          held_size = at - held_size;
          continue;
        }
        for (size_t i = 0; i < held_size; ++i) frame[i] = held[i];
        if (held_size > 0) mode_.store(Mode::correct);
        held_size = 0;
        if (::send(fd, frame.data(), at, MSG_NOSIGNAL) < 0) break;
      }
      ::close(fd);
    }
  }
  struct Frame {
    std::array<std::uint8_t, 260> bytes{};
    size_t size = 0;
    void set(std::initializer_list<std::uint8_t> b) {
      size = 0;
      for (auto x : b) bytes[size++] = x;
    }
  };
  static void reply(std::uint8_t unit, std::uint8_t fc, const std::uint8_t* pdu, Frame& out) {
    if (fc == 3 || fc == 4) {
      const int n = pdu[3] << 8 | pdu[4];
      out.set({unit, fc, static_cast<std::uint8_t>(2 * n)});
      for (int i = 0; i < n; ++i) {
        out.bytes[out.size++] = 0;
        out.bytes[out.size++] = static_cast<std::uint8_t>(i == 1 ? 100 : 0);
      }
      return;
    }
    if (fc == 6 || fc == 16) return out.set({unit, fc, pdu[1], pdu[2], pdu[3], pdu[4]});
    out.set({unit, static_cast<std::uint8_t>(fc | 0x80), 0x01});
  }

  int listen_fd_ = -1;
  int port_ = 0;
  std::atomic<bool> stop_{false};
  std::atomic<Mode> mode_{Mode::correct};
  std::atomic<int> bad_replies_{0}, requests_{0};
  std::thread thread_;
};

}  // namespace pvcgel::test

#pragma once
// Real Modbus peers for the tests: the pymodbus plant server (tests/hal/modbus_plant_server.py,
// run by Debian's /usr/bin/python3) and a socat pseudo-terminal pair for RTU. Header-only;
// PVCGEL_SOURCE_DIR must be defined by the test target.

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace pvcgel::test {

inline const std::string kPlantServer = std::string(PVCGEL_SOURCE_DIR) + "/tests/hal/modbus_plant_server.py";

/// A TCP port on 127.0.0.1 that was free a moment ago (the kernel picks it).
inline int free_tcp_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  socklen_t len = sizeof a;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0) {
    ::close(fd);
    throw std::runtime_error("free_tcp_port: no port");
  }
  ::close(fd);
  return ntohs(a.sin_port);
}

/// True once something accepts connections on 127.0.0.1:port.
inline bool tcp_port_open(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  ::close(fd);
  return ok;
}

/// A child process, killed (SIGKILL) and reaped on destruction.
class Child {
 public:
  Child() = default;
  explicit Child(std::vector<std::string> argv, const std::string& stderr_path = "/dev/null") {
    std::vector<char*> args;
    for (auto& a : argv) args.push_back(a.data());
    args.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 2, stderr_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int rc = posix_spawn(&pid_, args[0], &fa, nullptr, args.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) throw std::runtime_error("cannot start " + argv[0]);
  }
  Child(Child&& o) noexcept : pid_(o.pid_) { o.pid_ = 0; }
  Child& operator=(Child&& o) noexcept {
    if (this != &o) {
      kill();
      pid_ = o.pid_;
      o.pid_ = 0;
    }
    return *this;
  }
  ~Child() { kill(); }
  /// SIGKILL and reap (a crash, as far as the peer can tell).
  void kill() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
    pid_ = 0;
  }
  void signal(int sig) const { ::kill(pid_, sig); }
  [[nodiscard]] pid_t pid() const { return pid_; }
  /// Waits for exit; returns the exit code, or -signal.
  int wait() {
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = 0;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
  }

 private:
  pid_t pid_ = 0;
};

/// A fresh scratch directory under the test temp dir.
inline std::string scratch_dir(const std::string& name) {
  static int counter = 0;
  const auto dir = std::filesystem::temp_directory_path() /
                   ("pvcgel_" + name + "_" + std::to_string(getpid()) + "_" + std::to_string(counter++));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

inline std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

/// The plant server's request journal, one entry per request without the
/// timestamp: {"W", "10", "3000"} (holding write), {"R", "4", "0", "4"} (input read).
inline std::vector<std::vector<std::string>> read_journal(const std::string& path) {
  std::vector<std::vector<std::string>> out;
  std::istringstream in(slurp(path));
  for (std::string line; std::getline(in, line);) {
    std::istringstream words_in(line);
    std::vector<std::string> words;
    std::string w;
    words_in >> w;  // timestamp
    while (words_in >> w) words.push_back(w);
    if (!words.empty()) out.push_back(words);
  }
  return out;
}

/// Waits until pred() or the timeout; returns pred().
template <typename Pred>
bool wait_for(Pred pred, double timeout_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return pred();
}

/// The pymodbus plant server as a child process.
struct PlantServerOptions {
  std::string transport = "tcp";
  int port = 0;          ///< tcp; 0 = pick a free one
  std::string device;    ///< rtu
  int unit = 1;
  std::string journal;   ///< request journal file ("" = none)
  double slow_ms = 20.0;
};

class PlantServer {
 public:
  explicit PlantServer(PlantServerOptions o) : options_(std::move(o)) {
    if (options_.transport == "tcp" && options_.port == 0) options_.port = free_tcp_port();
    start();
  }
  /// Starts (again, after kill()) with the same options; waits until it serves.
  void start() {
    const std::string dir = scratch_dir("plant");
    const std::string ready = dir + "/ready";
    std::vector<std::string> argv{"/usr/bin/python3", kPlantServer, "--transport", options_.transport,
                                  "--unit", std::to_string(options_.unit), "--slow-ms", std::to_string(options_.slow_ms),
                                  "--ready-file", ready};
    if (options_.transport == "tcp") {
      argv.insert(argv.end(), {"--port", std::to_string(options_.port)});
    } else {
      argv.insert(argv.end(), {"--device", options_.device});
    }
    if (!options_.journal.empty()) argv.insert(argv.end(), {"--journal", options_.journal});
    stderr_path_ = dir + "/stderr.txt";
    child_ = Child(argv, stderr_path_);
    const bool up = wait_for(
        [&] { return std::filesystem::exists(ready) && (options_.transport != "tcp" || tcp_port_open(options_.port)); },
        20.0);
    if (!up) throw std::runtime_error("the pymodbus plant server did not come up: " + slurp(stderr_path_));
  }
  void kill() { child_.kill(); }
  /// Toggles the slow mode (every read delayed by slow_ms).
  void toggle_slow() const { child_.signal(SIGUSR1); }
  /// Refuse (again: answer) writes to the amplifier register with an exception; reads stay answered.
  void toggle_refuse_writes() const { child_.signal(SIGUSR2); }
  [[nodiscard]] int port() const { return options_.port; }
  [[nodiscard]] std::string errors() const { return slurp(stderr_path_); }

 private:
  PlantServerOptions options_;
  Child child_;
  std::string stderr_path_;
};

/// A socat pseudo-terminal pair: bytes written to one end come out of the other.
class PtyPair {
 public:
  PtyPair() {
    dir_ = scratch_dir("pty");
    a_ = dir_ + "/a";
    b_ = dir_ + "/b";
    child_ = Child({"/usr/bin/socat", "pty,raw,echo=0,link=" + a_, "pty,raw,echo=0,link=" + b_}, dir_ + "/socat.txt");
    if (!wait_for([&] { return std::filesystem::exists(a_) && std::filesystem::exists(b_); }, 10.0))
      throw std::runtime_error("socat did not create the pty pair: " + slurp(dir_ + "/socat.txt"));
  }
  [[nodiscard]] const std::string& a() const { return a_; }
  [[nodiscard]] const std::string& b() const { return b_; }

 private:
  std::string dir_, a_, b_;
  Child child_;
};

}  // namespace pvcgel::test

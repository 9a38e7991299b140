#pragma once
// A program run by a test as a subprocess, concurrently with the test (the real
// daemon, a client), its stdout and stderr kept in files for the test to read.

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace pvcgel::test {

/// The whole file as a string ("" when it does not exist).
inline std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

/// A running subprocess; SIGTERM and reaped on destruction if still running.
class ChildProcess final {
 public:
  /// Starts `program args...` with stdout in `output_stem`.out and stderr in `output_stem`.err.
  ChildProcess(const std::string& program, std::vector<std::string> args, const std::string& output_stem)
      : out_path_(output_stem + ".out"), err_path_(output_stem + ".err") {
    args.insert(args.begin(), program);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, out_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 2, err_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (posix_spawn(&pid_, program.c_str(), &fa, nullptr, argv.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&fa);
  }
  ~ChildProcess() {
    if (pid_ > 0) (void)terminate_and_wait();
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  /// Exit code; 128 + signal if killed by one; -1 if it did not start or
  /// outlived `timeout_s` (it is then killed).
  int wait(double timeout_s) {
    if (pid_ <= 0) return -1;
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    int status = 0;
    bool timed_out = false;
    while (waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > end) {
        kill(pid_, SIGKILL);
        waitpid(pid_, &status, 0);
        timed_out = true;
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    pid_ = -1;
    if (timed_out) return -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }
  /// SIGTERM, then wait() up to 30 s.
  int terminate_and_wait() {
    if (pid_ > 0) kill(pid_, SIGTERM);
    return wait(30.0);
  }
  /// Process id while running (-1 once reaped or if it never started).
  [[nodiscard]] pid_t pid() const { return pid_; }
  /// What it wrote to stdout so far.
  [[nodiscard]] std::string out() const { return slurp(out_path_); }
  /// What it wrote to stderr so far.
  [[nodiscard]] std::string err() const { return slurp(err_path_); }
  /// Both, labelled, for failure messages.
  [[nodiscard]] std::string output() const { return "stdout:\n" + out() + "\nstderr:\n" + err(); }

 private:
  std::string out_path_, err_path_;
  pid_t pid_ = -1;
};

}  // namespace pvcgel::test

#pragma once
// Running the project's real binaries from tests: foreground with a result,
// or in the background until the test stops them.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace pvcgel::test {

struct Result {
  int exit_code = -1;
  int signal = 0;
  std::string out, err;
};

inline std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

/// A child process with stdout and stderr captured to files.
class Process final {
 public:
  Process(const std::string& program, std::vector<std::string> args) {
    static int counter = 0;
    const std::string base = ::testing::TempDir() + "proc_" + std::to_string(getpid()) + "_" + std::to_string(counter++);
    out_path_ = base + ".out";
    err_path_ = base + ".err";
    args.insert(args.begin(), program);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, out_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 2, err_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    EXPECT_EQ(posix_spawn(&pid_, program.c_str(), &fa, nullptr, argv.data(), environ), 0) << program;
    posix_spawn_file_actions_destroy(&fa);
  }
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;
  ~Process() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  /// SIGTERM (unless 0) and wait for the exit.
  Result stop(int sig = SIGTERM) {
    if (sig) kill(pid_, sig);
    return wait();
  }
  Result wait() {
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = 0;
    Result r;
    if (WIFEXITED(status)) r.exit_code = WEXITSTATUS(status);
    if (WIFSIGNALED(status)) r.signal = WTERMSIG(status);
    r.out = slurp(out_path_);
    r.err = slurp(err_path_);
    // Say which scheduling the daemon got: the tests must pass either way.
    const auto pos = r.err.find("loop running");
    if (pos != std::string::npos) std::cout << "[mode] " << r.err.substr(pos, r.err.find('\n', pos) - pos) << "\n";
    return r;
  }
  [[nodiscard]] std::string err_so_far() const { return slurp(err_path_); }
  /// Process id while it runs (0 once waited for).
  [[nodiscard]] pid_t pid() const { return pid_; }

 private:
  pid_t pid_ = 0;
  std::string out_path_, err_path_;
};

/// Runs `program`; if sigterm_after_s > 0, sends SIGTERM then. Waits for the exit.
inline Result run_program(const std::string& program, std::vector<std::string> args, double sigterm_after_s = 0.0) {
  Process p(program, std::move(args));
  if (sigterm_after_s > 0.0) {
    std::this_thread::sleep_for(std::chrono::duration<double>(sigterm_after_s));
    return p.stop();
  }
  return p.wait();
}

/// A DDS domain for this test process (30..219): tests that run at the same
/// time (ctest -j, or two checkouts on one machine) never see each other's daemons.
inline int unique_dds_domain() { return 30 + static_cast<int>((static_cast<long>(getpid()) * 7) % 190); }

/// The shipped sim config with DDS on `domain` (and the loopback XML by absolute path).
inline std::string sim_config_on_domain(const std::string& source_dir, int domain, const std::string& name) {
  std::string text = slurp(source_dir + "/config/pvcgeld-sim.toml");
  const auto replace = [&text](const std::string& from, const std::string& to) {
    const auto at = text.find(from);
    if (at != std::string::npos) text.replace(at, from.size(), to);
  };
  replace("\ndomain = 0", "\ndomain = " + std::to_string(domain));
  replace("config = \"cyclonedds-loopback.xml\"", "config = \"" + source_dir + "/config/cyclonedds-loopback.xml\"");
  const std::string path = ::testing::TempDir() + name + "_" + std::to_string(getpid()) + ".toml";
  std::ofstream(path) << text;
  return path;
}

}  // namespace pvcgel::test

// A command-line tool run as a child process the test controls: started with posix_spawn (its
// stdout and stderr to a log file, no other descriptor of the test's), signalled (kill -9 a
// server), waited for with a limit, and always killed and reaped by the destructor, so a failed
// test leaves nothing running (the log stays for a failed test, and is removed otherwise).
// command() makes its argument vector from a line of words.
#pragma once

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace irradcast::test {

// An argument vector: `exe` and the words of `args`.
inline std::vector<std::string> command(const std::string& exe, const std::string& args) {
  std::vector<std::string> v = {exe};
  std::istringstream ss(args);
  for (std::string w; ss >> w;) v.push_back(w);
  return v;
}

class Process {
 public:
  Process(std::vector<std::string> args, std::filesystem::path log) : log_(std::move(log)) {
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    // Nothing else of the test's: a listening socket the child inherited would stay open (and
    // take connections) after the test closed it.
    posix_spawn_file_actions_addclosefrom_np(&fa, 3);
    const int rc = posix_spawn(&pid_, args[0].c_str(), &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) throw std::runtime_error("cannot start " + args[0] + ": " + std::strerror(rc));
  }
  ~Process() {
    if (running()) {
      ::kill(pid_, SIGKILL);
      wait_for(std::chrono::seconds(10));
    }
    if (!::testing::Test::HasFailure()) {
      std::error_code ec;
      std::filesystem::remove(log_, ec);
    }
  }
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;

  pid_t pid() const { return pid_; }
  void signal(int sig) const {
    if (!status_) ::kill(pid_, sig);
  }
  bool running() { return !poll(); }
  // The exit status (-1 for a signal) once the process has ended, or nullopt after `limit`.
  std::optional<int> wait_for(std::chrono::milliseconds limit) {
    const auto deadline = std::chrono::steady_clock::now() + limit;
    for (;;) {
      if (auto s = poll()) return s;
      if (std::chrono::steady_clock::now() >= deadline) return std::nullopt;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
  std::string output() const {
    std::ifstream f(log_);
    std::ostringstream ss;
    ss << f.rdbuf();
    return ss.str();
  }

 private:
  std::optional<int> poll() {
    if (status_) return status_;
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == pid_)
      status_ = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return status_;
  }

  std::filesystem::path log_;
  pid_t pid_ = -1;
  std::optional<int> status_;
};

}  // namespace irradcast::test

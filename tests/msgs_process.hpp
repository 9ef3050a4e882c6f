// tests/msgs_process.hpp
// The `msgs` tool (MSGS_BIN) as a child process for tests that talk to its HTTP server:
// `msgs view` or `msgs train --view` on a free port, stdout / stderr in files, the URL it prints
// parsed for the port, SIGTERM (or SIGINT) on request and on destruction.
#pragma once

#include <doctest/doctest.h>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <regex>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace msgs::testing {

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

/// `msgs <command> ARGS` as a child process; ready once it printed `http://127.0.0.1:PORT/`.
class MsgsServer {
 public:
  MsgsServer(const std::string& command, const std::vector<std::string>& args, const std::filesystem::path& dir,
             int wait_seconds = 60)
      : out_(dir / (command + ".out")), err_(dir / (command + ".err")) {
    std::vector<std::string> argv = {MSGS_BIN, command};
    argv.insert(argv.end(), args.begin(), args.end());
    std::vector<char*> cargv;
    for (auto& a : argv) cargv.push_back(a.data());
    cargv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, out_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 2, err_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int rc = posix_spawn(&pid_, MSGS_BIN, &fa, nullptr, cargv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    REQUIRE_MESSAGE(rc == 0, "cannot start " MSGS_BIN);
    // The chosen port is printed once the socket is bound.
    const std::regex re("http://127\\.0\\.0\\.1:([0-9]+)/");
    const auto t0 = std::chrono::steady_clock::now();
    while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(wait_seconds)) {
      std::smatch m;
      const std::string s = slurp(out_);
      if (std::regex_search(s, m, re)) { port_ = std::stoi(m[1]); return; }
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        FAIL("msgs " << command << " exited early: " << slurp(err_));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    FAIL("msgs " << command << " printed no URL within " << wait_seconds << " s: " << slurp(err_));
  }
  MsgsServer(const MsgsServer&) = delete;
  MsgsServer& operator=(const MsgsServer&) = delete;
  ~MsgsServer() { (void)stop(); }
  /// Send `sig` and wait; the exit status (0 = clean shutdown), or -1 when it was not running.
  int stop(int sig = SIGTERM) {
    if (pid_ <= 0) return -1;
    kill(pid_, sig);
    return wait();
  }
  /// Wait for the process to end on its own; its exit status.
  int wait() {
    if (pid_ <= 0) return -1;
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  }
  int port() const { return port_; }
  std::string out() const { return slurp(out_); }
  std::string log() const { return slurp(err_); }

 private:
  std::filesystem::path out_, err_;
  pid_t pid_ = -1;
  int port_ = 0;
};

}  // namespace msgs::testing

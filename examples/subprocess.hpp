// examples/subprocess.hpp: running external tools (colmap, exiv2) from the `msgs` tool without a
// shell: argv passed as is (no quoting problems with odd file names), stdout and stderr into files.
#pragma once

#include <spawn.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

#include <csignal>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <chrono>
#include <deque>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <msgs/io/error.hpp>

extern char** environ;

namespace msgs::cli {

/// The program `name` on PATH (or `name` itself when it contains a '/'), if it is executable.
inline std::optional<std::filesystem::path> find_program(const std::string& name) {
  if (name.empty()) return std::nullopt;
  if (name.find('/') != std::string::npos)
    return ::access(name.c_str(), X_OK) == 0 ? std::optional<std::filesystem::path>(name) : std::nullopt;
  const char* path = std::getenv("PATH");
  std::string p = path ? path : "/usr/local/bin:/usr/bin:/bin";
  std::size_t start = 0;
  for (std::size_t i = 0; i <= p.size(); ++i) {
    if (i < p.size() && p[i] != ':') continue;
    const std::string dir = p.substr(start, i - start);
    start = i + 1;
    const std::filesystem::path cand = std::filesystem::path(dir.empty() ? "." : dir) / name;
    std::error_code ec;
    if (std::filesystem::is_regular_file(cand, ec) && ::access(cand.c_str(), X_OK) == 0) return cand;
  }
  return std::nullopt;
}

/// run_process's result for a child that used no CPU time for `idle_limit_s` seconds and was killed.
inline constexpr int kProcessHung = -2;

/// CPU seconds (user + system, all threads) process `pid` has used, from /proc; -1 when unreadable.
inline double process_cpu_seconds(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string stat;
  if (!std::getline(in, stat)) return -1;
  const std::size_t close = stat.rfind(')');  // the command name may hold spaces and parentheses
  if (close == std::string::npos) return -1;
  std::istringstream fields(stat.substr(close + 2));
  std::string f;
  unsigned long long utime = 0, stime = 0;
  for (int i = 3; i <= 15 && fields >> f; ++i) {  // fields 14 and 15 (1-based) of proc(5)
    if (i == 14) utime = std::strtoull(f.c_str(), nullptr, 10);
    if (i == 15) stime = std::strtoull(f.c_str(), nullptr, 10);
  }
  if (!fields) return -1;
  const long tick = ::sysconf(_SC_CLK_TCK);
  return tick > 0 ? double(utime + stime) / double(tick) : -1;
}

/// Run argv[0] (looked up on PATH) with stdout appended to `out_file` and stderr to `err_file`
/// (the same file is fine). Returns the exit status (128 + signal when killed). IoError when the
/// program cannot be started. With `idle_limit_s` > 0, a child whose CPU time has not advanced for
/// that long (deadlocked: COLMAP 3.8's feature extractor sometimes stops with every thread
/// waiting on its job queues) is killed and kProcessHung returned. `on_poll`, when given (with
/// `idle_limit_s` > 0), is called at every check, 20 times a second, while the child runs.
inline int run_process(const std::vector<std::string>& argv, const std::filesystem::path& out_file,
                       const std::filesystem::path& err_file, double idle_limit_s = 0,
                       const std::function<void()>& on_poll = {}) {
  if (argv.empty()) throw io::IoError("run_process: empty command");
  std::vector<char*> cargv;
  for (const auto& a : argv) cargv.push_back(const_cast<char*>(a.c_str()));
  cargv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 1, out_file.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  if (err_file == out_file) posix_spawn_file_actions_adddup2(&fa, 1, 2);
  else posix_spawn_file_actions_addopen(&fa, 2, err_file.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, cargv[0], &fa, nullptr, cargv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) io::fail(argv[0], io::cat("cannot start: ", std::strerror(rc)));
  int status = 0;
  if (idle_limit_s > 0) {
    using clock = std::chrono::steady_clock;
    double last_cpu = -1;
    auto last_progress = clock::now();
    for (;;) {
      const pid_t r = ::waitpid(pid, &status, WNOHANG);
      if (r == pid) break;
      if (r < 0 && errno != EINTR) io::fail(argv[0], io::cat("waitpid failed: ", std::strerror(errno)));
      const double cpu = process_cpu_seconds(pid);
      if (cpu < 0 || cpu > last_cpu) {  // unreadable counts as progress: never kill on a guess
        last_cpu = cpu;
        last_progress = clock::now();
      } else if (std::chrono::duration<double>(clock::now() - last_progress).count() > idle_limit_s) {
        ::kill(pid, SIGKILL);
        while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {}
        return kProcessHung;
      }
      if (on_poll) on_poll();
      ::usleep(50000);
    }
  } else {
    while (::waitpid(pid, &status, 0) < 0) {
      if (errno != EINTR) io::fail(argv[0], io::cat("waitpid failed: ", std::strerror(errno)));
    }
  }
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return 255;
}

/// The last `n` lines of a text file ("" when it cannot be read).
inline std::string tail_lines(const std::filesystem::path& p, std::size_t n) {
  std::ifstream in(p);
  std::deque<std::string> last;
  for (std::string line; std::getline(in, line);) {
    last.push_back(line);
    if (last.size() > n) last.pop_front();
  }
  std::string s;
  for (const auto& l : last) s += "    | " + l + "\n";
  return s;
}

}  // namespace msgs::cli

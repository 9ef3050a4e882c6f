// examples/subprocess.hpp: running external tools (colmap, exiv2) from the `msgs` tool without a
// shell: argv passed as is (no quoting problems with odd file names), stdout and stderr into files.
#pragma once

#include <spawn.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <optional>
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

/// Run argv[0] (looked up on PATH) with stdout appended to `out_file` and stderr to `err_file`
/// (the same file is fine). Returns the exit status (128 + signal when killed). IoError when the
/// program cannot be started.
inline int run_process(const std::vector<std::string>& argv, const std::filesystem::path& out_file,
                       const std::filesystem::path& err_file) {
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
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) io::fail(argv[0], io::cat("waitpid failed: ", std::strerror(errno)));
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

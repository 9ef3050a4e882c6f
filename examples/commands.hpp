// examples/commands.hpp: the subcommands of the `msgs` tool and a tiny shared argument parser.
// Each subcommand lives in its own cmd_<name>.cpp and registers itself with MSGS_COMMAND.
#pragma once

#include <cstdlib>
#include <functional>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace msgs::cli {

/// A subcommand: receives its arguments (without the program and subcommand names), returns the exit code.
struct Command {
  std::string summary;
  std::function<int(const std::vector<std::string>&)> run;
};

inline std::map<std::string, Command>& registry() {
  static std::map<std::string, Command> r;
  return r;
}

struct Registrar {
  Registrar(const std::string& name, std::string summary, std::function<int(const std::vector<std::string>&)> fn) {
    registry()[name] = Command{std::move(summary), std::move(fn)};
  }
};

/// Error in the command line: printed with the usage, exit code 2.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// `--key value` and `--flag` parsing. Unknown options are an error, so typos do not pass silently.
class Args {
 public:
  Args(const std::vector<std::string>& argv, std::vector<std::string> value_options,
       std::vector<std::string> flag_options = {}) {
    for (std::size_t i = 0; i < argv.size(); ++i) {
      const std::string& a = argv[i];
      if (a.rfind("--", 0) != 0) { positional_.push_back(a); continue; }
      std::string key = a.substr(2), value;
      const auto eq = key.find('=');
      bool has_value = false;
      if (eq != std::string::npos) { value = key.substr(eq + 1); key = key.substr(0, eq); has_value = true; }
      if (contains(flag_options, key)) { flags_[key] = true; continue; }
      if (!contains(value_options, key)) throw UsageError("unknown option --" + key);
      if (!has_value) {
        if (i + 1 >= argv.size()) throw UsageError("option --" + key + " needs a value");
        value = argv[++i];
      }
      values_[key] = value;
    }
  }
  bool has(const std::string& k) const { return values_.count(k) > 0; }
  bool flag(const std::string& k) const { return flags_.count(k) > 0; }
  std::string get(const std::string& k, const std::string& def = "") const {
    auto it = values_.find(k);
    return it == values_.end() ? def : it->second;
  }
  std::string require(const std::string& k) const {
    if (!has(k)) throw UsageError("missing required option --" + k);
    return get(k);
  }
  double number(const std::string& k, double def) const {
    if (!has(k)) return def;
    const std::string v = get(k);
    char* end = nullptr;
    const double d = std::strtod(v.c_str(), &end);
    if (v.empty() || *end != '\0') throw UsageError("option --" + k + " expects a number, got '" + v + "'");
    return d;
  }
  long integer(const std::string& k, long def) const {
    if (!has(k)) return def;
    const std::string v = get(k);
    char* end = nullptr;
    const long d = std::strtol(v.c_str(), &end, 10);
    if (v.empty() || *end != '\0') throw UsageError("option --" + k + " expects an integer, got '" + v + "'");
    return d;
  }
  const std::vector<std::string>& positional() const { return positional_; }

 private:
  static bool contains(const std::vector<std::string>& v, const std::string& s) {
    for (const auto& x : v) if (x == s) return true;
    return false;
  }
  std::map<std::string, std::string> values_;
  std::map<std::string, bool> flags_;
  std::vector<std::string> positional_;
};

/// Pose re-orientation from `--orient none|center` (default center: mean up becomes +z, mean
/// camera position the origin) or the older `--no-orient` flag.
inline bool orient_and_center(const Args& args) {
  const std::string o = args.get("orient", "center");
  if (o != "none" && o != "center") throw UsageError("--orient expects none or center, got '" + o + "'");
  return o == "center" && !args.flag("no-orient");
}

/// "a,b,,c" -> {"a", "b", "c"}: comma-separated option values (band lists, backgrounds).
inline std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : s) {
    if (c == ',') {
      if (!cur.empty()) out.push_back(cur);
      cur.clear();
    } else {
      cur += c;
    }
  }
  if (!cur.empty()) out.push_back(cur);
  return out;
}

}  // namespace msgs::cli

#define MSGS_CONCAT_INNER(a, b) a##b
#define MSGS_CONCAT(a, b) MSGS_CONCAT_INNER(a, b)
/// Register a subcommand: MSGS_COMMAND("render", "Render a model", run_render); the registrar is
/// named by __COUNTER__, not __LINE__, since the files of a unity group are one unit.
#define MSGS_COMMAND(name, summary, fn) \
  static ::msgs::cli::Registrar MSGS_CONCAT(msgs_cmd_registrar_, __COUNTER__)(name, summary, fn)

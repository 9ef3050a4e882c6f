// include/msgs/io/error.hpp
// IoError, the one exception type of the loaders and writers, and helpers that build messages
// naming the file, the field and what was expected.
#pragma once

#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>

namespace msgs::io {

/// Bad or unreadable input, or output that could not be written. The message always names the
/// file, and where it makes sense the field and what was expected.
struct IoError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

namespace detail {
inline void append_piece(std::string& s, std::string_view v) { s.append(v); }
inline void append_piece(std::string& s, const char* v) { s.append(v); }
inline void append_piece(std::string& s, const std::string& v) { s.append(v); }
inline void append_piece(std::string& s, char v) { s.push_back(v); }
inline void append_piece(std::string& s, const std::filesystem::path& v) { s.append(v.string()); }
template <class T>
  requires std::is_arithmetic_v<T>
void append_piece(std::string& s, T v) {
  s.append(std::to_string(v));
}
}  // namespace detail

/// Concatenate strings and numbers into a message. (Appending, rather than `"literal" + str`,
/// also sidesteps a GCC 12 -Wrestrict false positive.)
template <class... A>
std::string cat(const A&... pieces) {
  std::string s;
  (detail::append_piece(s, pieces), ...);
  return s;
}

/// A number for a message, to `digits` significant digits without trailing zeros ("%g"): 540
/// rather than cat's "540.000000". Where the digits matter (values written into files) use cat.
inline std::string short_number(double v, int digits = 6) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

/// Throw IoError("<file>: <what>").
[[noreturn]] inline void fail(const std::filesystem::path& file, const std::string& what) {
  throw IoError(cat(file.string(), ": ", what));
}

/// Throw IoError("<file>: field '<field>': <what>").
[[noreturn]] inline void fail(const std::filesystem::path& file, const std::string& field, const std::string& what) {
  throw IoError(cat(file.string(), ": field '", field, "': ", what));
}

}  // namespace msgs::io

// include/msgs/io/sunshine_sensor.hpp
// The Parrot Sequoia's sunshine sensor: the light sensor on top of the drone that records, in the
// four bands of the camera, the sunlight falling on it. Each band image carries the readings of its
// band since the previous capture, and the sensor's factory calibration of its gains:
//
//   Xmp.Camera.IrradianceList                     base64 of 28-byte little-endian records, about
//                                                 five a second: uint64 time (microseconds),
//                                                 uint16 CH0 count, uint16 CH1 count, uint16 gain
//                                                 index, uint16 integration time (ms), float yaw,
//                                                 pitch, roll
//   Xmp.Camera.IrradianceCalibrationMeasurement   rows of (gain index, integration time in ms,
//                                                 CH0, CH1), each gain index measured under the
//                                                 same light: "0,600,33,17,1,600,820,417,..."
//
// As Parrot describes the sensor (developer forum, "Details of Irradiance List tag for Sunshine
// sensor in exif data of Sequoia"), it is linear with no black level:
//
//   CH0 = k x gain(gain index) x integration time x irradiance,
//
// and its gains differ from unit to unit: the calibration rows give them, as the ratios of their
// counts per millisecond. So a reading's irradiance relative to the light of the calibration is
//
//   E = (CH0 / t) / (CH0_cal(g) / t_cal(g))       (g the reading's gain index),
//
// in the same units whatever the gain, for every image of the same unit. That is what msgs takes
// as the light sensor's reading of a band image (in its own units, as DJI's): the mean of E over
// the readings of the last kSunshineWindowS seconds of the list, the light at the capture rather
// than since the previous one. Readings at CH0 0 or 65535 (saturated), and those whose gain index
// has no usable calibration row, are left out. Firmware before 1.1.0 wrote 20-byte records
// without gain and integration time; msgs does not read those and says so.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "msgs/io/error.hpp"

namespace msgs::io {

/// One record of Xmp.Camera.IrradianceList.
struct SunshineReading {
  std::uint64_t time_us = 0;           ///< the camera's clock, microseconds
  std::uint16_t ch0 = 0, ch1 = 0;      ///< counts; CH0 follows the band's irradiance
  std::uint16_t gain_index = 0;        ///< which of the sensor's gains (a row of the calibration)
  std::uint16_t integration_ms = 0;    ///< integration time, milliseconds
  float yaw = 0.0f, pitch = 0.0f, roll = 0.0f;  ///< the sensor's attitude (not used by msgs)
};

/// One row of Xmp.Camera.IrradianceCalibrationMeasurement.
struct SunshineCalibrationRow {
  int gain_index = 0;
  double integration_ms = 0.0, ch0 = 0.0, ch1 = 0.0;
};

/// Bytes of one IrradianceList record (firmware 1.1.0 and later).
inline constexpr std::size_t kSunshineRecordBytes = 28;
/// A count the sensor saturates at.
inline constexpr double kSunshineSaturated = 65535.0;
/// The readings averaged for a capture: those of the last this many seconds of its list.
inline constexpr double kSunshineWindowS = 1.0;

/// What came of reading the sensor's tags: `readings` or `problem`.
struct SunshineList {
  std::vector<SunshineReading> readings;
  std::string problem;  ///< empty when the list was read
};

/// The light sensor's reading at a capture: `irradiance` (relative to the calibration's light) from
/// `readings` readings, or `problem`.
struct SunshineIrradiance {
  double irradiance = 0.0;
  int readings = 0;
  std::string problem;
};

namespace detail {

/// Standard base64 (RFC 4648, '+' and '/', '=' padding); spaces and line breaks are skipped, as an
/// XMP value may wrap. nullopt for any other character or a length that is not whole.
inline std::optional<std::vector<unsigned char>> decode_base64(std::string_view s) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::vector<unsigned char> out;
  out.reserve(s.size() * 3 / 4);
  std::uint32_t acc = 0;
  int bits = 0, pad = 0, digits = 0;
  for (const char c : s) {
    if (c == ' ' || c == '\n' || c == '\r' || c == '\t') continue;
    if (c == '=') {
      ++pad;
      ++digits;
      continue;
    }
    const int v = value(c);
    if (v < 0 || pad > 0) return std::nullopt;  // a foreign character, or data after the padding
    acc = (acc << 6) | std::uint32_t(v);
    bits += 6;
    ++digits;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<unsigned char>((acc >> bits) & 0xffu));
    }
  }
  if (digits % 4 != 0 || pad > 2) return std::nullopt;
  return out;
}

/// Little-endian integers and IEEE floats from `p`.
inline std::uint64_t load_le(const unsigned char* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = bytes - 1; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
inline float load_le_float(const unsigned char* p) {
  const std::uint32_t bits = std::uint32_t(load_le(p, 4));
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}

}  // namespace detail

/// Decode Xmp.Camera.IrradianceList. A list that is not base64, not a whole number of 28-byte
/// records, whose times go back, or whose records are not plausible (an integration time of 0 or
/// above 10 s, a non-finite angle) comes back with `problem` saying so.
inline SunshineList parse_sunshine_list(std::string_view base64) {
  SunshineList r;
  const auto bytes = detail::decode_base64(base64);
  if (!bytes) {
    r.problem = "not base64";
    return r;
  }
  if (bytes->empty()) {
    r.problem = "an empty list";
    return r;
  }
  if (bytes->size() % kSunshineRecordBytes != 0) {
    r.problem = cat(bytes->size(), " bytes, not a whole number of ", kSunshineRecordBytes,
                    "-byte readings (firmware before 1.1.0 wrote readings of 20 bytes, which msgs does not read)");
    return r;
  }
  for (std::size_t at = 0; at < bytes->size(); at += kSunshineRecordBytes) {
    const unsigned char* p = bytes->data() + at;
    SunshineReading s;
    s.time_us = detail::load_le(p, 8);
    s.ch0 = std::uint16_t(detail::load_le(p + 8, 2));
    s.ch1 = std::uint16_t(detail::load_le(p + 10, 2));
    s.gain_index = std::uint16_t(detail::load_le(p + 12, 2));
    s.integration_ms = std::uint16_t(detail::load_le(p + 14, 2));
    s.yaw = detail::load_le_float(p + 16);
    s.pitch = detail::load_le_float(p + 20);
    s.roll = detail::load_le_float(p + 24);
    const std::size_t k = r.readings.size();
    if (s.integration_ms == 0 || s.integration_ms > 10000 || !std::isfinite(s.yaw) || !std::isfinite(s.pitch) ||
        !std::isfinite(s.roll)) {
      r.problem = cat("reading ", k, " is not plausible (integration time ", s.integration_ms,
                      " ms, attitude ", s.yaw, " ", s.pitch, " ", s.roll, "): not the 28-byte format");
      r.readings.clear();
      return r;
    }
    if (k > 0 && s.time_us < r.readings.back().time_us) {
      r.problem = cat("reading ", k, " is earlier than reading ", k - 1, ": not the 28-byte format");
      r.readings.clear();
      return r;
    }
    r.readings.push_back(s);
  }
  return r;
}

/// The inverse of parse_sunshine_list: `readings` as an IrradianceList value (base64 of 28-byte
/// little-endian records), as `msgs synth --raw sequoia` writes it.
inline std::string sunshine_list_base64(const std::vector<SunshineReading>& readings) {
  std::vector<unsigned char> bytes;
  auto put = [&](std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) bytes.push_back(static_cast<unsigned char>((v >> (8 * i)) & 0xffu));
  };
  auto put_float = [&](float f) {
    std::uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    put(bits, 4);
  };
  for (const auto& s : readings) {
    put(s.time_us, 8);
    put(s.ch0, 2);
    put(s.ch1, 2);
    put(s.gain_index, 2);
    put(s.integration_ms, 2);
    put_float(s.yaw);
    put_float(s.pitch);
    put_float(s.roll);
  }
  static constexpr char digits[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    const std::size_t n = std::min<std::size_t>(3, bytes.size() - i);
    std::uint32_t v = 0;
    for (std::size_t k = 0; k < 3; ++k) v = (v << 8) | (k < n ? bytes[i + k] : 0u);
    for (std::size_t k = 0; k < 4; ++k) out += k <= n ? digits[(v >> (18 - 6 * k)) & 63u] : '=';
  }
  return out;
}

/// Parse Xmp.Camera.IrradianceCalibrationMeasurement's numbers (`values`, four per row): nullopt
/// unless they are whole rows of a non-negative integer gain index, each index once.
inline std::optional<std::vector<SunshineCalibrationRow>> sunshine_calibration(const std::vector<double>& values) {
  if (values.empty() || values.size() % 4 != 0) return std::nullopt;
  std::vector<SunshineCalibrationRow> rows;
  for (std::size_t i = 0; i < values.size(); i += 4) {
    const double g = values[i];
    if (!(g >= 0 && g <= 255) || g != std::floor(g)) return std::nullopt;
    for (const auto& row : rows)
      if (row.gain_index == int(g)) return std::nullopt;
    rows.push_back({int(g), values[i + 1], values[i + 2], values[i + 3]});
  }
  return rows;
}

/// The sensor's reading at the capture (see the top of this file): the mean of
/// (CH0 / t) / (CH0_cal / t_cal) over the usable readings of the last kSunshineWindowS seconds.
inline SunshineIrradiance sunshine_irradiance(const std::vector<SunshineReading>& readings,
                                              const std::vector<SunshineCalibrationRow>& calibration) {
  SunshineIrradiance r;
  if (readings.empty()) {
    r.problem = "no reading";
    return r;
  }
  // A calibration row gives its gain's counts per millisecond under the calibration's light: a
  // count of 1 .. 65534 in at most 1000 s, so that every reading's ratio to it is finite.
  auto rate_of = [&](int gain_index) -> double {
    for (const auto& row : calibration)
      if (row.gain_index == gain_index)
        return row.integration_ms > 0 && row.integration_ms <= 1e6 && row.ch0 >= 1 && row.ch0 < kSunshineSaturated
                   ? row.ch0 / row.integration_ms
                   : 0.0;
    return 0.0;
  };
  const std::uint64_t last = readings.back().time_us;
  const std::uint64_t window = std::uint64_t(kSunshineWindowS * 1e6);
  double sum = 0.0;
  int saturated = 0, uncalibrated = 0, in_window = 0;
  for (const auto& s : readings) {
    if (last - s.time_us > window) continue;
    ++in_window;
    if (s.ch0 == 0 || s.ch0 >= kSunshineSaturated) {
      ++saturated;
      continue;
    }
    const double cal = rate_of(s.gain_index);
    if (!(cal > 0)) {
      ++uncalibrated;
      continue;
    }
    sum += (double(s.ch0) / s.integration_ms) / cal;
    ++r.readings;
  }
  if (r.readings == 0)
    r.problem = cat("none of its ", in_window, " readings of the last ", short_number(kSunshineWindowS), " s is usable (", saturated,
                    " at count 0 or saturated, ", uncalibrated,
                    " at a gain index without an unsaturated row in Xmp.Camera.IrradianceCalibrationMeasurement)");
  else
    r.irradiance = sum / r.readings;
  return r;
}

}  // namespace msgs::io

// examples/run_sheets.hpp
// Contact sheets of a finished training run (<run>/sheets/sheet_<capture>.png), written by
// `msgs train` and by every `msgs study` run from the model PLYs the run wrote.
#pragma once

#include <cstdio>
#include <filesystem>
#include <random>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include <msgs/io/error.hpp>
#include <msgs/render_util.hpp>
#include <msgs/run.hpp>

namespace msgs::cli {

/// Contact sheets a run writes unless told otherwise (`msgs train --sheets N`, every study run).
inline constexpr int default_run_sheets = 3;

/// What write_run_sheets did.
struct RunSheets {
  std::vector<std::string> files;  ///< written, relative to the run directory ("sheets/sheet_<capture>.png")
  std::string skipped;             ///< why none were written (off, interrupted, no eval frame); empty otherwise
};

namespace detail {

/// A directory under construction: removed with everything in it unless released.
class ScratchDir {
 public:
  explicit ScratchDir(std::filesystem::path p) : path_(std::move(p)) {
    std::error_code ec;
    if (!std::filesystem::create_directory(path_, ec) || ec)
      io::fail(path_, io::cat("cannot create a temporary directory: ", ec ? ec.message() : "it exists"));
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  ~ScratchDir() {
    std::error_code ec;
    if (!released_) std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }
  void release() { released_ = true; }

 private:
  std::filesystem::path path_;
  bool released_ = false;
};

/// `<dir>/.<stem>-<8 hex digits>`, not existing yet.
inline std::filesystem::path hidden_sibling(const std::filesystem::path& dir, const std::string& stem) {
  std::random_device rd;
  for (int attempt = 0; attempt < 16; ++attempt) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "-%08x", unsigned(rd()));
    std::filesystem::path p = dir / ("." + stem + buf);
    std::error_code ec;
    if (!std::filesystem::exists(p, ec)) return p;
  }
  io::fail(dir, "cannot find an unused temporary name");
}

}  // namespace detail

/// After a finished run, load the models it wrote (res.models) and write contact sheets of the
/// first `max_sheets` eval captures (evaluate_models, capture order) into `<run_dir>/sheets`.
/// The sheets are made in a hidden directory beside it which then replaces `sheets/` whole, so a
/// failure or a crash leaves either the previous sheets or the new ones, never a part.
/// Writes nothing (and leaves an existing `sheets/` alone) when max_sheets == 0, the run was
/// interrupted, it wrote no models, or the dataset has no eval frame of a trained band.
/// Only files under <run_dir>/sheets are written: result.json and its metrics, which come from
/// the trainer, are the caller's and unchanged. Throws io::IoError / std::invalid_argument on
/// unreadable models or unwritable directories; max_sheets < -1 is std::invalid_argument.
inline RunSheets write_run_sheets(const io::Dataset& ds, const RunResult& res, const std::filesystem::path& run_dir,
                                  int max_sheets, const RendererFactory& factory) {
  namespace fs = std::filesystem;
  if (max_sheets < -1)
    throw std::invalid_argument("write_run_sheets: max_sheets must be -1 (all) or >= 0, got " +
                                std::to_string(max_sheets));
  RunSheets out;
  if (max_sheets == 0) { out.skipped = "off"; return out; }
  if (res.interrupted) { out.skipped = "the run was interrupted"; return out; }
  if (res.models.empty()) { out.skipped = "the run wrote no models"; return out; }

  std::vector<LoadedModel> loaded;
  for (const auto& [key, path] : res.models) loaded.push_back(load_model(path));
  const ModelSet models = ModelSet::from_models(std::move(loaded), factory);
  bool any_eval = false;
  for (const io::Frame& f : ds.frames) any_eval = any_eval || (f.split == io::Split::eval && models.renders(f.band));
  if (!any_eval) { out.skipped = "no eval frame of a trained band"; return out; }

  const fs::path final_dir = run_dir / "sheets";
  detail::ScratchDir stage(detail::hidden_sibling(run_dir, "sheets-stage"));
  EvalOptions opt;
  opt.max_sheets = max_sheets;
  const EvalResult ev = evaluate_models(ds, models, stage.path(), opt);

  // Swap the finished directory in: the old one moves aside first (rename cannot replace a
  // non-empty directory), and comes back if the new one cannot be moved into place.
  std::error_code ec;
  fs::path old;
  if (fs::exists(final_dir, ec)) {
    old = detail::hidden_sibling(run_dir, "sheets-old");
    fs::rename(final_dir, old, ec);
    if (ec) io::fail(final_dir, io::cat("cannot move the previous sheets aside: ", ec.message()));
  }
  fs::rename(stage.path(), final_dir, ec);
  if (ec) {
    std::error_code ignored;
    if (!old.empty()) fs::rename(old, final_dir, ignored);
    io::fail(final_dir, io::cat("cannot move the finished sheets into place: ", ec.message()));
  }
  stage.release();
  if (!old.empty()) fs::remove_all(old, ec);  // best effort: the new sheets are in place
  for (const auto& f : ev.files) out.files.push_back((fs::path("sheets") / f).generic_string());
  return out;
}

}  // namespace msgs::cli

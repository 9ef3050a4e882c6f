// examples/cmd_export.cpp
// `msgs export`: a band, the colour-infrared composite or a spectral index of a trained model as a
// file that ordinary 3DGS viewers open (.ply, .splat, .spz). The work is in msgs/export.hpp and
// msgs/io/splat_formats.hpp; this file parses, checks the output path and prints a summary.
#include <cstdio>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include <msgs/export.hpp>

#include "commands.hpp"
#include "export_index.hpp"

namespace cmd_export {  // this file's own names: the tool's files compile in unity groups
namespace {

constexpr const char* kUsage =
    "usage: msgs export --model PLY|DIR --out FILE (--band ID | --composite cir | --index NAME)\n"
    "                   [--format ply|splat|spz] [--spz-version 3|2]\n"
    "\n"
    "Write one band, the colour-infrared composite or a spectral index of a trained model as a\n"
    "3-channel Gaussian splat file that ordinary viewers open (SuperSplat, the antimatter15 splat\n"
    "viewer, gsplat.js, Spark):\n"
    "  --model PLY|DIR     a model PLY, or a run directory of model_*.ply files (as `msgs train` writes)\n"
    "  --out FILE          the file to write; the format comes from its extension unless --format\n"
    "  --band ID           D, MS_G, MS_R, MS_RE or MS_NIR. D as it is; a single band is copied into\n"
    "                      all three channels (DC and every SH coefficient), so every channel renders\n"
    "                      exactly as the band: a grey-scale splat\n"
    "  --composite cir     NIR, R, G as red, green, blue: exact. Needs the three bands on the same\n"
    "                      Gaussians (a Joint model); Separate/Split runs have different Gaussians per\n"
    "                      band, so export their bands one by one with --band\n"
    "  --index NAME        ndvi, ndre, gndvi, ndwi or savi, computed PER GAUSSIAN from its\n"
    "                      view-independent (DC) colours and shown on the viewer's red-yellow-green\n"
    "                      scale over [-1, 1], without view-dependent colour. An approximation:\n"
    "                      `msgs view` and `msgs render` compute indices per pixel from the rendered\n"
    "                      bands. Needs both bands on the same Gaussians (a Joint model)\n"
    "  --format F          ply: standard 3DGS PLY (float32, SH kept, band names in a comment)\n"
    "                      splat: antimatter15 .splat, 32 bytes per Gaussian, colour from DC only\n"
    "                      spz: Niantic .spz, gzip, quantised (24-bit positions, 8-bit colours, SH)\n"
    "  --spz-version V     3 (default, Niantic's current) or 2 (for readers that predate version 3)\n"
    "\n"
    "Gaussians the rasteriser never draws (non-finite values, zero quaternions) are left out and\n"
    "log-scales are clamped to +-50, as msgs renders them; the summary says how many. The file is\n"
    "written under a temporary name and renamed, so a failure leaves no partial file.\n";

std::string format_name(msgs::ExportFormat f) {
  switch (f) {
    case msgs::ExportFormat::ply: return "ply";
    case msgs::ExportFormat::splat: return "splat";
    default: return "spz";
  }
}

int run_export(const std::vector<std::string>& argv) {
  using msgs::cli::UsageError;
  const msgs::cli::Args args(argv, {"model", "out", "band", "composite", "index", "format", "spz-version"}, {"help"});
  if (args.flag("help")) { std::fputs(kUsage, stdout); return 0; }
  if (!args.positional().empty()) throw UsageError("unexpected argument '" + args.positional()[0] + "'");
  const std::filesystem::path model = args.require("model"), out = args.require("out");

  const int chosen = int(args.has("band")) + int(args.has("composite")) + int(args.has("index"));
  if (chosen != 1) throw UsageError("give exactly one of --band ID, --composite cir, --index NAME");
  msgs::ExportSelection sel;
  try {
    if (args.has("band")) {
      sel.kind = msgs::ExportSelection::band;
      sel.band_id = args.get("band");
    } else if (args.has("composite")) {
      if (args.get("composite") != "cir")
        throw UsageError("--composite expects cir (NIR, R, G as red, green, blue), got '" + args.get("composite") +
                         "'");
      sel.kind = msgs::ExportSelection::cir;
    } else {
      sel.kind = msgs::ExportSelection::index;
      sel.idx = msgs::cli::export_index(args.get("index"));
    }
  } catch (const msgs::ExportError& e) {
    throw UsageError(std::string("--index: ") + e.what());
  }

  msgs::ExportFormat fmt;
  try {
    fmt = args.has("format") ? msgs::parse_export_format(args.get("format")) : msgs::export_format_from_path(out);
  } catch (const msgs::ExportError& e) {
    throw UsageError(std::string("--out/--format: ") + e.what());
  }
  if (args.has("format")) {
    // A known extension that names another format would make viewers pick the wrong reader.
    try {
      const msgs::ExportFormat by_name = msgs::export_format_from_path(out);
      if (by_name != fmt)
        throw UsageError("--format " + format_name(fmt) + " but --out " + out.string() + " names " +
                         format_name(by_name) + " (viewers choose the reader by extension): end --out in ." +
                         format_name(fmt));
    } catch (const msgs::ExportError&) {
      // Any other extension: the explicit format decides.
    }
  }
  msgs::io::SpzOptions spz;
  spz.version = int(args.integer("spz-version", 3));
  if (spz.version != 2 && spz.version != 3) throw UsageError("--spz-version must be 2 or 3");

  // Check the destination before the work: a missing folder is the common mistake.
  {
    std::error_code ec;
    const std::filesystem::path parent = out.parent_path().empty() ? std::filesystem::path(".") : out.parent_path();
    if (!std::filesystem::is_directory(parent, ec))
      msgs::io::fail(out, "--out",
                     "the folder " + parent.string() + " does not exist; create it or choose another path");
    if (std::filesystem::is_directory(out, ec))
      msgs::io::fail(out, "--out", "is a folder; give a file name such as " + (out / "model.splat").string());
  }

  const msgs::ModelSet models = msgs::load_models_for_export(model);
  // Never replace a source model, nor add a model_*.ply that msgs would read as part of the run.
  auto folder = [](const std::filesystem::path& p) {
    return p.parent_path().empty() ? std::filesystem::path(".") : p.parent_path();
  };
  const bool run_model_name =
      out.filename().string().rfind("model_", 0) == 0 && msgs::io::detail::lower_extension(out) == ".ply";
  for (const auto& m : models.models()) {
    std::error_code ec;
    if (std::filesystem::exists(out, ec) && std::filesystem::equivalent(out, m->path, ec))
      msgs::io::fail(out, "--out", "is the model being exported; choose another file name");
    if (run_model_name && std::filesystem::is_directory(model, ec) &&
        std::filesystem::equivalent(folder(out), folder(m->path), ec))
      msgs::io::fail(out, "--out", "a model_*.ply in the run folder would be read as one more model of the run; "
                                   "choose another name or folder");
  }
  const msgs::ExportedModel e = msgs::select_export(models, sel);
  if (e.size() == 0)
    msgs::io::fail(e.source, "vertex",
                   msgs::io::cat("no Gaussian to export (", e.dropped,
                                 " left out for non-finite values or zero quaternions); expected a trained model "
                                 "with at least one drawable Gaussian"));
  msgs::write_export(out, e, fmt, spz);

  std::error_code ec;
  const auto bytes = std::filesystem::file_size(out, ec);
  std::printf("wrote %s: %s of %s, %zu Gaussians, SH degree %d, %s format, %llu bytes\n", out.string().c_str(),
              e.what.c_str(), e.source.string().c_str(), e.size(), e.sh_degree(), format_name(fmt).c_str(),
              static_cast<unsigned long long>(ec ? 0 : bytes));
  if (e.dropped) std::printf("left out %zu Gaussian(s) with non-finite values or zero quaternions\n", e.dropped);
  if (e.clamped) std::printf("clamped the log-scales of %zu Gaussian(s) to +-50, as the rasteriser does\n", e.clamped);
  if (sel.kind == msgs::ExportSelection::index)
    std::printf("note: %s is computed per Gaussian from DC colours, an approximation of the per-pixel index "
                "that `msgs view` shows\n", sel.idx.name.c_str());
  if (fmt == msgs::ExportFormat::splat && e.sh_degree() > 0)
    std::printf("note: .splat has no view-dependent colour; SH degree %d was reduced to its DC term\n", e.sh_degree());
  if (fmt == msgs::ExportFormat::spz && e.size() > 10'000'000)
    std::printf("note: Niantic's spz reader refuses files of more than 10M Gaussians\n");
  return 0;
}

}  // namespace
}  // namespace cmd_export

MSGS_COMMAND("export", "Write a band, CIR or index of a model as .ply / .splat / .spz for other viewers", cmd_export::run_export);

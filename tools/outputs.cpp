#include "outputs.h"

#include "shards.h"

#include "artrace/io/file_name.h"

#include <algorithm>
#include <stdexcept>
#include <system_error>

namespace artrace::tools {
namespace {

namespace fs = std::filesystem;

/// The path with links, "." and ".." resolved as far as it exists (the rest taken as written).
fs::path resolved(const fs::path& p) {
  std::error_code ec;
  fs::path r = fs::weakly_canonical(fs::absolute(p), ec);
  return ec ? fs::absolute(p).lexically_normal() : r;
}

/// Whether `inner` lies strictly inside `outer` (both resolved).
bool inside(const fs::path& inner, const fs::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i) {
    if (o->empty()) continue;  // a trailing separator
    if (i == inner.end() || *i != *o) return false;
  }
  for (; i != inner.end(); ++i) {
    if (!i->empty()) return true;
  }
  return false;
}

std::vector<fs::path> sorted_entries(const fs::path& folder) {
  std::vector<fs::path> names;
  for (const auto& e : fs::directory_iterator(folder)) names.push_back(e.path());
  std::sort(names.begin(), names.end());
  return names;
}

bool is_frame_png(const std::string& name) {
  constexpr size_t kPrefix = 6, kSuffix = 4;  // "frame_", ".png"
  if (name.size() <= kPrefix + kSuffix || name.compare(0, kPrefix, "frame_") != 0 ||
      name.compare(name.size() - kSuffix, kSuffix, ".png") != 0) {
    return false;
  }
  return std::all_of(name.begin() + kPrefix, name.end() - kSuffix, [](char c) { return c >= '0' && c <= '9'; });
}

/// The first entry of `folder` (by name) that this kind of output does not write, relative to the
/// folder; "" when every entry is one it writes.
std::string foreign_entry(const fs::path& folder, OutputKind kind) {
  for (const fs::path& p : sorted_entries(folder)) {
    const std::string name = p.filename().string();
    const fs::file_status st = fs::symlink_status(p);
    if (kind == OutputKind::frame_folder) {
      if (fs::is_regular_file(st) && (name == kShardManifest || is_frame_png(name))) continue;
    } else if (name == "rgb" || name == "depth") {
      if (!fs::is_directory(st)) return name;
      for (const fs::path& q : sorted_entries(p)) {
        if (!fs::is_regular_file(fs::symlink_status(q)) || io::lower_extension(q) != ".png") {
          return name + "/" + q.filename().string();
        }
      }
      continue;
    } else if (fs::is_regular_file(st) &&
               (name == "rgb.txt" || name == "depth.txt" || name == "groundtruth.txt" || name == "intrinsics.txt")) {
      continue;
    }
    return name;
  }
  return "";
}

/// Whether a path inside an input folder (relative to it) is one the readers read there: a
/// recording's lists, trajectory, intrinsics and image folders, or a shard's frames and manifest.
bool read_there(const fs::path& rel) {
  const std::string first = rel.begin()->string();
  static const char* const kRead[] = {"rgb",           "depth",           "color",          "rgb.txt",
                                      "depth.txt",     "groundtruth.txt", "trajectory.txt", "intrinsics.txt",
                                      "intrinsics.json", "camera_intrinsic.json", "camera.yaml", "camera_info.yaml",
                                      "calibration.yaml", kShardManifest};
  return std::find(std::begin(kRead), std::end(kRead), first) != std::end(kRead) || fs::path(first).stem() == "color" ||
         is_frame_png(first);
}

void check_output(const Output& out, const std::vector<std::string>& inputs) {
  const fs::path o = resolved(out.path);
  auto refuse = [&](const std::string& why) { throw std::invalid_argument(out.path + ": " + why + " (nothing written)"); };
  for (const std::string& in : inputs) {
    if (in.empty()) continue;
    const fs::path i = resolved(in);
    if (o == i) refuse("is the input " + in);
    if (inside(i, o)) refuse("holds the input " + in + ", which writing it would replace");
    std::error_code ec;
    if (inside(o, i) && read_there(o.lexically_relative(i))) {
      refuse("lies inside the input " + in + ", which reads it: writing it would change that input; choose another name");
    }
  }
  std::error_code ec;
  const fs::file_status st = fs::symlink_status(out.path, ec);
  if (ec || !fs::exists(st) || fs::is_symlink(st)) return;  // nothing there, or a link, replaced itself
  if (out.kind == OutputKind::file) {
    if (fs::is_directory(st)) refuse("is a folder, not a file: this command writes a file under that name");
    return;
  }
  if (!fs::is_directory(st)) refuse("is a file, not a folder: this command writes a folder under that name");
  const std::string foreign = foreign_entry(out.path, out.kind);
  if (!foreign.empty()) {
    refuse("holds " + foreign + ", which this command did not write, and writing the folder would replace it: remove it or choose another name");
  }
}

}  // namespace

void check_outputs(const std::vector<Output>& outputs, const std::vector<std::string>& inputs) {
  for (size_t a = 0; a < outputs.size(); ++a) {
    if (outputs[a].path.empty()) continue;
    for (size_t b = 0; b < a; ++b) {
      if (!outputs[b].path.empty() && resolved(outputs[a].path) == resolved(outputs[b].path)) {
        throw std::invalid_argument(outputs[a].path + ": named as two outputs (" + outputs[b].path + ")");
      }
    }
    check_output(outputs[a], inputs);
  }
}

OutputKind clip_or_frames(const fs::path& out) { return is_video_path(out) ? OutputKind::file : OutputKind::frame_folder; }

std::vector<Output> recording_outputs(const std::string& out) {
  if (io::lower_extension(out) != ".oni") return {{out, OutputKind::tum_folder}};
  return {{out, OutputKind::file}, {out + ".trajectory.txt", OutputKind::file}};
}

std::vector<std::string> recording_inputs(const std::string& recording, const std::string& intrinsics, const std::string& trajectory) {
  std::vector<std::string> in{recording, intrinsics, trajectory};
  std::error_code ec;
  if (fs::is_regular_file(recording, ec) && fs::exists(recording + ".trajectory.txt", ec)) in.push_back(recording + ".trajectory.txt");
  return in;
}

}  // namespace artrace::tools

#include "shards.h"

#include "artrace/io/atomic_file.h"
#include "artrace/io/file_name.h"
#include "artrace/io/text_file.h"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <stdexcept>

namespace artrace::tools {
namespace {

int64_t parse_index(const std::string& text, const std::string& whole) {
  size_t used = 0;
  long long v = 0;
  try {
    v = std::stoll(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != text.size() || v < 0) {
    throw std::invalid_argument("frame range \"" + whole + "\": \"" + text + "\" is not a frame number (expected A:B, A: or :B)");
  }
  return v;
}

std::string span(int64_t a, int64_t b) {  // frames [a, b) in words
  return b - a == 1 ? "frame " + std::to_string(a) : "frames " + std::to_string(a) + "-" + std::to_string(b - 1);
}

}  // namespace

FrameRange parse_frame_range(const std::string& text) {
  const size_t colon = text.find(':');
  if (colon == std::string::npos || text.find(':', colon + 1) != std::string::npos) {
    throw std::invalid_argument("frame range \"" + text + "\": expected A:B (frames A to B-1), A: or :B");
  }
  FrameRange r;
  const std::string a = text.substr(0, colon), b = text.substr(colon + 1);
  if (!a.empty()) r.first = parse_index(a, text);
  if (!b.empty()) r.end = parse_index(b, text);
  if (r.end >= 0 && r.end <= r.first) throw std::invalid_argument("frame range \"" + text + "\" is empty");
  return r;
}

std::filesystem::path frame_png(const std::filesystem::path& folder, int64_t index) {
  char name[40];
  std::snprintf(name, sizeof(name), "frame_%06lld.png", static_cast<long long>(index));
  return folder / name;
}

void write_shard_info(const ShardInfo& s) {
  const nlohmann::json j = {{"recording", s.recording}, {"first", s.first},   {"end", s.end},
                            {"recording_frames", s.recording_frames},       {"width", s.width},
                            {"height", s.height},       {"fps", s.fps},     {"settings", s.settings}};
  io::write_file(s.folder / kShardManifest, j.dump(2) + "\n");
}

ShardInfo read_shard_info(const std::filesystem::path& folder) {
  const std::filesystem::path file = folder / kShardManifest;
  if (!std::filesystem::is_directory(folder)) throw std::runtime_error(folder.string() + ": not a folder of an export's frames");
  if (!std::filesystem::exists(file)) {
    throw std::runtime_error(folder.string() + ": not a complete shard (no " + kShardManifest +
                             "; an export of it that did not finish leaves only a .partial folder)");
  }
  ShardInfo s;
  s.folder = folder;
  const std::string text = io::read_text_file(file);
  try {
    const nlohmann::json j = nlohmann::json::parse(text);
    s.recording = j.at("recording").get<std::string>();
    s.first = j.at("first").get<int64_t>();
    s.end = j.at("end").get<int64_t>();
    s.recording_frames = j.at("recording_frames").get<int64_t>();
    s.width = j.at("width").get<int>();
    s.height = j.at("height").get<int>();
    s.fps = j.at("fps").get<double>();
    if (j.contains("settings")) s.settings = j.at("settings");
    if (!s.settings.is_object()) throw std::runtime_error("\"settings\" is not an object");
  } catch (const std::exception& e) {
    throw std::runtime_error(file.string() + ": " + e.what());
  }
  if (s.first < 0 || s.end <= s.first || s.recording_frames < s.end || s.width <= 0 || s.height <= 0 || !(s.fps > 0.0)) {
    throw std::runtime_error(file.string() + ": inconsistent values (frames " + std::to_string(s.first) + ".." +
                             std::to_string(s.end) + " of " + std::to_string(s.recording_frames) + ", " +
                             std::to_string(s.width) + "x" + std::to_string(s.height) + ")");
  }
  return s;
}

std::string file_digest(const std::string& path) {
  if (path.empty()) return "";
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path + ": cannot open file");
  uint64_t h = 14695981039346656037ull;  // FNV-1a
  char buf[1 << 16];
  while (in.read(buf, sizeof buf) || in.gcount() > 0) {
    for (std::streamsize i = 0; i < in.gcount(); ++i) h = (h ^ static_cast<unsigned char>(buf[i])) * 1099511628211ull;
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
  return hex;
}

std::string settings_difference(const nlohmann::json& a, const nlohmann::json& b) {
  if (a.empty() || b.empty()) return "";
  for (auto it = a.begin(); it != a.end(); ++it) {
    const nlohmann::json other = b.contains(it.key()) ? b.at(it.key()) : nlohmann::json();
    if (other != it.value()) return it.key() + " differs (" + other.dump() + " against " + it.value().dump() + ")";
  }
  for (auto it = b.begin(); it != b.end(); ++it) {
    if (!a.contains(it.key())) return it.key() + " differs (" + it.value().dump() + " against null)";
  }
  return "";
}

std::vector<std::string> coverage_problems(std::vector<ShardInfo> shards, int64_t first, int64_t end) {
  std::vector<std::string> out;
  std::sort(shards.begin(), shards.end(), [](const ShardInfo& a, const ShardInfo& b) {
    return a.first != b.first ? a.first < b.first : a.end < b.end;
  });
  int64_t covered = first;  // frames [first, covered) are in some shard
  const ShardInfo* last = nullptr;
  for (const ShardInfo& s : shards) {
    if (s.end <= first || s.first >= end) {
      out.push_back(s.folder.string() + " holds " + span(s.first, s.end) + ", outside " + span(first, end));
      continue;
    }
    if (s.first > covered) out.push_back(span(covered, s.first) + (s.first - covered == 1 ? " is missing" : " are missing"));
    if (last && s.first < covered) {
      const int64_t e = std::min(covered, s.end);
      out.push_back(span(s.first, e) + (e - s.first == 1 ? " is" : " are") + " in both " + last->folder.string() + " and " +
                    s.folder.string());
    }
    if (s.end > covered) {
      covered = s.end;
      last = &s;
    }
  }
  if (covered < end) out.push_back(span(covered, end) + (end - covered == 1 ? " is missing" : " are missing"));
  return out;
}

namespace {
bool is_clip_extension(const std::string& lower_ext) {
  return lower_ext == ".mp4" || lower_ext == ".avi" || lower_ext == ".mkv" || lower_ext == ".mov";
}
}  // namespace

bool is_video_path(const std::filesystem::path& p) { return is_clip_extension(io::lower_extension(p)); }

void check_output_name(const std::filesystem::path& out) {
  const std::string ext = io::lower_extension(out);
  if (ext.empty() || is_clip_extension(ext)) return;
  static const char* const kNotWritten[] = {".webm", ".gif",  ".m4v",  ".mpg",  ".mpeg", ".mjpeg", ".wmv",
                                            ".flv",  ".ogv",  ".ts",   ".3gp",  ".y4m",  ".h264",  ".h265",
                                            ".hevc", ".png",  ".jpg",  ".jpeg", ".bmp",  ".tif",   ".tiff",
                                            ".webp", ".exr",  ".avif", ".ppm"};
  if (std::find(std::begin(kNotWritten), std::end(kNotWritten), ext) != std::end(kNotWritten)) {
    throw std::invalid_argument(out.string() + ": " + out.extension().string() +
                                " is not an output format (clips: .mp4, .mkv, .mov, .avi; numbered PNGs: a folder "
                                "name without an extension)");
  }
  std::fprintf(stderr, "note: %s is not a clip name (.mp4, .mkv, .mov, .avi): numbered PNGs go into the folder %s\n",
               out.string().c_str(), out.string().c_str());
}

void require_output_extension(const std::filesystem::path& out, const std::string& ext, const std::string& what) {
  if (io::lower_extension(out) != ext) {
    throw std::invalid_argument(out.string() + ": this command writes " + what + " (a name ending in " + ext + ")");
  }
}

void note_recording_output(const std::filesystem::path& out) {
  const std::string ext = io::lower_extension(out);
  if (ext.empty() || ext == ".oni") return;
  std::fprintf(stderr, "note: %s does not end in .oni: it becomes a folder in the TUM RGB-D layout\n", out.string().c_str());
}

io::PartialOutput prepare_partial(const std::filesystem::path& out) {
  const bool video = is_video_path(out);
  const std::filesystem::path partial = video ? out.parent_path() / (out.stem().string() + ".partial" + out.extension().string())
                                              : std::filesystem::path(out.string() + ".partial");
  return io::PartialOutput(partial, video ? io::PartialOutput::Kind::file : io::PartialOutput::Kind::folder, out.string());
}

}  // namespace artrace::tools

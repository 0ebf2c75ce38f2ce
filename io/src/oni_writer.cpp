#include "artrace/io/oni_writer.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <tuple>
#include <stdexcept>

namespace artrace::io {
namespace {

constexpr uint32_t kRecordMagic = 0x0052494E;  // "NIR\0"
enum : uint32_t {
  kIntProperty = 0x03,
  kGeneralProperty = 0x06,
  kNodeDataBegin = 0x08,
  kNodeStateReady = 0x09,
  kNewData = 0x0A,
  kEnd = 0x0B,
  kNodeAdded = 0x0D,
  kSeekTable = 0x0E,
};
constexpr uint32_t kCodecNone = 0x454E4F4E;  // "NONE"
constexpr uint32_t kNodeDepth = 2, kNodeImage = 3;
constexpr uint32_t kHeaderSize = 28;

}  // namespace

OniWriter::OniWriter(const std::filesystem::path& path, const OniStreamFormat& depth, const OniStreamFormat& color,
                     uint32_t max_depth_mm)
    : path_(path), partial_(path.string() + ".partial") {
  if (depth.width <= 0 || depth.height <= 0 || color.width <= 0 || color.height <= 0) {
    throw std::invalid_argument(path.string() + ": stream sizes must be positive");
  }
  if (static_cast<size_t>(color.width) * color.height * 3 > 5760000u) {
    throw std::invalid_argument(path.string() + ": OpenNI2's player takes frames of at most 5,760,000 bytes");
  }
  claim_ = std::make_unique<PartialOutput>(partial_, PartialOutput::Kind::file, path.string());
  file_ = std::fopen(partial_.string().c_str(), "wb");
  if (!file_) throw std::runtime_error(partial_.string() + ": cannot create: " + std::strerror(errno));
  depth_.frame_bytes = static_cast<size_t>(depth.width) * depth.height * 2;
  color_.frame_bytes = static_cast<size_t>(color.width) * color.height * 3;
  // File header: magic, version 1.0.1.0, max timestamp (patched at close), max node id.
  const char magic[4] = {'N', 'I', '1', '0'};
  put(magic, 4);
  const uint8_t major = 1, minor = 0;
  const uint16_t maintenance = 1;
  const uint32_t build = 0;
  const uint64_t max_ts = 0;
  const uint32_t max_node = 2;
  put(&major, 1);
  put(&minor, 1);
  put(&maintenance, 2);
  put(&build, 4);
  put(&max_ts, 8);
  put(&max_node, 4);
  node_added(depth_, "Depth", kNodeDepth);
  stream_properties(depth_, depth, true, max_depth_mm);
  record_header(kNodeStateReady, depth_.id, kHeaderSize, 0, 0);
  node_added(color_, "Image", kNodeImage);
  stream_properties(color_, color, false, max_depth_mm);
  record_header(kNodeStateReady, color_.id, kHeaderSize, 0, 0);
  for (const Node* n : {&depth_, &color_}) {
    record_header(kNodeDataBegin, n->id, kHeaderSize + 12, 0, 0);
    const uint32_t frames = 0xffffffffu;
    const uint64_t ts = ~0ull;
    put(&frames, 4);
    put(&ts, 8);
  }
}

OniWriter::~OniWriter() {
  if (file_) {
    std::fclose(file_);
    std::error_code ec;
    std::filesystem::remove(partial_, ec);  // never leave a half-written recording behind
  }
}

void OniWriter::put(const void* p, size_t n) {
  if (std::fwrite(p, 1, n, file_) != n) throw std::runtime_error(partial_.string() + ": write failed (disk full?)");
}

uint64_t OniWriter::tell() const { return static_cast<uint64_t>(std::ftell(file_)); }

void OniWriter::record_header(uint32_t type, uint32_t node, uint32_t fields_size, uint32_t payload, uint64_t undo) {
  const uint32_t h[5] = {kRecordMagic, type, node, fields_size, payload};
  put(h, sizeof(h));
  put(&undo, 8);
}

void OniWriter::put_string(const std::string& s) {
  const uint32_t len = static_cast<uint32_t>(s.size() + 1);
  put(&len, 4);
  put(s.c_str(), len);
}

void OniWriter::node_added(Node& n, const std::string& name, uint32_t type) {
  n.added_offset = tell();
  n.name_bytes = static_cast<uint32_t>(name.size() + 1);
  const uint32_t l = static_cast<uint32_t>(name.size() + 1);
  record_header(kNodeAdded, n.id, 68 + l, 0, 0);
  put_string(name);
  const uint32_t fields[3] = {type, kCodecNone, 0};  // frame count patched at close
  put(fields, sizeof(fields));
  const uint64_t times[3] = {0, 0, 0};  // min, max timestamp and seek-table position, patched
  put(times, sizeof(times));
}

void OniWriter::int_property(uint32_t node, const std::string& name, uint64_t v) {
  record_header(kIntProperty, node, 44 + static_cast<uint32_t>(name.size() + 1), 0, 0);
  put_string(name);
  const uint32_t size = 8;
  put(&size, 4);
  put(&v, 8);
}

void OniWriter::general_property(uint32_t node, const std::string& name, const void* data, uint32_t size) {
  record_header(kGeneralProperty, node, 36 + static_cast<uint32_t>(name.size() + 1) + size, 0, 0);
  put_string(name);
  put(&size, 4);
  put(data, size);
}

void OniWriter::stream_properties(Node& n, const OniStreamFormat& f, bool depth, uint32_t max_depth_mm) {
  const uint32_t mode[3] = {static_cast<uint32_t>(f.width), static_cast<uint32_t>(f.height), static_cast<uint32_t>(f.fps)};
  general_property(n.id, "xnMapOutputMode", mode, 12);
  const uint8_t cropping[12] = {};  // disabled; the stream drops every frame without this record
  general_property(n.id, "xnCropping", cropping, 12);
  int_property(n.id, "oniRequiredFrameSize", n.frame_bytes);
  int_property(n.id, "xnIsGenerating", 1);
  int_property(n.id, "xnPixelFormat", depth ? 4 : 1);
  int_property(n.id, "oniPixelFormat", depth ? 100 : 200);
  int_property(n.id, "xnMirror", 0);
  const double fov[2] = {f.fov_x_rad, f.fov_y_rad};
  general_property(n.id, "xnFOV", fov, 16);
  if (depth) int_property(n.id, "xnDeviceMaxDepth", max_depth_mm);
}

void OniWriter::write(const uint16_t* depth_mm, const uint8_t* rgb, uint64_t depth_us, uint64_t color_us) {
  if (!file_) throw std::logic_error(path_.string() + ": write after close");
  if (frames_ > 0 && (depth_us <= depth_.timestamps.back() || color_us <= color_.timestamps.back())) {
    throw std::invalid_argument(path_.string() + ": timestamps must increase");
  }
  ++frames_;
  const std::tuple<Node*, const void*, uint64_t> streams[2] = {{&depth_, depth_mm, depth_us}, {&color_, rgb, color_us}};
  for (const auto& [n, data, ts] : streams) {
    const uint64_t at = tell();
    record_header(kNewData, n->id, 40, static_cast<uint32_t>(n->frame_bytes), n->last_data);
    put(&ts, 8);
    put(&frames_, 4);  // frame numbers start at 1
    put(data, n->frame_bytes);
    n->last_data = at;
    n->data_offsets.push_back(at);
    n->timestamps.push_back(ts);
  }
}

void OniWriter::close() {
  if (!file_) return;
  for (Node* n : {&depth_, &color_}) {
    const uint64_t table_at = tell();
    record_header(kSeekTable, n->id, kHeaderSize, (frames_ + 1) * 20, 0);
    const uint8_t zero[20] = {};
    put(zero, 20);
    for (uint32_t k = 0; k < frames_; ++k) {
      // entry k + 1: timestamp, configuration id 0, offset of the frame's NewData record
      uint8_t entry[20] = {};
      std::memcpy(entry, &n->timestamps[k], 8);
      std::memcpy(entry + 12, &n->data_offsets[k], 8);
      put(entry, 20);
    }
    // patch NodeAdded: after header, name (u32 + chars), type and codec come frames, min and max
    // timestamp and the seek-table position
    const uint64_t end = tell();
    std::fseek(file_, static_cast<long>(n->added_offset + kHeaderSize + 4 + n->name_bytes + 8), SEEK_SET);
    const uint64_t first = n->timestamps.empty() ? 0 : n->timestamps.front(), last = n->timestamps.empty() ? 0 : n->timestamps.back();
    put(&frames_, 4);
    put(&first, 8);
    put(&last, 8);
    put(&table_at, 8);
    std::fseek(file_, static_cast<long>(end), SEEK_SET);
  }
  record_header(kEnd, 0, kHeaderSize, 0, 0);
  std::fseek(file_, 12, SEEK_SET);
  const uint64_t last_ts = frames_ ? std::max(depth_.timestamps.back(), color_.timestamps.back()) : 0;
  put(&last_ts, 8);  // the player rejects frames later than this
  const bool ok = std::fflush(file_) == 0;
  std::fclose(file_);
  file_ = nullptr;
  if (!ok) {
    std::filesystem::remove(partial_);
    throw std::runtime_error(partial_.string() + ": write failed");
  }
  std::filesystem::rename(partial_, path_);
}

}  // namespace artrace::io

// Writes ONI recordings (OpenNI 1.0.1.0 container, codec NONE) with one depth stream
// (DEPTH_1_MM, 16-bit millimetres) and one colour stream (RGB888) that OpenNI2's own file driver
// plays back. Layout and traps: shared/docs/oni-format.md. The file appears under its final name
// only when close() succeeds; until then it is written to "<name>.partial" (claimed: another
// process writing the same file is refused), which the destructor removes if close() was never
// reached.
#pragma once

#include "artrace/io/atomic_file.h"

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace artrace::io {

struct OniStreamFormat {
  int width = 640;
  int height = 480;
  int fps = 30;
  double fov_x_rad = 1.0144686;  ///< horizontal field of view (OpenNI's CoordinateConverter uses it)
  double fov_y_rad = 0.7898467;
};

class OniWriter {
 public:
  OniWriter(const std::filesystem::path& path, const OniStreamFormat& depth, const OniStreamFormat& color,
            uint32_t max_depth_mm = 10000);
  ~OniWriter();
  OniWriter(const OniWriter&) = delete;
  OniWriter& operator=(const OniWriter&) = delete;

  /// Appends one frame of each stream at `timestamp_us` (increasing). depth: width x height u16 mm;
  /// rgb: width x height x 3 bytes.
  void write(const uint16_t* depth_mm, const uint8_t* rgb, uint64_t timestamp_us) { write(depth_mm, rgb, timestamp_us, timestamp_us); }
  /// The same with each stream's own timestamp (each stream's increasing), as sensors record them.
  void write(const uint16_t* depth_mm, const uint8_t* rgb, uint64_t depth_us, uint64_t color_us);
  /// Seek tables, End record, header patched, file renamed into place.
  void close();
  uint32_t frames() const { return frames_; }

 private:
  struct Node {
    explicit Node(uint32_t node_id) : id(node_id) {}
    uint32_t id;
    uint64_t added_offset = 0;  ///< NodeAdded record
    uint64_t last_data = 0;     ///< previous NewData (undo chain)
    std::vector<uint64_t> data_offsets;
    std::vector<uint64_t> timestamps;
    size_t frame_bytes = 0;
    uint32_t name_bytes = 0;
  };
  void put(const void* p, size_t n);
  void record_header(uint32_t type, uint32_t node, uint32_t fields_size, uint32_t payload, uint64_t undo);
  void put_string(const std::string& s);
  void node_added(Node& n, const std::string& name, uint32_t type);
  void int_property(uint32_t node, const std::string& name, uint64_t v);
  void general_property(uint32_t node, const std::string& name, const void* data, uint32_t size);
  void stream_properties(Node& n, const OniStreamFormat& f, bool depth, uint32_t max_depth_mm);
  uint64_t tell() const;

  std::filesystem::path path_, partial_;
  std::unique_ptr<PartialOutput> claim_;  ///< partial_, held while it is written
  std::FILE* file_ = nullptr;
  Node depth_{1}, color_{2};
  uint32_t frames_ = 0;
};

}  // namespace artrace::io

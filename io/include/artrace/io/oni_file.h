// The ONI container (OpenNI's recording format) as OpenNI 1.x and OpenNI2 write it, read by
// scanning its records: file versions 1.0.0.4 to 1.0.1.x (24-byte record headers before 1.0.1.0,
// 28-byte ones from it), the NodeAdded variants of 1.0.0.4/5, properties anywhere (the last before
// a frame is in effect for it), End followed by NodeRemoved and SeekTable records, seek tables, and
// recordings that were never finalised (header maxima all ones, no End, no seek table, frame counts
// 0: frames are counted by scanning) or cut short (a partial last record is dropped with a warning).
// Formats: shared/docs/oni-format.md (the container) and shared/docs/oni-compressed.md (OpenNI 1.x
// records and codecs), written from OpenNI's sources (Apache-2.0: DataRecords, PlayerNode).
//
// Why not OpenNI2's file driver: Debian's OpenNI2 2.2 crashes on any seek (OpenNI2 issue 51),
// refuses never-finalised files (its node table is sized max node id + 1, which wraps to 0), and
// its player thread spun at the end of a file and crashed on close under load. It remains the
// cross-check in the tests, for the files it plays front to back (openni2_reader.h).
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace artrace::io {

enum OniNodeType : uint32_t { kOniDevice = 1, kOniDepth = 2, kOniImage = 3, kOniAudio = 4, kOniIr = 5 };

/// One record as found in the file.
struct OniRecord {
  uint64_t offset = 0;
  uint32_t type = 0, node = 0, fields_size = 0, payload_size = 0;
  uint64_t undo = 0;  ///< offset of an earlier record (the undo chain), or 0
};

/// A NewData record: one frame of one stream.
struct OniFrameRecord {
  uint64_t record_offset = 0;  ///< where its record starts
  uint64_t data_offset = 0;    ///< its first payload byte
  uint32_t data_size = 0;
  uint64_t timestamp_us = 0;
  uint32_t frame_number = 0;  ///< from 1
  int width = 0, height = 0;  ///< the node's xnMapOutputMode in effect when it was recorded
  uint64_t undo = 0;
};

struct OniSeekEntry {
  uint64_t timestamp_us = 0;
  uint32_t config_id = 0;
  uint64_t offset = 0;  ///< of the frame's NewData record
};

struct OniNode {
  uint32_t id = 0;
  std::string name;
  uint32_t type = 0;  ///< OniNodeType
  std::string codec;  ///< four characters: "NONE", "16zP", "16zT", "JPEG", "Im8z"
  uint32_t declared_frames = 0;  ///< NodeAdded's count (0 in files never finalised)
  uint64_t declared_seek_table = 0;
  int width = 0, height = 0, fps = 0;  ///< xnMapOutputMode (the last one recorded)
  /// Properties by name, the last value recorded: integers and reals as 8 bytes, strings and
  /// general properties as their bytes.
  std::map<std::string, std::vector<uint8_t>> properties;
  std::vector<OniFrameRecord> frames;    ///< in file order
  std::vector<OniSeekEntry> seek_table;  ///< entry k for frame k (entry 0 is all zero); empty when none

  std::optional<int64_t> int_property(const std::string& name) const;
  std::optional<double> real_property(const std::string& name) const;
};

class OniContainer {
 public:
  /// Opens and scans the file. Throws ParseError ("file @ byte N: problem") for what is not an
  /// ONI recording or is malformed; a file cut short inside a record keeps what precedes it (see
  /// warnings()).
  explicit OniContainer(const std::filesystem::path& path);

  const std::filesystem::path& path() const { return path_; }
  /// Major, minor, maintenance, build.
  const uint32_t* version() const { return version_; }
  int record_header_size() const { return header_; }
  /// The header's maxima are all ones and there is no End record: recording never stopped cleanly.
  bool finalised() const { return finalised_; }
  bool has_end() const { return end_offset_ != 0; }
  uint64_t end_offset() const { return end_offset_; }
  const std::vector<OniNode>& nodes() const { return nodes_; }
  /// The first node of a type (kOniDepth, kOniImage), or null.
  const OniNode* find(uint32_t type) const;
  const std::vector<OniRecord>& records() const { return records_; }
  /// What was dropped or doubted while scanning (a partial last record, a broken record magic).
  const std::vector<std::string>& warnings() const { return warnings_; }

  /// A frame's payload (throws ParseError when the file cannot be read there).
  void read_payload(const OniFrameRecord& frame, std::vector<uint8_t>& out) const;
  /// "file @ byte N" for messages.
  std::string where(uint64_t offset) const;

 private:
  std::filesystem::path path_;
  mutable std::ifstream in_;
  uint64_t size_ = 0;
  uint32_t version_[4] = {};
  int header_ = 28;
  bool finalised_ = true;
  uint64_t end_offset_ = 0;
  std::vector<OniNode> nodes_;
  std::vector<OniRecord> records_;
  std::vector<std::string> warnings_;
};

}  // namespace artrace::io

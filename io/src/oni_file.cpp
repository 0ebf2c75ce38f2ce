#include "artrace/io/oni_file.h"
#include "artrace/io/parse_error.h"

#include <cstring>
#include <fstream>
#include <map>

namespace artrace::io {
namespace {

constexpr uint32_t kRecordMagic = 0x0052494E;

class Bytes {
 public:
  Bytes(const std::filesystem::path& path, std::vector<uint8_t> data) : path_(path), data_(std::move(data)) {}
  [[noreturn]] void fail(uint64_t at, const std::string& what) const {
    throw ParseError(path_.string() + " @ byte " + std::to_string(at), 0, 0, what);
  }
  template <class T>
  T get(uint64_t at) const {
    if (at + sizeof(T) > data_.size()) fail(at, "truncated: the file ends inside a record");
    T v;
    std::memcpy(&v, data_.data() + at, sizeof(T));
    return v;
  }
  std::string str(uint64_t at, uint32_t& consumed) const {
    const uint32_t len = get<uint32_t>(at);
    if (len == 0 || len > 80) fail(at, "string length " + std::to_string(len) + " out of range (1..80)");
    if (at + 4 + len > data_.size()) fail(at, "truncated inside a string");
    const std::string s(reinterpret_cast<const char*>(data_.data() + at + 4), len - 1);
    // names of nodes and properties: OpenNI2's player crashed (SIGSEGV) on a byte above 127 in a
    // property name, found by fuzzing; control bytes are refused as malformed
    for (const char c : s) {
      if (c < 0x20 || c > 0x7e) {
        fail(at, "name holds byte " + std::to_string(static_cast<unsigned char>(c)) +
                     ", outside printable ASCII (OpenNI2's player crashed on bytes above 127 in property names)");
      }
    }
    consumed = 4 + len;
    return s;
  }
  uint64_t size() const { return data_.size(); }

 private:
  std::filesystem::path path_;
  std::vector<uint8_t> data_;
};

}  // namespace

OniFileInfo inspect_oni(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ParseError(path.string(), 0, 0, "cannot open file");
  std::vector<uint8_t> data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const Bytes b(path, std::move(data));
  const uint32_t magic = b.size() >= 24 ? b.get<uint32_t>(0) : 0;
  if (std::memcmp(&magic, "NI10", 4) != 0) {
    b.fail(0, "not an ONI file (no 'NI10' header)");
  }
  const uint8_t major = b.get<uint8_t>(4), minor = b.get<uint8_t>(5);
  const uint16_t maint = b.get<uint16_t>(6);
  if (major != 1 || minor != 0 || maint != 1) {
    b.fail(4, "unsupported ONI version " + std::to_string(major) + "." + std::to_string(minor) + "." +
                  std::to_string(maint) + " (this reader takes 1.0.1.x)");
  }
  const uint32_t max_node = b.get<uint32_t>(20);
  OniFileInfo info;
  std::map<uint32_t, size_t> node_index;
  std::map<uint32_t, bool> ready;
  bool data_begin = false;
  uint64_t at = 24;
  for (;;) {
    if (at >= b.size()) b.fail(at, "no End record: the file is truncated");
    if (b.get<uint32_t>(at) != kRecordMagic) b.fail(at, "bad record magic (corrupt file)");
    const uint32_t type = b.get<uint32_t>(at + 4), node = b.get<uint32_t>(at + 8);
    const uint32_t fields = b.get<uint32_t>(at + 12), payload = b.get<uint32_t>(at + 16);
    if (fields < 28) b.fail(at, "record fields size " + std::to_string(fields) + " is below 28");
    if (at + fields + payload > b.size()) b.fail(at, "truncated: record runs past the end of the file");
    if (node > max_node) b.fail(at, "node id " + std::to_string(node) + " above the header's maximum " + std::to_string(max_node));
    const uint64_t f = at + 28;
    switch (type) {
      case 0x0B:  // End
        info.end_offset = at;
        if (!data_begin) b.fail(at, "no DataBegin record before End");
        for (const auto& [id, ok] : ready) {
          if (!ok) b.fail(at, "node " + std::to_string(id) + " has no StateReady record");
        }
        return info;
      case 0x0D: {  // NodeAdded
        OniNodeInfo n;
        n.id = node;
        uint32_t used = 0;
        n.name = b.str(f, used);
        n.type = b.get<uint32_t>(f + used);
        n.codec = b.get<uint32_t>(f + used + 4);
        n.frames = b.get<uint32_t>(f + used + 8);
        if (n.codec == 0) b.fail(at, "node '" + n.name + "' has codec 0 (OpenNI2 crashes on it)");
        node_index[node] = info.nodes.size();
        info.nodes.push_back(n);
        ready[node] = false;
        break;
      }
      case 0x03: case 0x04: case 0x05: case 0x06: {  // properties
        if (!node_index.count(node)) b.fail(at, "property for node " + std::to_string(node) + " before it was added");
        uint32_t used = 0;
        const std::string name = b.str(f, used);
        OniNodeInfo& n = info.nodes[node_index[node]];
        n.has_mode |= name == "xnMapOutputMode";
        n.has_cropping |= name == "xnCropping";
        if (type == 0x06 && name == "xnMapOutputMode") {
          if (b.get<uint32_t>(f + used) != 12) b.fail(at, "xnMapOutputMode must hold 12 bytes");
          n.width = static_cast<int>(b.get<uint32_t>(f + used + 4));
          n.height = static_cast<int>(b.get<uint32_t>(f + used + 8));
          n.fps = static_cast<int>(b.get<uint32_t>(f + used + 12));
        }
        break;
      }
      case 0x09:
        if (!node_index.count(node)) b.fail(at, "StateReady for an unknown node");
        ready[node] = true;
        break;
      case 0x08:
        data_begin = true;
        break;
      case 0x0A: {  // NewData
        if (!node_index.count(node)) b.fail(at, "frame data for an unknown node");
        OniNodeInfo& n = info.nodes[node_index[node]];
        // without either property the player drops every frame of the stream (oni-format.md)
        if (!n.has_mode || !n.has_cropping) {
          b.fail(at, "frame data for node '" + n.name + "' before its " + (n.has_mode ? "xnCropping" : "xnMapOutputMode") +
                         " property (OpenNI2 plays no frame without it)");
        }
        const uint32_t number = b.get<uint32_t>(f + 8);
        if (number == 0 || number > n.frames) {
          b.fail(at, "frame number " + std::to_string(number) + " outside 1.." + std::to_string(n.frames));
        }
        if (payload > 5760000u) b.fail(at, "frame of " + std::to_string(payload) + " bytes is larger than OpenNI2 plays");
        ++n.data_records;
        break;
      }
      case 0x07: case 0x0E:
        break;
      default:
        b.fail(at, "unknown record type " + std::to_string(type));
    }
    at += fields + static_cast<uint64_t>(payload);
  }
}

}  // namespace artrace::io

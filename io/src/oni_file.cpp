#include "artrace/io/oni_file.h"
#include "artrace/io/parse_error.h"

#include <algorithm>
#include <cstring>
#include <tuple>

namespace artrace::io {
namespace {

constexpr uint32_t kRecordMagic = 0x0052494E;  // "NIR\0"
enum : uint32_t {
  kNodeAdded104 = 0x02,
  kIntProperty = 0x03,
  kRealProperty = 0x04,
  kStringProperty = 0x05,
  kGeneralProperty = 0x06,
  kNodeRemoved = 0x07,
  kNodeDataBegin = 0x08,
  kNodeStateReady = 0x09,
  kNewData = 0x0A,
  kEnd = 0x0B,
  kNodeAdded105 = 0x0C,
  kNodeAdded = 0x0D,
  kSeekTable = 0x0E,
};
// Sanity limits: the largest property OpenNI records is the depth-to-shift table (20,002 bytes); a
// 1280x1024 RGB frame is 3.9 MB.
constexpr uint32_t kMaxFields = 1u << 20;
constexpr uint32_t kMaxPayload = 64u << 20;
constexpr int kMaxSide = 16384;

/// The fields of one record, read from the file, with bounds-checked access.
class Fields {
 public:
  Fields(const OniContainer& c, uint64_t offset, std::vector<uint8_t> bytes) : c_(c), offset_(offset), b_(std::move(bytes)) {}
  [[noreturn]] void fail(size_t at, const std::string& what) const { throw ParseError(c_.where(offset_ + at), 0, 0, what); }
  template <class T>
  T get(size_t& at) const {
    if (at + sizeof(T) > b_.size()) fail(at, "record fields end inside a value (fields size too small)");
    T v;
    std::memcpy(&v, b_.data() + at, sizeof(T));
    at += sizeof(T);
    return v;
  }
  std::string name(size_t& at) const {
    const uint32_t len = get<uint32_t>(at);
    if (len == 0 || len > 80) fail(at - 4, "name length " + std::to_string(len) + " out of range (1..80)");
    if (at + len > b_.size()) fail(at, "record fields end inside a name");
    std::string s(reinterpret_cast<const char*>(b_.data() + at), len);
    if (s.back() == '\0') s.pop_back();
    for (const char ch : s) {
      if (ch < 0x20 || ch > 0x7e) fail(at, "name holds byte " + std::to_string(static_cast<unsigned char>(ch)) + ", outside printable ASCII");
    }
    at += len;
    return s;
  }
  std::vector<uint8_t> bytes(size_t& at, uint32_t n) const {
    if (at + n > b_.size()) fail(at, "property of " + std::to_string(n) + " bytes runs past its record");
    std::vector<uint8_t> v(b_.begin() + static_cast<std::ptrdiff_t>(at), b_.begin() + static_cast<std::ptrdiff_t>(at + n));
    at += n;
    return v;
  }

 private:
  const OniContainer& c_;
  uint64_t offset_;
  std::vector<uint8_t> b_;
};

template <class T>
T from_bytes(const std::vector<uint8_t>& v) {
  T x{};
  std::memcpy(&x, v.data(), std::min(sizeof(T), v.size()));
  return x;
}

}  // namespace

std::optional<int64_t> OniNode::int_property(const std::string& name) const {
  const auto it = properties.find(name);
  if (it == properties.end() || it->second.size() != 8) return std::nullopt;
  return from_bytes<int64_t>(it->second);
}

std::optional<double> OniNode::real_property(const std::string& name) const {
  const auto it = properties.find(name);
  if (it == properties.end() || it->second.size() != 8) return std::nullopt;
  return from_bytes<double>(it->second);
}

std::string OniContainer::where(uint64_t offset) const { return path_.string() + " @ byte " + std::to_string(offset); }

const OniNode* OniContainer::find(uint32_t type) const {
  for (const OniNode& n : nodes_) {
    if (n.type == type) return &n;
  }
  return nullptr;
}

void OniContainer::read_payload(const OniFrameRecord& f, std::vector<uint8_t>& out) const {
  out.resize(f.data_size);
  in_.clear();
  in_.seekg(static_cast<std::streamoff>(f.data_offset));
  if (!in_.read(reinterpret_cast<char*>(out.data()), f.data_size)) throw ParseError(where(f.data_offset), 0, 0, "cannot read the frame's data");
}

OniContainer::OniContainer(const std::filesystem::path& path) : path_(path) {
  in_.open(path, std::ios::binary);
  if (!in_) throw ParseError(path.string(), 0, 0, "cannot open file");
  in_.seekg(0, std::ios::end);
  size_ = static_cast<uint64_t>(in_.tellg());
  in_.seekg(0);
  auto read_at = [&](uint64_t at, void* out, size_t n) {
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(at));
    return static_cast<bool>(in_.read(static_cast<char*>(out), static_cast<std::streamsize>(n)));
  };
  uint8_t head[24];
  if (size_ < 24 || !read_at(0, head, 24) || std::memcmp(head, "NI10", 4) != 0) {
    throw ParseError(where(0), 0, 0, "not an ONI file (no 'NI10' header)");
  }
  version_[0] = head[4];
  version_[1] = head[5];
  uint16_t maint;
  std::memcpy(&maint, head + 6, 2);
  version_[2] = maint;
  std::memcpy(&version_[3], head + 8, 4);
  uint64_t max_ts;
  uint32_t max_node;
  std::memcpy(&max_ts, head + 12, 8);
  std::memcpy(&max_node, head + 20, 4);
  const auto v = std::make_tuple(version_[0], version_[1], version_[2], version_[3]);
  if (v < std::make_tuple(1u, 0u, 0u, 4u) || v >= std::make_tuple(1u, 1u, 0u, 0u)) {
    throw ParseError(where(4), 0, 0, "unsupported ONI version " + std::to_string(version_[0]) + "." + std::to_string(version_[1]) + "." +
                                         std::to_string(version_[2]) + "." + std::to_string(version_[3]) +
                                         " (this reader takes 1.0.0.4 to 1.0.1.x)");
  }
  const bool old_layout = v < std::make_tuple(1u, 0u, 1u, 0u);
  header_ = old_layout ? 24 : 28;
  const bool header_unfinished = max_ts == ~0ull && max_node == 0xffffffffu;

  std::map<uint32_t, size_t> index;  // node id -> nodes_ (never sized by the header's maximum)
  auto node_of = [&](const OniRecord& r, const char* what) -> OniNode& {
    const auto it = index.find(r.node);
    if (it == index.end()) throw ParseError(where(r.offset), 0, 0, std::string(what) + " for node " + std::to_string(r.node) + ", which was never added");
    return nodes_[it->second];
  };
  uint64_t at = 24;
  std::vector<uint8_t> raw(static_cast<size_t>(header_));
  for (;;) {
    if (size_ - at < static_cast<uint64_t>(header_)) {
      if (at < size_ && !has_end()) warnings_.push_back(where(at) + ": " + std::to_string(size_ - at) + " bytes after the last whole record (dropped)");
      break;
    }
    read_at(at, raw.data(), raw.size());
    OniRecord r;
    r.offset = at;
    uint32_t magic;
    std::memcpy(&magic, raw.data(), 4);
    std::memcpy(&r.type, raw.data() + 4, 4);
    std::memcpy(&r.node, raw.data() + 8, 4);
    std::memcpy(&r.fields_size, raw.data() + 12, 4);
    std::memcpy(&r.payload_size, raw.data() + 16, 4);
    if (old_layout) {
      uint32_t undo;
      std::memcpy(&undo, raw.data() + 20, 4);
      r.undo = undo;
    } else {
      std::memcpy(&r.undo, raw.data() + 20, 8);
    }
    if (magic != kRecordMagic) {
      // after End, OpenNI's recorder may pad the file; before it, a recording cut off mid-write
      if (!has_end()) warnings_.push_back(where(at) + ": no record here (bad record magic): the recording is read up to this byte");
      break;
    }
    if (r.fields_size < static_cast<uint32_t>(header_) || r.fields_size > kMaxFields) {
      throw ParseError(where(at), 0, 0, "record fields size " + std::to_string(r.fields_size) + " out of range (" + std::to_string(header_) + ".." +
                                            std::to_string(kMaxFields) + ")");
    }
    if (r.payload_size > kMaxPayload) throw ParseError(where(at), 0, 0, "record payload of " + std::to_string(r.payload_size) + " bytes (corrupt size)");
    if (at + r.fields_size + r.payload_size > size_) {
      warnings_.push_back(where(at) + ": the last record runs " + std::to_string(at + r.fields_size + r.payload_size - size_) +
                          " bytes past the end of the file (a recording cut short): dropped");
      break;
    }
    std::vector<uint8_t> fb(r.fields_size - static_cast<uint32_t>(header_));
    if (!fb.empty()) read_at(at + static_cast<uint64_t>(header_), fb.data(), fb.size());
    const Fields f(*this, at + static_cast<uint64_t>(header_), std::move(fb));
    size_t p = 0;
    switch (r.type) {
      case kNodeAdded:
      case kNodeAdded105:
      case kNodeAdded104: {
        OniNode n;
        n.id = r.node;
        n.name = f.name(p);
        n.type = f.get<uint32_t>(p);
        const uint32_t codec = f.get<uint32_t>(p);
        n.codec.assign(reinterpret_cast<const char*>(&codec), 4);
        for (char& ch : n.codec) {
          if (ch < 0x20 || ch > 0x7e) ch = '?';
        }
        if (r.type != kNodeAdded104) {
          n.declared_frames = f.get<uint32_t>(p);
          f.get<uint64_t>(p);  // min and max timestamps: recounted from the frames
          f.get<uint64_t>(p);
        }
        if (r.type == kNodeAdded) n.declared_seek_table = old_layout ? f.get<uint32_t>(p) : f.get<uint64_t>(p);
        if (index.count(r.node)) throw ParseError(where(at), 0, 0, "node " + std::to_string(r.node) + " ('" + n.name + "') is added twice");
        index[r.node] = nodes_.size();
        nodes_.push_back(std::move(n));
        break;
      }
      case kIntProperty:
      case kRealProperty:
      case kStringProperty:
      case kGeneralProperty: {
        OniNode& n = node_of(r, "a property");
        const std::string name = f.name(p);
        const uint32_t size = f.get<uint32_t>(p);
        if ((r.type == kIntProperty || r.type == kRealProperty) && size != 8) {
          f.fail(p - 4, "property '" + name + "' of " + std::to_string(size) + " bytes (numbers take 8)");
        }
        std::vector<uint8_t> value = f.bytes(p, size);
        if (name == "xnMapOutputMode") {
          if (size != 12) f.fail(p - size, "xnMapOutputMode of " + std::to_string(size) + " bytes (expected 12)");
          uint32_t mode[3];
          std::memcpy(mode, value.data(), 12);
          if (mode[0] < 1 || mode[1] < 1 || mode[0] > kMaxSide || mode[1] > kMaxSide || mode[2] > 1000) {
            f.fail(p - size, "xnMapOutputMode " + std::to_string(mode[0]) + "x" + std::to_string(mode[1]) + " at " + std::to_string(mode[2]) +
                                 " fps is out of range");
          }
          n.width = static_cast<int>(mode[0]);
          n.height = static_cast<int>(mode[1]);
          n.fps = static_cast<int>(mode[2]);
        }
        n.properties[name] = std::move(value);
        break;
      }
      case kNewData: {
        OniNode& n = node_of(r, "frame data");
        if (has_end()) break;  // frames end at End
        OniFrameRecord fr;
        fr.record_offset = at;
        fr.data_offset = at + r.fields_size;
        fr.data_size = r.payload_size;
        fr.timestamp_us = f.get<uint64_t>(p);
        fr.frame_number = f.get<uint32_t>(p);
        fr.width = n.width;
        fr.height = n.height;
        fr.undo = r.undo;
        if (n.width == 0) throw ParseError(where(at), 0, 0, "frame data for node '" + n.name + "' before its xnMapOutputMode property");
        n.frames.push_back(fr);
        break;
      }
      case kSeekTable: {
        OniNode& n = node_of(r, "a seek table");
        const uint32_t entry = old_layout ? 16 : 20;
        if (r.payload_size % entry != 0) throw ParseError(where(at), 0, 0, "seek table of " + std::to_string(r.payload_size) + " bytes is not a whole number of entries");
        std::vector<uint8_t> table(r.payload_size);
        read_at(at + r.fields_size, table.data(), table.size());
        n.seek_table.clear();
        for (size_t k = 0; k < table.size(); k += entry) {
          OniSeekEntry e;
          std::memcpy(&e.timestamp_us, &table[k], 8);
          std::memcpy(&e.config_id, &table[k + 8], 4);
          if (old_layout) {
            uint32_t off;
            std::memcpy(&off, &table[k + 12], 4);
            e.offset = off;
          } else {
            std::memcpy(&e.offset, &table[k + 12], 8);
          }
          n.seek_table.push_back(e);
        }
        break;
      }
      case kEnd:
        // End's node id is left unset (0xFFFFFFFF) by OpenNI 1.x: not checked
        if (!has_end()) end_offset_ = at;
        break;
      case kNodeRemoved:
      case kNodeDataBegin:
      case kNodeStateReady:
        break;
      default:
        throw ParseError(where(at), 0, 0, "unknown record type " + std::to_string(r.type));
    }
    records_.push_back(r);
    at += r.fields_size + static_cast<uint64_t>(r.payload_size);
  }
  finalised_ = has_end() && !header_unfinished;
}

}  // namespace artrace::io

// Pieces of a PNG writer for the PNG decoder's tests and its fuzz harness: big-endian numbers,
// chunks with their CRCs, and the zlib stream, on libdeflate.
#pragma once

#include <libdeflate.h>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace artrace::test {

using Bytes = std::vector<uint8_t>;

inline void put32(Bytes& o, uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) o.push_back(static_cast<uint8_t>(v >> s));
}

inline uint32_t get32(const uint8_t* p) { return uint32_t{p[0]} << 24 | uint32_t{p[1]} << 16 | uint32_t{p[2]} << 8 | p[3]; }

/// Appends a chunk: its length, type, data and the CRC of type and data.
inline void put_chunk(Bytes& out, const char* type, const uint8_t* data, size_t n) {
  put32(out, static_cast<uint32_t>(n));
  const size_t start = out.size();
  out.insert(out.end(), type, type + 4);
  out.insert(out.end(), data, data + n);
  put32(out, static_cast<uint32_t>(libdeflate_crc32(0, out.data() + start, n + 4)));
}

/// `raw` as a zlib stream (libdeflate, level 6).
inline Bytes zlib_compress(const Bytes& raw) {
  libdeflate_compressor* c = libdeflate_alloc_compressor(6);
  Bytes out(libdeflate_zlib_compress_bound(c, raw.size()));
  out.resize(libdeflate_zlib_compress(c, raw.data(), raw.size(), out.data(), out.size()));
  libdeflate_free_compressor(c);
  return out;
}

}  // namespace artrace::test

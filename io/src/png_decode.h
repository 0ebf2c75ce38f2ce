// PNG decoding for the recordings' frames, on libdeflate. Internal to io.
//
// Why not OpenCV alone: OpenCV decodes PNG through libpng, and libpng inflates with zlib's
// streaming inflater; on the TUM frames that inflation and its checksums were about 70% of the
// reader's instructions (callgrind of `bench-io`). libdeflate inflates a whole buffer at once,
// with SIMD checksums, and is well kept. What remains is PNG's own layer: the chunk walk, the
// checks libpng makes, and the five row filters, written from the PNG specification (ISO/IEC
// 15948, sections 5, 9 and 11).
//
// It takes only the layouts recordings use and answers exactly as cv::imdecode would; for any
// other file (interlaced, palette, transparency chunk, other bit depths, anything irregular:
// a wrong checksum, a stream that ends early or runs on, chunks out of order) it declines, and the
// caller decodes with OpenCV, which keeps OpenCV's answer, error or image, for every such file.
#pragma once

#include <opencv2/core.hpp>

#include <cstddef>
#include <cstdint>

namespace artrace::io {

/// `data` decoded as cv::imdecode(data, flags) would decode it, for:
///   - flags cv::IMREAD_COLOR: 8-bit grey, grey + alpha, RGB or RGBA, to 8-bit BGR (alpha dropped,
///     grey repeated);
///   - flags cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR: 16-bit grey, to CV_16UC1.
/// An empty Mat where this decoder declines (see above); the caller then uses OpenCV.
cv::Mat decode_png(const uint8_t* data, size_t size, int flags);

}  // namespace artrace::io

// ClipWriter on FFmpeg's libraries, following FFmpeg's own muxing example (doc/examples/mux.c):
// an output context guessed from the file name, one video stream, frames converted by libswscale,
// packets sent through avcodec_send_frame / avcodec_receive_packet, and the trailer written last.
#include "clip_writer.h"

#include "artrace/io/file_name.h"

#include <CLI/CLI.hpp>
#include <opencv2/core.hpp>

#include <stdexcept>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/opt.h>
#include <libavutil/pixdesc.h>
#include <libswscale/swscale.h>
}

namespace artrace::tools {
namespace {

std::string av_error(int code) {
  char text[AV_ERROR_MAX_STRING_SIZE] = {};
  av_strerror(code, text, sizeof(text));
  return text;
}

}  // namespace

void add_clip_options(CLI::App* cmd, ClipOptions& clip) {
  cmd->add_option("--preset", clip.preset, "x264's speed preset for .mp4/.mkv/.mov")
      ->capture_default_str()
      ->check(CLI::IsMember({"ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow", "placebo"}));
  cmd->add_option("--crf", clip.crf, "x264's constant rate factor (0 lossless, 51 worst; 18 looks lossless)")
      ->capture_default_str()
      ->check(CLI::Range(0, 51));
}

struct ClipWriter::Impl {
  std::string name;
  cv::Size size, coded;  // the frames', and the encoder's (even)
  AVFormatContext* format = nullptr;
  AVCodecContext* codec = nullptr;
  AVStream* stream = nullptr;
  AVFrame* frame = nullptr;
  AVPacket* packet = nullptr;
  SwsContext* sws = nullptr;
  cv::Mat padded;
  int64_t next_pts = 0;
  bool finished = false;

  void check(int code, const char* what) const {
    if (code < 0) throw std::runtime_error(name + ": " + what + ": " + av_error(code));
  }

  /// Sends a frame (nullptr: the end) and writes every packet the encoder has ready.
  void encode(const AVFrame* f) {
    check(avcodec_send_frame(codec, f), "encoding a frame");
    for (;;) {
      const int r = avcodec_receive_packet(codec, packet);
      if (r == AVERROR(EAGAIN) || r == AVERROR_EOF) return;
      check(r, "encoding a frame");
      av_packet_rescale_ts(packet, codec->time_base, stream->time_base);
      packet->stream_index = stream->index;
      check(av_interleaved_write_frame(format, packet), "writing a packet");  // takes the packet's data
    }
  }

  ~Impl() {
    sws_freeContext(sws);
    av_packet_free(&packet);
    av_frame_free(&frame);
    avcodec_free_context(&codec);
    if (format) {
      if (!(format->oformat->flags & AVFMT_NOFILE)) avio_closep(&format->pb);
      avformat_free_context(format);
    }
  }
};

ClipWriter::ClipWriter(const std::filesystem::path& file, const std::string& shown_name, cv::Size size, const ClipOptions& options)
    : impl_(std::make_unique<Impl>()) {
  Impl& w = *impl_;
  if (size.width <= 0 || size.height <= 0) throw std::runtime_error(shown_name + ": frames of " + std::to_string(size.width) + "x" + std::to_string(size.height));
  w.name = shown_name;
  w.size = size;
  w.coded = cv::Size((size.width + 1) & ~1, (size.height + 1) & ~1);
  if (!(options.fps > 0.0)) throw std::runtime_error(shown_name + ": frame rate " + std::to_string(options.fps));
  av_log_set_level(AV_LOG_ERROR);
  const std::string path = file.string();
  w.check(avformat_alloc_output_context2(&w.format, nullptr, nullptr, path.c_str()), "no container for this file name");

  const AVCodec* encoder = nullptr;
  AVPixelFormat pixels = AV_PIX_FMT_YUV420P;
  if (io::lower_extension(file) == ".avi") {
    encoder = avcodec_find_encoder(AV_CODEC_ID_MJPEG);
    pixels = AV_PIX_FMT_YUVJ420P;  // JPEG's full range
  } else {
    encoder = avcodec_find_encoder_by_name("libx264");
    if (!encoder) encoder = avcodec_find_encoder(AV_CODEC_ID_MPEG4);
  }
  if (!encoder) throw std::runtime_error(shown_name + ": this FFmpeg has no video encoder for " + file.extension().string());

  w.stream = avformat_new_stream(w.format, nullptr);
  w.codec = avcodec_alloc_context3(encoder);
  w.frame = av_frame_alloc();
  w.packet = av_packet_alloc();
  if (!w.stream || !w.codec || !w.frame || !w.packet) throw std::bad_alloc();
  AVCodecContext& c = *w.codec;
  c.width = w.coded.width;
  c.height = w.coded.height;
  c.pix_fmt = pixels;
  c.framerate = av_d2q(options.fps, 1000000);
  c.time_base = av_inv_q(c.framerate);
  c.thread_count = 0;  // the encoder's own choice of threads
  if (w.format->oformat->flags & AVFMT_GLOBALHEADER) c.flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
  if (std::string(encoder->name) == "libx264") {
    w.check(av_opt_set(c.priv_data, "preset", options.preset.c_str(), 0), ("x264 preset \"" + options.preset + "\"").c_str());
    w.check(av_opt_set_int(c.priv_data, "crf", options.crf, 0), "x264 crf");
  } else {
    c.flags |= AV_CODEC_FLAG_QSCALE;  // a fixed quantiser: q 3 of 31 for MPEG-4 and Motion JPEG
    c.global_quality = FF_QP2LAMBDA * 3;
  }
  w.check(avcodec_open2(w.codec, encoder, nullptr), ("opening the encoder " + std::string(encoder->name)).c_str());
  w.check(avcodec_parameters_from_context(w.stream->codecpar, w.codec), "stream parameters");
  w.stream->time_base = c.time_base;
  w.stream->avg_frame_rate = c.framerate;
  if (!(w.format->oformat->flags & AVFMT_NOFILE)) w.check(avio_open(&w.format->pb, path.c_str(), AVIO_FLAG_WRITE), "cannot create the file");
  w.check(avformat_write_header(w.format, nullptr), "writing the header");

  w.frame->format = pixels;
  w.frame->width = c.width;
  w.frame->height = c.height;
  w.check(av_frame_get_buffer(w.frame, 0), "a frame buffer");
  w.sws = sws_getContext(c.width, c.height, AV_PIX_FMT_BGR24, c.width, c.height, pixels, SWS_BILINEAR | SWS_ACCURATE_RND, nullptr, nullptr, nullptr);
  if (!w.sws) throw std::runtime_error(shown_name + ": no conversion from BGR to " + av_get_pix_fmt_name(pixels));
}

ClipWriter::~ClipWriter() = default;

void ClipWriter::write(const cv::Mat& bgr) {
  Impl& w = *impl_;
  if (w.finished) throw std::logic_error(w.name + ": written after finish()");
  if (bgr.type() != CV_8UC3 || bgr.size() != w.size) {
    throw std::runtime_error(w.name + ": a frame of " + std::to_string(bgr.cols) + "x" + std::to_string(bgr.rows) +
                             " in a clip of " + std::to_string(w.size.width) + "x" + std::to_string(w.size.height));
  }
  const cv::Mat* src = &bgr;
  if (w.coded != w.size) {
    cv::copyMakeBorder(bgr, w.padded, 0, w.coded.height - w.size.height, 0, w.coded.width - w.size.width, cv::BORDER_REPLICATE);
    src = &w.padded;
  }
  w.check(av_frame_make_writable(w.frame), "a frame buffer");
  const uint8_t* planes[1] = {src->data};
  const int strides[1] = {static_cast<int>(src->step[0])};
  sws_scale(w.sws, planes, strides, 0, w.coded.height, w.frame->data, w.frame->linesize);
  w.frame->pts = w.next_pts++;
  w.encode(w.frame);
}

void ClipWriter::finish() {
  Impl& w = *impl_;
  if (w.finished) return;
  w.encode(nullptr);  // the frames the encoder still holds (x264 looks ahead)
  w.check(av_write_trailer(w.format), "writing the trailer");
  w.finished = true;
  if (!(w.format->oformat->flags & AVFMT_NOFILE)) w.check(avio_closep(&w.format->pb), "closing the file");
}

}  // namespace artrace::tools

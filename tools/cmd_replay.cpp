// artrace replay: plays a recording with the AR overlay in an OpenCV window at the recording's
// rate. Keys (also listed with h):
//   space  pause / play          n or .  step one frame      p or ,  step back one frame
//   ] or → seek +1 s             [ or ←  seek -1 s           Home    back to the first frame
//   o      toggle occlusion      s       toggle shadows       d       depth view
//   b      side by side          w       save the view as PNG h       help          q, Esc  quit
// The head-up display shows the frame, the achieved frame rate and the time split (read, update,
// trace, composite). Without a display it says so and points to `artrace export`.
#include "bench_util.h"
#include "commands.h"
#include "ar_session.h"
#include "frame_views.h"
#include "soak.h"

#include "artrace/ar/compositor.h"
#include "artrace/io/ar_scene.h"
#include "artrace/io/atomic_file.h"
#include "artrace/io/recording.h"

#include <opencv2/highgui.hpp>
#include <opencv2/imgproc.hpp>

#include <dlfcn.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <memory>
#include <thread>

namespace artrace::tools {
namespace {

constexpr const char* kWindow = "artrace replay";

/// Whether a window can be opened. OpenCV's Qt backend aborts the process when it cannot reach
/// the X server, so the connection is tried first (libX11 loaded at run time: no build dependency).
bool display_available(std::string& why) {
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  if (wayland && *wayland) return true;
  const char* x = std::getenv("DISPLAY");
  if (!x || !*x) {
    why = "no display (DISPLAY is not set)";
    return false;
  }
  void* lib = dlopen("libX11.so.6", RTLD_LAZY | RTLD_LOCAL);
  if (!lib) return true;  // let OpenCV try
  using Open = void* (*)(const char*);
  using Close = int (*)(void*);
  auto open = reinterpret_cast<Open>(dlsym(lib, "XOpenDisplay"));
  auto close = reinterpret_cast<Close>(dlsym(lib, "XCloseDisplay"));
  bool ok = true;
  if (open && close) {
    void* d = open(nullptr);
    if (d) {
      close(d);
    } else {
      why = std::string("cannot open display \"") + x + "\"";
      ok = false;
    }
  }
  dlclose(lib);
  return ok;
}

struct Options {
  std::string recording, screenshot, keys, json, soak;
  int soak_every = 200;
  ArArgs ar;
  int frames = 0;
  double speed = 1.0;
  bool loop = false;
};

enum class View { kComposite, kSideBySide, kDepth };

struct Timing {
  double read = 0, update = 0, trace = 0, composite = 0;
};

class Replay {
 public:
  explicit Replay(const Options& opt)
: opt_(opt), session_(opt.recording, opt.ar), reader_(session_.source()), copt_(session_.options()) {
    count_ = session_.source().frame_count().value_or(0);
    if (count_ <= 0) throw std::runtime_error(opt.recording + ": no frames");
  }

  int run() {
    cv::namedWindow(kWindow, cv::WINDOW_AUTOSIZE);
    if (count_ > 1) cv::createTrackbar("frame", kWindow, nullptr, static_cast<int>(count_ - 1));
    std::deque<char> scripted(opt_.keys.begin(), opt_.keys.end());
    read_next();
    int shown = 0;
    auto anchor_wall = std::chrono::steady_clock::now();
    double anchor_t = frame_.color_time_s;
    bool dirty = true;
    SoakLog soak(opt_.soak, opt_.soak_every, "view");
    std::vector<double> view_ms;  // compositing, drawing and showing each view
    const auto start = std::chrono::steady_clock::now();
    for (;;) {
      if (dirty) {
        const auto t0 = std::chrono::steady_clock::now();
        render();
        cv::imshow(kWindow, view_);
        view_ms.push_back(ms_since(t0));
        soak.add(view_ms.back());
        ++shown;
      }
      dirty = true;
      if (count_ > 1) cv::setTrackbarPos("frame", kWindow, static_cast<int>(index_));
      if (opt_.frames > 0 && shown >= opt_.frames) break;

      // wait until the next frame is due at the recording's rate (or for a key when paused)
      int key = -1;
      if (!scripted.empty()) {
        key = scripted.front();
        scripted.pop_front();
        cv::waitKey(1);
      } else if (paused_) {
        key = cv::waitKeyEx(30);
      } else {
        const double due_ms = (next_time_ - anchor_t) / opt_.speed * 1000.0 - ms_since(anchor_wall);
        key = cv::waitKeyEx(std::max(1, static_cast<int>(due_ms)));
      }
      if (cv::getWindowProperty(kWindow, cv::WND_PROP_VISIBLE) < 1.0) break;  // window closed
      const int64_t wanted = count_ > 1 ? cv::getTrackbarPos("frame", kWindow) : index_;
      bool reanchor = false;
      if (key >= 0) {
        const Action a = handle_key(key);
        if (a == Action::kQuit) break;
        reanchor = a != Action::kNone;
      } else if (wanted != index_) {
        seek(wanted);
        reanchor = true;
      } else if (paused_) {
        dirty = false;  // nothing changed: no need to trace the same frame again
      } else {
        if (index_ + 1 >= count_) {
          if (opt_.loop) {
            seek(0);
            reanchor = true;
          } else {
            paused_ = true;  // stay on the last frame
          }
        } else {
          read_next();
        }
      }
      if (reanchor) {
        anchor_wall = std::chrono::steady_clock::now();
        anchor_t = frame_.color_time_s;
      }
    }
    const double views_per_s = shown / std::max(ms_since(start) / 1000.0, 1e-9);
    if (!opt_.screenshot.empty()) save(opt_.screenshot);
    cv::destroyAllWindows();
    std::printf("replay: %d views shown, stopped on frame %lld/%lld; %.1f views/s, %.2f ms median a view (composited and shown)\n", shown,
                static_cast<long long>(index_ + 1), static_cast<long long>(count_), views_per_s, median(view_ms));
    nlohmann::json out{{"recording", opt_.recording}, {"scene", opt_.ar.scene}, {"views", shown},
                       {"views_per_s", views_per_s}, {"view_ms_median", median(view_ms)}};
    if (soak.on()) out["soak"] = soak.report();
    write_json(opt_.json, out);
    return 0;
  }

 private:
  enum class Action { kNone, kChanged, kQuit };

  Action handle_key(int key) {
    const int k = key & 0xffff;
    const bool left = key == 0x1000012 || k == 0xff51 || key == 2424832;
    const bool right = key == 0x1000014 || k == 0xff53 || key == 2555904;
    const bool home = key == 0x1000010 || k == 0xff50 || key == 2359296;
    const int64_t second = std::max<int64_t>(1, static_cast<int64_t>(std::lround(fps_estimate())));
    if (k == 'q' || k == 27) return Action::kQuit;
    if (k == ' ') {
      paused_ = !paused_;
    } else if (k == 'n' || k == '.') {
      paused_ = true;
      if (index_ + 1 < count_) read_next();
    } else if (k == 'p' || k == ',') {
      paused_ = true;
      seek(std::max<int64_t>(0, index_ - 1));
    } else if (k == ']' || right) {
      seek(std::min(count_ - 1, index_ + second));
    } else if (k == '[' || left) {
      seek(std::max<int64_t>(0, index_ - second));
    } else if (home) {
      seek(0);
    } else if (k == 'o') {
      copt_.occlusion = !copt_.occlusion;
    } else if (k == 's') {
      copt_.shadows = !copt_.shadows;
    } else if (k == 'd') {
      view_mode_ = view_mode_ == View::kDepth ? View::kComposite : View::kDepth;
    } else if (k == 'b') {
      view_mode_ = view_mode_ == View::kSideBySide ? View::kComposite : View::kSideBySide;
    } else if (k == 'w') {
      char name[48];
      std::snprintf(name, sizeof(name), "replay_%06lld.png", static_cast<long long>(index_));
      save(name);
      std::printf("wrote %s\n", name);
    } else if (k == 'h') {
      help_ = !help_;
    } else {
      return Action::kNone;
    }
    return Action::kChanged;
  }

  double fps_estimate() const {
    const double span = last_time_ - first_time_;
    return furthest_ > 0 && span > 0 ? furthest_ / span : 30.0;
  }

  void read_next() {
    // decoded on the reader's own thread while the previous frame was composited and shown
    if (!reader_.next(frame_, &timing_.read)) throw std::runtime_error(opt_.recording + ": ended at frame " + std::to_string(index_ + 1));
    ++index_;
    if (index_ == 0) first_time_ = frame_.color_time_s;
    if (index_ > furthest_) {
      furthest_ = index_;
      last_time_ = frame_.color_time_s;
    }
    // the next frame's time is not known before it is read: assume the rate so far
    next_time_ = frame_.color_time_s + 1.0 / fps_estimate();
  }

  void seek(int64_t index) {
    reader_.seek(index);
    index_ = index - 1;
    read_next();
  }

  void render() {
    const auto t0 = std::chrono::steady_clock::now();
    ar::CompositeStats st;
    const ar::ColorImage c = session_.composite(frame_, &st, &timing_.update);
    timing_.trace = st.trace_ms;
    // the real scene (depth mesh or cleaned depth), shadows on real surfaces, occlusion, blend
    timing_.composite = st.proxy_ms + st.real_depth_ms + st.real_shadow_ms + st.occlusion_ms + st.composite_ms;
    cv::Mat img = to_bgr(c);
    if (view_mode_ == View::kDepth) {
      img = depth_view(frame_.depth, c.width, c.height);
    } else if (view_mode_ == View::kSideBySide) {
      cv::hconcat(std::vector<cv::Mat>{img, to_bgr(frame_.color), depth_view(frame_.depth, c.width, c.height)}, img);
    }
    // small recordings are shown enlarged so the head-up display stays readable
    const int scale = std::max(1, 640 / std::max(1, img.cols));
    if (scale > 1) cv::resize(img, img, cv::Size(), scale, scale, cv::INTER_NEAREST);
    const auto now = std::chrono::steady_clock::now();
    shown_at_.push_back(now);
    while (shown_at_.size() > 30) shown_at_.pop_front();
    const double shown_fps =
        shown_at_.size() > 1
            ? (shown_at_.size() - 1) * 1000.0 / std::chrono::duration<double, std::milli>(now - shown_at_.front()).count()
            : 0.0;
    draw_hud(img, shown_fps, ms_since(t0));
    view_ = img;
  }

  void draw_hud(cv::Mat& img, double shown_fps, double work_ms) const {
    char line[256];
    std::vector<std::string> lines;
    std::snprintf(line, sizeof(line), "frame %lld/%lld  t=%.2f s  %.1f fps%s", static_cast<long long>(index_ + 1),
                  static_cast<long long>(count_), frame_.color_time_s - first_time_, shown_fps, paused_ ? "  [paused]" : "");
    lines.emplace_back(line);
    std::snprintf(line, sizeof(line), "read %.1f  update %.1f  trace %.1f  composite %.1f ms (%.0f fps possible)",
                  timing_.read, timing_.update, timing_.trace, timing_.composite,
                  // the next frame is read on its own thread meanwhile: the slower of the two bounds the rate
                  1000.0 / std::max({work_ms, timing_.read, 1e-3}));
    lines.emplace_back(line);
    std::snprintf(line, sizeof(line), "occlusion %s  shadows %s  (h: keys)", copt_.occlusion ? "on" : "off",
                  copt_.shadows ? "on" : "off");
    lines.emplace_back(line);
    if (help_) {
      for (const char* h : {"space pause  n/. step  p/, back  [/] or arrows: -/+1 s  Home: start",
                            "o occlusion  s shadows  d depth  b side by side  w save PNG  q quit"}) {
        lines.emplace_back(h);
      }
    }
    const double font = 0.45;
    const int row = 17;
    cv::Mat band = img(cv::Rect(0, 0, img.cols, std::min(img.rows, 8 + row * static_cast<int>(lines.size()))));
    band *= 0.45;  // darken behind the text
    for (size_t i = 0; i < lines.size(); ++i) {
      cv::putText(img, lines[i], cv::Point(6, 16 + row * static_cast<int>(i)), cv::FONT_HERSHEY_SIMPLEX, font,
                  cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
    }
  }

  void save(const std::string& path) const { io::write_png(path, view_); }

  const Options& opt_;
  ArSession session_;
  FrameReader reader_;
  ar::CompositeOptions& copt_;
  ar::SensorFrame frame_;
  int64_t count_ = 0, index_ = -1, furthest_ = 0;
  double first_time_ = 0, last_time_ = 0, next_time_ = 0;
  bool paused_ = false, help_ = false;
  View view_mode_ = View::kComposite;
  Timing timing_;
  std::deque<std::chrono::steady_clock::time_point> shown_at_;
  cv::Mat view_;
};

}  // namespace

void add_replay_command(CLI::App& app) {
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "replay",
      "Play a recording with the AR overlay in a window. Keys: space pause, n/p step, [/] seek 1 s, o occlusion, "
      "s shadows, d depth view, b side by side, w save PNG, h help, q quit");
  cmd->add_option("recording", opt->recording, "TUM folder, image folder or .oni file")->required();
  add_ar_options(cmd, opt->ar);
  cmd->add_option("--speed", opt->speed, "playback speed relative to the recording's rate")
      ->capture_default_str()
      ->check(finite_range(0.01, 100.0));
  cmd->add_flag("--loop", opt->loop, "start again at the end (otherwise it pauses on the last frame)");
  cmd->add_option("--frames", opt->frames, "quit after showing this many frames (0: run until q)")->capture_default_str()->check(CLI::Range(0, 100000000));
  cmd->add_option("--keys", opt->keys, "keys to press first, one per shown frame (e.g. \"o\" starts without occlusion)");
  cmd->add_option("--json", opt->json, "write views, views_per_s and view_ms_median (and the soak's figures) as JSON");
  cmd->add_option("--soak", opt->soak, "a long run: sample resident memory and the time of each view into PREFIX.csv, PREFIX_memory.png and PREFIX_frame_time.png");
  cmd->add_option("--soak-every", opt->soak_every, "views between --soak samples")->capture_default_str()->check(CLI::Range(1, 1000000));
  cmd->add_option("--screenshot", opt->screenshot, "on quitting, save the last view (with its head-up display) as PNG");
  cmd->callback([opt] {
    std::string why;
    if (!display_available(why)) {
      throw std::runtime_error("replay needs a window: " + why +
                               ". To write the composited clip to a file instead, run: artrace export " + opt->recording +
                               " --scene " + opt->ar.scene + " -o clip.mp4");
    }
    std::vector<Output> outputs = SoakLog::outputs(opt->soak);
    outputs.insert(outputs.end(), {{opt->json}, {opt->screenshot}});
    check_outputs(outputs, ar_inputs(opt->recording, opt->ar));
    Replay(*opt).run();
  });
}

}  // namespace artrace::tools

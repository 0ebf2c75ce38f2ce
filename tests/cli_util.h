// Helpers for tests that run the artrace program as a user does: the program's path, a shell
// runner, a synthetic recording of the demo room and an AR scene with a green box in view.
#pragma once

#include "artrace/io/recording_writer.h"
#include "artrace/io/synth.h"
#include "test_util.h"

#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <string>

namespace artrace::io {

inline const std::filesystem::path kRoot = ARTRACE_SOURCE_DIR;

#define ARTRACE_REQUIRE_BINARY()                                                             \
  if (!std::filesystem::exists(ARTRACE_BINARY)) {                                          \
    GTEST_SKIP() << "the artrace program is not built in this configuration (tools off)";  \
  }

inline int run(const std::string& cmd) {
  const int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

/// Runs `command` (its output into `log`) in the background and sends it SIG`signal` ("TERM",
/// "INT", "HUP") once the shell test `ready` holds (looked at every 10 ms, for at most 30 s): the
/// signal comes while the command is at work, however long it takes to start on a loaded machine.
/// Returns the command's exit status (128 + the signal's number when the signal ended it).
inline int run_until(const std::string& command, const std::string& ready, const std::string& signal, const std::filesystem::path& log) {
  return run("bash -c '" + command + " > " + log.string() + " 2>&1 & p=$!; for i in $(seq 3000); do " + ready +
             " && break; sleep 0.01; done; kill -" + signal + " $p; wait $p'");
}

/// A synthetic recording of the demo room.
inline void synth_room(const std::filesystem::path& out, int frames, int width, int height) {
  const AffScene room = load_aff(kRoot / "data/scenes/room.aff");
  SynthOptions o;
  o.frames = frames;
  o.width = width;
  o.height = height;
  Synthesizer synth(room, o);
  auto w = make_recording_writer(out);
  synth.write(*w);
}

/// An AR scene with one green diffuse box, by default right in front of the demo room's first
/// view; `position` and `light` are JSON arrays (world metres).
inline std::filesystem::path box_scene(const std::filesystem::path& dir, const std::string& position = "[0.7, 0.45, 1.0]",
                                       double scale = 2.5, const std::string& light = "[2.6, 1.6, 3.4]") {
  std::filesystem::create_directories(dir);
  const auto scene = dir / "scene.json";
  std::ofstream(scene) << R"({ "models": [ { "file": ")" << (kRoot / "data/models/spinning_box.gltf").string()
                       << R"(", "position": )" << position << R"(, "scale": )" << scale << R"(,
                            "material": { "kind": "diffuse", "base_color": [0.0, 1.0, 0.0] } } ],
                          "lights": [ { "position": )" << light << R"(, "color": [1, 1, 1] } ], "ambient": 1.0 })";
  return scene;
}

}  // namespace artrace::io

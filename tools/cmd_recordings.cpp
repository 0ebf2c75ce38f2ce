// Commands on recordings: synth, convert, info, bench-io.
#include "bench_util.h"
#include "commands.h"

#include "artrace/io/ar_scene.h"
#include "artrace/io/gltf_model.h"

#include "artrace/io/aff_scene.h"
#include "artrace/io/file_name.h"
#include "artrace/io/fusion.h"
#include "artrace/io/odometry.h"
#include "artrace/io/oni_file.h"
#include "artrace/io/oni_reader.h"
#include "outputs.h"
#include "recording_options.h"
#include "shards.h"
#include "stop_signals.h"

#include "artrace/ar/plane_fit.h"
#include "artrace/io/tum_reader.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/recording.h"
#include "artrace/io/recording_writer.h"
#include "artrace/io/synth.h"

#include <opencv2/videoio.hpp>

#include <cstdio>
#include <iostream>
#include <memory>

namespace artrace::tools {
namespace {

nlohmann::json intrinsics_json(const ar::PinholeIntrinsics& k) {
  return {{"width", k.width}, {"height", k.height}, {"fx", k.fx}, {"fy", k.fy}, {"cx", k.cx}, {"cy", k.cy}};
}

nlohmann::json info_oni(const std::filesystem::path& path) {
  const io::OniContainer file(path);
  nlohmann::json j;
  j["version"] = std::to_string(file.version()[0]) + "." + std::to_string(file.version()[1]) + "." + std::to_string(file.version()[2]) + "." +
                 std::to_string(file.version()[3]);
  j["finalised"] = file.finalised();
  nlohmann::json streams = nlohmann::json::array();
  for (const io::OniNode& n : file.nodes()) {
    static const char* kTypes[] = {"?", "device", "depth", "colour", "audio", "IR"};
    nlohmann::json s{{"name", n.name}, {"type", n.type < 6 ? kTypes[n.type] : "?"}, {"codec", n.codec}, {"frames", n.frames.size()}};
    if (n.width > 0) {
      s["width"] = n.width;
      s["height"] = n.height;
      s["fps"] = n.fps;
    }
    if (!n.frames.empty()) {
      s["first_timestamp_us"] = n.frames.front().timestamp_us;
      s["last_timestamp_us"] = n.frames.back().timestamp_us;
    }
    streams.push_back(s);
  }
  j["streams"] = streams;
  return j;
}

nlohmann::json planes_json(const ar::SensorFrame& f) {
  nlohmann::json planes = nlohmann::json::array();
  for (const ar::Plane& p : ar::detect_planes(f)) {
    planes.push_back({{"normal", {p.normal.x(), p.normal.y(), p.normal.z()}},
                      {"point", {p.point.x(), p.point.y(), p.point.z()}},
                      {"pixel", {p.pixel_u, p.pixel_v}},
                      {"area_m2", p.area_m2},
                      {"inliers", p.inliers},
                      {"rms_m", p.rms_m}});
  }
  return planes;
}

nlohmann::json info_recording(const std::filesystem::path& path, const RecordingArgs& args, int planes_frame = -1) {
  nlohmann::json j;
  j["kind"] = "recording";
  const bool oni = !std::filesystem::is_directory(path);
  std::unique_ptr<ar::FrameSource> src;
  if (oni) {
    j["oni"] = info_oni(path);  // what the file holds, even when it cannot be played
    try {
      src = open_recording(path.string(), args);
    } catch (const io::ParseError& e) {
      j["playable"] = false;
      j["problem"] = e.what();
      return j;
    }
  } else {
    src = open_recording(path.string(), args);
  }
  ar::SensorFrame first;
  j["source"] = src->describe();
  j["frames"] = src->frame_count().value_or(-1);
  if (!src->next(first)) throw io::ParseError(path.string(), 0, 0, "holds no frame");
  j["width"] = first.color.width;
  j["height"] = first.color.height;
  j["depth_width"] = first.depth.width;
  j["depth_height"] = first.depth.height;
  j["color_intrinsics"] = intrinsics_json(first.color_intrinsics);
  j["intrinsics_from"] = src->intrinsics_source();
  j["depth_units_per_metre"] = src->depth_units_per_metre();
  j["first_time_s"] = first.color_time_s;
  j["has_pose"] = first.world_from_camera.has_value();
  // the trajectory the poses come from: a frame outside it, or in a gap, has none
  if (const auto span = src->trajectory_span()) j["trajectory_s"] = {span->first, span->second};
  if (const auto n = src->frame_count(); n && *n > 1) {
    src->seek(*n - 1);
    ar::SensorFrame last;
    if (src->next(last)) {
      j["duration_s"] = last.color_time_s - first.color_time_s;
      j["last_has_pose"] = last.world_from_camera.has_value();
    }
  }
  if (const auto* reader = dynamic_cast<const io::OniReader*>(src.get())) {
    nlohmann::json gaps = nlohmann::json::array();
    int dropped = 0;
    for (const io::OniGap& g : reader->gaps()) {
      gaps.push_back({{"stream", g.stream}, {"after_frame", g.after}, {"gap_ms", g.gap_ms}, {"missing", g.missing}});
      dropped += g.missing;
    }
    j["dropped_frames"] = dropped;
    j["gaps"] = gaps;
    if (reader->registered()) j["depth_registered_to_colour"] = *reader->registered();
  }
  j["warnings"] = src->warnings();
  {
    // what --depth-shift auto would find (export, replay, bench-ar, fuse and track apply it)
    const ar::DepthShiftEstimate e = ar::estimate_depth_shift(*src);
    j["depth_shift"] = {{"dx", e.best.dx}, {"dy", e.best.dy}, {"applied", e.confident}, {"colour_step", e.score},
                        {"colour_step_unshifted", e.score_zero}, {"colour_step_two_px_off", e.score_ring},
                        {"discontinuities", e.discontinuities}, {"summary", e.describe()}};
  }
  if (planes_frame >= 0) {
    const int64_t n = src->frame_count().value_or(0);
    if (planes_frame >= n) throw std::invalid_argument("--frame " + std::to_string(planes_frame) + ": the recording has " + std::to_string(n) + " frames");
    src->seek(planes_frame);
    ar::SensorFrame f;
    if (!src->next(f)) throw io::ParseError(path.string(), 0, 0, "cannot read frame " + std::to_string(planes_frame));
    j["planes_frame"] = planes_frame;
    j["planes"] = planes_json(f);
  }
  return j;
}

/// A video clip (export's or join's output): its frames counted by decoding them all.
nlohmann::json info_video(const std::filesystem::path& path) {
  cv::VideoCapture clip(path.string());
  if (!clip.isOpened()) throw std::runtime_error(path.string() + ": OpenCV cannot open it as a video");
  int frames = 0;
  cv::Mat f;
  int width = 0, height = 0;
  while (clip.read(f)) {
    if (frames == 0) width = f.cols, height = f.rows;
    ++frames;
  }
  return {{"frames", frames}, {"width", width}, {"height", height}, {"fps", clip.get(cv::CAP_PROP_FPS)},
          {"codec", [&] {
             const int cc = static_cast<int>(clip.get(cv::CAP_PROP_FOURCC));
             return std::string{static_cast<char>(cc & 255), static_cast<char>((cc >> 8) & 255), static_cast<char>((cc >> 16) & 255),
                                static_cast<char>((cc >> 24) & 255)};
           }()}};
}

nlohmann::json info_aff(const std::filesystem::path& path) {
  const io::AffScene s = io::load_aff(path);
  nlohmann::json j;
  j["kind"] = "aff scene";
  j["triangles"] = s.triangle_count();
  j["static_triangles"] = s.static_triangle_count();
  j["animated_nodes"] = s.nodes.size() - 1;
  j["animations"] = s.animations.size();
  j["lights"] = s.lights.size();
  j["materials"] = s.materials.size();
  j["textures"] = s.textures.size();
  j["frames"] = s.anim_frames;
  j["time_range"] = {s.anim_start, s.anim_end};
  if (s.view) {
    j["width"] = s.view->width;
    j["height"] = s.view->height;
  }
  return j;
}

nlohmann::json info_gltf_model(const io::GltfModel& m) {
  nlohmann::json j;
  j["triangles"] = m.triangle_count();
  j["meshes"] = m.meshes.size();
  j["nodes"] = m.nodes.size();
  j["skins"] = m.skins.size();
  nlohmann::json textures = nlohmann::json::array();
  for (const io::GltfImage& img : m.images) textures.push_back({{"image", img.name}, {"width", img.width}, {"height", img.height}});
  j["textures"] = textures;
  static const char* kAlpha[] = {"OPAQUE", "MASK", "BLEND"};
  nlohmann::json materials = nlohmann::json::array();
  for (size_t i = 1; i < m.materials.size(); ++i) {
    const io::GltfMaterial& g = m.materials[i];
    nlohmann::json mj{{"name", g.name},
                      {"base_color", {g.base_color.r, g.base_color.g, g.base_color.b, g.alpha}},
                      {"metallic", g.metallic},
                      {"roughness", g.roughness},
                      {"alpha_mode", kAlpha[static_cast<int>(g.alpha_mode)]},
                      {"double_sided", g.double_sided}};
    if (g.alpha_mode == io::AlphaMode::kMask) mj["alpha_cutoff"] = g.alpha_cutoff;
    if (g.emissive != glm::vec3(0.0f)) mj["emissive"] = {g.emissive.r, g.emissive.g, g.emissive.b};
    if (g.transmission > 0.0f) mj["transmission"] = g.transmission;
    nlohmann::json maps = nlohmann::json::object();
    const std::pair<const char*, const io::GltfTextureRef*> refs[] = {{"base_color", &g.base_color_texture},
                                                                      {"metallic_roughness", &g.metallic_roughness_texture},
                                                                      {"normal", &g.normal_texture},
                                                                      {"occlusion", &g.occlusion_texture},
                                                                      {"emissive", &g.emissive_texture}};
    for (const auto& [name, t] : refs) {
      if (t->valid()) maps[name] = {{"image", m.images[static_cast<size_t>(t->image)].name}, {"tex_coord", t->tex_coord}};
    }
    mj["maps"] = maps;
    materials.push_back(mj);
  }
  j["materials"] = materials;
  size_t targets = 0;
  for (const io::GltfMesh& mesh : m.meshes) targets += mesh.targets.size();
  j["morph_targets"] = targets;
  nlohmann::json anims = nlohmann::json::array();
  for (const io::GltfAnimation& a : m.animations) anims.push_back({{"name", a.name}, {"duration_s", a.duration_s}, {"channels", a.channels.size()}});
  j["animations"] = anims;
  j["extensions_used"] = m.extensions_used;
  j["extensions_required"] = m.extensions_required;
  j["warnings"] = m.warnings;
  return j;
}

nlohmann::json info_gltf(const std::filesystem::path& path) {
  nlohmann::json j = info_gltf_model(io::load_gltf(path));
  j["kind"] = "glTF model";
  return j;
}

nlohmann::json info_ar_scene(const std::filesystem::path& path) {
  const io::ArSceneFile f = io::load_ar_scene(path);
  io::ArRuntime rt(f);
  nlohmann::json j;
  j["kind"] = "AR scene";
  nlohmann::json models = nlohmann::json::array();
  size_t triangles = 0;
  for (size_t i = 0; i < f.models.size(); ++i) {
    nlohmann::json m = info_gltf_model(f.loaded[i]);
    m["file"] = f.models[i].file.string();
    m["animated"] = f.models[i].clip >= 0;
    triangles += f.loaded[i].triangle_count();
    models.push_back(m);
  }
  j["models"] = models;
  j["triangles"] = triangles;
  j["static_triangles_in_kd_tree"] = rt.static_triangles();
  j["animated_instances"] = rt.instance_count();
  j["skinned_meshes"] = rt.skinned_meshes();
  j["lights"] = f.lights.size();
  j["ambient"] = f.ambient;
  return j;
}

}  // namespace

void add_recording_commands(CLI::App& app) {
  {
    struct Options {
      std::string scene, output;
      io::SynthOptions synth;
      bool kinect = false;
    };
    auto opt = std::make_shared<Options>();
    CLI::App* cmd = app.add_subcommand("synth", "Render a synthetic RGBD recording (exact depth and poses) from a scene");
    cmd->add_option("--scene", opt->scene, "AFF scene (BART, or the project's data/scenes/room.aff)")->required()->check(CLI::ExistingFile);
    cmd->add_option("-o,--output", opt->output, "TUM folder, or a file ending in .oni")->required();
    cmd->add_option("--frames", opt->synth.frames, "number of frames")->capture_default_str()->check(CLI::Range(1, 100000));
    cmd->add_option("--fps", opt->synth.fps, "frame rate")->capture_default_str()->check(CLI::Range(1, 1000));
    cmd->add_option("--width", opt->synth.width, "image width")->capture_default_str()->check(CLI::Range(8, 4096));
    cmd->add_option("--height", opt->synth.height, "image height")->capture_default_str()->check(CLI::Range(8, 4096));
    cmd->add_option("--fov", opt->synth.fov_y_deg, "vertical field of view in degrees")->capture_default_str()->check(finite_range(1, 179));
    cmd->add_option("--orbit", opt->synth.orbit_deg, "degrees the camera orbits over the clip (scenes without a camera track)")
        ->capture_default_str()
        ->check(finite_range(-36000, 36000));
    cmd->add_flag("--kinect", opt->kinect, "apply the Kinect-like depth model (noise, quantisation, holes, offset)");
    cmd->add_option("--seed", opt->synth.seed, "seed of the depth model")->capture_default_str();
    add_threads_option(cmd, opt->synth.threads);
    cmd->callback([opt] {
      note_recording_output(opt->output);
      check_outputs(recording_outputs(opt->output), {opt->scene});
      if (opt->kinect) opt->synth.depth_model = ar::DepthModel{};
      const io::AffScene scene = io::load_aff(opt->scene);
      io::Synthesizer synth(scene, opt->synth);
      StoppableRecordingWriter writer(io::make_recording_writer(opt->output, opt->synth.fps), opt->output);
      const auto t0 = std::chrono::steady_clock::now();
      const int n = synth.write(writer);
      std::printf("%s: %d frames %dx%d (%s depth) in %.2f s\n", opt->output.c_str(), n, opt->synth.width,
                  opt->synth.height, opt->kinect ? "Kinect-like" : "exact", ms_since(t0) / 1000.0);
    });
  }
  {
    auto src = std::make_shared<std::string>();
    auto dst = std::make_shared<std::string>();
    auto rec = std::make_shared<RecordingArgs>();
    CLI::App* cmd = app.add_subcommand("convert", "Convert a recording (TUM folder, image folder or .oni) to .oni or the TUM layout");
    cmd->add_option("source", *src, "TUM folder, image folder or .oni file")->required();
    cmd->add_option("-o,--output", *dst, "TUM folder, or a file ending in .oni")->required();
    add_recording_options(cmd, *rec);
    cmd->callback([src, dst, rec] {
      note_recording_output(*dst);
      check_outputs(recording_outputs(*dst), recording_inputs(*src, rec->intrinsics, rec->trajectory));
      auto in = open_recording(*src, *rec);
      const int fps = static_cast<int>(std::lround(recording_rate(in->frame_count().value_or(0), frame_time_span(*in))));
      StoppableRecordingWriter out(io::make_recording_writer(*dst, fps), *dst);
      ar::SensorFrame f;
      int n = 0;
      while (in->next(f)) {
        out.write(f);
        ++n;
      }
      out.close();
      std::printf("%s: %d frames from %s\n", dst->c_str(), n, in->describe().c_str());
    });
  }
  {
    struct Options {
      std::string source, output, json;
      io::OdometryOptions odometry;
      RecordingArgs rec;
    };
    auto opt = std::make_shared<Options>();
    CLI::App* cmd = app.add_subcommand("track", "Estimate the camera trajectory of a recording with RGB-D odometry");
    cmd->add_option("source", opt->source, "TUM folder or .oni file")->required();
    cmd->add_option("-o,--output", opt->output, "trajectory file to write (TUM format)")->required();
    cmd->add_option("--method", opt->odometry.method, "RgbdICPOdometry, RgbdOdometry or ICPOdometry")->capture_default_str();
    cmd->add_option("--frames", opt->odometry.max_frames, "frames to track (0 = all)")->capture_default_str()->check(CLI::Range(0, 100000000));
    cmd->add_option("--json", opt->json, "write the drift report as JSON");
    add_recording_options(cmd, opt->rec);
    add_depth_shift_option(cmd, opt->rec.depth_shift);
    cmd->callback([opt] {
      check_outputs({{opt->output}, {opt->json}}, recording_inputs(opt->source, opt->rec.intrinsics, opt->rec.trajectory));
      auto in = open_recording(opt->source, opt->rec);
      const auto t0 = std::chrono::steady_clock::now();
      const io::OdometryResult r = io::estimate_trajectory(*in, opt->odometry);
      const double s = ms_since(t0) / 1000.0;
      io::write_tum_trajectory(opt->output, r.trajectory);
      std::printf("%s: %zu poses in %.2f s (%.1f frames/s), %d odometry failures\n", opt->output.c_str(),
                  r.trajectory.size(), s, r.trajectory.size() / std::max(s, 1e-9), r.failures);
      nlohmann::json j{{"frames", r.trajectory.size()}, {"failures", r.failures}, {"seconds", s}};
      if (!r.reference.empty()) {
        const io::DriftReport d = io::compare_trajectories(r.trajectory, r.reference);
        std::printf("  drift against the recording's poses: RMS %.4f m, final %.4f m and %.3f deg over %d frames\n",
                    d.rms_m, d.final_m, d.final_deg, d.compared);
        j["drift"] = {{"rms_m", d.rms_m}, {"final_m", d.final_m}, {"final_deg", d.final_deg}, {"compared", d.compared}};
      }
      write_json(opt->json, j);
    });
  }
  {
    auto path = std::make_shared<std::string>();
    auto json = std::make_shared<std::string>();
    auto rec = std::make_shared<RecordingArgs>();
    auto planes = std::make_shared<bool>(false);
    auto frame = std::make_shared<int>(0);
    CLI::App* cmd = app.add_subcommand("info", "What a recording, ONI file, AFF scene, glTF model, AR scene or video clip holds, or why it cannot be read");
    cmd->add_option("path", *path, "TUM folder, image folder, .oni file, .aff scene, .gltf/.glb model or AR scene .json")->required();
    cmd->add_option("--json", *json, "also write the answer as JSON");
    add_recording_options(cmd, *rec);
    cmd->add_flag("--planes", *planes, "recordings: list the large planar surfaces of a frame (world coordinates), to anchor models on");
    cmd->add_option("--frame", *frame, "the frame --planes looks at")->capture_default_str()->check(CLI::Range(0, 100000000));
    cmd->callback([path, json, rec, planes, frame] {
      check_outputs({{*json}}, recording_inputs(*path, rec->intrinsics, rec->trajectory));
      const std::filesystem::path p(*path);
      const std::string ext = io::lower_extension(p);
      const nlohmann::json j = is_video_path(p)                  ? info_video(p)
                               : ext == ".aff"                   ? info_aff(p)
                               : ext == ".gltf" || ext == ".glb" ? info_gltf(p)
                               : ext == ".json"                  ? info_ar_scene(p)
                                                                 : info_recording(p, *rec, *planes ? *frame : -1);
      std::cout << *path << "\n";
      for (const auto& [key, value] : j.items()) std::cout << "  " << key << ": " << value.dump() << "\n";
      write_json(*json, j);
    });
  }
  {
    struct Options {
      std::string source, output, json;
      io::FusionOptions fusion;
      RecordingArgs rec;
      bool quiet = false;
    };
    auto opt = std::make_shared<Options>();
    CLI::App* cmd = app.add_subcommand("fuse", "Fuse every frame of a recording with its pose into a mesh of the room (TSDF, Open3D)");
    cmd->add_option("source", opt->source, "TUM folder, image folder or .oni file (with poses: a trajectory, or a fixed camera)")->required();
    cmd->add_option("-o,--output", opt->output, "the mesh to write (.ply)")->required();
    cmd->add_option("--voxel", opt->fusion.voxel_m, "voxel edge, metres")->capture_default_str()->check(finite_range(0.001, 1.0));
    cmd->add_option("--truncation", opt->fusion.truncation_m, "signed distances are cut off beyond this, metres")
        ->capture_default_str()
        ->check(finite_range(0.002, 5.0));
    cmd->add_option("--max-depth", opt->fusion.max_depth_m, "depths beyond are left out, metres")->capture_default_str()->check(finite_range(0.1, 100.0));
    cmd->add_option("--every", opt->fusion.every, "integrate every n-th frame")->capture_default_str()->check(CLI::Range(1, 100000));
    cmd->add_option("--json", opt->json, "write the figures as JSON");
    cmd->add_flag("-q,--quiet", opt->quiet, "no progress line");
    add_recording_options(cmd, opt->rec);
    add_depth_shift_option(cmd, opt->rec.depth_shift);
    cmd->callback([opt] {
      require_output_extension(opt->output, ".ply", "PLY meshes");
      check_outputs({{opt->output}, {opt->json}}, recording_inputs(opt->source, opt->rec.intrinsics, opt->rec.trajectory));
      auto in = open_recording(opt->source, opt->rec, opt->quiet);
      io::FusionStats st;
      const ar::RoomMesh mesh = io::fuse_recording(*in, opt->fusion, &st, [&](int k, int n) {
        if (!opt->quiet) std::fprintf(stderr, "\rfusing frame %d/%d   ", k, n);
      });
      if (!opt->quiet) std::fprintf(stderr, "\n");
      io::write_room_ply(mesh, opt->output);
      std::printf("%s: %zu triangles, %zu vertices from %d frames (%d without a pose skipped) in %.2f s\n", opt->output.c_str(),
                  mesh.triangles.size(), mesh.positions.size(), st.frames, st.without_pose, st.seconds);
      write_json(opt->json, {{"source", opt->source}, {"output", opt->output}, {"frames", st.frames}, {"without_pose", st.without_pose},
                             {"triangles", mesh.triangles.size()}, {"vertices", mesh.positions.size()}, {"seconds", st.seconds},
                             {"voxel_m", opt->fusion.voxel_m}});
    });
  }
  {
    struct Options {
      std::string source, json;
      int min_frames = 300;
      RecordingArgs rec;
    };
    auto opt = std::make_shared<Options>();
    CLI::App* cmd = app.add_subcommand("bench-io", "Frames per second a recording is read at on one thread, decoding included");
    cmd->add_option("source", opt->source, "TUM folder, image folder or .oni file")->required();
    cmd->add_option("--min-frames", opt->min_frames, "read the recording again until this many frames are timed")
        ->capture_default_str()
        ->check(CLI::Range(1, 10000000));
    cmd->add_option("--json", opt->json, "write the result as JSON");
    add_recording_options(cmd, opt->rec);
    cmd->callback([opt] {
      check_outputs({{opt->json}}, recording_inputs(opt->source, opt->rec.intrinsics, opt->rec.trajectory));
      auto in = open_recording(opt->source, opt->rec);
      ar::SensorFrame f;
      in->next(f);  // warm-up: first frame, file caches
      std::vector<double> frame_ms;
      int n = 0, passes = 0;
      const auto t0 = std::chrono::steady_clock::now();
      while (n < opt->min_frames) {
        in->rewind();
        ++passes;
        for (auto tf = std::chrono::steady_clock::now(); in->next(f); tf = std::chrono::steady_clock::now()) {
          frame_ms.push_back(ms_since(tf));
          ++n;
        }
        if (n == 0) throw std::runtime_error(opt->source + ": holds no frame");
      }
      const double s = ms_since(t0) / 1000.0;
      const double fps = s > 0.0 ? n / s : 0.0;
      std::printf("%s: %d frames (%d passes) in %.3f s on one thread = %.1f frames/s, median %.2f ms a frame (%dx%d)\n",
                  opt->source.c_str(), n, passes, s, fps, median(frame_ms), f.color.width, f.color.height);
      write_json(opt->json, {{"source", opt->source}, {"frames", n}, {"passes", passes}, {"seconds", s}, {"fps", fps},
                             {"frame_ms_median", median(frame_ms)}, {"width", f.color.width}, {"height", f.color.height}});
    });
  }
}

}  // namespace artrace::tools

// artrace bench-core: kd-tree build and ray throughput on one frame of a scene, verified first
// (kd-tree against brute force, packets against single rays), then timed as the median of N runs
// after a warm-up; optionally the same rays through Embree in the same run.
#include "bench_util.h"
#include "commands.h"
#include "embree_reference.h"

#include "artrace/core/simd_level.h"
#include "artrace/core/wide_bvh.h"
#include "artrace/io/aff_scene.h"

#include <nlohmann/json.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>
#include <random>

namespace artrace::tools {
namespace {

using core::HitPacket;
using core::kPacketSize;
using core::LaneMask;
using core::RayPacket;
using Clock = std::chrono::steady_clock;

/// A batch of packets in tile order: packets [k i, k i + k) are the blocks of tile i (k = 64 /
/// lanes: 4x2 blocks for 8-ray packets, 4x4 for 16).
struct Workload {
  std::vector<RayPacket> packets;
  std::vector<LaneMask> masks;
  size_t rays = 0;
};

void count_rays(Workload& w) {
  w.rays = 0;
  for (const LaneMask m : w.masks) w.rays += static_cast<size_t>(__builtin_popcount(m));
}

/// Camera packets of `lanes` rays (8 or 16: 4 x lanes / 4 pixels), in tile order.
Workload primary_rays(const core::Camera& cam, int lanes) {
  Workload w;
  const int rows = lanes / 4;
  const int tiles_x = (cam.width + 7) / 8, tiles_y = (cam.height + 7) / 8;
  for (int ty = 0; ty < tiles_y; ++ty) {
    for (int tx = 0; tx < tiles_x; ++tx) {
      for (int by = 0; by < 8 / rows; ++by) {
        for (int bx = 0; bx < 2; ++bx) {
          RayPacket p;
          const int x = tx * 8 + bx * 4, y = ty * 8 + by * rows;
          LaneMask m = 0;
          if (x < cam.width && y < cam.height) m = core::primary_packet(cam, x, y, p, rows);
          w.packets.push_back(p);
          w.masks.push_back(m);
        }
      }
    }
  }
  count_rays(w);
  return w;
}

template <class Fn>
void parallel_tiles(tbb::task_arena& arena, size_t tiles, const Fn& fn) {
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, tiles, 1),
                      [&](const tbb::blocked_range<size_t>& r) {
                        for (size_t i = r.begin(); i != r.end(); ++i) fn(i);
                      },
                      tbb::simple_partitioner());
  });
}

/// One pass over a workload's packets, tile by tile as the renderer hands them out (`per_tile`
/// packets a tile): fn(p) for every packet p.
template <class Fn>
auto tile_pass(tbb::task_arena& arena, size_t tiles, size_t packets, size_t per_tile, Fn fn) {
  return [&arena, tiles, packets, per_tile, fn] {
    parallel_tiles(arena, tiles, [&](size_t t) {
      for (size_t p = t * per_tile; p < std::min(packets, (t + 1) * per_tile); ++p) fn(p);
    });
  };
}

/// Median of `runs` timings in ms after one warm-up call.
template <class Fn>
double median_ms(int runs, const Fn& fn) {
  fn();
  std::vector<double> ms;
  for (int r = 0; r < runs; ++r) {
    const auto t0 = Clock::now();
    fn();
    ms.push_back(ms_since(t0));
  }
  return median(ms);
}

/// Median of `runs` timings of `fn`, each after an untimed `prepare`, after one warm-up.
template <class Prepare, class Fn>
double median_ms(int runs, const Prepare& prepare, const Fn& fn) {
  prepare();
  fn();
  std::vector<double> ms;
  for (int r = 0; r < runs; ++r) {
    prepare();
    const auto t0 = Clock::now();
    fn();
    ms.push_back(ms_since(t0));
  }
  return median(ms);
}

/// Median over `runs` pairs of (time of `theirs` / time of `ours`), the two taken in turns after
/// one warm-up each, which of them goes first alternating from pair to pair: ours' speed relative
/// to theirs, measured side by side. `prepare_theirs` runs untimed before each of theirs.
template <class Ours, class Prepare, class Theirs>
double paired_ratio(int runs, const Ours& ours, const Prepare& prepare_theirs, const Theirs& theirs) {
  ours();
  prepare_theirs();
  theirs();
  std::vector<double> ratio;
  for (int r = 0; r < runs; ++r) {
    double a = 0.0, b = 0.0;
    auto time_ours = [&] {
      const auto t0 = Clock::now();
      ours();
      a = ms_since(t0);
    };
    auto time_theirs = [&] {
      prepare_theirs();
      const auto t0 = Clock::now();
      theirs();
      b = ms_since(t0);
    };
    if (r % 2 == 0) {
      time_ours();
      time_theirs();
    } else {
      time_theirs();
      time_ours();
    }
    ratio.push_back(b / std::max(1e-9, a));
  }
  return median(ratio);
}

/// Secondary workloads built from the primary hits: shadow packets towards each light (the lanes
/// of one block share the light), and one cosine-distributed bounce per hit (fixed seed).
void secondary_rays(const core::KdTree& tree, const Workload& primary, const std::vector<HitPacket>& hits,
                    const std::vector<glm::vec3>& lights, Workload& shadow, Workload& bounce) {
  std::mt19937 rng(12345);
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  for (size_t p = 0; p < primary.packets.size(); ++p) {
    RayPacket bounce_packet;
    LaneMask bounce_mask = 0;
    std::vector<RayPacket> to_light(lights.size());
    LaneMask hit_mask = 0;
    for (int i = 0; i < kPacketSize; ++i) {
      if (!((primary.masks[p] >> i) & 1u) || hits[p].prim[i] == core::kInvalidId) continue;
      hit_mask |= 1u << i;
      const core::Ray r = primary.packets[p].get(i);
      const glm::vec3 x = r.org + hits[p].t[i] * r.dir;
      glm::vec3 n = glm::normalize(tree.triangles()[hits[p].prim[i]].geometric_normal());
      if (glm::dot(n, r.dir) > 0.0f) n = -n;
      const glm::vec3 o = x + n * (1e-4f * std::max(1.0f, glm::length(x)));
      for (size_t l = 0; l < lights.size(); ++l) to_light[l].set(i, core::Ray{o, lights[l] - o, 0.0f, 1.0f});
      // cosine-distributed direction about n
      const float u1 = uni(rng), u2 = uni(rng);
      const float rad = std::sqrt(u1), phi = 6.2831853f * u2;
      const glm::vec3 a = std::fabs(n.x) > 0.5f ? glm::vec3(0, 1, 0) : glm::vec3(1, 0, 0);
      const glm::vec3 t = glm::normalize(glm::cross(n, a)), b = glm::cross(n, t);
      const glm::vec3 d = rad * std::cos(phi) * t + rad * std::sin(phi) * b + std::sqrt(1.0f - u1) * n;
      bounce_packet.set(i, core::Ray{o, d});
      bounce_mask |= 1u << i;
    }
    for (size_t l = 0; l < lights.size(); ++l) {
      shadow.packets.push_back(to_light[l]);
      shadow.masks.push_back(hit_mask);
    }
    bounce.packets.push_back(bounce_packet);
    bounce.masks.push_back(bounce_mask);
  }
  count_rays(shadow);
  count_rays(bounce);
}

/// Subdivides every triangle into 4 (midpoints), `levels` times: the build-scaling meshes.
std::vector<core::Triangle> subdivide(std::vector<core::Triangle> tris, int levels) {
  for (int l = 0; l < levels; ++l) {
    std::vector<core::Triangle> out;
    out.reserve(tris.size() * 4);
    for (const auto& t : tris) {
      const glm::vec3 a = 0.5f * (t.v0 + t.v1), b = 0.5f * (t.v1 + t.v2), c = 0.5f * (t.v2 + t.v0);
      out.push_back({t.v0, a, c});
      out.push_back({a, t.v1, b});
      out.push_back({c, b, t.v2});
      out.push_back({a, b, c});
    }
    tris = std::move(out);
  }
  return tris;
}

struct Options {
  std::string scene, json, reference = "none", simd = "auto";
  double time = 0.0;
  int width = 512, height = 400, threads = 0, runs = 7, subdivide = 0, verify_rays = 1000;
  int lanes = 8;  ///< rays a packet: 8 (4x2 pixels, against Embree's 8-wide calls) or 16 (4x4, its 16-wide ones)
  bool embree_robust = false;  ///< the reference's scenes in Embree's robust mode instead of its default
  core::KdTreeBuildOptions build;
  core::WideBvhBuildOptions wide;
};

void run(const Options& opt) {
  if (opt.embree_robust && opt.reference != "embree")
    throw std::runtime_error("--embree-robust needs --reference embree");
  check_outputs({{opt.json}}, {opt.scene});
  core::set_simd_level(core::parse_simd_level(opt.simd));
  const int threads = opt.threads > 0 ? opt.threads : tbb::this_task_arena::max_concurrency();
  tbb::task_arena arena(threads);
  const io::AffScene scene = io::load_aff(opt.scene);
  const std::vector<core::Triangle> tris = subdivide(scene.triangles_at(opt.time), opt.subdivide);
  const core::Camera cam = scene.camera_at(opt.time, opt.width, opt.height);
  std::vector<glm::vec3> lights;
  for (const auto& l : scene.lights) lights.push_back(l.position);

  nlohmann::json out;
  out["scene"] = opt.scene;
  out["time"] = opt.time;
  out["width"] = opt.width;
  out["height"] = opt.height;
  out["threads"] = threads;
  out["runs"] = opt.runs;
  out["simd"] = core::to_string(core::simd_level());
  out["lanes"] = opt.lanes;
  out["subdivide"] = opt.subdivide;
  out["triangles"] = tris.size();

  core::KdTree tree;
  const double build_ms = median_ms(opt.runs, [&] { arena.execute([&] { tree = core::KdTree(tris, opt.build); }); });
  const core::KdTreeStats st = tree.stats(opt.build);
  out["kdtree"] = {{"build_ms", build_ms}, {"nodes", st.nodes}, {"node_bytes", st.node_bytes},
                   {"leaves", st.leaves}, {"empty_leaves", st.empty_leaves}, {"prim_refs", st.prim_refs},
                   {"max_depth", st.max_depth}, {"sah_cost", st.sah_cost},
                   {"build_ns_per_triangle", build_ms * 1e6 / std::max<size_t>(1, tris.size())},
                   {"binned_above", opt.build.binned_above}};

  Workload primary = primary_rays(cam, opt.lanes);
  const size_t per_tile = static_cast<size_t>(64 / opt.lanes);  // packets a tile
  const size_t tiles = (primary.packets.size() + per_tile - 1) / per_tile;
  std::vector<HitPacket> hits(primary.packets.size());
  for (size_t p = 0; p < primary.packets.size(); ++p) tree.intersect(primary.packets[p], primary.masks[p], hits[p]);

  // Verify before timing: packets equal single rays on every primary ray; a sample of rays agrees
  // with brute force.
  size_t packet_mismatch = 0, brute_mismatch = 0, brute_checked = 0;
  for (size_t p = 0; p < primary.packets.size(); ++p) {
    for (int i = 0; i < kPacketSize; ++i) {
      if (!((primary.masks[p] >> i) & 1u)) continue;
      const core::Hit h = tree.intersect(primary.packets[p].get(i));
      if (h.prim != hits[p].prim[i] || (h.valid() && h.t != hits[p].t[i])) ++packet_mismatch;
    }
  }
  std::mt19937 rng(7);
  for (int k = 0; k < opt.verify_rays && !primary.packets.empty(); ++k) {
    const size_t p = rng() % primary.packets.size();
    const int i = static_cast<int>(rng() % kPacketSize);
    if (!((primary.masks[p] >> i) & 1u)) continue;
    const core::Ray r = primary.packets[p].get(i);
    ++brute_checked;
    if (core::intersect_brute_force(r, tris).prim != tree.intersect(r).prim) ++brute_mismatch;
  }
  out["verify"] = {{"packet_vs_single_mismatches", packet_mismatch}, {"brute_force_checked", brute_checked},
                   {"brute_force_mismatches", brute_mismatch}};
  if (packet_mismatch || brute_mismatch) {
    throw std::runtime_error("verification failed: " + std::to_string(packet_mismatch) + " packet and " +
                             std::to_string(brute_mismatch) + " brute-force mismatches");
  }

  Workload shadow, bounce;
  secondary_rays(tree, primary, hits, lights, shadow, bounce);

  std::vector<HitPacket> scratch(primary.packets.size());
  // The wide BVH for single and incoherent rays, and coherent packets where it traces them as
  // frustums: built over the same triangles, checked to give the kd-tree's hits bit for bit on
  // every primary and bounce ray, single and (primary) in packets, then timed.
  core::WideBvh wide;
  const double wide_build_ms = median_ms(opt.runs, [&] { arena.execute([&] { wide = core::WideBvh(tris, opt.wide); }); });
  const core::WideBvhStats wst = wide.stats(opt.wide);
  out["wide_bvh"] = {{"build_ms", wide_build_ms}, {"spatial_budget", opt.wide.spatial_budget}, {"bins", opt.wide.bins}, {"nodes", wst.nodes}, {"leaves", wst.leaves}, {"blocks", wst.blocks},
                     {"triangles_in_blocks", wst.triangles_in_blocks}, {"max_depth", wst.max_depth}, {"sah_cost", wst.sah_cost}};
  size_t wide_mismatch = 0;
  for (const Workload* w : {&primary, &bounce}) {
    for (size_t p = 0; p < w->packets.size(); ++p) {
      for (int i = 0; i < kPacketSize; ++i) {
        if (!((w->masks[p] >> i) & 1u)) continue;
        const core::Ray r = w->packets[p].get(i);
        const core::Hit a = tree.intersect(r), b = wide.intersect(r);
        if (a.prim != b.prim || a.t != b.t || a.u != b.u || a.v != b.v) {
          if (wide_mismatch++ == 0) {
            const core::Hit c = core::intersect_brute_force(r, tris);
            std::fprintf(stderr, "bench-core: the wide BVH and the kd-tree differ on the ray from (%.9g, %.9g, %.9g) along (%.9g, %.9g, %.9g): "
                         "kd-tree triangle %u at t %.9g, wide BVH %u at %.9g, brute force %u at %.9g\n",
                         r.org.x, r.org.y, r.org.z, r.dir.x, r.dir.y, r.dir.z, a.prim, a.t, b.prim, b.t, c.prim, c.t);
          }
        }
      }
    }
  }
  for (size_t p = 0; p < primary.packets.size(); ++p) {
    wide.intersect(primary.packets[p], primary.masks[p], scratch[p]);
    for (int i = 0; i < kPacketSize; ++i) {
      if (!((primary.masks[p] >> i) & 1u)) continue;
      const HitPacket& a = hits[p];
      const HitPacket& b = scratch[p];
      if (a.prim[i] != b.prim[i] || a.t[i] != b.t[i] || a.u[i] != b.u[i] || a.v[i] != b.v[i]) {
        if (wide_mismatch++ == 0) std::fprintf(stderr, "bench-core: a wide BVH packet's lane %d differs from the kd-tree's hit\n", i);
      }
    }
  }
  out["verify"]["wide_bvh_vs_kdtree_mismatches"] = wide_mismatch;
  if (wide_mismatch) throw std::runtime_error("verification failed: " + std::to_string(wide_mismatch) + " wide BVH hits differ from the kd-tree's");
  auto mrays = [](size_t rays, double ms) { return ms > 0.0 ? rays / (ms * 1e3) : 0.0; };
  auto pass = [&](const Workload& w, size_t w_per_tile, auto fn) {  // w_per_tile: this workload's packets a tile
    return tile_pass(arena, tiles, w.packets.size(), w_per_tile, fn);
  };
  auto single_rays = [&](const Workload& w) {
    return pass(w, per_tile, [&, &w = w](size_t p) {
      for (int i = 0; i < kPacketSize; ++i) {
        if ((w.masks[p] >> i) & 1u) scratch[p].prim[i] = tree.intersect(w.packets[p].get(i)).prim;
      }
    });
  };
  const double single_ms = median_ms(opt.runs, single_rays(primary));
  // camera packets as TwoLevelScene traces them: frustums through the wide BVH where they
  // pay (WideBvh::frustums_pay), the kd-tree's packets elsewhere; and the kd-tree's alone
  const auto packet_pass = pass(primary, per_tile, [&](size_t p) {
    if (core::WideBvh::frustums_pay(primary.masks[p]))
      wide.intersect(primary.packets[p], primary.masks[p], scratch[p]);
    else
      tree.intersect(primary.packets[p], primary.masks[p], scratch[p]);
  });
  const double packet_ms = median_ms(opt.runs, packet_pass);
  const auto kd_packet_pass =
      pass(primary, per_tile, [&](size_t p) { tree.intersect(primary.packets[p], primary.masks[p], scratch[p]); });
  const double kd_packet_ms = median_ms(opt.runs, kd_packet_pass);
  const size_t per_tile_shadow = per_tile * std::max<size_t>(1, lights.size());
  std::vector<LaneMask> blocked(shadow.packets.size());
  const auto shadow_pass =
      pass(shadow, per_tile_shadow, [&](size_t p) { blocked[p] = tree.occluded(shadow.packets[p], shadow.masks[p]); });
  const double shadow_ms = median_ms(opt.runs, shadow_pass);
  // the same packets with a last-occluder hint per light and tile, as the renderer traces them
  auto hinted_pass = [&] {
    parallel_tiles(arena, tiles, [&](size_t t) {
      std::vector<core::ShadowHint> hints(std::max<size_t>(1, lights.size()));
      for (size_t p = t * per_tile_shadow; p < std::min(shadow.packets.size(), (t + 1) * per_tile_shadow); ++p) {
        const LaneMask b = tree.occluded(shadow.packets[p], shadow.masks[p], &hints[p % hints.size()]);
        if (b != blocked[p]) throw std::logic_error("bench-core: a shadow hint changed an answer");
      }
    });
  };
  const double hinted_ms = median_ms(opt.runs, hinted_pass);
  const double bounce_ms = median_ms(opt.runs, single_rays(bounce));

  auto wide_rays = [&](const Workload& w) {
    return pass(w, per_tile, [&, &w = w](size_t p) {
      for (int i = 0; i < kPacketSize; ++i) {
        if ((w.masks[p] >> i) & 1u) scratch[p].prim[i] = wide.intersect(w.packets[p].get(i)).prim;
      }
    });
  };
  const double wide_single_ms = median_ms(opt.runs, wide_rays(primary));
  // the bounce rays as the kd-tree's packets (8 neighbouring pixels' bounces a packet)
  const double bounce_packet_ms =
      median_ms(opt.runs, pass(bounce, per_tile, [&](size_t p) { tree.intersect(bounce.packets[p], bounce.masks[p], scratch[p]); }));
  const double wide_bounce_ms = median_ms(opt.runs, wide_rays(bounce));

  out["ray_counts"] = {{"primary", primary.rays}, {"shadow", shadow.rays}, {"incoherent", bounce.rays}};
  out["rays"] = {{"primary_single", mrays(primary.rays, wide_single_ms)},
                 {"primary_single_kdtree", mrays(primary.rays, single_ms)},
                 {"primary_packet", mrays(primary.rays, packet_ms)},
                 {"primary_packet_kdtree", mrays(primary.rays, kd_packet_ms)},
                 {"shadow", mrays(shadow.rays, shadow_ms)},
                 {"shadow_hinted", mrays(shadow.rays, hinted_ms)},
                 {"incoherent", mrays(bounce.rays, wide_bounce_ms)},
                 {"incoherent_kdtree", mrays(bounce.rays, bounce_ms)},
                 {"incoherent_kdtree_packets", mrays(bounce.rays, bounce_packet_ms)}};

  if (opt.reference == "embree") {
#if defined(ARTRACE_HAVE_EMBREE)
    EmbreeReference ref(tris, threads, opt.embree_robust);
    nlohmann::json e;
    e["setup"] =
        std::string("BVHs of RTC_BUILD_QUALITY_HIGH and MEDIUM, each kind of ray timed through both (the faster counts); "
                    "camera packets RTC_INTERSECT_CONTEXT_FLAG_COHERENT, single and bounce rays the default incoherent "
                    "context, shadow packets both (the faster counts); rays converted before and hits after the timed "
                    "passes") +
        (opt.embree_robust ? "; both scenes in robust mode (RTC_SCENE_FLAG_ROBUST)" : "");
    e["robust"] = opt.embree_robust;
    e["build_ms"] = median_ms(opt.runs, [&] { ref.build(EmbreeQuality::kHigh); });
    e["build_ms_medium"] = median_ms(opt.runs, [&] { ref.build(EmbreeQuality::kMedium); });
    // of the scenes the rays are timed through (the last builds), as Embree reports them
    e["scene_flags"] = {{"HIGH", ref.scene_flags(EmbreeQuality::kHigh)},
                        {"MEDIUM", ref.scene_flags(EmbreeQuality::kMedium)}};
    // a timed pass over a batch: the tiles' calls, in parallel as ours are traced
    auto embree_pass = [&](EmbreeQuality q, EmbreeBatch& batch, size_t w_per_tile, size_t w_packets, bool occlusion,
                           bool coherent) {
      return [&ref, q, &batch, &arena, tiles, w_per_tile, w_packets, occlusion, coherent] {
        parallel_tiles(arena, tiles, [&](size_t t) {
          const size_t first = batch.first_call(std::min(w_packets, t * w_per_tile));
          const size_t last = batch.first_call(std::min(w_packets, (t + 1) * w_per_tile));
          if (occlusion)
            ref.occluded(q, batch, first, last, coherent);
          else
            ref.intersect(q, batch, first, last, coherent);
        });
      };
    };
    // A kind of ray through both BVHs: each rate kept as key_HIGH and key_MEDIUM, the faster (and
    // its BVH) as key; returns the faster.
    struct Faster {
      EmbreeQuality quality = EmbreeQuality::kHigh;
      double rate = -1.0;
    };
    auto faster = [&](const std::string& key, size_t rays, EmbreeBatch& batch, size_t w_per_tile, size_t w_packets,
                      bool occlusion, bool coherent) {
      Faster best;
      for (const EmbreeQuality q : {EmbreeQuality::kHigh, EmbreeQuality::kMedium}) {
        const double r = mrays(rays, median_ms(
                                         opt.runs, [&] { batch.restore(); },
                                         embree_pass(q, batch, w_per_tile, w_packets, occlusion, coherent)));
        e["rays"][key + "_" + to_string(q)] = r;
        if (r > best.rate) best = Faster{q, r};
      }
      e["rays"][key] = best.rate;
      e["quality"][key] = to_string(best.quality);
      return best;
    };
    // camera rays: rtcIntersect1, and packets of 4, 8 and 16 (coherent); their best width counts
    EmbreeBatch single_batch(primary.packets, primary.masks, 1);
    const EmbreeQuality single_q =
        faster("primary_single", primary.rays, single_batch, per_tile, primary.packets.size(), false, false).quality;
    const auto embree_single_pass = embree_pass(single_q, single_batch, per_tile, primary.packets.size(), false, false);
    single_batch.restore();
    embree_single_pass();
    std::vector<uint32_t> embree_prim;
    EmbreeReference::hits(single_batch, embree_prim);
    size_t agree = 0;
    for (size_t p = 0; p < primary.packets.size(); ++p)
      for (int i = 0; i < kPacketSize; ++i)
        if ((primary.masks[p] >> i) & 1u) agree += embree_prim[p * kPacketSize + i] == hits[p].prim[i];
    e["primary_agreement"] = static_cast<double>(agree) / std::max<size_t>(1, primary.rays);
    int best_width = 0;
    Faster packet;
    std::unique_ptr<EmbreeBatch> best_batch;
    for (const int width : {4, 8, 16}) {
      auto batch = std::make_unique<EmbreeBatch>(primary.packets, primary.masks, width);
      const Faster f = faster("primary_packet_" + std::to_string(width), primary.rays, *batch, per_tile,
                              primary.packets.size(), false, true);
      if (f.rate > packet.rate) {
        packet = f;
        best_width = width;
        best_batch = std::move(batch);
      }
    }
    e["rays"]["primary_packet"] = packet.rate;
    e["quality"]["primary_packet"] = to_string(packet.quality);
    e["primary_packet_best_width"] = best_width;
    const auto embree_packet_pass =
        embree_pass(packet.quality, *best_batch, per_tile, primary.packets.size(), false, true);
    // shadow packets: the width of our packets, both context flags through both BVHs
    EmbreeBatch shadow_batch(shadow.packets, shadow.masks, opt.lanes);
    const Faster shadow_incoherent = faster("shadow_incoherent_flag", shadow.rays, shadow_batch, per_tile_shadow,
                                            shadow.packets.size(), true, false);
    const Faster shadow_coherent_flag =
        faster("shadow_coherent_flag", shadow.rays, shadow_batch, per_tile_shadow, shadow.packets.size(), true, true);
    const bool shadow_coherent = shadow_coherent_flag.rate > shadow_incoherent.rate;
    const Faster shadow_best = shadow_coherent ? shadow_coherent_flag : shadow_incoherent;
    e["rays"]["shadow"] = shadow_best.rate;
    e["quality"]["shadow"] = to_string(shadow_best.quality);
    e["shadow_flag"] = shadow_coherent ? "coherent" : "incoherent";
    const auto embree_shadow_pass =
        embree_pass(shadow_best.quality, shadow_batch, per_tile_shadow, shadow.packets.size(), true, shadow_coherent);
    shadow_batch.restore();
    embree_shadow_pass();
    std::vector<LaneMask> embree_blocked;
    EmbreeReference::blocked(shadow_batch, embree_blocked);
    // Where the two disagree, brute force says who is right.
    size_t shadow_disagree = 0, ours_wrong = 0, embree_wrong = 0;
    for (size_t p = 0; p < shadow.packets.size(); ++p) {
      const LaneMask differ = embree_blocked[p] ^ blocked[p];
      if (!differ) continue;
      ++shadow_disagree;
      for (int i = 0; i < kPacketSize; ++i) {
        if (!((differ >> i) & 1u)) continue;
        const bool truth = core::occluded_brute_force(shadow.packets[p].get(i), tris);
        ours_wrong += (((blocked[p] >> i) & 1u) != 0) != truth;
        embree_wrong += (((embree_blocked[p] >> i) & 1u) != 0) != truth;
      }
    }
    e["shadow_packets_disagreeing"] = shadow_disagree;
    e["shadow_disagreeing_lanes_wrong"] = {{"artrace", ours_wrong}, {"embree", embree_wrong}};
    // incoherent bounce rays: rtcIntersect1
    EmbreeBatch bounce_batch(bounce.packets, bounce.masks, 1);
    const EmbreeQuality bounce_q =
        faster("incoherent", bounce.rays, bounce_batch, per_tile, bounce.packets.size(), false, false).quality;
    const auto embree_bounce_pass = embree_pass(bounce_q, bounce_batch, per_tile, bounce.packets.size(), false, false);
    // Speed ratios (ours / Embree's best) from runs taken in turns, the median of the per-pair
    // ratios: the machine's drift over the benchmark cancels out.
    e["paired_ratio"] = {
        {"runs", opt.runs},
        {"primary_single", paired_ratio(opt.runs, wide_rays(primary), [&] { single_batch.restore(); }, embree_single_pass)},
        {"primary_single_kdtree", paired_ratio(opt.runs, single_rays(primary), [&] { single_batch.restore(); }, embree_single_pass)},
        {"primary_packet", paired_ratio(opt.runs, packet_pass, [&] { best_batch->restore(); }, embree_packet_pass)},
        {"primary_packet_kdtree", paired_ratio(opt.runs, kd_packet_pass, [&] { best_batch->restore(); }, embree_packet_pass)},
        {"shadow", paired_ratio(opt.runs, shadow_pass, [&] { shadow_batch.restore(); }, embree_shadow_pass)},
        {"shadow_hinted", paired_ratio(opt.runs, hinted_pass, [&] { shadow_batch.restore(); }, embree_shadow_pass)},
        {"incoherent", paired_ratio(opt.runs, wide_rays(bounce), [&] { bounce_batch.restore(); }, embree_bounce_pass)},
        {"incoherent_kdtree", paired_ratio(opt.runs, single_rays(bounce), [&] { bounce_batch.restore(); }, embree_bounce_pass)}};
    out["embree"] = e;
#else
    throw std::runtime_error("this build has no Embree (install libembree-dev and reconfigure)");
#endif
  }

  std::printf("bench-core %s t=%g %dx%d, %d threads, %s kernels, packets of %d rays, %zu triangles "
              "(median of %d runs)\n",
              opt.scene.c_str(), opt.time, opt.width, opt.height, threads, core::to_string(core::simd_level()).c_str(),
              opt.lanes, tris.size(), opt.runs);
  std::printf("  kd-tree build %.1f ms, %u nodes (%zu bytes), %u leaves, depth %u, SAH cost %.2f\n", build_ms,
              st.nodes, st.node_bytes, st.leaves, st.max_depth, st.sah_cost);
  std::printf("  wide BVH build %.1f ms (%d bins, spatial splits: budget %g), %u nodes, %u leaves (%u blocks of 8 for %u triangle references), depth %u, SAH cost %.2f\n",
              wide_build_ms, opt.wide.bins, opt.wide.spatial_budget, wst.nodes, wst.leaves, wst.blocks, wst.triangles_in_blocks, wst.max_depth, wst.sah_cost);
  std::printf("  %-22s %12s %12s\n", "Mrays/s", "artrace", opt.reference == "embree" ? "embree" : "");
  for (const char* key : {"primary_single", "primary_single_kdtree", "primary_packet", "primary_packet_kdtree", "shadow", "shadow_hinted", "incoherent",
                          "incoherent_kdtree", "incoherent_kdtree_packets"}) {
    std::printf("  %-22s %12.2f", key, out["rays"][key].get<double>());
    if (out.contains("embree") && out["embree"]["rays"].contains(key)) {
      std::printf(" %12.2f", out["embree"]["rays"][key].get<double>());
    }
    std::printf("\n");
  }
  if (out.contains("embree")) {
    const nlohmann::json& e = out["embree"];
    const nlohmann::json& r = e["rays"];
    auto quality = [&](const char* key) { return e["quality"][key].get<std::string>(); };
    std::printf(
        "  embree%s builds: HIGH %.1f ms, MEDIUM %.1f ms; rays through both BVHs, Mrays/s HIGH / MEDIUM: "
        "single %.2f / %.2f, incoherent %.2f / %.2f\n",
        e["robust"].get<bool>() ? " (robust mode)" : "", e["build_ms"].get<double>(), e["build_ms_medium"].get<double>(), r["primary_single_HIGH"].get<double>(),
        r["primary_single_MEDIUM"].get<double>(), r["incoherent_HIGH"].get<double>(),
        r["incoherent_MEDIUM"].get<double>());
    std::printf(
        "  embree's best camera packet width %d (4: %.2f, 8: %.2f, 16: %.2f Mrays/s, coherent, each through its faster "
        "BVH); shadow packets incoherent flag %.2f (%s), coherent %.2f (%s); the faster BVH for camera packets %s, "
        "shadow %s\n",
        e["primary_packet_best_width"].get<int>(), r["primary_packet_4"].get<double>(),
        r["primary_packet_8"].get<double>(), r["primary_packet_16"].get<double>(),
        r["shadow_incoherent_flag"].get<double>(), quality("shadow_incoherent_flag").c_str(),
        r["shadow_coherent_flag"].get<double>(), quality("shadow_coherent_flag").c_str(),
        quality("primary_packet").c_str(), quality("shadow").c_str());
    std::printf("  speed ratio artrace / embree's best, runs in turns (median of %d pairs, order alternating): primary_single %.3f "
                "(kd-tree %.3f), primary_packet %.3f (kd-tree %.3f), shadow %.3f, shadow_hinted %.3f, incoherent %.3f (kd-tree %.3f)\n",
                opt.runs, e["paired_ratio"]["primary_single"].get<double>(), e["paired_ratio"]["primary_single_kdtree"].get<double>(),
                e["paired_ratio"]["primary_packet"].get<double>(), e["paired_ratio"]["primary_packet_kdtree"].get<double>(),
                e["paired_ratio"]["shadow"].get<double>(),
                e["paired_ratio"]["shadow_hinted"].get<double>(), e["paired_ratio"]["incoherent"].get<double>(),
                e["paired_ratio"]["incoherent_kdtree"].get<double>());
    const nlohmann::json& wrong = e["shadow_disagreeing_lanes_wrong"];
    std::printf("  shadow packets answered differently by embree: %zu (the differing lanes, by brute force: %zu of "
                "ours wrong, %zu of embree's)\n",
                e["shadow_packets_disagreeing"].get<size_t>(), wrong["artrace"].get<size_t>(),
                wrong["embree"].get<size_t>());
  }
  write_json(opt.json, out);
}

}  // namespace

void add_bench_core_command(CLI::App& app) {
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("bench-core", "kd-tree build time and ray throughput (verified, then timed)");
  cmd->add_option("--scene", opt->scene, "BART .aff scene")->required()->check(CLI::ExistingFile);
  cmd->add_option("--time", opt->time, "scene time t (camera from its track)")->capture_default_str()->check(finite_range(-1e6, 1e6));
  cmd->add_option("--width", opt->width, "image width")->capture_default_str()->check(CLI::Range(8, 16384));
  cmd->add_option("--height", opt->height, "image height")->capture_default_str()->check(CLI::Range(8, 16384));
  add_threads_option(cmd, opt->threads);
  cmd->add_option("--runs", opt->runs, "timed runs after the warm-up (median reported)")->capture_default_str()->check(CLI::Range(1, 1000));
  cmd->add_option("--subdivide", opt->subdivide, "split every triangle into 4, this many times")->capture_default_str()->check(CLI::Range(0, 4));
  cmd->add_option("--verify-rays", opt->verify_rays, "primary rays checked against brute force")->capture_default_str()->check(CLI::Range(0, 100000000));
  cmd->add_option("--reference", opt->reference, "also time the same rays with: none, embree")
      ->capture_default_str()->check(CLI::IsMember({"none", "embree"}));
  cmd->add_option("--simd", opt->simd, "packet kernels: auto, scalar, sse, avx2, avx512")->capture_default_str();
  cmd->add_option("--lanes", opt->lanes,
                  "rays a packet: 8 (4x2 pixels; Embree's 8-wide calls) or 16 (4x4; its 16-wide ones)")
      ->capture_default_str()
      ->check(CLI::IsMember({8, 16}));
  cmd->add_flag("--embree-robust", opt->embree_robust,
                "the Embree reference's scenes in its robust mode (RTC_SCENE_FLAG_ROBUST: robust traversal, no "
                "optimisations that reduce arithmetic accuracy), the nearest it comes to our kernels' guarantee (every "
                "hit as brute force gives it); the targets compare against its default, faster mode");
  cmd->add_option("--json", opt->json, "write the results as JSON");
  cmd->add_option("--wide-spatial", opt->wide.spatial_budget,
                  "the wide BVH's spatial splits: references they may add per triangle (0: none)")
      ->capture_default_str()
      ->check(finite_range(0, 1));
  cmd->add_option("--wide-bins", opt->wide.bins, "the wide BVH's SAH bins per axis")
      ->capture_default_str()
      ->check(CLI::Range(2, 256));
  cmd->add_option("--sah-traversal", opt->build.traversal_cost, "SAH traversal cost K_T")->capture_default_str()->check(finite_range(0.001, 1000));
  cmd->add_option("--sah-intersection", opt->build.intersection_cost, "SAH intersection cost K_I")->capture_default_str()->check(finite_range(0.001, 1000));
  cmd->add_option("--empty-bonus", opt->build.empty_bonus, "SAH empty-space factor")->capture_default_str()->check(finite_range(0, 1));
  cmd->add_option("--binned-above", opt->build.binned_above,
                  "nodes of more triangles split by binned SAH (0: the exact sweep everywhere)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1000000000));
  cmd->callback([opt] { run(*opt); });
}

}  // namespace artrace::tools

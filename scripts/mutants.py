#!/usr/bin/env python3
"""Mutation testing: small deliberate bugs put into the product code one at a time, each built and
run against the test suite in a scratch clone. A mutant that every test survives shows a rule the
tests do not guard.

    python3 scripts/mutants.py                 # every mutant of the catalogue (about 2 min each)
    python3 scripts/mutants.py --list          # the catalogue
    python3 scripts/mutants.py --only NAME ... # some of them
    python3 scripts/mutants.py --report FILE   # also write the results as JSON

The scratch clone is made from the working tree's HEAD (commit first), built once, then each mutant
is applied, built incrementally, run with `ctest` (the whole suite, as the README's test command,
stopping at the first failure), and reverted. A mutant whose text is not found exactly once is an
error of the catalogue, reported as such: the catalogue must follow the code.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# name, file, exact text, replacement, why the replacement is wrong
CATALOGUE = [
    # occlusion scores and rules
    ("occlusion-iou-constant", "ar/src/occlusion.cpp",
     "s.iou = uni ? static_cast<double>(inter) / uni : 1.0;", "s.iou = 1.0;",
     "the IoU of the occlusion mask would always read perfect"),
    ("occlusion-boundary-zero", "ar/src/occlusion.cpp",
     "s.boundary_px = (distance_sum(o_truth, f_est, none) + distance_sum(o_est, f_truth, none)) / s.boundary_pixels;",
     "s.boundary_px = 0.0;",
     "the boundary error would always read zero"),
    ("occlusion-boundary-one-sided", "ar/src/occlusion.cpp",
     "s.boundary_px = (distance_sum(o_truth, f_est, none) + distance_sum(o_est, f_truth, none)) / s.boundary_pixels;",
     "s.boundary_px = o_est.empty() ? 0.0 : distance_sum(o_est, f_truth, none) / o_est.size();",
     "a missed occlusion boundary would cost nothing"),
    ("occlusion-large-holes-filled", "ar/src/occlusion.cpp",
     "if (static_cast<int>(component.size()) <= max_hole_px) {", "if (true) {",
     "large holes (no reading: beyond range, glass, black) would be grown over from their rim and hide the virtual surface"),
    ("occlusion-fixed-band", "ar/src/occlusion.cpp",
     "const double band = std::max(opt.min_band_m, opt.band_sigmas * sigma);", "const double band = 0.005;",
     "the soft band would not follow the sensor's noise, which grows with distance squared"),
    ("occlusion-median-not-far-side", "ar/src/occlusion.cpp",
     "const size_t pick = window.size() * 3 / 4;", "const size_t pick = window.size() / 2;",
     "holes at silhouettes (the sensor's shadow on the background) would be filled with the occluder's depth"),
    # the watertight triangle test
    ("triangle-no-double-fallback", "core/src/traversal.inc",
     "uint32_t fix = movemask(alive & (eq(u, zero) | eq(v, zero) | eq(w, zero)));", "uint32_t fix = 0;",
     "an edge function rounded to zero would not be recomputed: a ray near a shared edge can take the wrong triangle"),
    ("triangle-rejects-exact-edges", "core/src/traversal.inc",
     "const K reject = (lt(u, zero) | lt(v, zero) | lt(w, zero)) & (lt(zero, u) | lt(zero, v) | lt(zero, w));",
     "const K reject = (lt(u, zero) | lt(v, zero) | lt(w, zero)) & (lt(zero, u) | lt(zero, v) | lt(zero, w)) | eq(u, zero) | eq(v, zero) | eq(w, zero);",
     "rays through shared edges and vertices would leak through closed meshes"),
    # kd-tree build
    ("kdtree-no-empty-bonus", "core/src/kd_tree_build.cpp",
     "const float lambda = (n_left == 0 || n_right == 0) ? opt_.empty_bonus : 1.0f;", "const float lambda = 1.0f;",
     "the empty-space bonus would be ignored: empty space is no longer cut off"),
    ("kdtree-clipped-bounds-not-widened", "core/src/clipping.h",
     "      b->lo -= margin;\n      b->hi += margin;\n", "",
     "a sliver leaning a fraction of an ulp off a split plane is handed to the wrong side only and lost"),
    # the wide BVH
    ("wide-box-test-no-slack", "core/src/wide_traversal.inc",
     "return movemask(le(t0, Signed ? raised(t1) : t1));", "return movemask(lt(t0, t1));",
     "a ray grazing a box edge, or entering a flat box, would skip what it holds"),
    ("wide-pop-culls-equal-distances", "core/src/wide_traversal.inc",
     "if (AnyHit || e.t <= reach) {", "if (AnyHit || e.t < best.t) {",
     "a box entered exactly at the current hit's distance would be skipped: ties could go to the larger triangle"),
    ("wide-tie-to-larger-primitive", "core/src/wide_traversal.inc",
     "if (t < best.t || (t == best.t && block.prim[i] < best.prim)) {", "if (t < best.t) {",
     "equal distances would go to whichever triangle is visited first, not the smaller one: not the kd-tree's hit"),
    # Not a mutant: padding a block's empty lanes with triangle 0 instead of the block's first
    # triangle changes no answer. A padded lane holds a real triangle's geometry, so a ray meeting it
    # also meets that triangle in its own leaf at the same distance, where the real id wins the tie
    # against kInvalidId (and an any-hit answer is the same). It survived the whole suite and was
    # taken out of the catalogue as an equivalent mutant.
    ("wide-build-sah-depth-unbounded", "core/src/wide_bvh_build.cpp",
     "if (depth >= kSahDepth) {", "if (false) {",
     "inputs that defeat the SAH would build trees deeper than the traversal's stack"),
    ("wide-spatial-split-drops-upper-part", "core/src/wide_bvh_build.cpp",
     "        above.push_back(Ref{t, ref.prim});\n        ++copies;\n", "        ++copies;\n",
     "a triangle cut by a spatial split would keep only its part below the plane: rays meeting the rest miss it"),
    ("wide-spatial-budget-ignored", "core/src/wide_bvh_build.cpp",
     "if (cnt + right[b].count - r.size() > r.budget) continue;", "if (false) continue;",
     "spatial splits would copy references past the budget (and its count would wrap)"),
    # Table 1's workloads
    ("whitted-paper-mode-shadows-everywhere", "core/include/artrace/core/whitted.h",
     "(m == ShadingMode::kPaper && depth == 0)", "m == ShadingMode::kPaper",
     "the paper's workload would trace shadow rays at secondary hits too: full Whitted under another name"),
    # ONI writer
    ("oni-seek-table-offsets", "io/src/oni_writer.cpp",
     "std::memcpy(entry + 12, &n->data_offsets[k], 8);", "std::memcpy(entry + 12, &n->added_offset, 8);",
     "every seek-table entry would point at the wrong record"),
    ("oni-undo-zero", "io/src/oni_writer.cpp",
     "record_header(kNewData, n->id, 40, static_cast<uint32_t>(n->frame_bytes), n->last_data);",
     "record_header(kNewData, n->id, 40, static_cast<uint32_t>(n->frame_bytes), 0);",
     "the undo chain of data records would be broken"),
    # ONI 16z/16zT depth decoding
    ("oni-16z-escape-difference-sign", "io/src/oni_codecs.cpp",
     "cur = static_cast<uint16_t>(cur + 192 - in[pos]);", "cur = static_cast<uint16_t>(cur - 192 + in[pos]);",
     "an escaped difference would be applied with the wrong sign"),
    ("oni-16zt-table-big-endian", "io/src/oni_codecs.cpp",
     "lut[k] = static_cast<uint16_t>(in[2 + 2 * k] | in[3 + 2 * k] << 8);",
     "lut[k] = static_cast<uint16_t>(in[3 + 2 * k] | in[2 + 2 * k] << 8);",
     "16zT table entries would be read big-endian"),
    # glTF textures
    ("texture-srgb-ignored", "ar/src/texture.cpp",
     "  if (srgb_) return {core::srgb8_to_linear(p[0])", "  if (false) return {core::srgb8_to_linear(p[0])",
     "base-colour textures would be taken as linear, too bright in the mid-tones"),
    ("texture-mirrored-repeat-as-repeat", "ar/src/texture.cpp",
     "return m < n ? m : period - 1 - m;", "return m < n ? m : m - n;",
     "mirrored repeat would repeat without the mirror"),
    # anchors on real surfaces
    ("anchor-left-handed-frame", "io/src/ar_scene.cpp",
     "const Eigen::Vector3d x = y.cross(z);", "const Eigen::Vector3d x = z.cross(y);",
     "an anchored model would be mirrored"),
    ("anchor-offset-sign", "io/src/ar_scene.cpp",
     "const Eigen::Vector3d o = plane->point + y * p.anchor->offset_m;",
     "const Eigen::Vector3d o = plane->point - y * p.anchor->offset_m;",
     "anchor.offset would sink the model into the surface"),
    ("anchor-point-not-on-the-pixel-ray", "ar/src/plane_fit.cpp",
     "  if (std::fabs(den) > 1e-9) p->point = eye + dir * (p->normal.dot(p->point - eye) / den);\n", "",
     "an anchored model would stand at the fitted points' centre, not where the pixel's ray meets the plane"),
    # fusion
    ("fusion-extrinsic-not-inverted", "io/src/fusion.cpp",
     "f.world_from_camera->inverse().matrix();  // camera from world", "f.world_from_camera->matrix();  // camera from world",
     "frames would be fused with the inverse of their poses"),
    # intrinsics files
    ("intrinsics-image-size-unchecked", "io/src/intrinsics_file.cpp",
     "if (!(v >= 0.0 && v <= 100000.0) || v != std::floor(v)) {", "if (false) {",
     "a width beyond int would be converted to int (undefined behaviour), a fractional one truncated"),
    # declared sizes checked before allocating (found by fuzzing)
    ("ppm-allocates-before-checking", "io/src/bart_shading.cpp",
     "  if (held < n * bytes_per) {", "  if (false) {",
     "a PPM header declaring a huge image would make the reader allocate and zero gigabytes for a few bytes"),
    ("gltf-image-size-unchecked", "io/src/cv_convert.h",
     "constexpr uint32_t kMaxImageSide = 16384;", "constexpr uint32_t kMaxImageSide = 1u << 20;",
     "an image declaring 40000 x 40000 pixels would reach OpenCV's decoder, which allocates for it first"),
    ("oni-jpeg-size-unchecked", "io/src/oni_codecs.cpp",
     "  if (declared->width != static_cast<uint32_t>(width) || declared->height != static_cast<uint32_t>(height)) {",
     "  if (false) {",
     "a colour frame declaring a huge JPEG would be decoded (gigabytes allocated) before its size is compared with the mode's"),
    ("png-chunk-length-unchecked", "io/src/cv_convert.cpp",
     "    if (length + 12 > size - pos) {", "    if (false) {",
     "a PNG chunk declaring gigabytes would reach libpng, which allocates the declared length before reading"),
    ("gltf-image-bufferview-unchecked", "io/src/gltf_model.cpp",
     "    if (!view_holds(v, held, 0, v.byteLength, 1, 1) || v.byteLength > static_cast<size_t>(std::numeric_limits<int>::max())) {",
     "    if (false) {",
     "an image whose bufferView runs past its buffer would be decoded from bytes past the buffer's end"),
    ("gltf-unbacked-accessor-unchecked", "io/src/gltf_model.cpp",
     "      if (a.count > unbacked_limit_) {", "      if (false) {",
     "an accessor with no bufferView declaring 100 million elements would be allocated (3 GB) from a file of a few hundred bytes"),
    ("oni-yuv422-odd-width-accepted", "io/src/oni_codecs.cpp",
     "  if (format == 2 && width % 2 != 0) throw", "  if (false) throw",
     "an odd-width YUV422 frame would reach OpenCV's conversion, which writes past the image"),
    # scale-out: shards must tile the frames
    ("shards-gap-unreported", "tools/shards.cpp",
     "if (s.first > covered) out.push_back(", "if (false) out.push_back(",
     "join would encode a clip with frames missing in the middle"),
    # TUM association
    ("tum-pairing-window-one-side", "io/src/tum_reader.cpp",
     "while (lo < depth.size() && depth[lo].time_s < color[c].time_s - max_dt_s) ++lo;",
     "while (lo < depth.size() && depth[lo].time_s < color[c].time_s - 3.0 * max_dt_s) ++lo;",
     "depth frames up to three windows before a colour frame would be paired with it"),
    # thread-count determinism of the compositor
    ("compositor-shadow-smoothing-in-place", "ar/src/compositor.cpp",
     "    smooth[k] = sum / static_cast<float>(n);", "    smooth[k] = factor[i] = sum / static_cast<float>(n);",
     "smoothing in place makes the shadows depend on the order in which threads listed the pixels"),
]


def run(cmd, cwd, log, timeout=None):
    with open(log, "a") as f:
        f.write("$ " + " ".join(cmd) + "\n")
        f.flush()
        return subprocess.run(cmd, cwd=cwd, stdout=f, stderr=subprocess.STDOUT, timeout=timeout).returncode


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", nargs="*", help="names of the mutants to run")
    ap.add_argument("--list", action="store_true", help="print the catalogue")
    ap.add_argument("--report", help="write the results as JSON")
    ap.add_argument("--scratch", help="scratch folder (default: a new temporary one, kept for a look)")
    ap.add_argument("--jobs", type=int, default=2, help="ctest -j")
    args = ap.parse_args()

    if args.list:
        for name, path, _, _, why in CATALOGUE:
            print(f"{name:40s} {path}: {why}")
        return 0
    chosen = [m for m in CATALOGUE if not args.only or m[0] in args.only]
    if args.only and len(chosen) != len(args.only):
        known = {m[0] for m in CATALOGUE}
        print("unknown mutants: " + ", ".join(n for n in args.only if n not in known), file=sys.stderr)
        return 2

    top = Path(__file__).resolve().parent.parent
    scratch = Path(args.scratch or tempfile.mkdtemp(prefix="artrace-mutants-"))
    clone = scratch / "src"
    log = scratch / "log.txt"
    if not clone.exists():
        subprocess.run(["git", "clone", "-q", "--local", str(top), str(clone)], check=True)
    build = clone / "build"
    env_data = os.environ.get("ARTRACE_SHARED_DATA", str((top.parent / "shared" / "data").resolve()))
    print(f"scratch clone {clone} (log: {log})", flush=True)
    if run(["cmake", "-S", ".", "-B", "build", "-G", "Ninja", "-DCMAKE_BUILD_TYPE=Release",
            f"-DARTRACE_SHARED_DATA={env_data}"], clone, log) or run(["cmake", "--build", "build"], clone, log):
        print("the unmutated tree does not build; see the log", file=sys.stderr)
        return 2
    if run(["ctest", "--test-dir", "build", "-j", str(args.jobs)], clone, log):
        print("the unmutated tree fails its tests; see the log", file=sys.stderr)
        return 2

    results = []
    for name, path, text, replacement, why in chosen:
        f = clone / path
        original = f.read_text()
        count = original.count(text)
        if count != 1:
            print(f"{name:40s} CATALOGUE ERROR: its text occurs {count} times in {path}", flush=True)
            results.append({"name": name, "file": path, "result": "catalogue error", "occurrences": count})
            continue
        f.write_text(original.replace(text, replacement))
        t0 = time.time()
        try:
            if run(["cmake", "--build", "build"], clone, log):
                result, failed = "killed (does not build)", []
            else:
                junit = scratch / f"{name}.xml"
                code = run(["ctest", "--test-dir", "build", "-j", str(args.jobs), "--stop-on-failure",
                            "--output-junit", str(junit)], clone, log, timeout=3600)
                failed = []
                if junit.exists():
                    import xml.etree.ElementTree as ET
                    for case in ET.parse(junit).getroot().iter("testcase"):
                        if case.get("status") == "fail" or case.find("failure") is not None:
                            failed.append(case.get("name"))
                result = "killed" if code else "SURVIVED"
        finally:
            f.write_text(original)
        seconds = time.time() - t0
        print(f"{name:40s} {result:10s} {seconds:6.0f} s  {', '.join(failed[:3])}", flush=True)
        results.append({"name": name, "file": path, "why": why, "result": result, "failed_tests": failed,
                        "seconds": round(seconds)})
    run(["cmake", "--build", "build"], clone, log)  # leave the clone unmutated and built

    killed = sum(r["result"].startswith("killed") for r in results)
    print(f"\n{killed} of {len(results)} mutants killed")
    for r in results:
        if not r["result"].startswith("killed"):
            print(f"  {r['result']}: {r['name']} ({r['file']}): {r.get('why', '')}")
    if args.report:
        Path(args.report).write_text(json.dumps({"killed": killed, "total": len(results), "mutants": results}, indent=2) + "\n")
    return 0 if killed == len(results) else 1


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Writes the fuzz harnesses' seed corpora, tests/fuzz/corpus/<reader>/, from small files of the project
(data/, tests) and of ../shared/data, and hand-made ones for what those lack. The result is kept in
the repository; run this again only to change it:

    python3 tests/fuzz/make_corpus.py [--artrace build/tools/artrace] [--shared ../shared/data]

--artrace makes a tiny ONI recording (artrace synth, then convert) for the ONI seeds.
"""

import argparse
import base64
import json
import os
import shutil
import subprocess
import sys
import tempfile
import zlib
import struct
from pathlib import Path

top = Path(__file__).resolve().parent.parent.parent


def tiny_png(w=4, h=4):
    """An RGB PNG written by hand (no imaging library needed)."""
    raw = b"".join(b"\x00" + b"".join(bytes((x * 60 % 256, y * 60 % 256, 128)) for x in range(w)) for y in range(h))
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)) + \
        chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")


def png_seeds():
    """Small PNGs in the layouts the PNG decoder takes, every row filter and split IDATs, with the
    harness's first byte (1: decoded as colour, 0: as 16-bit depth) in front."""
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)

    def png(w, h, depth, colour_type, extra=b""):
        bpp = {0: 1, 2: 3, 4: 2, 6: 4}[colour_type] * depth // 8
        # any filtered bytes decode: row y gets filter y % 5 over a fixed pattern
        raw = b"".join(bytes([y % 5]) + bytes((x * 37 + y * 101) % 256 for x in range(w * bpp)) for y in range(h))
        z = zlib.compress(raw, 6)
        return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, colour_type, 0, 0, 0)) + extra + \
            chunk(b"IDAT", z[:len(z) // 2]) + chunk(b"IDAT", z[len(z) // 2:]) + chunk(b"IEND", b"")
    # and two image descriptions the harness writes as PNGs (first byte bit 1): width, height,
    # layout, IDAT piece, then the filtered rows
    described = {"described_rgb": b"\x03" + bytes([5, 4, 2, 1]) + bytes(range(80)),
                 "described_depth": b"\x02" + bytes([6, 3, 4, 0]) + bytes((i * 7) % 256 for i in range(60))}
    return {**described,
            "rgb8": b"\x01" + png(6, 5, 8, 2),
            "rgba8": b"\x01" + png(5, 5, 8, 6, chunk(b"gAMA", b"\x00\x00\xb1\x8f")),
            "grey8": b"\x01" + png(7, 3, 8, 0),
            "grey_alpha8": b"\x01" + png(4, 6, 8, 4, chunk(b"tEXt", b"k\x00v")),
            "depth16": b"\x00" + png(6, 5, 16, 0)}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--artrace", default=str(top / "build/tools/artrace"))
    ap.add_argument("--shared", default=str(top.parent / "shared/data"))
    args = ap.parse_args()
    shared = Path(args.shared)
    out = top / "tests/fuzz/corpus"
    if out.exists():
        shutil.rmtree(out)

    def put(reader, name, data):
        d = out / reader
        d.mkdir(parents=True, exist_ok=True)
        (d / name).write_bytes(data if isinstance(data, bytes) else data.encode())

    # a texture the glTF harness offers beside its models
    (top / "tests/data/fuzz").mkdir(parents=True, exist_ok=True)
    (top / "tests/data/fuzz/texture.png").write_bytes(tiny_png())

    # AFF: the demo room, small kitchen parts, hand-made ones for each kind of line
    put("aff", "room.aff", (top / "data/scenes/room.aff").read_bytes())
    for f in ["floor.aff", "roof.aff", "bar_stools.aff", "support1.aff", "param_window.aff"]:
        p = shared / "bart/kitchen/aff" / f
        if p.exists():
            put("aff", "kitchen_" + f, p.read_bytes())
    put("aff", "include.aff", "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 0.1\nresolution 32 24\n"
        "l 1 1 1\nf 1 0 0 1 0 0 0 1\np 3\n0 0 0\n1 0 0\n0 1 0\ni 0 inc.aff\n")
    put("aff", "animated.aff", "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 0.1\nresolution 32 24\n"
        "anim 0 1 2\ntra pos linear 2\n0 0 0 0\n1 1 0 0\nxs pos\nf 0 1 0 1 0 0 0 1\npp 3\n0 0 0 0 0 1\n1 0 0 0 0 1\n"
        "0 1 0 0 0 1\nx\n")
    put("aff", "textured.aff", "fm 0.2 0.2 0.2 0.4 0.4 0.4 0.5 0.5 0.5 255 0 0\nm\n vertices 3\n 0 0 0\n 1 0 0\n 0 1 0\n"
        " texturecoords 3 texture.ppm\n 0 0\n 1 0\n 0 1\n triangles 1\n 0 1 2 0 1 2\n")

    # PPM
    put("ppm", "p6.ppm", b"P6\n2 2\n255\n" + bytes(range(12)))
    put("ppm", "p3.ppm", "P3\n# a comment\n2 1\n15\n0 0 0 15 15 15\n")

    # glTF: the project's own models, the shared binary box, and primitive modes inlined
    put("gltf", "spinning_box.gltf", (top / "data/models/spinning_box.gltf").read_bytes())
    box = shared / "models/BoxTextured/glTF-Binary/BoxTextured.glb"
    if box.exists():
        put("gltf", "box_textured.glb", box.read_bytes())
    for k in ["04", "05", "11"]:
        g = shared / f"models/Mesh_PrimitiveMode/Mesh_PrimitiveMode_{k}.gltf"
        if g.exists():
            j = json.loads(g.read_text())
            for b in j.get("buffers", []):
                data = (g.parent / b["uri"]).read_bytes()
                b["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode()
            put("gltf", f"primitive_mode_{k}.gltf", json.dumps(j))
    put("gltf", "texture_file.gltf", json.dumps({
        "asset": {"version": "2.0"}, "images": [{"uri": "texture.png"}], "textures": [{"source": 0}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]}))

    # PNG frames (the decoder on libdeflate, against OpenCV's)
    for name, data in png_seeds().items():
        put("png", name, data)

    # AR scenes: the demo's, with the models beside the scene (where the harness puts them)
    for f in ["demo.json", "two_models.json"]:
        j = json.loads((top / "data/ar" / f).read_text())
        for m in j.get("models", []):
            m["file"] = os.path.basename(m["file"])
        put("ar_scene", f, json.dumps(j, indent=1))
    put("ar_scene", "anchor.json", json.dumps({"models": [{"file": "spinning_box.gltf", "scale": 0.3,
        "anchor": {"frame": 0, "pixel": [10, 10], "offset": 0.0, "rotation_deg": 30},
        "material": {"kind": "glass", "ior": 1.5}}], "lights": [{"position": [0, 1, 0], "color": [1, 1, 1]}],
        "ambient": 0.3}))

    # TUM: the first byte chooses the reader
    room = top / "data/recordings/room"
    put("tum", "rgb.txt", b"\x00" + b"".join((room / "rgb.txt").read_bytes().splitlines(True)[:8]))
    put("tum", "groundtruth.txt", b"\x01" + b"".join((room / "groundtruth.txt").read_bytes().splitlines(True)[:8]))
    put("tum", "intrinsics.txt", b"\x02" + (room / "intrinsics.txt").read_bytes())

    # intrinsics: JSON, YAML, text
    put("intrinsics", "open3d.json", b"\x00" + b'{ "width": 640, "height": 480, "intrinsic_matrix": '
        b'[600.0, 0.0, 0.0, 0.0, 601.0, 0.0, 320.5, 240.25, 1.0] }')
    put("intrinsics", "opencv.yaml", b"\x01" + b"%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
        b"camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 517.3, 0., 318.6, 0., 516.5, 255.3, 0., 0., 1. ]\n"
        b"distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n   data: [ 0.26, -0.95, -0.005, 0.002, 1.16 ]\n")
    put("intrinsics", "ros.yaml", b"\x01" + b"image_width: 320\nimage_height: 240\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
        b"  data: [285.17, 0, 160, 0, 285.17, 120, 0, 0, 1]\ndistortion_model: plumb_bob\n")
    put("intrinsics", "intrinsics.txt", b"\x02" + (room / "intrinsics.txt").read_bytes())

    # ONI: a tiny recording the project writes, and the heads of the real ones (cut short on purpose)
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        if Path(args.artrace).exists():
            subprocess.run([args.artrace, "synth", "--scene", str(top / "data/scenes/room.aff"), "-o", str(t / "tiny"),
                            "--frames", "2", "--width", "16", "--height", "12"], check=True, stdout=subprocess.DEVNULL)
            subprocess.run([args.artrace, "convert", str(t / "tiny"), "-o", str(t / "tiny.oni")], check=True,
                           stdout=subprocess.DEVNULL)
            put("oni", "tiny.oni", (t / "tiny.oni").read_bytes())
        else:
            print(f"no {args.artrace}: the ONI corpus has the real recordings' heads only", file=sys.stderr)
    for name, f in [("tabletop_head.oni", "rgbd/oni-kinect1-tabletop-4f/Captured.oni"), ("qvga_head.oni", "rgbd/oni-qvga-cc-40f/test.oni")]:
        p = shared / f
        if p.exists():
            put("oni", name, p.read_bytes()[:48 * 1024])

    # ONI codecs: [decoder, width-1, height-1, format] + stream bytes
    put("oni_codecs", "16z.bin", bytes([0, 7, 5, 0]) + bytes([0x00, 0x10, 0x12, 0x34, 0xf0, 0x21, 0xff, 0x00, 0x01] * 6))
    put("oni_codecs", "16zt.bin", bytes([1, 7, 5, 0]) + struct.pack("<H", 3) + struct.pack("<3H", 0, 800, 65535) +
        bytes([0x00, 0x01, 0x02, 0x10, 0x20] * 10))
    put("oni_codecs", "jpeg.bin", bytes([2, 3, 3, 0]) + b"\xff\xd8\xff\xe0" + b"\x00" * 32 + b"\xff\xd9")
    put("oni_codecs", "raw.bin", bytes([3, 3, 3, 1]) + bytes(range(48)))
    for reader in sorted(p.name for p in out.iterdir()):
        print(f"tests/fuzz/corpus/{reader}: {len(list((out / reader).iterdir()))} files")


if __name__ == "__main__":
    main()

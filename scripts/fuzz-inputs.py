#!/usr/bin/env python3
"""Mutation fuzzing of artrace's readers through the command line.

Mutates the bundled inputs (the demo AFF scene, the glTF models, the AR scene JSON, an ONI file
converted from the bundled recording, the TUM folder itself and a PPM texture) and runs `artrace
info` on each mutant, and what uses it further: `render` and `bench-bart` the scene, `export` (three
frames) the AR scene and each model placed in one, `bench-io` the recording (every frame decoded),
`bench-bart` a scene textured with the PPM.
A clean error (exit status 1) or success passes; a signal, an exit status above 2 (give a
sanitizer build exit codes above 2) or a hang is a failure, and the mutant is kept.

    python3 scripts/fuzz-inputs.py --artrace build/tools/artrace --cases 200 --seed 1

With a sanitizer build (ARTRACE_SANITIZE=ON, tools on):
    ASAN_OPTIONS=exitcode=99:detect_leaks=0 UBSAN_OPTIONS=halt_on_error=1:exitcode=98 \\
        python3 scripts/fuzz-inputs.py --artrace build-asan/tools/artrace --cases 100
"""
import argparse
import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile

NUMBERS = ['0', '-1', '1e38', '-1e38', '3e38', 'nan', 'inf', '-inf', '4294967296', '2147483647', '-2147483648',
           '99999999999', '1e-45', '0.5', '65536', '1e300', '-0', '7', '100000000']
NUMBER = re.compile(r'-?\d+(\.\d+)?([eE][-+]?\d+)?')
MUTANT = 'fuzz-mutant'  # a mutant's name, next to its source, with the source's extension


def mutate_text(s, rng):
    """Numbers replaced by extreme ones, a line dropped or repeated, a cut, or bytes overwritten."""
    kind = rng.randrange(7)
    if kind <= 2:
        for _ in range(rng.randint(1, 3)):
            found = list(NUMBER.finditer(s))
            if not found:
                break
            m = rng.choice(found)
            s = s[:m.start()] + rng.choice(NUMBERS) + s[m.end():]
        return s
    lines = s.split('\n')
    if kind == 3 and len(lines) > 1:
        del lines[rng.randrange(len(lines))]
    elif kind == 4:
        lines.insert(rng.randrange(len(lines)), rng.choice(lines))
    elif kind == 5:
        return s[:rng.randrange(len(s) + 1)]
    else:
        b = bytearray(s.encode('latin1'))
        for _ in range(rng.randint(1, 4)):
            if b:
                b[rng.randrange(len(b))] = rng.randrange(256)
        return b.decode('latin1')
    return '\n'.join(lines)


def mutate_binary(data, rng, hot):
    """A cut, or bytes, 32-bit words or bits overwritten, mostly in the first `hot` bytes."""
    b = bytearray(data)
    if not b:
        return bytes(b)
    kind = rng.randrange(4)
    if kind == 0:
        return bytes(b[:rng.randrange(len(b) + 1)])
    for _ in range(rng.randint(1, 4)):
        at = rng.randrange(min(len(b), hot)) if rng.random() < 0.8 else rng.randrange(len(b))
        if kind == 1:
            b[at] = rng.randrange(256)
        elif kind == 2:
            word = rng.choice([0, 0xffffffff, 0x7fffffff, 0x80000000, 1, 2, 0x10000, rng.randrange(1 << 32)])
            b[at:at + 4] = word.to_bytes(4, 'little')
        else:
            b[at] ^= 1 << rng.randrange(8)
    return bytes(b)


class Runner:
    def __init__(self, artrace, keep):
        self.artrace, self.keep, self.failures, self.runs = artrace, keep, 0, 0

    def run(self, args, mutant, label):
        """Runs artrace with `args`; on a failure copies `mutant` (file or folder) into the keep folder."""
        self.runs += 1
        try:
            p = subprocess.run([self.artrace] + args, capture_output=True, timeout=60)
            status, message = p.returncode, p.stderr.decode('latin1').strip().split('\n')[-1][:200]
        except subprocess.TimeoutExpired:
            status, message = 'timeout', ''
        if status == 'timeout' or status < 0 or status > 2:
            self.failures += 1
            os.makedirs(self.keep, exist_ok=True)
            kept = os.path.join(self.keep, '%s-%d%s' % (label, self.failures, os.path.splitext(mutant)[1]))
            (shutil.copytree if os.path.isdir(mutant) else shutil.copy)(mutant, kept)
            print('FAIL %s: %s %s (%s)' % (status, ' '.join(args[:1]), kept, message), flush=True)


def fuzz_file(runner, rng, source, binary, cases, commands):
    """Each mutant of `source` through each of `commands` ('{}' stands for the mutant's path)."""
    data = open(source, 'rb').read()
    # next to the source, so that relative references (models, recordings) still resolve
    mutant = os.path.join(os.path.dirname(source), MUTANT + os.path.splitext(source)[1])
    try:
        for _ in range(cases):
            out = mutate_binary(data, rng, 65536) if binary else mutate_text(data.decode('latin1'), rng).encode('latin1')
            open(mutant, 'wb').write(out)
            for command in commands:
                runner.run([mutant if a == '{}' else a for a in command], mutant, os.path.basename(source))
    finally:
        os.remove(mutant)


def model_scene(model, work):
    """An AR scene placing the mutant of `model` (where fuzz_file writes it) in the room, playing its first clip."""
    gltf = json.load(open(model))
    entry = {'file': os.path.join(os.path.dirname(model), MUTANT + '.gltf'), 'position': [0.1, 0.7, 0.0]}
    if gltf.get('animations'):
        entry['animation'] = {'clip': gltf['animations'][0].get('name', ''), 'speed': 1.0}
    path = os.path.join(work, os.path.basename(model) + '.json')
    json.dump({'models': [entry], 'lights': [{'position': [1.5, 2.8, 1.0], 'color': [1, 1, 1]}]}, open(path, 'w'))
    return path


def fuzz_tum(runner, rng, source, cases, work):
    folder = os.path.join(work, 'tum')
    for _ in range(cases):
        shutil.rmtree(folder, ignore_errors=True)
        shutil.copytree(source, folder)
        what = rng.choice(['rgb.txt', 'depth.txt', 'groundtruth.txt', 'intrinsics.txt', 'image', 'image', 'delete'])
        if what in ('image', 'delete'):
            sub = rng.choice(['rgb', 'depth'])
            path = os.path.join(folder, sub, rng.choice(sorted(os.listdir(os.path.join(folder, sub)))))
            if what == 'delete':
                os.remove(path)
            else:
                open(path, 'wb').write(mutate_binary(open(path, 'rb').read(), rng, 256))
        else:
            path = os.path.join(folder, what)
            open(path, 'wb').write(mutate_text(open(path, 'rb').read().decode('latin1'), rng).encode('latin1'))
        runner.run(['info', folder], folder, 'tum')
        runner.run(['bench-io', folder], folder, 'tum')


def fuzz_texture(runner, rng, cases, work):
    """A one-triangle AFF scene whose texture is mutated; bench-bart loads and samples it."""
    scene = os.path.join(work, 'textured')
    os.makedirs(os.path.join(scene, 'aff'), exist_ok=True)
    os.makedirs(os.path.join(scene, 'TextureFiles'), exist_ok=True)
    with open(os.path.join(scene, 'aff', 'scene.aff'), 'w') as f:
        f.write('v\nfrom 0 0 3\nat 0 0 0\nup 0 1 0\nangle 45\nhither 0.01\nresolution 16 16\nb 0 0 0\n'
                'l 0 2 3 1 1 1\nf 1 1 1 0.8 0 0 1 0\ntt tex.ppm\n-1 -1 0 0 0\n1 -1 0 1 0\n0 1 0 0.5 1\n')
    texels = bytes((x * 16 + y * 3) % 256 for y in range(16) for x in range(16 * 3))
    original = b'P6\n16 16\n255\n' + texels
    texture = os.path.join(scene, 'TextureFiles', 'tex.ppm')
    for _ in range(cases):
        if rng.random() < 0.5:
            header = len(b'P6\n16 16\n255\n')
            mutant = mutate_text(original[:header].decode('latin1'), rng).encode('latin1') + original[header:]
        else:
            mutant = mutate_binary(original, rng, 32)
        open(texture, 'wb').write(mutant)
        runner.run(['bench-bart', '--scene', os.path.join(scene, 'aff', 'scene.aff'), '--frames', '1', '--width', '16',
                    '--height', '16', '-q'], texture, 'texture')


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--artrace', default=os.path.join(root, 'build', 'tools', 'artrace'))
    ap.add_argument('--cases', type=int, default=100, help='mutants per input')
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--keep', default='fuzz-failures', help='folder for the mutants that failed')
    opt = ap.parse_args()
    rng = random.Random(opt.seed)
    runner = Runner(os.path.abspath(opt.artrace), opt.keep)
    data = os.path.join(root, 'data')
    with tempfile.TemporaryDirectory() as work:
        room = os.path.join(data, 'recordings', 'room')
        oni = os.path.join(work, 'room.oni')
        subprocess.run([runner.artrace, 'convert', room, '-o', oni], check=True, capture_output=True)
        frames = os.path.join(work, 'frames')  # export: three frames to PNG
        export = ['export', room, '-o', frames, '--last', '2', '-q', '--scene']
        fuzz_file(runner, rng, os.path.join(data, 'scenes', 'room.aff'), False, opt.cases,
                  [['info', '{}'], ['render', '{}', '--width', '32', '--height', '24', '-o', os.path.join(work, 'r.png')],
                   ['bench-bart', '--scene', '{}', '--frames', '3', '--width', '24', '--height', '16', '-q']])
        fuzz_file(runner, rng, os.path.join(data, 'ar', 'demo.json'), False, opt.cases, [['info', '{}'], export + ['{}']])
        for name in sorted(os.listdir(os.path.join(data, 'models'))):
            model = os.path.join(data, 'models', name)
            fuzz_file(runner, rng, model, False, opt.cases, [['info', '{}'], export + [model_scene(model, work)]])
        fuzz_file(runner, rng, oni, True, opt.cases, [['info', '{}']])
        fuzz_tum(runner, rng, room, opt.cases, work)
        fuzz_texture(runner, rng, opt.cases, work)
    print('%d runs, %d failures%s' % (runner.runs, runner.failures, ' (kept in %s)' % opt.keep if runner.failures else ''))
    return 1 if runner.failures else 0


if __name__ == '__main__':
    sys.exit(main())

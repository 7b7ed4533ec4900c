#!/usr/bin/env python3
"""Splits a ray file (`mipray export --rays`) by class and by bounce: first bounce or later.

A frame's shadow, mirror and glass rays are of two kinds that trace very differently:
those leaving the surfaces the camera sees (a tile's first bounce: neighbouring hits, so
coherent packets) and those leaving later bounces (scattered). The ray file records no
depth, so a secondary ray counts as first-bounce when its origin lies within `--tolerance`
(relative to the primary ray's hit distance) of its pixel's primary hit point (one sample
a pixel, as `export --rays` writes); every other secondary ray is a later bounce.

Writes one ray file per non-empty part into OUT_DIR (nothing else):
`primary.bin`, `shadow_first.bin`, `shadow_later.bin`, `reflection_first.bin`, ... each in
the same format, rays in the file's order, so that `mipray bench SCENE --frames F --rays
PART.bin` and Embree's anchor (`embree_ray_file.c` in this folder) trace exactly the same
rays. Prints the count of each part and, for shadow rays, the share blocked.

Usage: tools/anchors/split_ray_file.py rays_0400.bin OUT_DIR [--tolerance 1e-3]
Needs only Python 3's standard library.
"""

import argparse
import math
import os
import struct
import sys

MAGIC = b"MIPRAYS1"
RECORD = struct.Struct("<8f3If")
CLASSES = ["primary", "shadow", "reflection", "refraction"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rays", help="a ray file written by `mipray export --rays`")
    parser.add_argument("out", help="the folder the parts are written into")
    parser.add_argument("--tolerance", type=float, default=1e-3,
                        help="first bounce: origin within this fraction of the primary hit "
                             "distance of the pixel's primary hit point")
    args = parser.parse_args()
    with open(args.rays, "rb") as f:
        data = f.read()
    if len(data) < 16 or data[:8] != MAGIC:
        sys.exit(f"{args.rays}: not a ray file (no {MAGIC.decode()} header)")
    (count,) = struct.unpack_from("<Q", data, 8)
    if len(data) != 16 + count * RECORD.size:
        sys.exit(f"{args.rays}: header says {count} rays, the file holds "
                 f"{(len(data) - 16) / RECORD.size:.1f}")
    records = data[16:]

    # Each pixel's primary hit point and distance (pixels without a hit stay absent).
    hit_of = {}
    for rec in RECORD.iter_unpack(records):
        ox, oy, oz, dx, dy, dz, _tmin, _tmax, cls, pixel, result, t = rec
        if cls == 0 and result != 0xFFFFFFFF and math.isfinite(t):
            hit_of[pixel] = ((ox + dx * t, oy + dy * t, oz + dz * t), t)

    parts = {}
    for k, rec in enumerate(RECORD.iter_unpack(records)):
        ox, oy, oz = rec[0:3]
        cls, pixel, result = rec[8], rec[9], rec[10]
        if cls >= len(CLASSES):
            sys.exit(f"{args.rays}: ray {k} has class {cls} (0 to 3 expected)")
        name = CLASSES[cls]
        if cls != 0:
            first = False
            if pixel in hit_of:
                (hx, hy, hz), t = hit_of[pixel]
                gap = math.dist((ox, oy, oz), (hx, hy, hz))
                first = gap <= args.tolerance * max(t, 1e-30)
            name += "_first" if first else "_later"
        parts.setdefault(name, []).append((k, result))

    os.makedirs(args.out, exist_ok=True)
    for name in sorted(parts):
        rows = parts[name]
        path = os.path.join(args.out, f"{name}.bin")
        with open(path, "wb") as f:
            f.write(MAGIC + struct.pack("<Q", len(rows)))
            for k, _ in rows:
                f.write(records[k * RECORD.size:(k + 1) * RECORD.size])
        line = f"{name}: {len(rows)} rays -> {path}"
        if name.startswith("shadow"):
            blocked = sum(1 for _, result in rows if result == 1)
            line += f" ({100 * blocked / len(rows):.1f}% blocked)"
        print(line)


if __name__ == "__main__":
    main()

#!/usr/bin/env bash
# Instructions a ray, mipray against Embree 3 on the same recorded rays, class by class.
#
# usage (from the project root, after `cargo build --release`):
#   tools/anchors/instructions_side_by_side.sh SCENE FRAME WxH [LIGHTS]
#   e.g. tools/anchors/instructions_side_by_side.sh ../shared/bart/kitchen/aff/kitchen.aff 400 800x600 1
# needs: apt-get install -y valgrind libembree-dev; MIPRAY=path overrides the binary.
#
# Why: on a shared VM the time of a kernel spreads by a third between runs, its instruction
# count does not. `valgrind --tool=cachegrind` counts every instruction a process executes;
# each side runs once with 1 repetition of its tracing and once with 3, and the difference
# over twice the class's rays is what one more pass over the rays costs: loading, building
# and everything else that does not repeat cancels.
#   mipray: `mipray bench SCENE --rays CLASS_FILE --api packets --threads 1 --min-sample-ms 0`
#     (one pass a repetition; the packets the film traces: primary rays by tile, shadow rays
#     by light, bounce rays in spawn order), on a file holding that class's rays alone.
#   Embree: `embree_ray_file ... REPS BUILD:CLASS:API` (this folder) with the build and API
#     that were fastest for the class in a timed run just before (refittable or static
#     high-quality build; single rays or 4-, 8-, 16-wide packets).
# Both binaries are counted in their AVX2 copies: valgrind does not run AVX-512, and both
# choose their SIMD copy from what the CPU reports (Embree's verbose mode prints AVX2 under
# valgrind). Each count includes its harness (copying the rays into packets, checking the
# answers): Embree's, the anchor's own functions (`main` and its tracing loops), is printed
# apart; mipray's loop is inlined into functions shared with other code (23-41 instructions
# a ray in a first count by function on BART Kitchen).
# Takes 10-20 minutes on a BART frame at 800x600 (valgrind runs 30-60x slower).
set -euo pipefail
[ $# -ge 3 ] || { sed -n '4,6p' "$0" >&2; exit 2; }
scene=$1; frame=$2; size=$3; lights=${4:-1}
here=$(cd "$(dirname "$0")" && pwd)
bin=${MIPRAY:-target/release/mipray}
[ -x "$bin" ] || { echo "no $bin: run cargo build --release first (or set MIPRAY)" >&2; exit 2; }
command -v valgrind >/dev/null || { echo "needs valgrind: apt-get install -y valgrind" >&2; exit 2; }
work=${TMPDIR:-/tmp}/mipray-instructions; mkdir -p "$work"
anchor="$work/embree_ray_file_avx2"
if [ ! -x "$anchor" ] || [ "$here/embree_ray_file.c" -nt "$anchor" ]; then
  # x86-64-v3 (AVX2, no AVX-512): valgrind cannot run AVX-512 instructions.
  cc -O3 -march=x86-64-v3 -o "$anchor" "$here/embree_ray_file.c" -lembree3 -lm \
    || { echo "cannot build the Embree anchor: apt-get install -y libembree-dev" >&2; exit 2; }
fi
ex="$work/rays-$$"; rm -rf "$ex"; trap 'rm -rf "$ex"' EXIT
"$bin" export "$scene" --frames "$frame" --size "$size" --lights "$lights" --rays --out "$ex" >/dev/null \
  || { echo "mipray export failed (its message is above)" >&2; exit 1; }
obj=$(ls "$ex"/frame_*.obj | head -1); rays=$(ls "$ex"/rays_*.bin | head -1)
width=${size%x*}
# One file per class (same header, the class's records in file order).
python3 - "$rays" "$ex" <<'PY'
import struct, sys
data = open(sys.argv[1], "rb").read()
count = struct.unpack_from("<Q", data, 8)[0]
for cls, name in enumerate(["primary", "shadow", "reflection", "refraction"]):
    records = [data[16 + 48 * i:16 + 48 * (i + 1)] for i in range(count)
               if struct.unpack_from("<I", data, 16 + 48 * i + 32)[0] == cls]
    if records:
        with open(f"{sys.argv[2]}/class_{name}.bin", "wb") as f:
            f.write(data[:8] + struct.pack("<Q", len(records)) + b"".join(records))
PY
# Embree's fastest build and API per class, timed natively (3 repetitions, median).
"$anchor" "$obj" "$rays" "$width" 3 > "$ex/embree_timed.txt"
count_instructions() {  # NAME REPS COMMAND...
  local name=$1 reps=$2; shift 2
  valgrind --tool=cachegrind --cache-sim=no --cachegrind-out-file="$ex/$name.$reps.out" \
    "$@" > "$ex/$name.$reps.txt" 2> "$ex/$name.$reps.log" \
    || { echo "failed under valgrind: $*" >&2; cat "$ex/$name.$reps.log" >&2; exit 1; }
}
for file in "$ex"/class_*.bin; do
  class=$(basename "$file" .bin); class=${class#class_}
  best=$(awk -v c="$class" '$1 == "ray" && $3 == c && $2 != "robust" { if ($8 > m) { m = $8; k = $2 ":" $3 ":" $4 } } END { print k }' "$ex/embree_timed.txt")
  echo "$class: counting mipray packets and Embree $best" >&2
  for reps in 1 3; do
    count_instructions "mipray_$class" $reps "$bin" bench "$scene" --frames "$frame" --size "$size" \
      --lights "$lights" --rays "$file" --api packets --threads 1 --repeats $reps --min-sample-ms 0
    count_instructions "embree_$class" $reps "$anchor" "$obj" "$rays" "$width" $reps "$best"
  done
  echo "$best" > "$ex/embree_$class.best"
done
python3 - "$ex" "$scene" "$frame" "$size" "$lights" <<'PY'
import collections, glob, os, sys
ex, scene, frame, size, lights = sys.argv[1:6]

def per_function(path):
    """Instructions per function name in a cachegrind output file (every source file)."""
    counts, fn = collections.Counter(), None
    for line in open(path):
        if line.startswith("fn="):
            fn = line[3:].strip()
        elif line[:1].isdigit() and fn is not None:
            parts = line.split()
            if len(parts) >= 2:
                counts[fn] += int(parts[1])
    return counts

def per_ray(name, rays, harness):
    """Instructions of one more pass over the rays, a ray: all, and in `harness` functions."""
    one, three = per_function(f"{ex}/{name}.1.out"), per_function(f"{ex}/{name}.3.out")
    total = sum(three.values()) - sum(one.values())
    inside = sum(three[f] - one[f] for f in set(one) | set(three) if harness(f))
    return total / (2 * rays), inside / (2 * rays)

def rays_of(path):
    import struct
    return struct.unpack_from("<Q", open(path, "rb").read(16), 8)[0]

print(f"# instructions a ray (cachegrind, AVX2 copies): {scene} frame {frame} at {size}, {lights} light(s)")
print("| class | rays | mipray packets | Embree (build:API) | Embree | of which the anchor's loop | Embree / mipray |")
print("|---|---:|---:|---|---:|---:|---:|")
for cls in ["primary", "shadow", "reflection", "refraction"]:
    path = f"{ex}/class_{cls}.bin"
    if not os.path.exists(path):
        continue
    rays = rays_of(path)
    mipray, _ = per_ray(f"mipray_{cls}", rays, lambda f: False)
    anchor = {"main", "trace_api", "trace1", "trace4", "trace8", "trace16"}
    embree, loop = per_ray(f"embree_{cls}", rays, lambda f: f in anchor)
    best = open(f"{ex}/embree_{cls}.best").read().strip()
    build, _, api = best.split(":")
    print(f"| {cls} | {rays} | {mipray:.0f} | {build}:{api} | {embree:.0f} | {loop:.0f} | "
          f"{embree / mipray:.3f} |")
PY

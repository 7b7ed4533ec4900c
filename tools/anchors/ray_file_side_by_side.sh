#!/usr/bin/env bash
# Every class of ray a real frame traces, mipray against Embree 3 on the same rays, ONE thread.
#
# usage (from the project root, after `cargo build --release`):
#   tools/anchors/ray_file_side_by_side.sh SCENE FRAME WxH [LIGHTS] [ROUNDS]
#   e.g. tools/anchors/ray_file_side_by_side.sh ../shared/bart/kitchen/aff/kitchen.aff 400 800x600 1
# needs: apt-get install -y libembree-dev   (Debian's Embree 3.13); MIPRAY=path overrides the binary.
# EMBREE_CONFIG overrides Embree's device configuration (default "threads=1"); mipray's
# allocator maps large buffers in 2 MiB pages where the system has them (`mipray bench`
# prints how its memory was paged), and "threads=1,hugepages=1" gives Embree the same.
#
# `mipray export --rays` records the frame's rays (primary, shadow, reflection, refraction:
# every ray of a render at depth 5 with LIGHTS lights, default 1). Each round then runs
# `mipray bench --rays FILE --threads 1 --repeats 3` and `embree_ray_file` (this folder; 3
# repetitions of every build and API) on that file, alternately; on both sides a repetition
# is one pass over a class's rays, or passes back to back until 20 ms have gone by (only
# a class as small as Kitchen's glass rays takes more than one). Per class: mipray's fastest
# way (packets or single), Embree's single-ray API (rtcIntersect1/rtcOccluded1) and its best
# API (single, or 4/8/16-wide packets of the class's rays grouped by pixel block and bounce),
# each the best of its two builds (refittable, static high quality); figures are the median
# of a run's repetitions, then the median over rounds; the ratio is mipray / Embree best.
# Beside it, Embree's best API on the high-quality build in robust mode (RTC_SCENE_FLAG_ROBUST:
# robust traversal, no optimisation that loses accuracy), the Embree mode nearest mipray's
# padded boxes and watertight triangle test; it is not a candidate for "best".
# Each round also renders the frame whole (`mipray bench --methods paper --threads 1
# --max-depth 5 --repeats 3`: shaded, textured, the same rays) and the script prints its
# render time against the time the file's rays take on Embree's best API per class and on
# mipray's kernels (rays / Mrays/s, summed over the classes, medians over rounds): the whole
# frame's cost against tracing alone at Embree's best.
set -euo pipefail
[ $# -ge 3 ] || { sed -n '4,6p' "$0" >&2; exit 2; }
scene=$1; frame=$2; size=$3; lights=${4:-1}; rounds=${5:-3}
here=$(cd "$(dirname "$0")" && pwd)
bin=${MIPRAY:-target/release/mipray}
[ -x "$bin" ] || { echo "no $bin: run cargo build --release first (or set MIPRAY)" >&2; exit 2; }
work=${TMPDIR:-/tmp}/mipray-ray-file; mkdir -p "$work"
if [ ! -x "$work/embree_ray_file" ] || [ "$here/embree_ray_file.c" -nt "$work/embree_ray_file" ]; then
  cc -O3 -march=native -o "$work/embree_ray_file" "$here/embree_ray_file.c" -lembree3 -lm \
    || { echo "cannot build the Embree anchor: apt-get install -y libembree-dev" >&2; exit 2; }
fi
ex="$work/rays-$$"; rm -rf "$ex"; trap 'rm -rf "$ex"' EXIT
"$bin" export "$scene" --frames "$frame" --size "$size" --lights "$lights" --rays --out "$ex" >/dev/null 2>&1
obj=$(ls "$ex"/frame_*.obj | head -1); rays=$(ls "$ex"/rays_*.bin | head -1)
width=${size%x*}
for round in $(seq "$rounds"); do
  "$bin" bench "$scene" --frames "$frame" --size "$size" --lights "$lights" --rays "$rays" \
    --threads 1 --repeats 3 2>/dev/null > "$ex/mipray_$round.txt"
  "$work/embree_ray_file" "$obj" "$rays" "$width" 3 > "$ex/embree_$round.txt"
  "$bin" bench "$scene" --frames "$frame" --size "$size" --lights "$lights" --max-depth 5 \
    --methods paper --threads 1 --repeats 3 2>/dev/null > "$ex/frame_$round.txt"
done
python3 - "$ex" "$scene" "$frame" "$size" "$lights" "$rounds" <<'PY'
import statistics as st, sys
ex, scene, frame, size, lights, rounds = sys.argv[1:7]
rounds = int(rounds)
m = {}  # (class, api) -> medians over rounds, count, differing
e = {}  # (build, class, api) -> medians over rounds, count, hits, agree
for r in range(1, rounds + 1):
    for line in open(f"{ex}/mipray_{r}.txt"):
        f = [x.strip() for x in line.split("|")[1:-1]]
        if len(f) == 8 and f[0] in ("primary", "shadow", "reflection", "refraction"):
            d = m.setdefault((f[0], f[1]), {"med": [], "count": int(f[3]), "share": f[4], "differ": f[7]})
            d["med"].append(float(f[5]))
    for line in open(f"{ex}/embree_{r}.txt"):
        w = line.split()
        if w and w[0] == "ray":
            d = e.setdefault((w[1], w[2], w[3]), {"med": [], "rays": int(w[4]), "hits": int(w[5]), "agree": int(w[8])})
            d["med"].append(float(w[7]))
med = st.median
# The builds whose APIs compete for "Embree best". Robust mode is set beside them, not among
# them: it is the Embree mode whose accuracy is nearest mipray's (padded boxes, watertight
# triangle test).
BEST_BUILDS = ("refit", "high")
APIS = ("1", "4", "8", "16")
print(f"{scene} frame {frame} {size}, {lights} light(s), 1 thread, {rounds} rounds")
print("| class | rays | mipray (way) | Embree single (build) | Embree best (API/build) | mipray / E-single | mipray / E-best | Embree best, robust mode (API) | mipray / E-robust | answers equal to the file's (Embree) |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for cls in ("primary", "shadow", "reflection", "refraction"):
    mine = [(med(d["med"]), api, d) for (c, api), d in m.items() if c == cls]
    if not mine:
        continue
    mm, mapi, md = max(mine)
    single = max((med(e[(b, cls, "1")]["med"]), b) for b in BEST_BUILDS)
    best = max((med(e[(b, cls, a)]["med"]), f"{a}/{b}") for b in BEST_BUILDS for a in APIS)
    robust = max((med(e[("robust", cls, a)]["med"]), a) for a in APIS)
    agree = e[("refit", cls, "1")]
    print(f"| {cls} | {md['count']} | {mm:.3f} ({mapi}) | {single[0]:.3f} ({single[1]}) | {best[0]:.3f} ({best[1]}) "
          f"| {mm / single[0]:.3f} | {mm / best[0]:.3f} | {robust[0]:.3f} ({robust[1]}) | {mm / robust[0]:.3f} "
          f"| {100 * agree['agree'] / max(agree['rays'], 1):.3f}% |")
print("\nmipray answers differing from the file (must be 0):",
      {f"{c} {a}": d["differ"] for (c, a), d in m.items()})
print("\nEmbree, every API (median over rounds, Mrays/s):")
for cls in ("primary", "shadow", "reflection", "refraction"):
    for b in (*BEST_BUILDS, "robust"):
        if (b, cls, "1") in e:
            print(f"  {cls:10s} {b:6s} " + "  ".join(f"{a:>2s} {med(e[(b, cls, a)]['med']):7.3f}" for a in APIS))
print("\nmipray per round:", {f"{c} {a}": d["med"] for (c, a), d in m.items()})

# The whole frame against tracing its rays: per round, the shaded frame's render time, and the
# file's rays at that round's Embree best API per class and at mipray's best way per class.
frames, embree_ms, mipray_ms = [], [], []
for r in range(1, rounds + 1):
    for line in open(f"{ex}/frame_{r}.txt"):
        f = [x.strip() for x in line.split("|")[1:-1]]
        if len(f) == 8 and f[0] == "paper":
            frames.append(float(f[3]))
    best_e, best_m = {}, {}
    for line in open(f"{ex}/embree_{r}.txt"):
        w = line.split()
        if w and w[0] == "ray" and w[1] in BEST_BUILDS:
            best_e[w[2]] = max(best_e.get(w[2], 0.0), float(w[7]))
    for line in open(f"{ex}/mipray_{r}.txt"):
        f = [x.strip() for x in line.split("|")[1:-1]]
        if len(f) == 8 and f[0] in ("primary", "shadow", "reflection", "refraction"):
            best_m[f[0]] = max(best_m.get(f[0], 0.0), float(f[5]))
    counts = {c: d["count"] for (c, _), d in m.items()}
    embree_ms.append(sum(counts[c] / (best_e[c] * 1e3) for c in counts if best_e.get(c)))
    mipray_ms.append(sum(counts[c] / (best_m[c] * 1e3) for c in counts if best_m.get(c)))
if frames:
    fm, em, mm = med(frames), med(embree_ms), med(mipray_ms)
    print(f"\nwhole frame, shaded (mipray bench --methods paper, 1 thread): {fm:.1f} ms render "
          f"(rounds {', '.join(f'{x:.1f}' for x in frames)})")
    print(f"the file's rays at Embree's best API per class: {em:.1f} ms; on mipray's kernels: {mm:.1f} ms")
    print(f"frame / Embree's tracing: {fm / em:.2f} (target <= 1.5); mipray's tracing / Embree's: {mm / em:.2f}; "
          f"frame time outside tracing (frame - mipray's tracing): {fm - mm:.1f} ms")
PY

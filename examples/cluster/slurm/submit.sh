#!/usr/bin/env bash
# Render an animation on a Slurm cluster: queue one array task per shard (render.sbatch) and
# a merge job (merge.sbatch) that Slurm starts only once every shard has succeeded.
#
#   ./submit.sh                          # the settings below
#   MIPRAY_FRAMES=0..96 ./submit.sh      # any setting from the environment
#   ./submit.sh --partition=render       # extra arguments go to both sbatch calls
#
# Run it again after a failure or a cancellation: every shard renders with --resume, so the
# frames already finished are skipped and only the missing ones are rendered (the finished
# shards' tasks end within seconds). Keep MIPRAY_SHARDS and MIPRAY_FRAMES as they were:
# another split would start its shards' records afresh and render everything again.
#
# The folder MIPRAY_OUT must be on a file system every node sees (NFS, Lustre, BeeGFS...):
# each shard writes its frames there and its own stats.shard-I-of-N.jsonl beside them.
set -euo pipefail

# --- Settings (each one can be given in the environment instead) --------------------------
# The mipray binary on the compute nodes (a path, or a name on their PATH).
export MIPRAY="${MIPRAY:-mipray}"
# A scene file (.gltf, .glb, .aff, .obj), or a name in mipray's animations/ folder.
export MIPRAY_SCENE="${MIPRAY_SCENE:-default}"
# Frames A..B (B excluded), image size, and the shared output folder.
export MIPRAY_FRAMES="${MIPRAY_FRAMES:-0..480}"
export MIPRAY_SIZE="${MIPRAY_SIZE:-1280x720}"
export MIPRAY_OUT="${MIPRAY_OUT:-$HOME/renders/default}"
# Number of shards = array tasks. Each renders one contiguous block of the frames, so it
# refits its BVH from frame to frame; blocks differ in length by at most one frame.
export MIPRAY_SHARDS="${MIPRAY_SHARDS:-8}"
# ------------------------------------------------------------------------------------------

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
mkdir -p "$MIPRAY_OUT"

# --export=ALL hands the settings above to the jobs even where a site sets SBATCH_EXPORT.
# The array's indices are the shard indices (render.sbatch passes --shard INDEX/SHARDS).
array_job=$(sbatch --parsable --export=ALL "$@" \
  --array="0-$((MIPRAY_SHARDS - 1))" "$here/render.sbatch")
array_job=${array_job%%;*}   # --parsable prints "id;cluster" on multi-cluster sites

# afterok: the merge starts when every task of the array has exited 0. If one fails or is
# cancelled the dependency can never be met, and --kill-on-invalid-dep cancels the merge
# instead of leaving it pending forever (DependencyNeverSatisfied).
merge_job=$(sbatch --parsable --export=ALL "$@" \
  --dependency="afterok:${array_job}" --kill-on-invalid-dep=yes "$here/merge.sbatch")
merge_job=${merge_job%%;*}

echo "render: array job ${array_job} (shards 0-$((MIPRAY_SHARDS - 1)) of frames ${MIPRAY_FRAMES})"
echo "merge: job ${merge_job} (after every shard succeeded)"
echo "watch: squeue -j ${array_job},${merge_job}"

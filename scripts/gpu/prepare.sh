#!/usr/bin/env bash
# Run HERE (the 2-core dev machine) before a GPU session's device calls; docs/gpu.md says why and how.
#
# The H200 machine has torch 2.11, numpy, scipy, onnx, tqdm, lxml, ... but not MuJoCo, Warp, rsl_rl or trimesh,
# and it reaches no package registry. This downloads those as cp312 manylinux wheels, adds the G1 model's MJCF
# files (the simulation strips visual meshes, so the 35 MB of mesh assets are not needed), packs everything into
# one archive and splits it into parts of PART_MB under .gpu/p1, .gpu/p2, ... (git-ignored), one part per
# device call: a call carries at most 64 MiB, the working tree included.
#
#   MENAGERIE_ROOT=../shared/menagerie bash scripts/gpu/prepare.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
: "${MENAGERIE_ROOT:?set MENAGERIE_ROOT to a folder holding unitree_g1/}"
PART_MB="${PART_MB:-56}"
stage=.gpu/stage
rm -rf .gpu && mkdir -p "$stage/whl" "$stage/menagerie/unitree_g1"

# setup.py's pins and what the benches and CUDA tests import (not mujoco-studio and pyopengl: rendering only,
# and 16 MB that would need a fourth call)
pkgs=(mujoco==4.0.0 mujoco-core==4.0.0 mujoco-warp==4.0.0 warp-lang==1.19.0 rsl-rl-lib==5.5.1
  glfw tensordict pyvers gitpython gitdb smmap trimesh rtree mujoco-menagerie)
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_24_x86_64 \
  --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 --platform manylinux1_x86_64 \
  -d "$stage/whl" "${pkgs[@]}"
cp "$MENAGERIE_ROOT"/unitree_g1/*.xml "$stage/menagerie/unitree_g1/"

tar -C "$stage" -cf .gpu/payload.tar whl menagerie
rm -rf "$stage"
split -b "${PART_MB}m" -d -a 1 .gpu/payload.tar .gpu/part.
rm .gpu/payload.tar
k=0
for f in .gpu/part.*; do
  k=$((k + 1))
  mkdir -p ".gpu/p$k" && mv "$f" ".gpu/p$k/"
done
tracked=$(git ls-files -z | xargs -0 du -cb 2>/dev/null | tail -1 | cut -f1)
echo "payload: $k parts of <= ${PART_MB} MB in .gpu/p1 .. .gpu/p$k"
echo "tracked files: $((tracked / 1048576)) MiB (each call sends them: see docs/gpu.md for keeping checkpoints/ home)"

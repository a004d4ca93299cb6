#!/usr/bin/env bash
# Run THERE (the lent GPU machine, in the repo root) as the last of the device calls of docs/gpu.md: unpacks the
# payload of scripts/gpu/prepare.sh, installs it beside the machine's own torch, then runs the CUDA checks and
# benchmarks, each under its own time limit, logging to $OUT (one file per step). A failed step is logged and
# the next one runs; the exit code is the number of failed steps.
#
#   bash scripts/gpu/check.sh            # all steps (about 6-8 minutes on an H200)
#   STEPS="tests fields" bash scripts/gpu/check.sh
set -uo pipefail
cd "$(dirname "$0")/../.."
OUT="${OUT:-/tmp/gpu_out}"
mkdir -p "$OUT" /tmp/gpu
export PYTHONUNBUFFERED=1 RERUN_ANALYTICS=0

if [ ! -d /tmp/gpu/whl ]; then
  ls .gpu/p*/part.* >/dev/null 2>&1 || { echo "no payload under .gpu/p*/ (run scripts/gpu/prepare.sh here first)"; exit 99; }
  cat $(ls .gpu/p*/part.* | sort -t . -k 3 -n) | tar -x -C /tmp/gpu || { echo "payload incomplete"; exit 99; }
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site /tmp/gpu/whl/*.whl \
    || { echo "wheel install failed"; exit 99; }
fi
export PYTHONPATH="/tmp/site:$PWD" MENAGERIE_ROOT=/tmp/gpu/menagerie

fails=0
step() {  # step NAME SECONDS COMMAND...
  local name=$1 limit=$2
  shift 2
  case " ${STEPS:-all} " in *" all "* | *" $name "*) ;; *) return ;; esac
  echo "== $name: $*"
  timeout "$limit" "$@" >"$OUT/$name.log" 2>&1
  local rc=$?
  tail -n 25 "$OUT/$name.log"
  echo "== $name: exit $rc"
  [ "$rc" -eq 0 ] || fails=$((fails + 1))
}

step info 60 bash -c 'nvidia-smi -L; python3 -c "import torch, warp, mujoco, mujoco_warp; \
print(\"torch\", torch.__version__, torch.cuda.get_device_name(0)); print(\"warp\", warp.__version__, \
warp.get_cuda_device_count(), \"cuda devices\"); print(\"mujoco\", mujoco.__version__)"'
# CUDA against CPU: bank query, warp envs with per-world scenes, and the backend parity suite on CUDA
step tests 360 env CAT_WARP_TEST_DEVICE=cuda:0 python3 -m pytest -q -p no:cacheprovider tests/test_cuda.py \
  tests/test_sim_parity.py tests/test_fields_bank.py tests/test_warp_slots.py
# issue 11's query target: 4096 envs x 13 links <= 2 ms (8 fields, then the 355-scene x 12-goal bank)
step fields 180 python3 scripts/bench.py fields --device cuda:0
step scale_query 300 python3 scripts/bench.py scale --device cuda:0 --no-env --physics-scenes 0
# mujoco_warp + CUDA graphs at training sizes
step sim 300 python3 scripts/bench.py sim --backends warp --device cuda:0 --envs 1024 4096 16384
# issue 11's ratio on the GPU path: 355 scenes, each world its own (geom slots), against flat, 1024 envs
step scale_env 420 python3 scripts/bench.py scale --device cuda:0 --sim warp --per-world --physics-scenes 0
# the same at 16k envs, where the flat task fills the GPU (2026-12-04: 1024 envs gave 0.72, the GPU far from full)
step scale_env16k 420 python3 scripts/bench.py scale --device cuda:0 --sim warp --per-world --physics-scenes 0 \
  --envs 16384
# issue 28 at GPU scale (docs/gpu.md, "Training on a lent GPU"): the scenes are built there (data/hybrid's command;
# its 2.9 GB do not travel), then PPO continues the best hybrid teacher (hybrid_starts' baseline arm, 30.5 M env
# steps) at 16k envs for TRAIN_MIN minutes in floor-only worlds with field-judged contact (one model for every
# world); the run folder lands in $OUT/train_hybrid. GPU_DEVICE / TRAIN_ENVS / TRAIN_MIN / HYBRID_SCENES shrink it
# for a check on the CPU (tests/test_gpu_scripts.py).
GPU_DEVICE="${GPU_DEVICE:-cuda:0}"
step hybrid_scenes 300 python3 scripts/gen_scenes.py out=/tmp/data/hybrid data=all typical_variants=0 \
  ${HYBRID_SCENES:-indoor=40 procedural=40} seed=0 field_dtype=float16
step train_hybrid 600 python3 scripts/train.py task=scenes init=checkpoints/hybrid_starts_baseline/model_406.pt \
  task.scene_dir=/tmp/data/hybrid task.episodes.mode=free algo.num_learning_epochs=5 sim=warp \
  sim.device="$GPU_DEVICE" sim.obstacles=field num_envs="${TRAIN_ENVS:-16384}" max_minutes="${TRAIN_MIN:-7}" \
  run_dir="$OUT/train_hybrid"
echo "failed steps: $fails"
exit "$fails"

#!/usr/bin/env bash
# The GPU checks and figures of docs/benchmarks.md ("GPU") in one timed run: the CUDA-only tests, then noise
# optimization's cost and suites, a whole reach-walk training to eval success, then the sampler, env and PPO
# benchmarks on CUDA, most important first. Each part has its own time limit and the
# whole run a budget (GPU_CHECK_BUDGET_S, default 480 s); a part that no longer fits is skipped and says so.
#
#   bash scripts/gpu_check.sh                    # figures and logs go to $OUT (default: gpu_check_out/)
#
# Optional: WHEELS=dir installs the wheels there first (pip --target, for a machine without an index);
# DART_SRC=dir (a zkf1997/DART tree) and DART_BENCH=path/to/dart_peer_bench.py add DART's own sampler on
# the same GPU, in fp32 and in fp16 (DART's GPU default), for same-run ratios.
set -uo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
OUT=${OUT:-gpu_check_out}
mkdir -p "$OUT"
LOG="$OUT/log.txt"
START=$(date +%s)
BUDGET=${GPU_CHECK_BUDGET_S:-500}
export PYTHONUNBUFFERED=1

if [ -n "${WHEELS:-}" ]; then
    "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/latentrl-site \
        "$WHEELS"/*.whl || exit 1
    export PYTHONPATH="/tmp/latentrl-site:${PYTHONPATH:-}"
fi
export PYTHONPATH="$PWD:${PYTHONPATH:-}"

# part NAME LIMIT_S COMMAND...: run COMMAND under the smaller of LIMIT_S and what is left of the budget
part() {
    local name=$1 limit=$2
    shift 2
    local left=$((BUDGET - ($(date +%s) - START)))
    if [ "$left" -lt 30 ]; then
        echo "=== $name: skipped (${left} s left of the ${BUDGET} s budget)" | tee -a "$LOG"
        return
    fi
    [ "$limit" -gt "$left" ] && limit=$left
    echo "=== $name (limit ${limit} s): $*" | tee -a "$LOG"
    local t0
    t0=$(date +%s)
    timeout "$limit" "$@" 2>&1 | tee -a "$LOG"
    echo "=== $name: exit ${PIPESTATUS[0]} after $(($(date +%s) - t0)) s" | tee -a "$LOG"
}

DART=()
if [ -n "${DART_SRC:-}" ]; then
    DART=(--dart-src "$DART_SRC" --dart-python "$PY")
    [ -n "${DART_BENCH:-}" ] && DART+=(--dart-bench "$DART_BENCH")
fi
LR=("$PY" -m latentrl)

part machine 60 bash -c "nvidia-smi -L; $PY -c 'import torch; print(torch.__version__, torch.version.cuda, \
torch.cuda.get_device_name(0), torch.cuda.get_device_properties(0).multi_processor_count, \"SMs\")'; nproc"
part optimize_cost 100 "${LR[@]}" bench optimize --device cuda --skip-suites --models default official \
    --cost-steps 10 --json "$OUT/optimize_cost.json"
part optimize_suites 110 "${LR[@]}" bench optimize --device cuda --models default --cost-steps 3 \
    --suites inbetween joint_targets --json "$OUT/optimize_suites.json"
part train_to_success 220 "${LR[@]}" bench train --config configs/policies/reach_walk_default.yaml --target 0.98 \
    --eval-every 4 --no-side-by-side --no-progress --set ppo.device=cuda --set env.num_envs=1024 \
    --set env.compile=true --set ppo.num_minibatches=16 --set ppo.total_steps=3000000 --json "$OUT/train_gpu.json"
part tests 110 "$PY" -m pytest -q -p no:cacheprovider -rA tests/gpu
part refine_eval 90 "${LR[@]}" eval reach_joint_default --paths pelvis_far --episodes 32 --device cuda \
    --no-render --no-motions --no-progress --out "$OUT/refine_eval"
part rollout 240 "${LR[@]}" bench rollout --models official default --device cuda --batches 1 16 256 1024 4096 \
    --amp bf16 fp16 --repeats 10 --rounds 3 "${DART[@]}" --json "$OUT/rollout.json"
part env 110 "${LR[@]}" bench env --models default official --device cuda --num-envs 1 256 4096 --amp bf16 \
    --steps 5 --max-seconds 40 --json "$OUT/env.json"
part env_compiled_default 120 "${LR[@]}" bench env --models default --device cuda --num-envs 1 256 --compile \
    --amp bf16 --no-baseline --steps 10 --json "$OUT/env_compiled_default.json"
part rollout_graph 150 "${LR[@]}" bench rollout --models official --device cuda --batches 1 256 --cuda-graph \
    --amp fp16 bf16 --repeats 10 --json "$OUT/rollout_graph.json"
part ppo 100 "${LR[@]}" bench train --skip-success --iterations 4 --set ppo.device=cuda --no-progress \
    --json "$OUT/train.json"
part env_compiled_official 90 "${LR[@]}" bench env --models official --device cuda --num-envs 1 --compile \
    --amp bf16 --no-baseline --steps 10 --json "$OUT/env_compiled_official.json"
part quick_training 200 "${LR[@]}" train configs/quick.yaml --device cuda --run-dir /tmp/latentrl-quick-cuda \
    --no-progress
echo "=== done after $(($(date +%s) - START)) s" | tee -a "$LOG"

#!/usr/bin/env bash
# Env steps/s of an earlier commit against the working tree, alternated in one run on the same machine:
# the check that a change leaves the RL env step as fast as before (same-run ratio after/before).
#
#   bash tools/ab_env_speed.sh d0be8c5 [ROUNDS]     # default 3 rounds; figures in ab-env/
set -euo pipefail
cd "$(dirname "$0")/.."
BASE=${1:?usage: tools/ab_env_speed.sh COMMIT [ROUNDS]}
ROUNDS=${2:-3}
PY=${PYTHON:-.venv/bin/python}
OUT=ab-env
OLD=$(mktemp -d)/before
git worktree add -q --detach "$OLD" "$BASE"
trap 'git worktree remove --force "$OLD"' EXIT
mkdir -p "$OUT"
for round in $(seq "$ROUNDS"); do
    for side in before after; do
        dir=$PWD; [ "$side" = before ] && dir=$OLD
        (cd "$dir" && OMP_NUM_THREADS=1 PYTHONPATH="$dir" "$OLDPWD/$PY" -m latentrl bench env --models default \
            --num-envs 1 64 --no-baseline --steps 40 --threads 1 --device cpu --json "$OLDPWD/$OUT/${side}_${round}.json" \
            >/dev/null)
    done
done
"$PY" - "$OUT" "$ROUNDS" <<'PY'
import json, statistics, sys
out, rounds = sys.argv[1], int(sys.argv[2])
rates = {}
for side in ("before", "after"):
    for r in range(1, rounds + 1):
        for res in json.load(open(f"{out}/{side}_{r}.json"))["models"]["default"]["results"]:
            rates.setdefault((side, res["num_envs"]), []).append(res["vector"]["env_steps_per_s"])
for n in sorted({k[1] for k in rates}):
    b, a = rates[("before", n)], rates[("after", n)]
    print(f"N={n}: before {[round(x, 1) for x in b]} after {[round(x, 1) for x in a]} env steps/s; "
          f"median after/before {statistics.median(a) / statistics.median(b):.3f}")
PY

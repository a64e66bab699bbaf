"""Ship a trained policy: export it to policies/<name>.pt and write its card policies/<name>.md.

    python tools/ship_policy.py RUN_DIR EVAL_DIR NAME --config CONFIG --text TEXT [--task LINE] [--notes FILE]
                                [--half]

RUN_DIR is a `latentrl train` run (its final.pt is exported without optimizer state); EVAL_DIR holds
the `latentrl eval` report of that final.pt on the skill's suite. The eval's ``paths.png`` is copied to
``docs/eval/NAME_paths.png``; ``--notes`` appends a markdown file (what was tried, what fell short).
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import torch
import yaml

from latentrl.evaluation.report import DART_TABLE4, results_table
from latentrl.evaluation.task_eval import results_table as task_results_table
from latentrl.motion.checkpoint import embedded_sha256
from latentrl.motion.rollout import LOCK_MIN_WEIGHT
from latentrl.ppo.checkpoint import export_policy
from latentrl.safe_io import save_torch_atomic
from latentrl.timing import hardware

ROOT = Path(__file__).resolve().parents[1]


def name_motion(policy: Path, name: str) -> None:
    """Store ``name`` as the policy's env motion when it names the very file the policy was trained on.

    A run trained with ``env.motion=default-v5`` ships as a ``*_default`` policy once v5 is the default: it then
    says "default", as its config does. Any other name is refused (the file would not be the one it learned on).
    """
    state = torch.load(policy, weights_only=True)
    if state["config"]["env"].get("motion") == name:
        return
    if embedded_sha256(name) != state["motion"]["sha256"]:
        raise SystemExit(f"--motion-name {name}: that embedded model is not the one {policy.name} was trained on")
    state["config"]["env"]["motion"] = name
    save_torch_atomic(state, policy)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("run_dir")
    ap.add_argument("eval_dir")
    ap.add_argument("name")
    ap.add_argument("--config", required=True)
    ap.add_argument("--text", required=True)
    ap.add_argument("--task", default="Reach goals", help="what the policy does, e.g. 'Follow joystick commands'")
    ap.add_argument("--notes", help="markdown file appended to the card")
    ap.add_argument("--motion-name", default="default", help="the embedded motion model it was trained on")
    ap.add_argument("--half", action="store_true", help="store the weight matrices in float16 (evaluate the copy)")
    args = ap.parse_args()
    run, ev = Path(args.run_dir), Path(args.eval_dir)
    state = torch.load(run / "final.pt", weights_only=True)
    out = export_policy(run / "final.pt", ROOT / "policies" / f"{args.name}.pt", half=args.half)
    name_motion(out, args.motion_name)
    report = json.loads((ev / "report.json").read_text())
    s = report["settings"]
    hw = hardware()
    ours = "default model" if args.motion_name == "default" else f"`{args.motion_name}` model"
    run_cfg = yaml.safe_load((run / "config.yaml").read_text())
    threads = run_cfg.get("threads", "?")
    trained_w = (run_cfg.get("env") or {}).get("foot_lock_min_weight", LOCK_MIN_WEIGHT)
    lock_flag = ("" if s.get("foot_lock_min_weight", trained_w) == trained_w
                 else f" --foot-lock-min-weight {s['foot_lock_min_weight']:g}")  # evaluated unlike it trained
    card = [
        f"# {args.name}",
        "",
        f"{args.task} with **\"{args.text}\"** on the embedded "
        + ("default motion model" if args.motion_name == "default" else f"motion model `{args.motion_name}`")
        + f" (`--motion {args.motion_name}`, "
        f"sha256 `{state['motion']['sha256'][:16]}`).",
        "",
        "| | |",
        "|---|---|",
        f"| file | `policies/{out.name}` ({out.stat().st_size / 1e6:.1f} MB, optimizer state stripped"
        + (", weight matrices in float16" if args.half else "") + ") |",
        f"| config | [`{args.config}`](../{args.config}) |",
        f"| reproduce | `latentrl train {args.config}` |",
        f"| trainer | {state['trainer']} PPO |",
        f"| iterations / env steps | {state['iteration']} / {state['env_steps']:,} primitives |",
        f"| wall time | {state['elapsed_s'] / 60:.0f} min on {hw['cpu']} ({hw['cpu_count']} cores, CPU only, "
        f"{threads} torch thread(s), other trainings sharing the machine) |",
    ]
    if str(report.get("format", "")).startswith("latentrl.eval.task"):  # joystick / timed evaluations
        files = " ".join(Path(suite["file"]).stem for suite in report["suites"])
        card += [
            f"| evaluation | `latentrl eval policies/{out.name} --paths {files} --episodes {s['episodes']}` "
            "(stochastic actions) |",
            "",
            "## Evaluation",
            "",
            *task_results_table(report),
            "",
            report.get("definitions", ""),
            "",
        ]
    else:
        card += [
            f"| evaluation | `latentrl eval policies/{out.name} --paths {' '.join(report['suites'])} "
            f"--episodes {s['episodes']} --max-steps {s['max_steps']}{lock_flag}` (stochastic actions, like DART) |",
            "",
            "## Evaluation",
            "",
            *results_table(report),
            "",
            "Reach time counts failed (timed-out) episodes at the budget time "
            f"({s['budget_s']:.1f} s); 'reach time, successes' averages successful episodes only, which is what "
            "DART's script reports."
            + (f" DART's row is its paper's Table 4, on its released BABEL model; ours runs on the {ours} trained on "
               "synthetic locomotion." if any(suite in DART_TABLE4 for suite in report["suites"]) else ""),
            "",
        ]
    plot = ev / "paths.png"
    if plot.is_file():
        target = ROOT / "docs" / "eval" / f"{args.name}_paths.png"
        shutil.copyfile(plot, target)
        card += [f"![{args.name} on its evaluation paths](../../docs/eval/{target.name})", ""]
    if args.notes:
        card += [Path(args.notes).read_text().rstrip(), ""]
    (ROOT / "policies" / f"{args.name}.md").write_text("\n".join(card))
    print(f"wrote {out} and policies/{args.name}.md")


if __name__ == "__main__":
    main()

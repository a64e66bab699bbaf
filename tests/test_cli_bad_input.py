"""Bad input through every CLI entry point: one clear stderr line each, exit code 2, and nothing left behind.

Each row is (argv, regex the single stderr line must match). The CLI runs in-process (``latentrl.cli.main``)
from an empty working directory; afterwards the working directory must still be empty and the fixture
folder (which holds the policy, so ``eval``'s default output folder would appear there) unchanged.
"""

import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from latentrl.app.cli import main
from latentrl.motion import save_motion_model
from latentrl.motion.text import TableTextEncoder
from tests.helpers import make_tiny_model

ROOT = Path(__file__).resolve().parents[1]
TINY = str(ROOT / "configs" / "tiny.yaml")
MTINY = str(ROOT / "configs" / "motion" / "tiny.yaml")
CUDA = torch.cuda.is_available()
MPS = torch.backends.mps.is_available()
LONG = "x" * 1001


class Evil:
    def __reduce__(self):
        return (exec, ("raise SystemExit('payload ran')",))



@pytest.fixture(scope="module")
def fx(tmp_path_factory) -> Path:
    """Every file the rows refer to, in one folder outside the working directory."""
    from latentrl.ppo.checkpoint import make_checkpoint, save_checkpoint
    from tests.evaluation.conftest import fresh_policy

    root = tmp_path_factory.mktemp("fixtures")
    model = make_tiny_model()
    motion = save_motion_model(model, root / "motion.pt")
    table_only = make_tiny_model()
    table_only.text_encoder = TableTextEncoder(dict(model.text_encoder.table), name="table")
    save_motion_model(table_only, root / "table.pt")
    save_motion_model(make_tiny_model(seed=1), root / "other.pt")
    from latentrl.motion.checkpoint import file_sha256

    policy = fresh_policy(model)
    state = make_checkpoint(trainer="native", iteration=0, env_steps=0, elapsed_s=0.0, policy=policy,
                            optimizer=torch.optim.Adam(policy.parameters()), config={"test": True},
                            motion={"path": str(motion), "sha256": file_sha256(motion)})
    data = save_checkpoint(state, root / "policy.pt").read_bytes()
    (root / "truncated.pt").write_bytes(data[: len(data) // 2])
    torch.save({"format": "latentrl.ppo/1", "policy": Evil()}, root / "evil.pt")
    (root / "junk.pt").write_bytes(b"\x00not a torch file" * 10)
    (root / "junk.npz").write_text("not an archive")
    np.savez(root / "badshape.npz", joints=np.zeros((5, 21, 3)))
    (root / "bad.yaml").write_text("env: [unclosed\n")
    (root / "list.yaml").write_text("- env\n- ppo\n")
    (root / "afile").write_text("a file where a folder is expected")
    (root / "empty.json").write_text("[]")
    (root / "badjson.json").write_text('[{"goal_location": ')
    (root / "typo.json").write_text(json.dumps([{"goal_locaton": [[0, 1, 0]], "goal_text": ["walk"]}]))
    n = 10_001
    (root / "huge.json").write_text(json.dumps([{"goal_location": [[0.0, 0.3 * i, 0.0] for i in range(n)],
                                                 "goal_text": ["walk"] * n}]))
    return root


# (id, argv, regex); {fx} is the fixture folder, {TINY}/{MTINY} the tiny PPO / motion configs, {LONG} 1001 chars
TRAIN = ["train", "{TINY}", "--set", "env.motion={fx}/motion.pt"]
SAMPLE = ["motion", "sample", "--motion", "{fx}/motion.pt"]
EVAL = ["eval", "{fx}/policy.pt", "--motion", "{fx}/motion.pt", "--episodes", "1", "--max-steps", "2"]
ROWS = [
    # ---------------------------------------------------------------- train: config files and overrides
    ("train-no-config", ["train"], r"give a CONFIG file \(e\.g\. configs/quick\.yaml\) or --resume RUN_DIR"),
    ("train-missing-config", ["train", "missing.yaml"], r"config file not found: missing\.yaml"),
    ("train-invalid-yaml", ["train", "{fx}/bad.yaml"], r"bad\.yaml: invalid YAML: "),
    ("train-yaml-not-mapping", ["train", "{fx}/list.yaml"],
     r"list\.yaml: expected a mapping of config fields, got list"),
    ("train-unknown-key", [*TRAIN, "--set", "env.num_envz=3"], r"env\.num_envz: .*Did you mean: 'num_envs'\?"),
    ("train-negative-lr", [*TRAIN, "--set", "ppo.learning_rate=-0.1"],
     r"tiny\.yaml: ppo\.learning_rate: must be > 0, got -0\.1"),
    ("train-zero-envs", [*TRAIN, "--set", "env.num_envs=0"], r"tiny\.yaml: env\.num_envs: must be >= 1, got 0"),
    ("train-batch-not-divisible", [*TRAIN, "--set", "ppo.num_minibatches=3"],
     r"tiny\.yaml: ppo\.num_minibatches: 3 does not divide the batch .* = 64; try 2"),
    ("train-wrong-type", [*TRAIN, "--set", "ppo.num_steps=abc"],
     r"ppo\.num_steps: Value 'abc' of type 'str' could not be converted to Integer"),
    ("train-wrong-bool", [*TRAIN, "--set", "ppo.anneal_lr=maybe"],
     r"ppo\.anneal_lr: Value 'maybe' is not a valid bool"),
    ("train-override-syntax", [*TRAIN, "--set", "ppo.learning_rate"],
     r"override 'ppo\.learning_rate': expected key=value"),
    ("train-bad-choice", [*TRAIN, "--set", "env.task=dance"],
     r"env\.task: expected one of \('reach', 'path'\), got 'dance'"),
    ("train-out-of-range", [*TRAIN, "--set", "ppo.gamma=1.5"], r"ppo\.gamma: must lie in \[0, 1\], got 1\.5"),
    ("train-no-prompts", [*TRAIN, "--set", "env.texts=[]"], r"env\.texts: give at least one prompt"),
    ("train-empty-prompt", [*TRAIN, "--set", "env.texts=['']"], r"env\.texts: prompt '' is empty"),
    ("train-huge-prompt", [*TRAIN, "--set", "env.texts=[{LONG}]"],
     r"env\.texts: .*has 1001 characters, more than the 1000"),
    ("train-unknown-reward", [*TRAIN, "--set", "env.reward_weights.skatee=1"],
     r"env\.reward_weights: unknown reward term 'skatee' \(did you mean 'skate'\?\)"),
    ("train-negative-threads", [*TRAIN, "--set", "threads=-1"], r"threads: must be >= 0"),
    ("train-zero-steps", [*TRAIN, "--total-steps", "0"], r"ppo\.total_steps: must be > 0, got 0"),
    ("train-bad-seed", [*TRAIN, "--seed", "abc"], r"latentrl train: error: argument --seed: invalid int value: 'abc'"),
    ("train-bad-trainer", [*TRAIN, "--trainer", "jax"], r"argument --trainer: invalid choice: 'jax'"),
    # ---------------------------------------------------------------- train: devices
    ("train-device-tpu", [*TRAIN, "--device", "tpu"], r"argument --device: unknown device 'tpu'; use 'cpu', 'cuda'"),
    ("train-device-cuda", [*TRAIN, "--device", "cuda"],
     r"argument --device: 'cuda' requested but CUDA is not available"),
    ("train-device-cuda7", [*TRAIN, "--device", "cuda:7"], r"argument --device: 'cuda:7' (requested|does not exist)"),
    ("train-device-mps", [*TRAIN, "--device", "mps"], r"argument --device: 'mps' requested but MPS is not available"),
    ("train-config-device", [*TRAIN, "--set", "ppo.device=cuda:1"],
     r"ppo\.device: 'cuda:1' (requested|does not exist)"),
    # ---------------------------------------------------------------- train: files it reads and writes
    ("train-missing-motion", ["train", "{TINY}", "--set", "env.motion=missing.pt"],
     r"motion model not found: missing\.pt \(expected 'default', a latentrl \.pt file"),
    ("train-junk-motion", ["train", "{TINY}", "--set", "env.motion={fx}/junk.pt"],
     r"junk\.pt: not a readable torch file \(corrupt or truncated\?\)"),
    ("train-evil-motion", ["train", "{TINY}", "--set", "env.motion={fx}/evil.pt"],
     r"evil\.pt: refused to load: the file holds Python objects"),
    ("train-unknown-prompt", ["train", "{TINY}", "--set", "env.motion={fx}/table.pt", "--set", "env.texts=[jog]"],
     r"unknown prompt 'jog': this model's text table knows 'hop on left leg', 'run', 'walk'"),
    ("train-missing-paths", [*TRAIN, "--set", "env.task=path", "--set", "env.paths=missing.json"],
     r"path file not found: missing\.json \(looked in "),
    ("train-empty-paths", [*TRAIN, "--set", "env.task=path", "--set", "env.paths={fx}/empty.json"],
     r"empty\.json: holds no paths"),
    ("train-huge-path", [*TRAIN, "--set", "env.task=path", "--set", "env.paths={fx}/huge.json"],
     r"huge\.json: path 0: 10001 waypoints, more than the 10000 a path may have"),
    ("train-missing-eval-paths", [*TRAIN, "--set", "ppo.eval_every=1", "--set", "eval.paths=[nowhere.json]"],
     r"path file not found: nowhere\.json"),
    ("train-resume-nothing", ["train", "--resume", "nowhere"], r"--resume nowhere: no config\.yaml there"),
    ("train-run-dir-is-file", [*TRAIN, "--run-dir", "{fx}/afile"],
     r"run directory .*afile exists and is not a directory"),
    ("train-run-dir-under-file", [*TRAIN, "--run-dir", "{fx}/afile/run"],
     r"run directory .*afile/run cannot be created: .*afile is a file"),
    # ---------------------------------------------------------------- quickstart
    ("quickstart-unknown-key", ["quickstart", "--set", "ppo.learning_rat=1"], r"Did you mean: 'learning_rate'\?"),
    ("quickstart-zero-episodes", ["quickstart", "--set", "env.motion={fx}/motion.pt", "--episodes", "0"],
     r"--episodes: must be >= 1, got 0"),
    ("quickstart-negative-max-steps", ["quickstart", "--set", "env.motion={fx}/motion.pt", "--max-steps", "-1"],
     r"--max-steps: must be >= 1, got -1"),
    ("quickstart-missing-motion", ["quickstart", "--set", "env.motion=nowhere.pt"], r"motion model not found: nowhere"),
    # ---------------------------------------------------------------- motion info / sample
    ("info-missing-model", ["motion", "info", "--motion", "missing.pt"], r"motion model not found: missing\.pt"),
    ("info-folder-without-model", ["motion", "info", "--motion", "{fx}"], r"folder holds no motion_model\.pt"),
    ("info-evil-model", ["motion", "info", "--motion", "{fx}/evil.pt"], r"evil\.pt: refused to load"),
    ("info-junk-seed-history", ["motion", "info", "--motion", "{fx}/motion.pt", "--seed-history", "{fx}/junk.npz"],
     r"junk\.npz: not a readable seed-history \.npz"),
    ("sample-zero-seconds", [*SAMPLE, "--seconds", "0"], r"--seconds must be in \(0, 3600\], got 0\.0"),
    ("sample-nan-seconds", [*SAMPLE, "--seconds", "nan"], r"--seconds must be in \(0, 3600\], got nan"),
    ("sample-zero-batch", [*SAMPLE, "--batch", "0"], r"--batch must be in \[1, 1024\], got 0"),
    ("sample-infinite-guidance", [*SAMPLE, "--guidance", "inf"], r"--guidance must be a finite number, got inf"),
    ("sample-empty-prompt", [*SAMPLE, "--text", ""], r"--text: prompt '' is empty"),
    ("sample-huge-prompt", [*SAMPLE, "--text", "{LONG}"], r"--text: prompt 'xxx.*' has 1001 characters"),
    ("sample-unknown-prompt", ["motion", "sample", "--motion", "{fx}/table.pt", "--text", "moonwalk"],
     r"unknown prompt 'moonwalk': this model's text table knows"),
    ("sample-device", [*SAMPLE, "--device", "cuda:7"], r"argument --device: 'cuda:7' (requested|does not exist)"),
    ("sample-out-suffix", [*SAMPLE, "--out", "motion.txt"], r"--out must name a \.npz file, got 'motion\.txt'"),
    ("sample-out-under-file", [*SAMPLE, "--out", "{fx}/afile/m.npz"],
     r"--out folder .*afile exists and is not a direc"),
    ("sample-render-suffix", [*SAMPLE, "--render", "m.mp4"], r"--render must name a \.gif file"),
    # ---------------------------------------------------------------- motion train / export-bvh
    ("motion-train-no-config", ["motion", "train"], r"give a CONFIG file \(e\.g\. configs/motion/default\.yaml\)"),
    ("motion-train-missing-config", ["motion", "train", "nowhere.yaml"], r"config file not found: nowhere\.yaml"),
    ("motion-train-unknown-key", ["motion", "train", "{MTINY}", "--set", "vae_train.stepz=1"],
     r"vae_train\.stepz: .*Did you mean: 'steps'\?"),
    ("motion-train-zero-log-every", ["motion", "train", "{MTINY}", "--set", "log_every=0"],
     r"tiny\.yaml: log_every: must be > 0, got 0"),
    ("motion-train-negative-lr", ["motion", "train", "{MTINY}", "--set", "vae_train.learning_rate=-1"],
     r"vae_train\.learning_rate: must be > 0"),
    ("motion-train-clip-dim", ["motion", "train", "{MTINY}", "--set", "text_encoder=hashed-bow-32"],
     r"model\.denoiser\.clip_dim: is 64 but text encoder 'hashed-bow-32' gives 32 dims"),
    ("motion-train-missing-data", ["motion", "train", "{MTINY}", "--set", "data.source=nowhere"],
     r"data\.source: folder not found: nowhere"),
    ("motion-train-device", ["motion", "train", "{MTINY}", "--set", "device=cuda:7"],
     r"device: 'cuda:7' (requested|does)"),
    ("motion-train-resume-nothing", ["motion", "train", "--resume", "nowhere"], r"--resume nowhere: no config\.yaml"),
    ("export-bvh-missing", ["motion", "export-bvh", "missing.npz"], r"motion file not found: missing\.npz"),
    ("export-bvh-junk", ["motion", "export-bvh", "{fx}/junk.npz"], r"junk\.npz: not a readable motion \.npz"),
    ("export-bvh-bad-shape", ["motion", "export-bvh", "{fx}/badshape.npz"],
     r"badshape\.npz: field 'joints' must be \(T, 22, 3\), got \(5, 21, 3\)"),
    # ---------------------------------------------------------------- eval / compare
    ("eval-missing-policy", ["eval", "missing.pt", "--motion", "{fx}/motion.pt", "--paths", "dart_demo_walk"],
     r"PPO checkpoint file not found: missing\.pt"),
    ("eval-evil-policy", ["eval", "{fx}/evil.pt", "--motion", "{fx}/motion.pt", "--paths", "dart_demo_walk"],
     r"evil\.pt: refused to load"),
    ("eval-truncated-policy", ["eval", "{fx}/truncated.pt", "--motion", "{fx}/motion.pt", "--paths", "dart_demo_walk"],
     r"truncated\.pt: not a readable torch file \(corrupt or truncated\?\)"),
    ("eval-motion-as-policy", ["eval", "{fx}/motion.pt", "--motion", "{fx}/motion.pt", "--paths", "dart_demo_walk"],
     r"motion\.pt: not a latentrl PPO checkpoint \(format 'latentrl\.motion_model'"),
    ("eval-other-motion", ["eval", "{fx}/policy.pt", "--motion", "{fx}/other.pt", "--paths", "dart_demo_walk"],
     r"policy was trained on motion model .* \(--allow-motion-mismatch\)"),
    ("eval-zero-episodes", [*EVAL, "--episodes", "0"], r"--episodes: must be >= 1, got 0"),
    ("eval-negative-max-steps", [*EVAL, "--max-steps", "-1"], r"--max-steps: must be >= 1, got -1"),
    ("eval-negative-render", [*EVAL, "--render", "-1"], r"--render must be >= 0, got -1"),
    ("eval-device", [*EVAL, "--device", "tpu"], r"argument --device: unknown device 'tpu'"),
    ("eval-missing-suite", [*EVAL, "--paths", "nowhere"],
     r"path file not found: nowhere \(give a file, or one of the suites"),
    ("eval-empty-paths", [*EVAL, "--paths", "{fx}/empty.json"], r"empty\.json: holds no paths"),
    ("eval-invalid-json", [*EVAL, "--paths", "{fx}/badjson.json"], r"badjson\.json: invalid JSON: "),
    ("eval-field-typo", [*EVAL, "--paths", "{fx}/typo.json"],
     r"typo\.json: path 0: unknown field 'goal_locaton' \(did you mean 'goal_location'\?\)"),
    ("eval-huge-path", [*EVAL, "--paths", "{fx}/huge.json"], r"10001 waypoints, more than the 10000"),
    ("eval-out-is-file", [*EVAL, "--paths", "dart_demo_walk", "--out", "{fx}/afile"],
     r"--out .*afile exists and is not a"),
    ("compare-missing", ["compare", "missing.json"], r"report not found: missing\.json"),
    ("compare-junk", ["compare", "{fx}/junk.pt"], r"junk\.pt: not a JSON report"),
    ("compare-out-is-folder", ["compare", "missing.json", "--out", "{fx}"],
     r"--out .* is a directory; give a file name"),
    # ---------------------------------------------------------------- bench and the top level
    ("bench-no-benchmark", ["bench"], r"latentrl bench: error: the following arguments are required: BENCHMARK"),
    ("bench-unknown", ["bench", "speed"], r"argument BENCHMARK: invalid choice: 'speed'"),
    ("bench-motion-zero-batch", ["bench", "motion", "--batch", "0"], r"argument --batch: must be > 0, got 0"),
    ("bench-motion-negative-seconds", ["bench", "motion", "--seconds", "-1"],
     r"argument --seconds: must be > 0, got -1"),
    ("bench-motion-missing-model", ["bench", "motion", "--motion", "missing.pt"],
     r"motion model not found: missing\.pt"),
    ("bench-rollout-device", ["bench", "rollout", "--device", "cpu", "tpu"],
     r"argument --device: unknown device 'tpu'"),
    ("bench-env-zero-envs", ["bench", "env", "--num-envs", "64", "0"], r"argument --num-envs: must be > 0, got 0"),
    ("bench-env-steps-type", ["bench", "env", "--steps", "many"], r"argument --steps: expected an integer, got 'many'"),
    ("bench-train-target", ["bench", "train", "--target", "1.5"], r"argument --target: must lie in \(0, 1\], got 1\.5"),
    ("no-command", [], r"latentrl: error: the following arguments are required: COMMAND"),
    ("unknown-command", ["fly"], r"argument COMMAND: invalid choice: 'fly'"),
]
SKIP = {"train-device-cuda": CUDA, "train-device-mps": MPS}


def tree(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_size if p.is_file() else -1 for p in folder.rglob("*")}


@pytest.mark.parametrize(("argv", "pattern"), [pytest.param(a, p, id=i) for i, a, p in ROWS])
def test_bad_input_gets_one_clear_line_exit_2_and_leaves_nothing(argv, pattern, fx, tmp_path, monkeypatch, capsys,
                                                                  request):
    if SKIP.get(request.node.callspec.id):
        pytest.skip("this machine has the device")
    work = tmp_path / "cwd"
    work.mkdir()
    monkeypatch.chdir(work)
    before = tree(fx)
    values = {"fx": fx, "TINY": TINY, "MTINY": MTINY, "LONG": LONG}
    code = main([a.format(**values) for a in argv])
    out = capsys.readouterr()
    assert code == 2, out.err
    assert out.err.endswith("\n") and out.err.count("\n") == 1, f"not one line: {out.err!r}"
    assert out.err.startswith("latentrl") and " error: " in out.err and "Traceback" not in out.err
    assert re.search(pattern, out.err), f"{pattern!r} not in {out.err!r}"
    assert tree(work) == {}, "left files in the working directory"
    assert tree(fx) == before, "changed the fixture folder"


def test_every_command_is_covered_and_rows_are_distinct():
    assert len(ROWS) >= 40 and len({i for i, _, _ in ROWS}) == len(ROWS)
    assert len({tuple(a) for _, a, _ in ROWS}) == len(ROWS)
    commands = {" ".join(a[:2]) if a and a[0] in ("motion", "bench") else (a[0] if a else "") for _, a, _ in ROWS}
    assert {"train", "quickstart", "eval", "compare", "motion info", "motion sample", "motion train",
            "motion export-bvh", "bench motion", "bench env", "bench rollout", "bench train"} <= commands


def test_debug_shows_the_traceback_instead(fx, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    from latentrl.errors import ConfigError

    with pytest.raises(ConfigError, match="config file not found"):
        main(["--debug", "train", "missing.yaml"])

"""Bad input through every CLI entry point: one clear stderr line each, exit code 2, and nothing left behind.

Each row is (argv, regex the single stderr line must match). The CLI runs in-process (``latentrl.cli.main``)
from an empty working directory; afterwards the working directory must still be empty and the fixture
folder (which holds the policy, so ``eval``'s default output folder would appear there) unchanged.
"""

import copy
import importlib.util
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
MUJOCO = importlib.util.find_spec("mujoco") is not None
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
    _round2_files(root, state)
    _round3_files(root)
    _round3_late_files(root, model, motion)
    _security_files(root)
    _sit_files(root, model, motion)
    return root


def _round2_files(root: Path, state: dict) -> None:
    """Files of the second reliability round (issue 17): unreadable, tampered, huge and nonsensical inputs."""
    import copy

    (root / "text.pt").write_text("hello, a text file renamed .pt\n" * 4)
    (root / "binary.yaml").write_bytes(bytes(range(256)))
    (root / "utf16.yaml").write_bytes("env:\n  num_envs: 8\n".encode("utf-16"))
    (root / "latin1.yaml").write_bytes("env:\n  texts: [caf\xe9]\n".encode("latin-1"))
    (root / "empty.yaml").write_text("")
    (root / "comments.yaml").write_text("# only a comment\n")
    (root / "dup.yaml").write_text("env:\n  num_envs: 8\nenv:\n  num_envs: 4\n")
    (root / "dupinner.yaml").write_text("ppo:\n  seed: 1\n  seed: 2\n")
    rows = "".join(f"{c}: &{c} [{', '.join(['*' + chr(ord(c) - 1)] * 9)}]\n" for c in "bcdefg")
    (root / "bomb.yaml").write_text('a: &a ["x", "x", "x", "x", "x", "x", "x", "x", "x"]\n' + rows)
    (root / "aliases.yaml").write_text("a: &a 1\n" + "".join(f"k{i}: *a\n" for i in range(101)))
    (root / "bigseed.yaml").write_text("ppo: {seed: 100000000000000000000000}\n")
    run = root / "badrun"
    run.mkdir()
    (run / "config.yaml").write_bytes(b"\xff\xfe" + "env: {}".encode("utf-16-le"))
    mrun = root / "badmrun"
    mrun.mkdir()
    (mrun / "config.yaml").write_bytes(bytes(range(256)))

    def path_file(name: str, paths) -> None:
        (root / name).write_text(paths if isinstance(paths, str) else json.dumps(paths))

    path_file("digits.json", '[{"goal_location": [[0, ' + "9" * 400 + ', 0]], "goal_text": ["walk"]}]')
    path_file("deep.json", "[" * 200_000 + "]" * 200_000)
    path_file("many.json", [{"goal_location": [[0, 1, 0]], "goal_text": ["walk"]}] * 20_000)
    path_file("far.json", [{"goal_location": [[0, 1e308, 0]], "goal_text": ["walk"]}])
    path_file("nanpath.json", '[{"goal_location": [[0, NaN, 0]], "goal_text": ["walk"]}]')
    path_file("boolpath.json", [{"goal_location": [[0, True, 0]], "goal_text": ["walk"]}])
    path_file("utf16.json", None)
    (root / "utf16.json").write_bytes(json.dumps([]).encode("utf-16"))

    def policy(name: str, change) -> None:
        s = copy.deepcopy(state)
        change(s)
        torch.save(s, root / name)

    policy("nospec.pt", lambda s: s.pop("policy_spec"))
    policy("negobs.pt", lambda s: s["policy_spec"].__setitem__("obs_dim", -5))
    policy("strobs.pt", lambda s: s["policy_spec"].__setitem__("obs_dim", "64"))
    policy("hugelatent.pt", lambda s: s["policy_spec"]["config"].__setitem__("latent_dim", 10**9))
    policy("motionstr.pt", lambda s: s.__setitem__("motion", "default"))
    policy("noweights.pt", lambda s: s.__setitem__("policy", [1, 2, 3]))
    policy("negiter.pt", lambda s: s.__setitem__("iteration", -1))
    policy("specconfig.pt", lambda s: s["policy_spec"].__setitem__("config", "dart"))
    flipped = copy.deepcopy(state)
    name = next(k for k, v in flipped["policy"].items() if v.is_floating_point() and v.numel())
    flipped["policy"][name].view(-1)[0] = 3.5e35  # a bit flip; the recorded hash stays
    torch.save(flipped, root / "flipped.pt")

    joints = np.zeros((5, 22, 3), np.float32)
    for name, data in {
        "fps0": {"joints": joints, "fps": 0}, "fpsneg": {"joints": joints, "fps": -30},
        "fpsnan": {"joints": joints, "fps": np.nan}, "fpsarr": {"joints": joints, "fps": np.array([30, 60])},
        "fpsstr": {"joints": joints, "fps": "thirty"}, "fpshuge": {"joints": joints, "fps": 1e9},
        "jstr": {"joints": np.full((5, 22, 3), "a")}, "jcomplex": {"joints": joints.astype(complex)},
        "jint": {"joints": joints.astype(np.int64)}, "jhuge": {"joints": np.full((5, 22, 3), 3e40)},
        "jnan": {"joints": np.full((5, 22, 3), np.nan, np.float32)}, "jempty": {"joints": np.zeros((0, 22, 3))},
        "jbool": {"joints": joints.astype(bool)}, "nojoints": {"fps": 30.0},
    }.items():
        np.savez(root / f"{name}.npz", **data)
    np.savez(root / "nanseed.npz", seed_history=np.full((1, 2, 276), np.nan, np.float32))
    base = {"format": "latentrl.eval/1", "settings": {}, "overall": {"metrics": {}}}
    for name, report in {
        "rep_suites_list.json": {**base, "suites": [1, 2]},
        "rep_metrics_str.json": {**base, "suites": {"a": {"metrics": "x", "paths": []}}},
        "rep_mean_str.json": {**base, "suites": {"a": {"metrics": {"success": {"mean": "high"}}, "paths": []}}},
        "rep_overall_list.json": {**base, "suites": {}, "overall": []},
        "rep_paths_dict.json": {**base, "suites": {"a": {"metrics": {}, "paths": {"0": 1}}}},
        "rep_settings_str.json": {**base, "suites": {}, "settings": "cpu"},
    }.items():
        (root / name).write_text(json.dumps(report))


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
     r"env\.task: expected one of \('reach', 'path', 'joystick', 'timed'.*\), got 'dance'"),
    ("train-out-of-range", [*TRAIN, "--set", "ppo.gamma=1.5"], r"ppo\.gamma: must lie in \[0, 1\], got 1\.5"),
    ("train-no-prompts", [*TRAIN, "--set", "env.texts=[]"], r"env\.texts: give at least one prompt"),
    ("train-empty-prompt", [*TRAIN, "--set", "env.texts=['']"], r"env\.texts: prompt '' is empty"),
    ("train-huge-prompt", [*TRAIN, "--set", "env.texts=[{LONG}]"],
     r"env\.texts: .*has 1001 characters, more than the 1000"),
    ("train-unknown-reward", [*TRAIN, "--set", "env.reward_weights.skatee=1"],
     r"env\.reward_weights: unknown reward term 'skatee' \(did you mean 'skate'\?\)"),
    ("train-negative-threads", [*TRAIN, "--set", "threads=-1"],
     r"threads: must lie in \[0, 1024\] \(0: torch.s default\), got -1"),
    ("train-zero-steps", [*TRAIN, "--total-steps", "0"], r"ppo\.total_steps: must be > 0, got 0"),
    ("train-bad-seed", [*TRAIN, "--seed", "abc"],
     r"latentrl train: error: argument --seed: expected an integer seed, got 'abc'"),
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
    ("sample-infinite-guidance", [*SAMPLE, "--guidance", "inf"],
     r"--guidance must be a finite number in \[-100, 100\], got inf"),
    ("sample-empty-prompt", [*SAMPLE, "--text", ""], r"--text: prompt '' is empty"),
    ("sample-huge-prompt", [*SAMPLE, "--text", "{LONG}"], r"--text: prompt 'xxx.*' has 1001 characters"),
    ("sample-unknown-prompt", ["motion", "sample", "--motion", "{fx}/table.pt", "--text", "moonwalk"],
     r"unknown prompt 'moonwalk': this model's text table knows"),
    ("sample-device", [*SAMPLE, "--device", "cuda:7"], r"argument --device: 'cuda:7' (requested|does not exist)"),
    ("sample-out-suffix", [*SAMPLE, "--out", "motion.txt"], r"--out must name a \.npz file, got 'motion\.txt'"),
    ("sample-out-under-file", [*SAMPLE, "--out", "{fx}/afile/m.npz"],
     r"--out folder .*afile exists and is not a direc"),
    ("sample-render-suffix", [*SAMPLE, "--render", "m.avi"], r"--render must name a \.gif or \.mp4 file, got .m\.avi."),
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
    ("motion-train-vae-from-missing", ["motion", "train", "{MTINY}", "--run-dir", "{fx}/vae_from_run", "--vae-from",
                                       "nowhere.pt"], r"nowhere\.pt"),
    ("export-bvh-missing", ["motion", "export-bvh", "missing.npz"], r"motion file not found: missing\.npz"),
    ("export-bvh-junk", ["motion", "export-bvh", "{fx}/junk.npz"], r"junk\.npz: not a readable motion \.npz"),
    ("export-bvh-bad-shape", ["motion", "export-bvh", "{fx}/badshape.npz"],
     r"badshape\.npz: field 'joints' must be \(T, 22, 3\) with T > 0, got \(5, 21, 3\)"),
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
    ("eval-refine-a-reach-policy", [*EVAL, "--refine", "4"],
     r"--refine: only ReachJoint policies are refined \(the optimizer lands joint goals\); the policy's task is "),
    ("eval-negative-avoid", [*EVAL, "--avoid", "-1"], r"--avoid: expected 0-1000, got -1"),
    ("eval-sit-plan-a-reach-policy", [*EVAL, "--sit-plan", "8"],
     r"--sit-plan: only sit policies plan their sits; the policy's task is "),
    ("eval-avoid-zero-horizon", [*EVAL, "--avoid", "4", "--avoid-horizon", "0"],
     r"--avoid-horizon: expected 1-16 primitives, got 0"),
    ("eval-avoid-margin-of-two-metres", [*EVAL, "--avoid", "4", "--avoid-margin", "2"],
     r"--avoid-margin: expected metres in \[0, 1\], got 2\.0"),
    ("eval-avoid-samples-out-of-range", [*EVAL, "--avoid", "4", "--avoid-samples", "300"],
     r"--avoid-samples: expected 0-256, got 300"),
    ("eval-avoid-samples-of-a-refined-policy", ["eval", "reach_joint_default", "--avoid", "4", "--avoid-samples", "4"],
     r"--avoid-samples: not with --refine \(the draws would drop the refinement\); leave out one of them"),
    ("eval-route-of-five-metres", [*EVAL, "--route", "5"],
     r"--route: expected the route's clearance in metres, in \(0, 2\], got 5\.0"),
    ("eval-route-a-reach-joint-policy", ["eval", "reach_joint_default", "--route", "0.5"],
     r"--route: the reach_joint task's goal is not a place on the floor to plan a route to \(reach, path, timed and "),
    ("eval-physics-a-refined-reach-joint-policy", ["eval", "reach_joint_default", "--physics"],
     r"--physics: runs reach or path policies, this policy's task is 'reach_joint'"),
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
ROUND2 = [  # issue 17: tracebacks, hangs and silent nonsense found by a careless and a hostile user
    # ------------------------------------------------ unreadable files
    ("eval-text-as-policy", ["eval", "{fx}/text.pt", "--motion", "{fx}/motion.pt", "--paths", "dart_demo_walk"],
     r"text\.pt: not a readable torch file"),
    ("train-text-as-motion", ["train", "{TINY}", "--set", "env.motion={fx}/text.pt"],
     r"text\.pt: not a readable torch"),
    ("info-etc-passwd", ["motion", "info", "--motion", "/etc/passwd"], r"/etc/passwd: not a readable torch file"),
    ("sample-text-as-motion", ["motion", "sample", "--motion", "{fx}/text.pt"], r"text\.pt: not a readable torch"),
    ("train-binary-config", ["train", "{fx}/binary.yaml"], r"binary\.yaml: not a text config file"),
    ("train-utf16-config", ["train", "{fx}/utf16.yaml"], r"utf16\.yaml: not a text config file"),
    ("train-latin1-config", ["train", "{fx}/latin1.yaml"], r"latin1\.yaml: not a UTF-8 text config file \(byte 0xe9"),
    ("train-resume-utf16-config", ["train", "--resume", "{fx}/badrun"], r"config\.yaml: not a text config file"),
    ("motion-train-binary-config", ["motion", "train", "{fx}/binary.yaml"], r"binary\.yaml: not a text config"),
    ("motion-train-resume-binary", ["motion", "train", "--resume", "{fx}/badmrun"], r"config\.yaml: not a text config"),
    ("eval-utf16-paths", [*EVAL, "--paths", "{fx}/utf16.json"], r"utf16\.json: not a UTF-8 text file"),
    # ------------------------------------------------ malformed --set YAML
    ("train-set-unclosed-list", [*TRAIN, "--set", "env.texts=[walk"],
     r"override 'env\.texts=\[walk': invalid YAML value: while parsing a flow sequence"),
    ("train-set-python-tag", [*TRAIN, "--set", "env.texts=!!python/object/apply:os.system ['true']"],
     r"invalid YAML value: could not determine a constructor for the tag"),
    ("train-set-unclosed-map", [*TRAIN, "--set", 'env.texts=["walk'], r"invalid YAML value"),
    ("motion-train-set-unclosed", ["motion", "train", "{MTINY}", "--set", "data.source=[x"], r"invalid YAML value"),
    # ------------------------------------------------ seeds out of range
    ("train-seed-2-64", [*TRAIN, "--seed", str(2**64)], r"argument --seed: must lie in \[0, 2\*\*32 - 1"),
    ("train-seed-negative", [*TRAIN, "--seed", "-1"],
     r"argument --seed: must lie in \[0, 2\*\*32 - 1 = 4294967295\], got -1"),
    ("train-seed-float", [*TRAIN, "--seed", "1e23"], r"argument --seed: expected an integer seed, got '1e23'"),
    ("train-config-seed-huge", ["train", "{fx}/bigseed.yaml", "--set", "env.motion={fx}/motion.pt"],
     r"ppo\.seed: must lie in \[0, 2\*\*32 - 1"),
    ("train-set-seed-1e23", [*TRAIN, "--set", "ppo.seed=1e23"],
     r"ppo\.seed: Value '1e\+23' of type 'float' could not be converted to Integer"),
    ("eval-seed-2-64", [*EVAL, "--paths", "dart_demo_walk", "--seed", str(2**64)], r"argument --seed: must lie in"),
    ("sample-seed-2-64", [*SAMPLE, "--seed", str(2**64)], r"argument --seed: must lie in"),
    ("sample-seed-negative", [*SAMPLE, "--seed", "-5"], r"argument --seed: must lie in"),
    ("motion-train-seed", ["motion", "train", "{MTINY}", "--set", "seed=-1"], r"seed: must lie in \[0, 2\*\*32"),
    # ------------------------------------------------ path JSON
    ("eval-path-400-digits", [*EVAL, "--paths", "{fx}/digits.json"],
     r"digits\.json: path 0, waypoint 0: field 'goal_location' must be \[x, y, z\] finite numbers within"),
    ("eval-path-deep", [*EVAL, "--paths", "{fx}/deep.json"], r"deep\.json: JSON nested too deeply"),
    ("eval-path-20000-paths", [*EVAL, "--paths", "{fx}/many.json"],
     r"many\.json: 20000 paths, more than the 1000 a path file may hold"),
    ("eval-path-1e308", [*EVAL, "--paths", "{fx}/far.json"], r"far\.json: .*within \+/-10000 m, got \[0, 1e\+308, 0\]"),
    ("eval-path-nan", [*EVAL, "--paths", "{fx}/nanpath.json"], r"nanpath\.json: .*finite numbers"),
    ("eval-path-bool", [*EVAL, "--paths", "{fx}/boolpath.json"], r"boolpath\.json: .*finite numbers"),
    ("train-path-deep", [*TRAIN, "--set", "env.task=path", "--set", "env.paths={fx}/deep.json"],
     r"deep\.json: JSON nested too deeply"),
    ("quickstart-guidance-nan", ["quickstart", "--set", "env.motion={fx}/motion.pt", "--set", "env.guidance_scale=nan"],
     r"env\.guidance_scale: must be a finite number"),
    # ------------------------------------------------ hand-made policy checkpoints
    ("eval-policy-no-spec", ["eval", "{fx}/nospec.pt", "--motion", "{fx}/motion.pt"],
     r"nospec\.pt: field 'policy_spec': expected a dict"),
    ("eval-policy-negative-obs", ["eval", "{fx}/negobs.pt", "--motion", "{fx}/motion.pt"],
     r"field 'policy_spec\.obs_dim': expected an integer in \[1, 1000000\], got -5"),
    ("eval-policy-string-obs", ["eval", "{fx}/strobs.pt", "--motion", "{fx}/motion.pt"],
     r"field 'policy_spec\.obs_dim': expected an integer .* got '64'"),
    ("eval-policy-huge-latent", ["eval", "{fx}/hugelatent.pt", "--motion", "{fx}/motion.pt"],
     r"policy_spec\.config: latent_dim: must lie in \[1, 16384\], got 1000000000"),
    ("eval-policy-motion-string", ["eval", "{fx}/motionstr.pt", "--motion", "{fx}/motion.pt"],
     r"field 'motion': expected a dict \{path, sha256\} or None, got 'default'"),
    ("eval-policy-weights-list", ["eval", "{fx}/noweights.pt", "--motion", "{fx}/motion.pt"],
     r"field 'policy': expected a dict of tensors"),
    ("eval-policy-negative-iteration", ["eval", "{fx}/negiter.pt", "--motion", "{fx}/motion.pt"],
     r"field 'iteration': expected an integer >= 0, got -1"),
    ("eval-policy-spec-config-string", ["eval", "{fx}/specconfig.pt", "--motion", "{fx}/motion.pt"],
     r"field 'policy_spec\.config': expected a dict"),
    ("eval-policy-bit-flip", ["eval", "{fx}/flipped.pt", "--motion", "{fx}/motion.pt"],
     r"flipped\.pt: policy weights do not match their recorded sha256"),
    # ------------------------------------------------ export-bvh
    ("export-bvh-fps-0", ["motion", "export-bvh", "{fx}/fps0.npz"],
     r"fps0\.npz: field 'fps' must lie in \[0\.001, 1000\], got 0"),
    ("export-bvh-fps-negative", ["motion", "export-bvh", "{fx}/fpsneg.npz"], r"field 'fps' must lie in .*got -30"),
    ("export-bvh-fps-nan", ["motion", "export-bvh", "{fx}/fpsnan.npz"], r"field 'fps' must lie in .*got nan"),
    ("export-bvh-fps-array", ["motion", "export-bvh", "{fx}/fpsarr.npz"], r"field 'fps' must be one real number"),
    ("export-bvh-fps-string", ["motion", "export-bvh", "{fx}/fpsstr.npz"], r"field 'fps' must be one real number"),
    ("export-bvh-fps-huge", ["motion", "export-bvh", "{fx}/fpshuge.npz"], r"field 'fps' must lie in .*got 1e\+09"),
    ("export-bvh-joints-string", ["motion", "export-bvh", "{fx}/jstr.npz"],
     r"field 'joints' must hold real floating-point numbers, got dtype <U1"),
    ("export-bvh-joints-complex", ["motion", "export-bvh", "{fx}/jcomplex.npz"], r"got dtype complex128"),
    ("export-bvh-joints-int", ["motion", "export-bvh", "{fx}/jint.npz"], r"got dtype int64"),
    ("export-bvh-joints-bool", ["motion", "export-bvh", "{fx}/jbool.npz"], r"got dtype bool"),
    ("export-bvh-joints-huge", ["motion", "export-bvh", "{fx}/jhuge.npz"],
     r"field 'joints' reaches 3e\+40 m, beyond the \+/-10000 m"),
    ("export-bvh-joints-nan", ["motion", "export-bvh", "{fx}/jnan.npz"], r"field 'joints' holds NaN or inf in 5 of 5"),
    ("export-bvh-joints-empty", ["motion", "export-bvh", "{fx}/jempty.npz"], r"with T > 0, got \(0, 22, 3\)"),
    ("export-bvh-no-joints", ["motion", "export-bvh", "{fx}/nojoints.npz"], r"no field 'joints'"),
    # ------------------------------------------------ compare with wrong types
    ("compare-suites-list", ["compare", "{fx}/rep_suites_list.json"], r"field 'suites' must be an object of suites"),
    ("compare-metrics-string", ["compare", "{fx}/rep_metrics_str.json"],
     r"field 'suites\.a\.metrics' must be an object of metrics or null, got 'x'"),
    ("compare-mean-string", ["compare", "{fx}/rep_mean_str.json"],
     r"field 'suites\.a\.metrics\.success\.mean' must be a number or null, got 'high'"),
    ("compare-overall-list", ["compare", "{fx}/rep_overall_list.json"], r"field 'overall' must be an object"),
    ("compare-paths-dict", ["compare", "{fx}/rep_paths_dict.json"], r"field 'suites\.a\.paths' must be a list"),
    ("compare-settings-string", ["compare", "{fx}/rep_settings_str.json"], r"field 'settings' must be an object"),
    # ------------------------------------------------ what cannot fit, refused before work
    ("eval-episodes-1e8", [*EVAL, "--paths", "dart_demo_walk", "--episodes", "100000000"],
     r"--episodes: must be <= 65536 \(they run as one batch of envs\), got 100000000"),
    ("eval-max-steps-huge", [*EVAL, "--paths", "dart_demo_walk", "--max-steps", "10000000"],
     r"--max-steps: must be <= 100000"),
    ("train-num-envs-1e12", [*TRAIN, "--set", "env.num_envs=1000000000000"],
     r"env\.num_envs: must be <= 1048576, got 1000000000000"),
    ("train-num-steps-1e11", [*TRAIN, "--set", "ppo.num_steps=100000000000"],
     r"ppo\.num_steps: must be <= 100000, got 100000000000"),
    ("train-batch-too-big", [*TRAIN, "--set", "env.num_envs=1000000", "--set", "ppo.num_steps=100000"],
     r"the batch num_steps \* num_envs = 100000 \* 1000000 = 100000000000 exceeds 67108864"),
    ("train-prime-batch-hint", [*TRAIN, "--set", "env.num_envs=1000003", "--set", "ppo.num_steps=1",
                                "--set", "ppo.num_minibatches=2"], r"2 does not divide the batch .*; try 1\b"),
    ("train-policy-latent-huge", [*TRAIN, "--set", "policy.latent_dim=1000000000"],
     r"policy\.latent_dim: must lie in \[1, 16384\]"),
    # ------------------------------------------------ hangs: YAML bombs, empty and duplicated configs
    ("train-yaml-alias-bomb", ["train", "{fx}/bomb.yaml"],
     r"bomb\.yaml: invalid YAML: expands to \d+ values .*alias bomb"),
    ("train-yaml-many-aliases", ["train", "{fx}/aliases.yaml"], r"aliases\.yaml: invalid YAML: more than 100 aliases"),
    ("train-empty-config", ["train", "{fx}/empty.yaml"], r"empty\.yaml: holds no settings \(empty file\)"),
    ("train-comment-only-config", ["train", "{fx}/comments.yaml"], r"comments\.yaml: holds no settings"),
    ("train-duplicate-key", ["train", "{fx}/dup.yaml"], r"dup\.yaml: invalid YAML: duplicate key 'env' \(line 3\)"),
    ("train-duplicate-inner-key", ["train", "{fx}/dupinner.yaml"], r"duplicate key 'seed' \(line 3\)"),
    ("motion-train-empty-config", ["motion", "train", "{fx}/empty.yaml"], r"empty\.yaml: holds no settings"),
    ("motion-train-duplicate-key", ["motion", "train", "{fx}/dup.yaml"], r"duplicate key 'env'"),
    ("motion-train-alias-bomb", ["motion", "train", "{fx}/bomb.yaml"], r"alias bomb"),
    # ------------------------------------------------ silent nonsense
    ("train-guidance-nan", [*TRAIN, "--set", "env.guidance_scale=.nan"],
     r"env\.guidance_scale: must be a finite number in \[-100, 100\], got nan"),
    ("train-guidance-huge", [*TRAIN, "--set", "env.guidance_scale=1e30"], r"env\.guidance_scale: must be a finite"),
    ("sample-guidance-1e30", [*SAMPLE, "--guidance", "1e30"], r"--guidance must be a finite number in \[-100, 100\]"),
    ("sample-nan-seed-history", [*SAMPLE, "--seed-history", "{fx}/nanseed.npz"],
     r"nanseed\.npz: seed history holds NaN or inf in 1 of 1 seeds"),
    ("info-nan-seed-history", ["motion", "info", "--motion", "{fx}/motion.pt", "--seed-history", "{fx}/nanseed.npz"],
     r"seed history holds NaN"),
    ("eval-device-cpu9", [*EVAL, "--paths", "dart_demo_walk", "--device", "cpu:9"],
     r"argument --device: 'cpu:9' does not exist; the CPU is 'cpu'"),
    ("train-device-cpu9", [*TRAIN, "--device", "cpu:9"], r"argument --device: 'cpu:9' does not exist"),
    ("train-config-device-cpu1", [*TRAIN, "--set", "ppo.device=cpu:1"], r"ppo\.device: 'cpu:1' does not exist"),
    ("sample-device-cpu9", [*SAMPLE, "--device", "cpu:9"], r"'cpu:9' does not exist"),
    ("bench-rollout-missing-model", ["bench", "rollout", "--models", "nope.pt"], r"motion model not found: nope\.pt"),
    ("bench-env-missing-model", ["bench", "env", "--models", "tiny", "nope.pt"], r"motion model not found: nope\.pt"),
]
ROUND2 += [
    # ------------------------------------------------ misleading messages: outputs and tools checked before work
    ("train-threads-100000", [*TRAIN, "--set", "threads=100000"], r"threads: must lie in \[0, 1024\]"),
    ("motion-train-threads", ["motion", "train", "{MTINY}", "--set", "threads=100000"], r"threads: must lie in"),
    ("bench-motion-json-under-file", ["bench", "motion", "--json", "{fx}/afile/out.json"],
     r"--json folder .*afile exists and is not a directory"),
    ("bench-rollout-json-is-folder", ["bench", "rollout", "--json", "{fx}"], r"--json .* is a directory"),
    ("bench-env-json-under-file", ["bench", "env", "--json", "{fx}/afile/x.json"], r"--json folder"),
    ("bench-train-json-is-folder", ["bench", "train", "--json", "{fx}"], r"--json .* is a directory"),
    ("bench-rollout-dart-python", ["bench", "rollout", "--dart-python", "/nonexistent/python"],
     r"--dart-python /nonexistent/python: no such program"),
    ("bench-rollout-dart-src", ["bench", "rollout", "--dart-src", "/nonexistent/DART"], r"--dart-src .*: not found"),
]
ROWS += ROUND2


# ============================================================================ round 3 (issue 46)
# The environment a row runs in (row id -> variables; {fx} is the fixture folder) and each round-3 row's kind.
ENV: dict[str, dict[str, str]] = {}
KIND: dict[str, str] = {}
TORCHRUN = {"RANK": "0", "WORLD_SIZE": "2", "MASTER_ADDR": "127.0.0.1", "MASTER_PORT": "29500"}
OPT = ["optimize", "inbetween", "--no-progress", "--steps", "1"]
NPROC = [*TRAIN, "--nproc", "2"]
COMPILE = ["--set", "env.compile=true"]


def _suite_cases() -> dict[str, tuple[str | bytes, str]]:
    """Malformed, huge and hostile constraint suites: name -> (file content, what the line must say)."""
    joint = {"type": "joint", "frame": 10, "joint": "pelvis", "position": [0.0, 1.0, 0.9]}
    prob = {"name": "p", "start": {"seed": 1}, "text": "walk", "primitives": 2, "constraints": [joint]}
    base = {"format": "latentrl.constraints/1", "problems": [prob]}

    def change(path: tuple, value=None, delete: bool = False) -> str:
        suite = copy.deepcopy(base)
        obj = suite
        for key in path[:-1]:
            obj = obj[key]
        if delete:
            del obj[path[-1]]
        else:
            obj[path[-1]] = value
        return json.dumps(suite)

    p, c = ("problems", 0), ("problems", 0, "constraints", 0)
    q = r"problem 'p' "
    pos, jnt = q + r"constraints\[0\]\.position", q + r"constraints\[0\]\.joint: "
    cases = {
        "format-missing": (change(("format",), delete=True), r"format: expected 'latentrl\.constraints/1', got None"),
        "format-wrong": (change(("format",), "latentrl.constraints/9"), r"format: expected .*constraints/9'"),
        "format-number": (change(("format",), 1), r"format: expected .*got 1"),
        "problems-missing": (change(("problems",), delete=True), r"problems: expected a non-empty list"),
        "problems-dict": (change(("problems",), {"p": prob}), r"problems: expected a non-empty list"),
        "problems-empty": (change(("problems",), []), r"problems: expected a non-empty list"),
        "problems-1001": (change(("problems",), [dict(prob, name=f"p{i}") for i in range(1001)]),
                          r"1001 problems, more than the 1000 allowed"),
        "problem-string": (change(p, "p"), r"problem 0 problem: expected an object"),
        "name-empty": (change((*p, "name"), ""), r"problem 0 name: expected 1-80 letters"),
        "name-number": (change((*p, "name"), 7), r"problem 0 name: expected 1-80 letters.*got 7"),
        "name-path": (change((*p, "name"), "../../etc/x"), r"problem 0 name: expected 1-80 letters"),
        "name-duplicate": (change(("problems",), [prob, prob]), r"the name 'p' is used twice"),
        "unknown-field": (change((*p, "constrains"), []), r"problem 0 constrains: unknown field"),
        "seed-negative": (change((*p, "start", "seed"), -1), q + r"start\.seed: -1 is outside"),
        "seed-huge": (change((*p, "start", "seed"), 10**30), q + r"start\.seed: 10+ is outside"),
        "seed-string": (change((*p, "start", "seed"), "one"), q + r"start\.seed: expected an integer, got 'one'"),
        "seed-float": (change((*p, "start", "seed"), 1.5), q + r"start\.seed: expected an integer, got 1\.5"),
        "start-both": (change((*p, "start"), {"seed": 1, "motion": "x.npz"}), q + r"start: expected"),
        "text-empty": (change((*p, "text"), ""), q + r"text: prompt '' is empty"),
        "text-long": (change((*p, "text"), "x" * 1001), q + r"text: .*has 1001 characters"),
        "text-number": (change((*p, "text"), 3), q + r"text: expected one prompt or a list of 2"),
        "primitives-zero": (change((*p, "primitives"), 0), q + r"primitives: 0 is outside \[1, 64\]"),
        "primitives-negative": (change((*p, "primitives"), -2), q + r"primitives: -2 is outside"),
        "primitives-65": (change((*p, "primitives"), 65), q + r"primitives: 65 is outside"),
        "primitives-1e9": (change((*p, "primitives"), 10**9), q + r"primitives: 1000000000 is outside"),
        "primitives-string": (change((*p, "primitives"), "8"), q + r"primitives: expected an integer, got '8'"),
        "primitives-float": (change((*p, "primitives"), 2.5), q + r"primitives: expected an integer, got 2\.5"),
        "primitives-bool": (change((*p, "primitives"), True), q + r"primitives: expected an integer, got True"),
        "constraints-missing": (change((*p, "constraints"), delete=True), q + r"constraints: expected a non-empty"),
        "constraints-dict": (change((*p, "constraints"), {"a": joint}), q + r"constraints: expected a non-empty"),
        "constraints-empty": (change((*p, "constraints"), []), q + r"constraints: expected a non-empty"),
        "type-unknown": (change((*c, "type"), "teleport"), q + r"constraints\[0\]\.type: expected one of keyframe"),
        "type-typo": (change((*c, "type"), "joints"), q + r"constraints\[0\]\.type: .*got 'joints'"),
        "frame-negative": (change((*c, "frame"), -1), q + r"constraints\[0\]\.frame: -1 is outside \[0, 15\]"),
        "frame-beyond": (change((*c, "frame"), 16), q + r"constraints\[0\]\.frame: 16 is outside \[0, 15\]"),
        "frame-float": (change((*c, "frame"), 3.5), q + r"constraints\[0\]\.frame: expected an integer"),
        "frame-string": (change((*c, "frame"), "10"), q + r"constraints\[0\]\.frame: expected an integer"),
        "frame-huge": (change((*c, "frame"), 10**20), q + r"constraints\[0\]\.frame: 10+ is outside"),
        "joint-unknown": (change((*c, "joint"), "tail"), jnt + r"unknown joint 'tail'"),
        "joint-typo": (change((*c, "joint"), "pelvs"), jnt + r"unknown joint 'pelvs' \(did you mean 'pelvis'\?\)"),
        "joint-number": (change((*c, "joint"), 0), jnt + r"unknown joint 0"),
        "position-2": (change((*c, "position"), [0.0, 1.0]), pos + r": expected \[x, y, z\]"),
        "position-string": (change((*c, "position"), ["a", 1.0, 0.9]), pos + r"\[0\]: expected a number"),
        "position-bool": (change((*c, "position"), [True, 1.0, 0.9]), pos + r"\[0\]: expected a number"),
        "position-nested": (change((*c, "position"), [[0.0], 1.0, 0.9]), pos + r"\[0\]: expected a number"),
        "position-1001m": (change((*c, "position"), [0.0, 1001.0, 0.9]), pos + r"\[1\]: 1001\.0 is more"),
        "position-nan": (change((*c, "position"), [0.0, float("nan"), 0.9]), pos + r"\[1\]: .*finite.*nan"),
        "position-inf": (change((*c, "position"), [0.0, float("inf"), 0.9]), pos + r"\[1\]: .*finite.*inf"),
        "weight-nan": (change((*c, "weight"), float("nan")), q + r"constraints\[0\]\.weight: .*finite.*nan"),
        "keyframe-21-rows": (change(("problems", 0, "constraints"), [{"type": "keyframe", "frame": 10,
                                                                       "joints": [[0, 0, 0]] * 21}]),
                             q + r"constraints\[0\]\.joints: expected 22 rows"),
        "keyframe-no-joints": (change(("problems", 0, "constraints"), [{"type": "keyframe", "frame": 10}]),
                               q + r"constraints\[0\]\.joints: expected 22 rows"),
        "scene-weights-negative": (change((*p, "scene_weights"), {"collision": -1}),
                                   q + r"scene_weights\.collision: must be >= 0"),
        "scene-weights-unknown": (change((*p, "scene_weights"), {"colision": 1}),
                                  q + r"scene_weights: expected an object with some of collision, contact"),
        "scene-weights-nan": (change((*p, "scene_weights"), {"collision": float("nan")}),
                              q + r"scene_weights\.collision: .*finite.*nan"),
        "scene-number": (change((*p, "scene"), 5), q + r"scene: expected a scene file name or a latentrl\.scene/1"),
        "not-object": ("[1, 2, 3]", r"suite: expected a JSON object with 'format' and 'problems'"),
        "truncated": (json.dumps(base)[:40], r"invalid JSON: Unterminated string"),
        "empty": ("", r"invalid JSON: Expecting value"),
        "deep": ("[" * 200_000 + "]" * 200_000, r"JSON nested too deeply"),
        "digits": (json.dumps(base).replace("0.9]", "9" * 400 + "]"),
                   pos + r"\[2\]: an integer of 400 digits is more than 1000 m"),
        "far": (json.dumps(base).replace("0.9]", "1e308]"), pos + r"\[2\]: 1e\+308 is more than 1000 m"),
        "utf16": (json.dumps(base).encode("utf-16"), r"not a UTF-8 text file"),
        "binary": (bytes(range(256)), r"not a UTF-8 text file"),
        "oversized": (b" " * (16 * 1024 * 1024 + 1),
                      r"16,777,217 bytes is larger than the 16 MiB a constraint suite may have"),
    }
    return cases


SUITES = _suite_cases()
HOSTILE_SUITES = {"problems-1001", "name-path", "deep", "digits", "far", "oversized", "binary", "utf16"}


def _round3_files(root: Path) -> None:
    """Suites, an empty folder for PATH (no compiler on it), motions and folders for the viewer's rows."""
    suites = root / "suites"
    suites.mkdir()
    for name, (data, _) in SUITES.items():
        (suites / f"{name}.json").write_bytes(data if isinstance(data, bytes) else data.encode())
    (root / "emptybin").mkdir()
    np.savez(root / "ok.npz", joints=np.zeros((5, 22, 3), np.float32), fps=30.0)
    for name, report in {"evalbad": "{not json", "evallist": '{"format": "latentrl.eval/1", "suites": [1]}'}.items():
        (root / name).mkdir()
        (root / name / "report.json").write_text(report)
    (root / "runnoeval").mkdir()
    (root / "runnoeval" / "config.yaml").write_text("env: {}\n")


def _r3(kind: str, rid: str, argv: list[str], pattern: str, env: dict[str, str] | None = None) -> tuple:
    KIND[rid] = kind
    if env:
        ENV[rid] = env
    return rid, argv, pattern


NO_CXX = {"PATH": "{fx}/emptybin"}
ROUND3 = [
    # ------------------------------------------------ env.compile where torch cannot compile (no compiler, cache)
    _r3("fault", "train-compile-no-compiler", [*TRAIN, *COMPILE],
        r"env\.compile: torch\.compile on the CPU needs a C\+\+ compiler, and none runs here .*set env\.compile=false",
        NO_CXX),
    _r3("fault", "quickstart-compile-no-compiler", ["quickstart", "--set", "env.motion={fx}/motion.pt", *COMPILE],
        r"env\.compile: torch\.compile on the CPU needs a C\+\+ compiler", NO_CXX),
    _r3("fault", "train-nproc-compile-no-compiler", [*NPROC, *COMPILE], r"env\.compile: .*needs a C\+\+ compiler",
        NO_CXX),
    _r3("fault", "train-compile-cache-proc", [*TRAIN, *COMPILE],
        r"env\.compile: torch\.compile's cache folder /proc/inductor \(TORCHINDUCTOR_CACHE_DIR=/proc/inductor\) is "
        r"not writable \(.*\); set TORCHINDUCTOR_CACHE_DIR to a writable folder, or set env\.compile=false",
        {"TORCHINDUCTOR_CACHE_DIR": "/proc/inductor"}),
    _r3("fault", "train-compile-cache-is-file", [*TRAIN, *COMPILE], r"cache folder .*afile .*afile is a file",
        {"TORCHINDUCTOR_CACHE_DIR": "{fx}/afile"}),
    _r3("fault", "train-compile-cache-under-file", [*TRAIN, *COMPILE], r"cache folder .*afile/cache .*afile is a file",
        {"TORCHINDUCTOR_CACHE_DIR": "{fx}/afile/cache"}),
    _r3("fault", "train-compile-cache-dev-null", [*TRAIN, *COMPILE], r"cache folder /dev/null/x .*is not writable",
        {"TORCHINDUCTOR_CACHE_DIR": "/dev/null/x"}),
    _r3("fault", "quickstart-compile-cache-proc", ["quickstart", "--set", "env.motion={fx}/motion.pt", *COMPILE],
        r"TORCHINDUCTOR_CACHE_DIR=/proc/inductor", {"TORCHINDUCTOR_CACHE_DIR": "/proc/inductor"}),
    _r3("fault", "train-nproc-compile-cache-proc", [*NPROC, *COMPILE], r"TORCHINDUCTOR_CACHE_DIR=/proc/inductor",
        {"TORCHINDUCTOR_CACHE_DIR": "/proc/inductor"}),
    # ------------------------------------------------ stray or malformed torchrun variables
    _r3("bad value", "train-stray-rank-world", TRAIN,
        r"environment: RANK=1 WORLD_SIZE=2 is set but MASTER_ADDR and MASTER_PORT not: not a complete torchrun "
        r"launch; unset RANK WORLD_SIZE to train in one process", {"RANK": "1", "WORLD_SIZE": "2"}),
    _r3("bad value", "train-stray-world-only", TRAIN, r"environment: WORLD_SIZE=8 is set but RANK and MASTER_ADDR",
        {"WORLD_SIZE": "8"}),
    _r3("bad value", "train-stray-no-port", TRAIN, r"is set but MASTER_PORT not",
        {"RANK": "0", "WORLD_SIZE": "2", "MASTER_ADDR": "127.0.0.1"}),
    _r3("bad value", "quickstart-stray-rank-world", ["quickstart", "--set", "env.motion={fx}/motion.pt"],
        r"not a complete torchrun launch", {"RANK": "1", "WORLD_SIZE": "2"}),
    _r3("bad value", "train-rank-not-integer", TRAIN, r"environment variable RANK='abc': expected an integer >= 0",
        {"RANK": "abc", "WORLD_SIZE": "2"}),
    _r3("bad value", "train-world-size-zero", TRAIN, r"environment variable WORLD_SIZE='0': expected an integer >= 1",
        {"RANK": "0", "WORLD_SIZE": "0"}),
    _r3("bad value", "train-world-size-negative", TRAIN, r"WORLD_SIZE='-3': expected an integer >= 1",
        {"WORLD_SIZE": "-3"}),
    _r3("bad value", "train-world-size-float", TRAIN, r"WORLD_SIZE='2\.5': expected an integer", {"WORLD_SIZE": "2.5"}),
    _r3("bad value", "train-local-rank-negative", TRAIN, r"LOCAL_RANK='-1': expected an integer >= 0",
        {"LOCAL_RANK": "-1"}),
    _r3("bad value", "train-local-rank-name", TRAIN, r"LOCAL_RANK='gpu0': expected an integer", {"LOCAL_RANK": "gpu0"}),
    _r3("bad value", "train-launch-rank-too-big", TRAIN, r"environment: RANK=2 must be below WORLD_SIZE=2",
        {**TORCHRUN, "RANK": "2"}),
    _r3("bad value", "train-launch-timeout-word", TRAIN, r"LATENTRL_DIST_TIMEOUT='soon': expected the seconds",
        {**TORCHRUN, "LATENTRL_DIST_TIMEOUT": "soon"}),
    _r3("bad value", "train-stray-note-then-bad-config", [*TRAIN, "--set", "ppo.learning_rate=-1"],
        r"ppo\.learning_rate: must be > 0", {"RANK": "0", "WORLD_SIZE": "1"}),
]
for _value in ("abc", "nan", "NaN", "inf", "-inf", "-1", "0", "1e300", "", "30s", "1e6"):
    ROUND3.append(_r3("bad value", f"train-nproc-timeout-{_value or 'empty'}", NPROC,
                      rf"environment variable LATENTRL_DIST_TIMEOUT={re.escape(repr(_value))}: expected the seconds "
                      r"each collective may wait, a number in \(0, 604800\]", {"LATENTRL_DIST_TIMEOUT": _value}))
ROUND3 += [
    _r3("bad value", "train-resume-nproc-timeout-nan", ["train", "--resume", "{fx}/badrun", "--nproc", "2"],
        r"LATENTRL_DIST_TIMEOUT='nan'", {"LATENTRL_DIST_TIMEOUT": "nan"}),
    _r3("bad value", "train-nproc-sb3", [*NPROC, "--trainer", "sb3"], r"trainer 'sb3' runs in one process only"),
    # ------------------------------------------------ export onnx: joystick/timed bad arguments, unreadable policies
    _r3("bad value", "export-onnx-joystick-batch-0", ["export", "onnx", "joystick_walk_default", "--out", "c.onnx",
                                                      "--batch", "0"], r"argument --batch: must be > 0, got 0"),
    _r3("bad value", "export-onnx-timed-opset-5", ["export", "onnx", "timed_walk_default", "--out", "c.onnx",
                                                   "--opset", "5"], r"--opset must lie in \[17, \d+\], got 5"),
    _r3("bad file", "export-onnx-missing", ["export", "onnx", "nowhere.pt", "--out", "c.onnx"],
        r"policy checkpoint not found: nowhere\.pt"),
    _r3("bad file", "export-onnx-etc-passwd", ["export", "onnx", "/etc/passwd", "--out", "c.onnx"],
        r"/etc/passwd: not a readable torch file"),
    _r3("bad file", "export-onnx-truncated", ["export", "onnx", "{fx}/truncated.pt", "--out", "c.onnx"],
        r"truncated\.pt: not a readable torch file"),
    _r3("hostile file", "export-onnx-evil", ["export", "onnx", "{fx}/evil.pt", "--out", "c.onnx"],
        r"evil\.pt: refused to load"),
    _r3("hostile file", "export-onnx-bit-flip", ["export", "onnx", "{fx}/flipped.pt", "--out", "c.onnx"],
        r"flipped\.pt: policy weights do not match their recorded sha256"),
    _r3("bad file", "export-onnx-motion-as-policy", ["export", "onnx", "{fx}/motion.pt", "--out", "c.onnx"],
        r"motion\.pt: not a latentrl PPO checkpoint"),
    _r3("bad value", "export-onnx-out-is-folder", ["export", "onnx", "reach_walk_default", "--out", "{fx}"],
        r"--out .* is a directory; give a file name"),
    _r3("bad value", "export-onnx-out-under-file", ["export", "onnx", "reach_walk_default", "--out",
                                                    "{fx}/afile/c.onnx"], r"--out folder .*afile exists and is not a"),
    _r3("bad value", "export-onnx-no-out", ["export", "onnx", "reach_walk_default"],
        r"the following arguments are required: --out"),
    # ------------------------------------------------ optimize: flags
    _r3("bad value", "optimize-steps-0", [*OPT[:3], "--steps", "0"], r"argument --steps: must be > 0, got 0"),
    _r3("bad value", "optimize-steps-negative", [*OPT[:3], "--steps", "-5"], r"argument --steps: must be > 0"),
    _r3("bad value", "optimize-steps-1e10", [*OPT[:3], "--steps", "10000000000"], r"steps: expected 1-100000"),
    _r3("bad value", "optimize-steps-word", [*OPT[:3], "--steps", "many"], r"--steps: expected an integer"),
    _r3("bad value", "optimize-lr-0", [*OPT, "--lr", "0"], r"argument --lr: must be > 0, got 0"),
    _r3("bad value", "optimize-lr-nan", [*OPT, "--lr", "nan"], r"argument --lr: must be > 0, got nan"),
    _r3("bad value", "optimize-lr-inf", [*OPT, "--lr", "inf"], r"argument --lr: must be > 0, got inf"),
    _r3("bad value", "optimize-lr-negative", [*OPT, "--lr", "-1"], r"argument --lr: must be > 0"),
    _r3("bad value", "optimize-batch-0", [*OPT, "--batch", "0"], r"argument --batch: must be > 0"),
    _r3("bad value", "optimize-batch-1e8", [*OPT, "--batch", "100000000"], r"batch: expected 1-4096 problems"),
    _r3("bad value", "optimize-samples-0", [*OPT, "--samples", "0"], r"argument --samples: must be > 0"),
    _r3("bad value", "optimize-samples-1e8", [*OPT, "--samples", "100000000"], r"samples: expected 1-256"),
    _r3("bad value", "optimize-init-word", [*OPT, "--init", "gaussian"], r"--init gaussian: expected 'zeros', 'randn'"),
    _r3("bad file", "optimize-init-missing", [*OPT, "--init", "nowhere.pt"], r"--init nowhere\.pt: .*no such file"),
    _r3("bad value", "optimize-init-scale-nan", [*OPT, "--init-scale", "nan"], r"init_scale: expected 0-10, got nan"),
    _r3("bad value", "optimize-init-scale-negative", [*OPT, "--init-scale", "-1"], r"init_scale: expected 0-10"),
    _r3("bad value", "optimize-guidance-nan", [*OPT, "--guidance", "nan"],
        r"guidance: expected a finite number in \[-100, 100\], got nan"),
    _r3("bad value", "optimize-guidance-inf", [*OPT, "--guidance", "inf"], r"guidance: expected a finite number"),
    _r3("bad value", "optimize-guidance-1e30", [*OPT, "--guidance", "1e30"], r"guidance: expected a finite number"),
    _r3("bad value", "optimize-stop-cm-nan", [*OPT, "--stop-cm", "nan"], r"argument --stop-cm: must be > 0, got nan"),
    _r3("bad value", "optimize-stop-cm-negative", [*OPT, "--stop-cm", "-1"], r"argument --stop-cm: must be > 0"),
    _r3("bad value", "optimize-floor-nan", [*OPT, "--floor", "nan"], r"weights\.floor: expected a finite number >= 0"),
    _r3("bad value", "optimize-floor-negative", [*OPT, "--floor", "-1"], r"weights\.floor: expected a finite number"),
    _r3("bad value", "optimize-skate-inf", [*OPT, "--skate", "inf"], r"weights\.skate: expected a finite number"),
    _r3("bad value", "optimize-jerk-nan", [*OPT, "--jerk", "nan"], r"weights\.jerk: expected a finite number"),
    _r3("bad value", "optimize-prior-negative", [*OPT, "--prior", "-0.5"], r"weights\.prior: expected a finite"),
    _r3("bad value", "optimize-prior-nan", [*OPT, "--prior", "nan"], r"weights\.prior: expected a finite number"),
    _r3("bad value", "optimize-problem-unknown", [*OPT, "--problem", "nope"], r"--problem 'nope': not in .*inbetween"),
    _r3("bad value", "optimize-device-tpu", [*OPT, "--device", "tpu"], r"argument --device: unknown device 'tpu'"),
    _r3("bad value", "optimize-device-cpu9", [*OPT, "--device", "cpu:9"], r"argument --device: 'cpu:9' does not"),
    _r3("bad value", "optimize-seed-negative", [*OPT, "--seed", "-1"], r"argument --seed: must lie in"),
    _r3("bad value", "optimize-seed-2-64", [*OPT, "--seed", str(2**64)], r"argument --seed: must lie in"),
    _r3("bad value", "optimize-out-is-file", [*OPT, "--out", "{fx}/afile"], r"--out .*afile exists and is not a dir"),
    _r3("bad value", "optimize-out-under-file", [*OPT, "--out", "{fx}/afile/x"], r"--out .*afile is a file"),
    _r3("bad file", "optimize-missing-suite", ["optimize", "nowhere.json"], r"nowhere\.json: no such suite file"),
    _r3("bad value", "optimize-unknown-suite", ["optimize", "inbetweeen"], r"inbetweeen: no such suite file"),
    _r3("bad file", "optimize-suite-is-folder", ["optimize", "{fx}/suites"], r"suites: no such suite file"),
    _r3("bad file", "optimize-motion-missing", [*OPT, "--motion", "nowhere.pt"], r"motion model not found: nowhere"),
    _r3("bad file", "optimize-motion-etc-passwd", [*OPT, "--motion", "/etc/passwd"], r"/etc/passwd: not a readable"),
    _r3("hostile file", "optimize-motion-evil", [*OPT, "--motion", "{fx}/evil.pt"], r"evil\.pt: refused to load"),
    _r3("hostile file", "optimize-init-evil", [*OPT, "--init", "{fx}/evil.pt"], r"evil\.pt: refused to load"),
]
ROUND3 += [_r3("hostile file" if name in HOSTILE_SUITES else "bad file", f"optimize-suite-{name}",
               ["optimize", f"{{fx}}/suites/{name}.json", "--no-progress"], rf"{re.escape(name)}\.json: .*{pattern}")
           for name, (_, pattern) in SUITES.items()]
ROUND3 += [
    # ------------------------------------------------ view and play: what they are asked to serve, their flags
    *[_r3("bad file", f"view-{name}", ["view", f"{{fx}}/{name}.npz"], rf"{name}\.npz: .*{pattern}")
      for name, pattern in {"fps0": r"field 'fps' must lie in", "fpsnan": r"field 'fps' must lie in .*nan",
                            "jstr": r"must hold real floating-point", "jcomplex": r"must hold real floating-point",
                            "jhuge": r"reaches 3e\+40 m", "jnan": r"holds NaN or inf", "jempty": r"with T > 0",
                            "nojoints": r"no field 'joints'", "junk": r"not a readable motion \.npz",
                            "badshape": r"must be \(T, 22, 3\)"}.items()],
    _r3("bad file", "view-missing", ["view", "nowhere.npz"], r"nowhere\.npz: no such file or folder"),
    _r3("bad file", "view-empty-folder", ["view", "{fx}/emptybin"], r"emptybin: holds no report\.json"),
    _r3("bad file", "view-report-invalid-json", ["view", "{fx}/evalbad"], r"report\.json: invalid JSON"),
    _r3("bad file", "view-report-wrong-types", ["view", "{fx}/evallist"], r"report\.json: report lacks field"),
    _r3("bad file", "view-run-without-eval", ["view", "{fx}/runnoeval"], r"the run has no evaluation yet"),
    _r3("bad value", "view-port-negative", ["view", "{fx}/ok.npz", "--port", "-1"], r"expected a port in 0\.\.65535"),
    _r3("bad value", "view-port-70000", ["view", "{fx}/ok.npz", "--port", "70000"], r"expected a port in 0\.\.65535"),
    _r3("bad value", "view-port-word", ["view", "{fx}/ok.npz", "--port", "http"], r"expected a port in 0\.\.65535"),
    _r3("bad value", "view-record-suffix", ["view", "{fx}/ok.npz", "--record", "x.txt"],
        r"--record must name a \.gif or \.mp4 file"),
    _r3("bad value", "view-record-under-file", ["view", "{fx}/ok.npz", "--record", "{fx}/afile/x.gif"],
        r"--record folder .*afile exists and is not a directory"),
    _r3("bad value", "view-host-unresolvable", ["view", "{fx}/ok.npz", "--host", "999.1.1.1", "--port", "0"],
        r"--host 999\.1\.1\.1: cannot be resolved"),
    _r3("bad value", "view-host-not-here", ["view", "{fx}/ok.npz", "--host", "192.0.2.1", "--port", "0"],
        r"--host 192\.0\.2\.1 --port 0: cannot listen there"),
    _r3("bad file", "play-missing", ["play", "nowhere.pt"], r"nowhere\.pt: no such policy checkpoint"),
    _r3("bad value", "play-joystick-record", ["play", "joystick_walk_default", "--record", "x.txt"],
        r"--record must name a \.gif or \.mp4"),
    _r3("bad value", "play-timed", ["play", "timed_walk_default"], r"this policy's task is 'timed'"),
    _r3("bad value", "play-route-a-reach-joint-policy", ["play", "reach_joint_default", "--route", "0.5"],
        r"--route: only reach, path and joystick policies walk to a place on the floor; this policy's task is "
        r"'reach_joint'"),
    _r3("bad value", "play-route-of-three-metres", ["play", "reach_walk_default", "--route", "3"],
        r"--route: expected the route's clearance in metres, in \[0, 2\] \(0: off\), got 3\.0"),
    _r3("bad file", "play-etc-passwd", ["play", "/etc/passwd"], r"/etc/passwd: not a readable torch file"),
    _r3("hostile file", "play-evil", ["play", "{fx}/evil.pt"], r"evil\.pt: refused to load"),
    _r3("hostile file", "play-bit-flip", ["play", "{fx}/flipped.pt", "--motion", "{fx}/motion.pt"],
        r"flipped\.pt: policy weights do not match"),
    _r3("bad value", "play-long-text", ["play", "reach_walk_default", "--text", "{LONG}"], r"has 1001 characters"),
    _r3("bad value", "play-device", ["play", "reach_walk_default", "--device", "tpu"], r"unknown device 'tpu'"),
    _r3("bad value", "play-seed", ["play", "reach_walk_default", "--seed", "-1"], r"argument --seed: must lie in"),
    _r3("bad value", "play-record-suffix", ["play", "reach_walk_default", "--record", "x.txt"],
        r"--record must name a \.gif or \.mp4"),
    _r3("bad file", "play-motion-missing", ["play", "reach_walk_default", "--motion", "nowhere.pt"],
        r"motion model not found: nowhere\.pt"),
    _r3("bad file", "play-motion-etc-passwd", ["play", "reach_walk_default", "--motion", "/etc/passwd"],
        r"/etc/passwd: not a readable torch file"),
    _r3("bad value", "play-port-word", ["play", "reach_walk_default", "--port", "x"], r"expected a port in 0\.\.65535"),
]
SCENES = {  # scene files (latentrl.scene/1): name -> (content, what the line must say)
    "bad": ('{"format": ', r"invalid JSON: Expecting value"),
    "list": ("[1]", r"scene: expected a JSON object with 'format' and 'objects'"),
    "format": ('{"format": "latentrl.scene/2", "objects": []}',
               r"format: expected 'latentrl\.scene/1', got .*scene/2'"),
    "objects-65": (json.dumps({"format": "latentrl.scene/1", "objects": [
        {"type": "box", "center": [1, 2], "size": [0.6, 0.4, 1.0]}] * 65}), r"65 objects, more than the 64 allowed"),
    "size-nan": ('{"format": "latentrl.scene/1", "objects": [{"type": "box", "center": [1, 2], "size": [NaN, 1, 1]}]}',
                 r"objects\[0\]\.size\[0\]: expected a finite number, got nan"),
    "center-inf": ('{"format": "latentrl.scene/1", "objects": [{"type": "cylinder", "center": [1, Infinity], '
                   '"radius": 0.3, "height": 1}]}', r"objects\[0\]\.center\[1\]: expected a finite number, got inf"),
    "radius-negative": (json.dumps({"format": "latentrl.scene/1", "objects": [
        {"type": "cylinder", "center": [1, 2], "radius": -0.3, "height": 1}]}),
        r"objects\[0\]\.radius: .*> 0, got -0\.3"),
    "size-1e6": (json.dumps({"format": "latentrl.scene/1", "objects": [
        {"type": "box", "center": [1, 2], "size": [1e6, 1, 1]}]}),
        r"objects\[0\]\.size\[0\]: expected a number in \[0, 100\]"),
    "type-sphere": (json.dumps({"format": "latentrl.scene/1", "objects": [{"type": "sphere", "center": [1, 2]}]}),
                    r"objects\[0\]\.type: expected one of box, cylinder, seat, stairs, got 'sphere'"),
    "stairs-1e6": (json.dumps({"format": "latentrl.scene/1", "objects": [
        {"type": "stairs", "start": [0, 1], "direction_deg": 0, "width": 1, "riser": 0.1, "tread": 0.3,
         "count": 10**6}]}), r"objects\[0\]\.count: expected an integer in \[1, 32\], got 1000000"),
    "oversized": (b" " * ((1 << 20) + 1), r"1,048,577 bytes is larger than the 1 MiB a scene file may have"),
    "deep": ("[" * 200_000 + "]" * 200_000, r"JSON nested too deeply for a scene file"),
    "utf16": ('{"format": "latentrl.scene/1", "objects": []}'.encode("utf-16"), r"not a UTF-8 text file"),
}
HOSTILE_SCENES = {"objects-65", "size-1e6", "stairs-1e6", "oversized", "deep", "utf16"}
GOAL = {"joint": "pelvis", "target": [0, 0.3], "time": 0.5}


def _goals(**change) -> str:
    return json.dumps([{"text": "walk", "goals": [{**GOAL, **change}]}])


GOALS = {  # joint-goal files (docs/joint_goals.md): name -> (content, what the line must say)
    "target-nan": (_goals().replace("0.3", "NaN"), r"entry 0, goal 0: field 'target' must be .*got \[0, nan\]"),
    "time-nan": (_goals().replace("0.5", "NaN"), r"field 'time' must be seconds in \(0, 3600\] or \"asap\", got nan"),
    "time-negative": (_goals(time=-1), r"field 'time' must be seconds in \(0, 3600\].*got -1"),
    "time-1e9": (_goals(time=1e9), r"field 'time' must be seconds .*got 1000000000\.0"),
    "time-word": (_goals(time="soon"), r"field 'time' must be seconds .*got 'soon'"),
    "joint-tail": (_goals(joint="tail"), r"field 'joint' must be one of pelvis, .*got 'tail'"),
    "object": ('{"text": "walk"}', r"expected a non-empty list of entries .*got dict"),
    "target-4": (_goals(target=[0, 1, 2, 3]), r"field 'target' must be \[x, y, z\] or \[x, y\]"),
    "foot-3d": (_goals(joint="left_foot", target=[0, 1, 2]), r"field 'target' must be \[x, y\] \(a foot's target"),
    "no-text": ('[{"goals": []}]', r"entry 0: missing field 'text'"),
    "goals-2000": (json.dumps([{"text": "walk", "goals": [{**GOAL, "time": 0.5 + i} for i in range(2000)]}]),
                   r"field 'goals' must be a list of 1 to 1000 goals, got list of 2000"),
    "entries-20000": (json.dumps([{"text": "walk", "goals": [GOAL]}] * 20_000),
                      r"20000 entries, more than the 1000 a file may hold"),
    "truncated": ("[{", r"invalid JSON: Expecting property name"),
}
HOSTILE_GOALS = {"goals-2000", "entries-20000"}
SUITE_SCENES = {  # a constraint suite's problem naming a scene file: name -> (its "scene" value)
    "nan": "{fx}/scenes/size-nan.json", "oversized": "{fx}/scenes/oversized.json", "dev-zero": "/dev/zero",
    "folder": "{fx}/scenes", "missing": "nowhere_scene.json",
}


def _round3_late_files(root: Path, model, motion: Path) -> None:
    """Scene files, joint-goal files, a ReachJoint policy, a NaN motion and hostile links for the later rows."""
    from latentrl.envs.reach_joint import ReachJointEnv
    from latentrl.motion.checkpoint import file_sha256
    from latentrl.ppo.checkpoint import make_checkpoint, save_checkpoint
    from latentrl.ppo.config import PolicyConfig
    from latentrl.ppo.policy import ActorCritic

    for folder, cases in (("scenes", SCENES), ("goals", GOALS)):
        (root / folder).mkdir()
        for name, (data, _) in cases.items():
            (root / folder / f"{name}.json").write_bytes(data if isinstance(data, bytes) else data.encode())
    (root / "scenes" / "ok.json").write_text(json.dumps({"format": "latentrl.scene/1", "objects": []}))
    (root / "goals" / "ok.json").write_text(_goals())
    (root / "zero-link.json").symlink_to("/dev/zero")
    (root / "dangling.json").symlink_to(root / "nowhere.json")
    np.savez(root / "nanmotion.npz", joints=np.full((5, 22, 3), np.nan, np.float32), fps=30.0)
    joint = {"type": "joint", "frame": 10, "joint": "pelvis", "position": [0.0, 1.0, 0.9]}
    for name, scene in SUITE_SCENES.items():
        problem = {"name": "p", "start": {"seed": 1}, "text": "walk", "primitives": 2, "constraints": [joint],
                   "scene": scene.format(fx=root)}
        (root / "suites" / f"scene-{name}.json").write_text(
            json.dumps({"format": "latentrl.constraints/1", "problems": [problem]}))
    env = ReachJointEnv(1, motion=model)
    torch.manual_seed(0)
    policy = ActorCritic(env.single_observation_space.shape[0], env.single_action_space.shape[0],
                         PolicyConfig(latent_dim=32), env.metadata["observation_layout"])
    state = make_checkpoint(trainer="native", iteration=0, env_steps=0, elapsed_s=0.0, policy=policy,
                            optimizer=torch.optim.Adam(policy.parameters()),
                            config={"env": {"task": "reach_joint", "texts": ["walk"]}},
                            motion={"path": str(motion), "sha256": file_sha256(motion)})
    save_checkpoint(state, root / "reach_joint.pt")


RJ_EVAL = ["eval", "{fx}/reach_joint.pt", "--motion", "{fx}/motion.pt", "--episodes", "1", "--render", "0"]
RJ_TRAIN = [*TRAIN, "--set", "env.task=reach_joint"]
TRACK = ["physics", "track", "{fx}/ok.npz", "--out", "o"]
LOOP = ["physics", "loop", "--motion", "{fx}/motion.pt", "--out", "o"]
ROUND3 += [  # scenes, joint goals, physics: the formats and commands added after the rows above
    # ------------------------------------------------ scene files through eval --scene and env.scene
    *[_r3("hostile file" if name in HOSTILE_SCENES else "bad file", f"eval-scene-{name}",
          [*EVAL, "--paths", "dart_demo_walk", "--scene", f"{{fx}}/scenes/{name}.json"],
          rf"--scene: .*{re.escape(name)}\.json: .*{pattern}") for name, (_, pattern) in SCENES.items()],
    _r3("bad file", "eval-scene-missing", [*EVAL, "--scene", "nowhere_scene"],
        r"scene file not found: nowhere_scene \(looked in .*tasks/scenes\)"),
    _r3("bad file", "eval-scene-folder", [*EVAL, "--scene", "{fx}/scenes"], r"scene file not found: .*scenes \("),
    _r3("hostile file", "eval-scene-dev-zero", [*EVAL, "--scene", "/dev/zero"], r"scene file not found: /dev/zero"),
    _r3("hostile file", "eval-scene-link-to-dev-zero", [*EVAL, "--scene", "{fx}/zero-link.json"],
        r"scene file not found: .*zero-link\.json"),
    _r3("bad file", "eval-scene-dangling-link", [*EVAL, "--scene", "{fx}/dangling.json"],
        r"scene file not found: .*dangling\.json"),
    _r3("bad file", "eval-scene-etc-passwd", [*EVAL, "--scene", "/etc/passwd"], r"/etc/passwd: invalid JSON"),
    _r3("bad file", "train-scene-nan", [*TRAIN, "--set", "env.scene={fx}/scenes/size-nan.json"],
        r"env\.scene: .*size-nan\.json: objects\[0\]\.size\[0\]: expected a finite number, got nan"),
    _r3("hostile file", "train-scene-oversized", [*TRAIN, "--set", "env.scene={fx}/scenes/oversized.json"],
        r"env\.scene: .*1,048,577 bytes is larger than the 1 MiB"),
    _r3("bad file", "train-scene-folder", [*TRAIN, "--set", "env.scene={fx}/scenes"],
        r"env\.scene: scene file not found"),
    _r3("hostile file", "train-scene-dev-zero", [*TRAIN, "--set", "env.scene=/dev/zero"],
        r"env\.scene: scene file not found: /dev/zero"),
    _r3("bad value", "train-scene-random-count",
        [*TRAIN, "--set", "env.scene={{random_obstacles: {{count: [3, 1000000]}}}}"],
        r"random_obstacles\.count: expected \[min, max\] integers with 0 <= min <= max <= 64"),
    _r3("bad value", "train-scene-random-typo", [*TRAIN, "--set", "env.scene={{random_obstacles: {{counts: 3}}}}"],
        r"random_obstacles\.counts: unknown setting \(did you mean 'count'\?\)"),
    _r3("bad value", "train-scene-inline-nan",
        [*TRAIN, "--set", "env.scene={{format: latentrl.scene/1, objects: [{{type: box, center: [1, 2], "
                          "size: [.nan, 1, 1]}}]}}"],
        r"env\.scene: objects\[0\]\.size\[0\]: expected a finite number, got nan"),
    _r3("bad value", "train-scene-number", [*TRAIN, "--set", "env.scene=5"],
        r"env\.scene: expected a scene file, a latentrl\.scene/1 object, \{random_obstacles: \{\.\.\.\}\}, "
        r"\{random_mazes: \{\.\.\.\}\} or \{random_stairs"),
    *[_r3(kind, f"optimize-suite-scene-{name}", ["optimize", f"{{fx}}/suites/scene-{name}.json", "--no-progress"],
          pattern) for name, kind, pattern in (
        ("nan", "bad file", r"size-nan\.json: objects\[0\]\.size\[0\]: expected a finite number, got nan"),
        ("oversized", "hostile file", r"oversized\.json: 1,048,577 bytes is larger than the 1 MiB a scene file"),
        ("dev-zero", "hostile file", r"/dev/zero: not a regular file \(a device or pipe\); expected a scene file"),
        ("folder", "bad file", r"scenes: not a regular file \(a folder\); expected a scene file"),
        ("missing", "bad file", r"scene file not found: .*nowhere_scene\.json"))],
    # ------------------------------------------------ joint-goal files through eval of a ReachJoint policy
    *[_r3("hostile file" if name in HOSTILE_GOALS else "bad file", f"eval-joint-goals-{name}",
          [*RJ_EVAL, "--paths", f"{{fx}}/goals/{name}.json"], rf"{re.escape(name)}\.json: .*{pattern}")
      for name, (_, pattern) in GOALS.items()],
    _r3("bad file", "eval-joint-goals-missing", [*RJ_EVAL, "--paths", "nowhere_goals"],
        r"path file not found: nowhere_goals \(give a file, or one of the suites \['hands_walk', 'pelvis_far'"),
    _r3("hostile file", "eval-joint-goals-link-to-dev-zero", [*RJ_EVAL, "--paths", "{fx}/zero-link.json"],
        r"path file not found: .*zero-link\.json"),
    _r3("bad file", "eval-joint-goals-scene-file", [*RJ_EVAL, "--paths", "{fx}/scenes/ok.json"],
        r"ok\.json: expected a non-empty list of entries"),
    _r3("bad file", "eval-reach-policy-joint-goals", [*EVAL, "--paths", "{fx}/goals/ok.json"],
        r"ok\.json: path 0: unknown field 'text' \(did you mean 'goal_text'\?\)"),
    # ------------------------------------------------ env.reach_joint settings (train --set)
    *[_r3("bad value", f"train-reach-joint-{value.replace('=', '-').replace('[', '').replace(']', '')}",
          [*RJ_TRAIN, "--set", f"env.reach_joint.{value}"], rf"env\.reach_joint\.{value.split('=')[0]}: {pattern}")
      for value, pattern in {
          "radius=nan": r"must be metres > 0, got nan", "radius=-1": r"must be metres > 0, got -1\.0",
          "near_share=1.5": r"must be a share in \[0, 1\], got 1\.5",
          "far_time=[4,1]": r"must be \[min, max\] with 0\.0333 <= min <= max, got \[4\.0, 1\.0\]",
          "far_time=[0,1]": r"must be \[min, max\] with 0\.0333 <= min", "far_time=[1,1e9]": r"must end by 3600 s",
          "distance=[0,.inf]": r"must be \[min, max\] with 0 <= min <= max, got \[0\.0, inf\]",
          "max_speed=0": r"must be m/s > 0, got 0\.0", "angle_deg=200": r"must be degrees in \[0, 180\], got 200\.0",
          "joints=[tail]": r"unknown joint 'tail'", "joints=[]": r"must list goal joints from",
          "planar=[tail]": r"unknown joint 'tail'", "height_offset=[-100,0]": r"must be \[min, max\] with -10 <= min",
      }.items()],
    _r3("bad file", "train-reach-joint-goals-missing", [*RJ_TRAIN, "--set", "env.reach_joint.goals=nowhere"],
        r"goals: joint-goal file not found: nowhere"),
    _r3("bad file", "train-reach-joint-goals-nan",
        [*RJ_TRAIN, "--set", "env.reach_joint.goals={fx}/goals/target-nan.json"],
        r"target-nan\.json: entry 0, goal 0: field 'target'"),
    # ------------------------------------------------ physics track / loop (MuJoCo)
    _r3("bad file", "physics-track-missing", ["physics", "track", "nowhere.npz", "--out", "o"],
        r"motion file not found: nowhere\.npz"),
    _r3("bad file", "physics-track-nan", ["physics", "track", "{fx}/nanmotion.npz", "--out", "o"],
        r"nanmotion\.npz: field 'joints' holds NaN or inf in 5 of 5 frames"),
    _r3("hostile file", "physics-track-dev-zero", ["physics", "track", "/dev/zero", "--out", "o"],
        r"motion file not found: /dev/zero"),
    _r3("bad file", "physics-track-folder", ["physics", "track", "{fx}/scenes", "--out", "o"],
        r"motion file not found: .*scenes"),
    _r3("hostile file", "physics-track-pickle", ["physics", "track", "{fx}/scenes/ok.json", "--out", "o"],
        r"ok\.json: not a readable motion \.npz"),
    _r3("bad file", "physics-track-bad-shape", ["physics", "track", "{fx}/badshape.npz", "--out", "o"],
        r"badshape\.npz: field 'joints' must be \(T, 22, 3\)"),
    _r3("bad value", "physics-track-out-is-file", [*TRACK[:-1], "{fx}/afile"],
        r"--out .*afile exists and is not a dir"),
    _r3("bad value", "physics-track-out-under-file", [*TRACK[:-1], "{fx}/afile/x"], r"--out .*afile is a file"),
    _r3("bad value", "physics-track-no-out", TRACK[:-2], r"the following arguments are required: --out"),
    *[_r3("bad value", f"physics-track-{flag[2:]}-{value}", [*TRACK, flag, value], pattern)
      for flag, value, pattern in (
        ("--height", "nan", r"--height must be in \[1\.0, 2\.5\] m, got nan"),
        ("--height", "-1", r"--height must be in \[1\.0, 2\.5\] m, got -1\.0"),
        ("--height", "100", r"--height must be in \[1\.0, 2\.5\] m, got 100\.0"),
        ("--assist-hz", "nan", r"--assist-hz must be in \[0, 50\] \(0 switches the root assist off\), got nan"),
        ("--assist-hz", "-2", r"--assist-hz must be in \[0, 50\].*got -2\.0"),
        ("--assist-hz", "1e9", r"--assist-hz must be in \[0, 50\].*got 1000000000\.0"))],
    *[_r3("bad value", f"physics-loop-{flag[2:]}-{value or 'empty'}", [*LOOP, flag, value], pattern)
      for flag, value, pattern in (
        ("--seconds", "nan", r"--seconds must be in \(0, 3600\], got nan"),
        ("--seconds", "-1", r"--seconds must be in \(0, 3600\], got -1\.0"),
        ("--seconds", "1e9", r"--seconds must be in \(0, 3600\], got 1000000000\.0"),
        ("--text", "", r"--text: prompt '' is empty"), ("--text", "{LONG}", r"--text: .*has 1001 characters"),
        ("--seed", "-1", r"--seed: must lie in \[0, 2\*\*32 - 1"),
        ("--height", "inf", r"--height must be in .*got inf"),
        ("--assist-hz", "inf", r"--assist-hz must be in \[0, 50\].*got inf"))],
    _r3("bad file", "physics-loop-motion-missing", ["physics", "loop", "--motion", "nowhere.pt", "--out", "o"],
        r"motion model not found: nowhere\.pt"),
    _r3("bad file", "physics-loop-motion-etc-passwd", ["physics", "loop", "--motion", "/etc/passwd", "--out", "o"],
        r"/etc/passwd: not a readable torch file"),
    _r3("hostile file", "physics-loop-motion-evil", ["physics", "loop", "--motion", "{fx}/evil.pt", "--out", "o"],
        r"evil\.pt: refused to load"),
    _r3("bad value", "physics-loop-out-is-file", ["physics", "loop", "--out", "{fx}/afile"],
        r"--out .*afile exists and is not a directory"),
    _r3("bad value", "physics-loop-no-out", ["physics", "loop"], r"the following arguments are required: --out"),
    _r3("bad value", "physics-no-subcommand", ["physics"], r"the following arguments are required: SUBCOMMAND"),
    _r3("bad value", "physics-unknown-subcommand", ["physics", "fly"], r"argument SUBCOMMAND: invalid choice: 'fly'"),
    # ------------------------------------------------ leftovers: play's empty text, bench's --compile preflight
    _r3("bad value", "play-empty-text", ["play", "reach_walk_default", "--text", ""], r"--text: prompt '' is empty"),
    _r3("bad value", "play-blank-text", ["play", "reach_walk_default", "--text", "   "],
        r"--text: prompt '   ' is empty"),
    _r3("fault", "bench-rollout-compile-no-compiler", ["bench", "rollout", "--device", "cpu", "--compile"],
        r"--compile: torch\.compile on the CPU needs a C\+\+ compiler.*or leave out --compile", NO_CXX),
    _r3("fault", "bench-env-compile-no-compiler", ["bench", "env", "--device", "cpu", "--compile"],
        r"--compile: torch\.compile on the CPU needs a C\+\+ compiler.*or leave out --compile", NO_CXX),
    _r3("fault", "bench-rollout-compile-cache-proc", ["bench", "rollout", "--device", "cpu", "--compile"],
        r"--compile: torch\.compile's cache folder /proc/inductor .*or leave out --compile",
        {"TORCHINDUCTOR_CACHE_DIR": "/proc/inductor"}),
]
ROWS += ROUND3


def _npy_header_only(shape: tuple, dtype: str) -> bytes:
    """A ``.npy`` member that announces ``shape`` but holds 64 bytes: what a decompression bomb's header says."""
    import io

    from numpy.lib import format as npy

    buf = io.BytesIO()
    npy.write_array_header_1_0(buf, {"descr": npy.dtype_to_descr(np.dtype(dtype)), "fortran_order": False,
                                     "shape": shape})
    return buf.getvalue() + b"\0" * 64


def _security_files(root: Path) -> None:
    """Malformed and hostile motions and reports (issue 47): each field of the motion schema, a 20 M-frame header,
    a member announcing 3.2 GB, report entries of the wrong type, a report's motion outside its folder."""
    import io
    import zipfile

    sec = root / "sec"
    sec.mkdir()
    joints = np.zeros((10, 22, 3), np.float32)
    for name, fields in {
        "texts-0d": {"texts": np.array("walk")}, "texts-int": {"texts": np.arange(10)},
        "contacts-shape": {"contacts": np.zeros(3, bool)}, "goals-shape": {"goals": np.zeros((2, 2), np.float32)},
        "goals-nan": {"goals": np.full((2, 3), np.nan, np.float32)},
        "waypoints-shape": {"waypoints": np.ones(4, np.float32)}, "floor-array": {"floor": np.zeros(3)},
        "floor-word": {"floor": np.array("low")}, "fps-1e-300": {"fps": 1e-300},
        "primitive-text": {"primitive": np.array(["x"] * 10)}, "actions-inf": {"actions": np.full((2, 4), np.inf)},
        "features-short": {"features": np.zeros((10, 5), np.float32)}, "scene-int": {"scene": np.array(5)},
    }.items():
        np.savez(sec / f"{name}.npz", joints=joints, **fields)
    good = io.BytesIO()
    np.save(good, joints)
    with zipfile.ZipFile(sec / "frames-20m.npz", "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("joints.npy", _npy_header_only((20_000_000, 22, 3), "<f4"))
    with zipfile.ZipFile(sec / "bomb.npz", "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("joints.npy", good.getvalue())
        zf.writestr("features.npy", _npy_header_only((400_000_000,), "<f8"))
    (sec / "bomb-suite.json").write_text(json.dumps({"format": "latentrl.constraints/1", "problems": [
        {"name": "p", "start": {"motion": "bomb.npz"}, "text": "walk", "primitives": 1, "constraints": [
            {"type": "joint", "frame": 4, "joint": "pelvis", "position": [0.0, 1.0, 0.9]}]}]}))

    def evaluation(name: str, episode: dict | None = None, path: dict | None = None, top: dict | None = None) -> None:
        folder = sec / name
        folder.mkdir()
        np.savez(folder / "m.npz", joints=joints)
        entry = {"index": 0, "metrics": {}, "waypoints": [[0, 1, 0]],
                 "episodes": [{"episode": 0, "motion": "m.npz", "success": True, **(episode or {})}], **(path or {})}
        report = {"format": "latentrl.eval/1", "settings": {}, "overall": {"metrics": {}},
                  "suites": {"s": {"metrics": {}, "paths": [entry]}}, **(top or {})}
        (folder / "report.json").write_text(json.dumps(report))

    evaluation("eval-episode-word", {"episode": "x"})
    evaluation("eval-motion-int", {"motion": 5})
    evaluation("eval-motion-outside", {"motion": "../eval-motion-int/m.npz"})
    evaluation("eval-end-object", {"end": {"a": 1}})
    evaluation("eval-waypoint-pair", path={"waypoints": [[0, 1]]})
    evaluation("eval-episodes-object", path={"episodes": {"0": 1}})
    evaluation("eval-policy-int", top={"policy": 5})
    for name, problem, top in (
            ("opt-metric-word", {"metrics": {"goal_error_cm": {"mean": "x"}}}, {}),
            ("opt-frame-1e30", {"targets": [{"motion_frame": 10**30, "position": [0, 0, 0]}]}, {}),
            ("opt-suite-object", {}, {"suite": {"x": 1}})):
        folder = sec / name
        folder.mkdir()
        np.savez(folder / "m.npz", joints=joints)
        (folder / "report.json").write_text(json.dumps({"format": "latentrl.optimize-report/1", "overall": {},
                                                        "problems": [{"name": "a", "motion": "m.npz", **problem}],
                                                        **top}))


SEC = "{fx}/sec"
BVH = ["motion", "export-bvh"]
SECURITY = [
    # ------------------------------------------------ motion files: every schema field, frames, decompressed size
    *[_r3("bad file", f"view-{name}", ["view", f"{SEC}/{name}.npz"], rf"{re.escape(name)}\.npz: field {pattern}")
      for name, pattern in {
          "texts-0d": r"'texts' must be \(10,\) text", "texts-int": r"'texts' must be \(10,\) text",
          "contacts-shape": r"'contacts' must be \(10, 2\) booleans", "goals-shape": r"'goals' must be \(N, 3\)",
          "goals-nan": r"'goals' holds NaN or inf", "waypoints-shape": r"'waypoints' must be \(N, 3\)",
          "floor-array": r"'floor' must be one real number", "floor-word": r"'floor' must be one real number",
          "fps-1e-300": r"'fps' must lie in \[0\.001, 1000\], got 1e-300",
          "primitive-text": r"'primitive' must be \(10,\) integers", "actions-inf": r"'actions' holds NaN or inf",
          "features-short": r"'features' must be \(10, 276\)", "scene-int": r"'scene' must be the scene's JSON text",
      }.items()],
    _r3("hostile file", "view-frames-20m", ["view", f"{SEC}/frames-20m.npz"],
        r"frames-20m\.npz: field 'joints' has 20,000,000 frames; a motion may have at most 1,000,000"),
    _r3("hostile file", "view-decompression-bomb", ["view", f"{SEC}/bomb.npz"],
        r"bomb\.npz: its arrays decompress to more than 1 GiB \(field 'features' alone is 3,200,000,000 bytes\)"),
    _r3("hostile file", "view-folder-with-bomb", ["view", SEC], r"sec/actions-inf\.npz: field 'actions' holds NaN"),
    _r3("hostile file", "export-bvh-frames-20m", [*BVH, f"{SEC}/frames-20m.npz"], r"has 20,000,000 frames"),
    _r3("hostile file", "export-bvh-decompression-bomb", [*BVH, f"{SEC}/bomb.npz"], r"decompress to more than 1 GiB"),
    _r3("bad file", "export-bvh-fps-1e-300", [*BVH, f"{SEC}/fps-1e-300.npz"], r"'fps' must lie in \[0\.001, 1000\]"),
    _r3("bad file", "export-bvh-goals-nan", [*BVH, f"{SEC}/goals-nan.npz"], r"'goals' holds NaN or inf"),
    _r3("hostile file", "optimize-start-decompression-bomb", ["optimize", f"{SEC}/bomb-suite.json", "--no-progress",
                                                             "--steps", "1"], r"bomb\.npz: its arrays decompress"),
    # ------------------------------------------------ reports: entries of the wrong type, motions outside the folder
    _r3("bad file", "view-eval-episode-word", ["view", f"{SEC}/eval-episode-word"],
        r"field 'suites\.s\.paths\.0\.episodes\.0\.episode' must be an integer >= 0, got 'x'"),
    _r3("bad file", "view-eval-motion-int", ["view", f"{SEC}/eval-motion-int"], r"episodes\.0\.motion' must be null"),
    _r3("hostile file", "view-eval-motion-outside", ["view", f"{SEC}/eval-motion-outside"],
        r"episodes\.0\.motion' '\.\./eval-motion-int/m\.npz' points outside the report's folder"),
    _r3("bad file", "view-eval-end-object", ["view", f"{SEC}/eval-end-object"], r"episodes\.0\.end' must be a string"),
    _r3("bad file", "view-eval-waypoint-pair", ["view", f"{SEC}/eval-waypoint-pair"],
        r"paths\.0\.waypoints' must be a list of \[x, y, z\] finite numbers"),
    _r3("bad file", "view-eval-episodes-object", ["view", f"{SEC}/eval-episodes-object"],
        r"paths\.0\.episodes' must be a list"),
    _r3("bad file", "view-eval-policy-int", ["view", f"{SEC}/eval-policy-int"], r"field 'policy' must be an object"),
    _r3("bad file", "view-optimize-metric-word", ["view", f"{SEC}/opt-metric-word"],
        r"problems\.0\.metrics\.goal_error_cm' must be a number or null"),
    _r3("hostile file", "view-optimize-frame-1e30", ["view", f"{SEC}/opt-frame-1e30"],
        r"targets\.0\.motion_frame' must be an integer in \[0, 1000000\]"),
    _r3("bad file", "view-optimize-suite-object", ["view", f"{SEC}/opt-suite-object"],
        r"field 'suite' must be a string"),
    _r3("bad file", "compare-episode-word", ["compare", f"{SEC}/eval-episode-word", f"{SEC}/eval-end-object"],
        r"eval-episode-word/report\.json: field .*episode' must be an integer"),
    # ------------------------------------------------ config values: NaN and +/-inf in any float field
    *[_r3("bad value", f"train-{key.replace('.', '-')}-{name}", [*TRAIN, "--set", f"{key}={value}"],
          rf"{re.escape(key)}: must be (a finite number|finite numbers only) \(not NaN or inf\)")
      for key, value, name in (("ppo.adam_eps", ".inf", "inf"), ("ppo.max_grad_norm", ".inf", "inf"),
                               ("ppo.target_kl", ".inf", "inf"), ("policy.action_scale", ".inf", "inf"),
                               ("policy.obs_norm_clip", ".inf", "inf"), ("env.reach.goal_angle_deg", ".nan", "nan"),
                               ("env.timed.time_left_clip", ".inf", "inf"), ("eval.success_target", "-.inf", "-inf"),
                               ("env.reach.goal_distance", "[0.5,.inf]", "list-inf"),
                               ("policy.log_std_bounds", "[-.inf,1.0]", "tuple-inf"))],
    *[_r3("bad value", f"motion-train-{key.replace('.', '-')}-{name}",
          ["motion", "train", "{MTINY}", "--set", f"{key}={value}"],
          rf"{re.escape(key)}: must be a finite number \(not NaN or inf\)")
      for key, value, name in (("vae_train.learning_rate", ".inf", "inf"), ("model.vae.dropout", ".nan", "nan"),
                               ("denoiser_train.grad_clip", "-.inf", "-inf"),
                               ("data.locomotion.start_half_size", ".nan", "nan"))],
]
RB, EB = ["bench", "rollout", "--device", "cpu", "--models", "default"], ["bench", "env", "--device", "cpu"]
SECURITY += [
    # ------------------------------------------------ NaN, inf and unbounded sizes in bench, export and --nproc flags
    *[_r3("bad value", f"bench-motion-guidance-{value}", ["bench", "motion", "--guidance", value],
          rf"argument --guidance: must be a finite number in \[-100, 100\], got {value}")
      for value in ("nan", "1e30", "inf")],
    _r3("bad value", "bench-rollout-amp-fp16-cpu", [*RB, "--amp", "fp16", "--batches", "1", "--repeats", "1"],
        r"--amp fp16: fp16 autocast runs on CUDA only, and the devices include cpu; use --amp bf16 on the CPU"),
    _r3("bad value", "bench-env-amp-fp16-cpu", [*EB, "--amp", "fp16", "--num-envs", "1", "--steps", "1"],
        r"--amp fp16: fp16 autocast runs on CUDA only"),
    *[_r3("bad value", f"{rid}", argv, rf"argument {flag}: must be at most {bound}, got {value}")
      for rid, argv, flag, bound, value in (
          ("bench-rollout-batches-2-20-plus-1", [*RB, "--batches", "1", "1048577"], "--batches", "1,048,576", 1048577),
          ("bench-rollout-repeats-1e9", [*RB, "--repeats", "1000000000"], "--repeats", "100,000", 1000000000),
          ("bench-rollout-rounds-1e9", [*RB, "--rounds", "1000000000"], "--rounds", "100,000", 1000000000),
          ("bench-rollout-threads-100000", [*RB, "--threads", "100000"], "--threads", "1,024", 100000),
          ("bench-env-num-envs-1e12", [*EB, "--num-envs", "1000000000000"], "--num-envs", "1,048,576",
           1000000000000),
          ("bench-env-steps-1e9", [*EB, "--steps", "1000000000"], "--steps", "100,000", 1000000000),
          ("bench-env-threads-100000", [*EB, "--threads", "100000"], "--threads", "1,024", 100000),
          ("bench-env-max-seconds-1e300", [*EB, "--max-seconds", "1e300"], "--max-seconds", "86,400", "1e300"),
          ("bench-motion-seconds-1e9", ["bench", "motion", "--seconds", "1e9"], "--seconds", "3,600", "1e9"),
          ("bench-motion-batch-1e6", ["bench", "motion", "--batch", "1000000"], "--batch", "1,024", 1000000),
          ("bench-train-iterations-1e9", ["bench", "train", "--iterations", "1000000000"], "--iterations", "100,000",
           1000000000),
          ("bench-train-threads-100000", ["bench", "train", "--threads", "100000"], "--threads", "1,024", 100000),
          ("bench-optimize-batch-1e6", ["bench", "optimize", "--batch", "1000000"], "--batch", "4,096", 1000000),
          ("bench-optimize-batches-1e6", ["bench", "optimize", "--batches", "1000000"], "--batches", "4,096",
           1000000),
          ("bench-optimize-steps-1e9", ["bench", "optimize", "--steps", "1000000000"], "--steps", "100,000",
           1000000000),
          ("export-onnx-batch-2-20-plus-1", ["export", "onnx", "reach_walk_default", "--out", "c.onnx", "--batch",
                                             "1048577"], "--batch", "1,048,576", 1048577))],
    _r3("bad value", "bench-env-max-seconds-inf", [*EB, "--max-seconds", "inf"],
        r"argument --max-seconds: must be > 0"),
    _r3("bad value", "train-nproc-100000", [*TRAIN, "--nproc", "100000"],
        r"argument --nproc: must be at most this machine's \d+ CPU cores, got 100000"),
    _r3("bad value", "bench-train-nproc-100000", ["bench", "train", "--nproc", "1", "100000"],
        r"argument --nproc: must be at most this machine's \d+ CPU cores"),
    # ------------------------------------------------ memory estimated before allocation (far beyond any machine)
    _r3("bad value", "train-num-envs-2-20-memory", [*TRAIN, "--set", "env.num_envs=1048576", "--set",
                                                    "ppo.num_steps=64"],
        r"env\.num_envs: training 1 rank of 1,048,576 envs x 64 steps on the CPU needs about [\d,.]+ GiB of memory; "
        r"this machine has [\d,.]+ GiB available; lower env\.num_envs or ppo\.num_steps"),
    _r3("bad value", "train-widest-policy-memory", [*TRAIN, "--set", "policy.latent_dim=16384", "--set",
                                                    "policy.n_blocks=64"],
        r"policy\.latent_dim: training .* needs about [\d,.]+ GiB of memory; .*make the policy narrower"),
    _r3("bad value", "train-widest-mlp-memory", [*TRAIN, "--set", "policy.architecture=mlp", "--set",
                                                 f"policy.mlp_hidden=[{','.join(['16384'] * 64)}]"],
        r"policy\.mlp_hidden: training .* needs about [\d,.]+ GiB"),
    _r3("bad value", "train-nproc-memory", [*NPROC, "--set", "env.num_envs=1048576", "--set", "ppo.num_steps=64"],
        r"--nproc: training 2 ranks of 1,048,576 envs .* use fewer ranks"),
    _r3("bad value", "bench-rollout-batches-2-20-memory", [*RB, "--batches", "1", "1048576"],
        r"--batches: a sampler batch of 1,048,576 needs about [\d,.]+ GiB of memory; .*lower --batches"),
    _r3("bad value", "bench-env-num-envs-2-20-memory", [*EB, "--num-envs", "1048576"],
        r"--num-envs: a batched env of 1,048,576 needs about [\d,.]+ GiB of memory"),
    _r3("bad value", "export-onnx-batch-2-20-memory", ["export", "onnx", "reach_walk_default", "--out", "c.onnx",
                                                       "--batch", "1048576"],
        r"--batch: exporting a controller for 1,048,576 characters needs about [\d,.]+ GiB of memory"),
    _r3("bad value", "eval-episodes-65536-memory", [*EVAL, "--paths", "dart_demo_walk", "--episodes", "65536"],
        r"--episodes: 65536 episodes x 2 steps need about [\d.]+ GiB \(their envs and motion\)"),
]
ROWS += SECURITY
SEAT = {"center": [0.4, 2.2], "seat_height": 0.45, "facing_deg": 90}
SEATS = {  # seat files of the sit task (tasks/sit/README.md): name -> (content, what the line must say)
    "truncated": ('[{"center": ', r"invalid JSON: Expecting value"),
    "object": (json.dumps(SEAT), r"expected a list of 1 to 1000 seats like .*got dict"),
    "empty": ("[]", r"expected a list of 1 to 1000 seats .*got list of 0"),
    "no-height": (json.dumps([{"center": [0.4, 2.2], "facing_deg": 90}]), r"seat 0: missing field 'seat_height'"),
    "typo": (json.dumps([{"centre": [0, 1], "seat_height": 0.4, "facing_deg": 0}]),
             r"seat 0: unknown field 'centre' \(did you mean 'center'\?\)"),
    "height-2": (json.dumps([{**SEAT, "seat_height": 2.0}]),
                 r"seat 0: field 'seat_height' must be metres in \[0\.05, 1\.5\], got 2\.0"),
    "height-0.01": (json.dumps([{**SEAT, "seat_height": 0.01}]), r"field 'seat_height' must be metres .*got 0\.01"),
    "height-nan": (json.dumps([{**SEAT, "seat_height": float("nan")}]),
                   r"field 'seat_height' must be metres .*got nan"),
    "height-word": (json.dumps([{**SEAT, "seat_height": "low"}]), r"field 'seat_height' must be metres .*got 'low'"),
    "height-bool": (json.dumps([{**SEAT, "seat_height": True}]), r"field 'seat_height' must be metres .*got True"),
    "center-nan": (json.dumps([{**SEAT, "center": [float("nan"), 1]}]),
                   r"field 'center' must be \[x, y\] within \+/-100 m, got \[nan, 1\]"),
    "center-1e308": (json.dumps([{**SEAT, "center": [1e308, 1]}]), r"field 'center' must be \[x, y\] within"),
    "facing-inf": (json.dumps([{**SEAT, "facing_deg": float("inf")}]),
                   r"field 'facing_deg' must be degrees in \[-360, 360\], got inf"),
    "seats-2000": (json.dumps([SEAT] * 2000), r"expected a list of 1 to 1000 seats .*got list of 2000"),
    "oversized": (b" " * ((1 << 20) + 1), r"1,048,577 bytes is larger than the 1 MiB a seat file may have"),
    "deep": ("[" * 200_000 + "]" * 200_000, r"JSON nested too deeply for a seat file"),
    "path-file": (json.dumps([{"goal_location": [[0, 1, 0]], "goal_text": ["walk"]}]),
                  r"seat 0: unknown field 'goal_location'"),
}
HOSTILE_SEATS = {"center-1e308", "seats-2000", "oversized", "deep"}
PATH_SCENES = {  # a path file's per-path "scene" field: name -> (its value, what the line must say)
    "unknown-name": ("nowhere_scene", r"field 'scene': scene: scene file not found: nowhere_scene"),
    "traversal": ("../../etc/passwd", r"field 'scene': scene: scene file not found: \.\./\.\./etc/passwd"),
    "traversal-deep": ("../" * 40 + "etc/passwd", r"field 'scene': .*etc/passwd: invalid JSON"),
    "absolute": ("/etc/passwd", r"field 'scene': /etc/passwd: invalid JSON"),
    "dev-zero": ("/dev/zero", r"field 'scene': scene: scene file not found: /dev/zero"),
    "empty": ("", r"field 'scene': scene: scene file not found:  \("),
    "bad-file": ("../scenes/bad.json", r"field 'scene': .*bad\.json: invalid JSON"),
    "oversized-file": ("../scenes/oversized.json", r"field 'scene': .*1,048,577 bytes is larger than the 1 MiB"),
    "inline-nan": ({"format": "latentrl.scene/1", "objects": [{"type": "box", "center": [1, 2],
                                                                "size": [float("nan"), 1, 1]}]},
                   r"field 'scene': .*objects\[0\]\.size\[0\]: expected a finite number, got nan"),
    "inline-typo": ({"format": "latentrl.scene/1", "objectz": []},
                    r"field 'scene': .*objectz: unknown field; expected format, objects"),
    "inline-format": ({"format": "latentrl.scene/9", "objects": []},
                      r"field 'scene': .*format: expected 'latentrl\.scene/1', got 'latentrl\.scene/9'"),
    "inline-random": ({"random_obstacles": {"count": [1, 3]}},
                      r"field 'scene' must be a fixed scene \(random_obstacles is an env setting\)"),
    "inline-objects-65": ({"format": "latentrl.scene/1", "objects": [
        {"type": "box", "center": [1, 2], "size": [0.6, 0.4, 1.0]}] * 65},
        r"field 'scene': .*65 objects, more than the 64 allowed"),
    "number": (5, r"field 'scene' must be a scene file name or a latentrl\.scene/1 object, got int"),
    "list": ([1, 2], r"field 'scene' must be a scene file name or a latentrl\.scene/1 object, got list"),
}
HOSTILE_PATH_SCENES = {"traversal", "traversal-deep", "absolute", "dev-zero", "oversized-file", "inline-objects-65"}


def _sit_files(root: Path, model, motion: Path) -> None:
    """Seat files, a sit policy, path files whose paths name a scene (the rows of the sit task and path scenes)."""
    from latentrl.envs.sit import SitEnv
    from latentrl.motion.checkpoint import file_sha256
    from latentrl.ppo.checkpoint import make_checkpoint, save_checkpoint
    from latentrl.ppo.config import PolicyConfig
    from latentrl.ppo.policy import ActorCritic

    (root / "seats").mkdir()
    for name, (data, _) in SEATS.items():
        (root / "seats" / f"{name}.json").write_bytes(data if isinstance(data, bytes) else data.encode())
    (root / "seats" / "ok.json").write_text(json.dumps([SEAT]))
    (root / "pathscenes").mkdir()
    for name, (scene, _) in PATH_SCENES.items():
        (root / "pathscenes" / f"{name}.json").write_text(
            json.dumps([{"goal_location": [[0, 1, 0]], "goal_text": ["walk"], "scene": scene}]))
    env = SitEnv(1, motion=model)
    torch.manual_seed(0)
    policy = ActorCritic(env.single_observation_space.shape[0], env.single_action_space.shape[0],
                         PolicyConfig(latent_dim=32), env.metadata["observation_layout"])
    state = make_checkpoint(trainer="native", iteration=0, env_steps=0, elapsed_s=0.0, policy=policy,
                            optimizer=torch.optim.Adam(policy.parameters()),
                            config={"env": {"task": "sit", "texts": ["walk"]}},
                            motion={"path": str(motion), "sha256": file_sha256(motion)})
    save_checkpoint(state, root / "sit.pt")


SIT_EVAL = ["eval", "{fx}/sit.pt", "--motion", "{fx}/motion.pt", "--episodes", "1", "--max-steps", "2", "--render",
            "0"]
SIT_TRAIN = [*TRAIN, "--set", "env.task=sit"]
PLAY = ["play", "reach_walk_default"]  # every --scene row fails before the server starts (play_scene comes first)
SITS = [
    # ------------------------------------------------ seat files and the sit_seats suite (eval of a sit policy)
    *[_r3("hostile file" if name in HOSTILE_SEATS else "bad file", f"eval-seats-{name}",
          [*SIT_EVAL, "--paths", f"{{fx}}/seats/{name}.json"], rf"{re.escape(name)}\.json: .*{pattern}")
      for name, (_, pattern) in SEATS.items()],
    _r3("bad value", "eval-seats-suite-typo", [*SIT_EVAL, "--paths", "sit_seat"],
        r"path file not found: sit_seat \(give a file, or one of the suites \['sit_seats'\]\)"),
    _r3("bad file", "eval-seats-missing", [*SIT_EVAL, "--paths", "nowhere_seats.json"],
        r"path file not found: nowhere_seats\.json"),
    _r3("hostile file", "eval-seats-dev-zero", [*SIT_EVAL, "--paths", "/dev/zero"], r"path file not found: /dev/zero"),
    _r3("bad file", "eval-seats-etc-passwd", [*SIT_EVAL, "--paths", "/etc/passwd"], r"/etc/passwd: invalid JSON"),
    _r3("bad file", "eval-seats-motion-pt", [*SIT_EVAL, "--paths", "{fx}/motion.pt"],
        r"motion\.pt: not a UTF-8 text file"),
    _r3("bad file", "eval-reach-policy-seat-file", [*EVAL, "--paths", "{fx}/seats/ok.json"],
        r"ok\.json: path 0: unknown field 'center'"),
    _r3("bad value", "eval-sit-scene", [*SIT_EVAL, "--paths", "{fx}/seats/ok.json", "--scene", "maze_a"],
        r"--scene: the sit task's evaluation runs without a scene .*leave out --scene"),
    _r3("bad value", "eval-reach-joint-scene", [*RJ_EVAL, "--paths", "{fx}/goals/ok.json", "--scene", "maze_b_"],
        r"--scene: scene file not found: maze_b_ \(looked in .*tasks/scenes\)"),
    # ------------------------------------------------ env.task: sit settings (train --set env.options.*)
    *[_r3("bad value", f"train-sit-{value.split('=')[0]}-{name}", [*SIT_TRAIN, "--set", f"env.options.{value}"],
          rf"tiny\.yaml: env\.options\.{value.split('=')[0]}: {pattern}")
      for name, value, pattern in (
          ("outside", "seat_height=[0.1,2]", r"must be \[min, max\] with 0\.05 <= min <= max <= 1\.5, got \[0\.1, 2\]"),
          ("reversed", "seat_height=[0.6,0.2]", r"must be \[min, max\] .*got \[0\.6, 0\.2\]"),
          ("nan", "seat_height=[.nan,0.6]", r"must be \[min, max\] .*got \[nan, 0\.6\]"),
          ("scalar", "seat_height=0.4", r"must be \[min, max\] .*got 0\.4"),
          ("inf", "seat_distance=[0,.inf]", r"must be \[min, max\] with 0 <= min <= max <= 100, got \[0, inf\]"),
          ("zero", "seat_size=[0,0.5]", r"must be \[min, max\] with 0\.05 <= min"),
          ("200", "seat_angle_deg=200", r"must be degrees in \[0, 180\], got 200"),
          ("0", "hold_frames=0", r"must be an integer in \[1, 3000\], got 0"),
          ("1e9", "hold_frames=1000000000", r"must be an integer in \[1, 3000\], got 1000000000"),
          ("float", "hold_frames=1.5", r"must be an integer in \[1, 3000\], got 1\.5"),
          ("nan", "stand_fraction=.nan", r"must be in \(0, 1\], got nan"),
          ("negative", "sit_radius=-1", r"must be metres in \(0, 10\], got -1"),
          ("inf", "approach_offset=.inf", r"must be metres in \(0, 10\], got inf"),
          ("1e9", "leave_distance=1e9", r"must be metres in \(0, 10\], got 1000000000\.0"),
          ("empty", "sit_text=''", r"must be a prompt"))],
    _r3("bad value", "train-sit-unknown-option", [*SIT_TRAIN, "--set", "env.options.seat_heigth=[0.2,0.6]"],
        r"env\.options: .*unexpected keyword argument 'seat_heigth' \(the arguments of task 'sit'\)"),
    _r3("bad value", "train-sit-long-text", [*SIT_TRAIN, "--set", "env.options.walk_text={LONG}"],
        r"has 1001 characters, more than the 1000 allowed"),
    _r3("bad value", "train-sit-scene", [*SIT_TRAIN, "--set", "env.scene=maze_a"],
        r"scene: the sit task places its own seat; leave env\.scene unset"),
    _r3("bad value", "train-sit-compile", [*SIT_TRAIN, *COMPILE], r"compile: the sit task runs eagerly"),
    _r3("bad value", "train-sit-height-grid-even", [*SIT_TRAIN, "--set", "env.height_grid=4"],
        r"env\.height_grid: expected 0 \(none\) or an odd number of samples per side in \[3, 15\], got 4"),
    # ------------------------------------------------ env.height_grid / env.height_grid_spacing
    *[_r3("bad value", f"train-height-grid-{name}", [*TRAIN, "--set", f"env.{value}"],
          rf"tiny\.yaml: env\.{value.split('=')[0]}: {pattern}")
      for name, value, pattern in (
          ("even", "height_grid=6", r"expected 0 \(none\) or an odd number .*in \[3, 15\], got 6"),
          ("1", "height_grid=1", r"expected 0 \(none\) or an odd number .*got 1"),
          ("17", "height_grid=17", r"expected 0 \(none\) or an odd number .*got 17"),
          ("negative", "height_grid=-3", r"expected 0 \(none\) or an odd number .*got -3"),
          ("1e6", "height_grid=1000001", r"expected 0 \(none\) or an odd number .*got 1000001"),
          ("spacing-nan", "height_grid_spacing=.nan", r"expected metres in \(0, 2\], got nan"),
          ("spacing-inf", "height_grid_spacing=.inf", r"expected metres in \(0, 2\], got inf"),
          ("spacing-negative", "height_grid_spacing=-0.25", r"expected metres in \(0, 2\], got -0\.25"),
          ("spacing-0", "height_grid_spacing=0", r"expected metres in \(0, 2\], got 0\.0"),
          ("spacing-3", "height_grid_spacing=3", r"expected metres in \(0, 2\], got 3\.0"))],
    _r3("bad value", "train-height-grid-bool", [*TRAIN, "--set", "env.height_grid=true"],
        r"env\.height_grid: Value 'True' of type 'bool' could not be converted to Integer"),
    _r3("bad value", "train-height-grid-no-scene", [*TRAIN, "--set", "env.height_grid=7"],
        r"height_grid: needs a scene"),
    # ------------------------------------------------ a path's own "scene" field (path files through eval)
    *[_r3("hostile file" if name in HOSTILE_PATH_SCENES else "bad file", f"eval-path-scene-{name}",
          [*EVAL, "--paths", f"{{fx}}/pathscenes/{name}.json"],
          rf"{re.escape(name)}\.json: path 0: {pattern}") for name, (_, pattern) in PATH_SCENES.items()],
    # ------------------------------------------------ play --scene: refused before the server starts
    *[_r3("hostile file" if name in HOSTILE_SCENES else "bad file", f"play-scene-{name}",
          [*PLAY, "--scene", f"{{fx}}/scenes/{name}.json"], rf"--scene: .*{re.escape(name)}\.json: .*{pattern}")
      for name in ("bad", "list", "format", "size-nan", "objects-65", "oversized", "deep", "utf16")
      for pattern in (SCENES[name][1],)],
    _r3("bad file", "play-scene-unknown-name", [*PLAY, "--scene", "nowhere_scene"],
        r"--scene: scene file not found: nowhere_scene \(looked in .*tasks/scenes\)"),
    _r3("bad file", "play-scene-folder", [*PLAY, "--scene", "{fx}/scenes"], r"--scene: scene file not found: .*scenes"),
    _r3("hostile file", "play-scene-dev-zero", [*PLAY, "--scene", "/dev/zero"],
        r"--scene: scene file not found: /dev/zero"),
    _r3("hostile file", "play-scene-link-to-dev-zero", [*PLAY, "--scene", "{fx}/zero-link.json"],
        r"--scene: scene file not found: .*zero-link\.json"),
    _r3("hostile file", "play-scene-etc-passwd", [*PLAY, "--scene", "/etc/passwd"],
        r"--scene: /etc/passwd: invalid JSON"),
    _r3("bad file", "play-scene-motion-pt", [*PLAY, "--scene", "{fx}/motion.pt"],
        r"--scene: .*motion\.pt: not a UTF-8"),
    _r3("bad value", "play-scene-random", [*PLAY, "--scene", "random_obstacles"],
        r"--scene: play takes a scene file \(random obstacles are drawn per episode"),
    _r3("bad value", "play-scene-empty", [*PLAY, "--scene", ""], r"--scene: scene file not found:  \("),
    # ------------------------------------------------ eval.video_every / eval.video_size
    *[_r3("bad value", f"train-{value.split('=')[0].replace('.', '-').replace('_', '-')}-{name}",
          [*TRAIN, "--set", value], pattern)
      for name, value, pattern in (
          ("negative", "eval.video_every=-1", r"tiny\.yaml: eval\.video_every: must be >= 0 \(0: no video\), got -1"),
          ("nan", "eval.video_every=.nan", r"eval\.video_every: Value 'nan' of type 'float' could not be converted"),
          ("word", "eval.video_every=often", r"eval\.video_every: Value 'often' of type 'str' could not be"),
          ("100", "eval.video_size=100", r"tiny\.yaml: eval\.video_size: must be a multiple of 16 from 64 to 640, "
                                         r"got 100"),
          ("negative", "eval.video_size=-16", r"eval\.video_size: must be a multiple of 16 from 64 to 640, got -16"),
          ("0", "eval.video_size=0", r"eval\.video_size: must be a multiple of 16 .*got 0"),
          ("1e6", "eval.video_size=1000000", r"eval\.video_size: must be a multiple of 16 .*got 1000000"),
          ("nan", "eval.video_size=.nan", r"eval\.video_size: Value 'nan' of type 'float' could not be converted"))],
]
ROUND3 += SITS
ROWS += SITS


def _eval_memory_fits() -> bool:
    """Whether 65,536 two-step episodes fit in half this machine's RAM (then their row cannot be refused here)."""
    from latentrl.evaluation.config import EvalSettings
    from latentrl.memory import physical_memory

    total = physical_memory()
    return total is None or EvalSettings(episodes=65536, max_steps=2).memory_bytes() <= total // 2


SKIP = {"train-device-cuda": CUDA, "train-device-mps": MPS, "eval-episodes-65536-memory": _eval_memory_fits(),
        **{rid: not MUJOCO for rid, *_ in ROUND3 if rid.startswith("physics-")}}


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
    for name, value in ENV.get(request.node.callspec.id, {}).items():
        monkeypatch.setenv(name, value.format(**values))
    args = [a.format(**values) for a in argv]
    if args[:1] in (["view"], ["play"]) and "--port" not in args:  # any free port: 8080 may be another test's server
        args += ["--port", "0"]
    code = main(args)
    out = capsys.readouterr()
    assert code == 2, out.err
    assert out.err.endswith("\n") and out.err.count("\n") == 1, f"not one line: {out.err!r}"
    assert out.err.startswith("latentrl") and " error: " in out.err and "Traceback" not in out.err
    assert re.search(pattern, out.err), f"{pattern!r} not in {out.err!r}"
    assert tree(work) == {}, "left files in the working directory"
    assert tree(fx) == before, "changed the fixture folder"


def test_every_command_is_covered_and_rows_are_distinct():
    assert len(ROWS) >= 40 and len({i for i, _, _ in ROWS}) == len(ROWS)
    assert len({(tuple(a), tuple(ENV.get(i, {}).items())) for i, a, _ in ROWS}) == len(ROWS)  # argv + environment
    commands = {" ".join(a[:2]) if a and a[0] in ("motion", "bench") else (a[0] if a else "") for _, a, _ in ROWS}
    assert {"train", "quickstart", "eval", "compare", "motion info", "motion sample", "motion train",
            "motion export-bvh", "bench motion", "bench env", "bench rollout", "bench train"} <= commands


def test_debug_shows_the_traceback_instead(fx, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    from latentrl.errors import ConfigError

    with pytest.raises(ConfigError, match="config file not found"):
        main(["--debug", "train", "missing.yaml"])


def test_sample_never_writes_a_diverged_rollout(fx, tmp_path, monkeypatch, capsys):
    from latentrl.motion.rollout import MotionModel

    real = MotionModel.rollout

    def diverging(self, *args, **kwargs):
        roll = real(self, *args, **kwargs)
        roll.joints_world[:, 3:] = float("nan")
        return roll

    monkeypatch.setattr(MotionModel, "rollout", diverging)
    monkeypatch.chdir(tmp_path)
    code = main(["motion", "sample", "--motion", str(fx / "motion.pt"), "--seconds", "1", "--out", "m.npz"])
    err = capsys.readouterr().err
    assert code == 3 and "the rollout diverged" in err and "nothing written" in err
    assert not (tmp_path / "m.npz").exists()


HOSTILE = re.compile(r"evil|bomb|aliases|deep|20000|400-digits|1e308|bit-flip|python-tag|etc-passwd|huge-path")


def command_of(argv: list[str]) -> str:
    """The command a row drives: ``train``, ``motion sample``, ``export onnx``, ``bench env``, ..."""
    if not argv or argv[0] not in ("train", "quickstart", "eval", "compare", "optimize", "view", "play", "motion",
                                   "bench", "export", "physics"):
        return "top level"
    if argv[0] == "physics" and (len(argv) < 2 or argv[1] not in ("track", "loop")):
        return "physics"
    if argv[0] == "bench" and (len(argv) < 2 or argv[1] not in ("motion", "env", "rollout", "train")):
        return "bench"
    return " ".join(argv[:2]) if argv[0] in ("motion", "bench", "export", "physics") and len(argv) > 1 else argv[0]


def kind_of(rid: str, argv: list[str]) -> str:
    """bad value, bad file, hostile file or fault: round 3 rows say theirs, earlier rows are told by their input."""
    if rid in KIND:
        return KIND[rid]
    if HOSTILE.search(rid):
        return "hostile file"
    inputs = [a for a in argv if "{fx}/" in a and not a.endswith(("/motion.pt", "/policy.pt", "/ok.npz"))
              and "afile" not in a]  # the good fixtures, and a file standing where an output goes (a bad value)
    if inputs or any("missing" in a or "nowhere" in a for a in argv) or "missing" in rid:
        return "bad file"
    return "bad value"


def table_counts() -> tuple[dict[str, int], dict[str, int]]:
    """Rows by command and by kind (docs/robustness.md prints both)."""
    by_command: dict[str, int] = {}
    by_kind: dict[str, int] = {}
    for rid, argv, _ in ROWS:
        by_command[command_of(argv)] = by_command.get(command_of(argv), 0) + 1
        by_kind[kind_of(rid, argv)] = by_kind.get(kind_of(rid, argv), 0) + 1
    return by_command, by_kind


def test_the_table_has_300_distinct_rows_and_the_docs_count_them():
    by_command, by_kind = table_counts()
    assert len(ROWS) >= 300 and len({tuple(a) + tuple(ENV.get(i, {}).items()) for i, a, _ in ROWS}) == len(ROWS)
    doc = (ROOT / "docs" / "robustness.md").read_text()
    assert f"| all | {len(ROWS)} |" in doc, f"docs/robustness.md does not count {len(ROWS)} rows"
    for name, count in {**by_command, **by_kind}.items():
        assert f"| {name} | {count} |" in doc, f"docs/robustness.md lacks the row '| {name} | {count} |'"


def test_a_stray_single_rank_environment_is_ignored_with_a_note(fx, tmp_path, monkeypatch, capsys):
    """RANK=0 WORLD_SIZE=1 without MASTER_ADDR (a notebook's leftover): one process trains, and says why."""
    monkeypatch.setenv("RANK", "0")
    monkeypatch.setenv("WORLD_SIZE", "1")
    monkeypatch.chdir(tmp_path)
    code = main(["train", TINY, "--set", f"env.motion={fx}/motion.pt", "--total-steps", "64", "--run-dir", "run",
                 "--no-progress"])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert ("latentrl: note: ignoring RANK=0 WORLD_SIZE=1 (MASTER_ADDR and MASTER_PORT not set: not a torchrun "
            "launch); training in one process") in out.out
    assert (tmp_path / "run" / "final.pt").is_file() and out.err == ""


def test_a_compiler_named_by_cxx_that_does_not_exist_is_refused_before_training(fx, tmp_path):
    """``CXX=/nonexistent/g++`` read by torch at start-up, as in a user's shell: one line, exit 2, no run folder."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "CXX": "/nonexistent/g++", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-m", "latentrl", "train", TINY, "--set", f"env.motion={fx}/motion.pt",
                           "--set", "env.compile=true", "--run-dir", "run"], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert ("env.compile: torch.compile on the CPU needs a C++ compiler, and none runs here (tried "
            "'/nonexistent/g++'") in proc.stderr
    assert not (tmp_path / "run").exists()


def test_the_shared_json_reader_names_folders_devices_and_the_exact_size(tmp_path):
    """``read_json_file``: a folder or a device is not called missing; a size over the limit is said in bytes."""
    from latentrl.errors import DataError
    from latentrl.safe_io import read_json_file

    with pytest.raises(DataError, match=r"^.*: not a regular file \(a folder\); expected a scene file$"):
        read_json_file(tmp_path, "scene file", 1 << 20, DataError)
    with pytest.raises(DataError, match=r"^/dev/zero: not a regular file \(a device or pipe\); expected a scene file$"):
        read_json_file("/dev/zero", "scene file", 1 << 20, DataError)
    (tmp_path / "big.json").write_bytes(b" " * ((1 << 20) + 1))
    with pytest.raises(DataError, match=r"big\.json: 1,048,577 bytes is larger than the 1 MiB a scene file may have"):
        read_json_file(tmp_path / "big.json", "scene file", 1 << 20, DataError)
    with pytest.raises(DataError, match=r"big\.json: 1,048,577 bytes is larger than the 1,000 bytes a report"):
        read_json_file(tmp_path / "big.json", "report", 1000, DataError)


def test_a_missing_policy_is_the_only_thing_eval_says(tmp_path, monkeypatch, capsys):
    """No suite line or stored setting before the not-found error (the suites depend on the policy)."""
    monkeypatch.chdir(tmp_path)
    assert main(["eval", "missing.pt"]) == 2
    out = capsys.readouterr()
    assert out.out == "" and out.err == "latentrl: error: PPO checkpoint file not found: missing.pt\n"

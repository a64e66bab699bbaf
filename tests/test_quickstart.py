"""``latentrl quickstart`` end to end on a tiny model: it trains, evaluates and says where its wall time went."""

import re

from latentrl.app.cli import main
from latentrl.app.train import WallTimeSplit
from latentrl.motion.checkpoint import save_motion_model

SPLIT = re.compile(r"^\[quickstart\] wall time (\d+\.\d) s: set-up (-?\d+\.\d) s, training (\d+\.\d) s, "
                   r"evaluation (\d+\.\d) s \(Python and torch start-up before the command not counted\)$")


def test_quickstart_prints_its_wall_time_split_last(tmp_path, tiny_model, capsys):
    motion = save_motion_model(tiny_model, tmp_path / "motion.pt")
    run = tmp_path / "run"
    code = main(["quickstart", "--set", f"env.motion={motion}", "--set", "env.compile=false",
                 "--set", "env.num_envs=4", "--set", "ppo.num_steps=4", "--set", "ppo.num_minibatches=1",
                 "--set", "ppo.total_steps=32", "--set", "ppo.eval_every=0", "--set", "threads=1",
                 "--episodes", "1", "--max-steps", "2", "--run-dir", str(run), "--no-progress"])
    assert code == 0 and (run / "eval" / "report.md").is_file() and (run / "final.pt").is_file()
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-2].startswith("[quickstart] done: report")
    match = SPLIT.match(lines[-1])
    assert match, lines[-1]
    total, setup, training, evaluation = map(float, match.groups())
    assert setup >= 0 and training > 0 and evaluation > 0
    assert abs(total - (setup + training + evaluation)) <= 0.15  # each part rounded to 0.1 s
    trained = next(line for line in lines if line.startswith("[quickstart] trained"))
    assert "2 iterations (32 env steps)" in trained


def test_wall_time_split_line_sums_its_parts():
    line = WallTimeSplit(setup_s=4.0, training_s=55.3, evaluation_s=20.5).line()
    assert line.startswith("wall time 79.8 s: set-up 4.0 s, training 55.3 s, evaluation 20.5 s")


def test_quick_amp_only_on_native_bf16_cpus_and_never_over_a_choice():
    from latentrl.app.train import QUICK_CONFIG, load_train_config, quick_amp

    cfg = load_train_config(QUICK_CONFIG, [])
    assert cfg.env.amp is None  # the config file itself stays float32: portable to any CPU
    assert quick_amp(cfg, [], native_bf16=True)
    assert not quick_amp(cfg, [], native_bf16=False)  # emulated bf16 is slower than float32
    assert not quick_amp(cfg, ["env.amp=null"], native_bf16=True)  # the user's choice wins
    assert not quick_amp(load_train_config(QUICK_CONFIG, ["ppo.device=cuda"]), [], native_bf16=True)

"""``latentrl list``: every section prints what ships; a bad section or model is one line and exit 2."""

import gymnasium as gym
import pytest

from latentrl.app.cli import main
from latentrl.envs.tasks import TASKS
from latentrl.resources import packaged


def run(capsys, *args) -> tuple[int, list[str], str]:
    code = main(["list", *args])
    out, err = capsys.readouterr()
    return code, out.splitlines(), err


def row(lines: list[str], first: str) -> list[str]:
    """The cells of the table row whose first cell is ``first``."""
    found = [line.split("  ") for line in lines if line.split() and line.split()[0] == first]
    assert len(found) == 1, f"no single row '{first}' in {lines}"
    return [c.strip() for c in found[0] if c.strip()]


def test_tasks_print_every_registered_task_and_its_gymnasium_id(capsys):
    code, lines, _ = run(capsys, "tasks")
    assert code == 0
    assert row(lines, "reach")[:3] == ["reach", "latentrl/ReachLocation-v0", "paths"]
    for spec in TASKS.values():
        assert spec.gym_id in row(lines, spec.name) and spec.gym_id in gym.registry


def test_policies_print_every_shipped_policy_with_its_task_motion_and_card(capsys):
    code, lines, _ = run(capsys, "policies")
    assert code == 0
    assert row(lines, "reach_walk_default") == ["reach_walk_default", "reach", "default", "walk",
                                                "policies/reach_walk_default.md"]
    assert row(lines, "joystick_walk_default")[1] == "joystick"
    assert row(lines, "timed_walk_default")[1] == "timed"
    assert row(lines, "path_mixed_default")[1:4] == ["path", "default", "walk, run, hop on left leg"]
    shipped = sorted(p.stem for p in packaged("policies").glob("*.pt"))
    assert len(shipped) >= 6 and all(row(lines, name) for name in shipped)


def test_configs_print_training_and_motion_configs(capsys):
    code, lines, _ = run(capsys, "configs")
    assert code == 0
    assert row(lines, "quick")[1:] == ["latentrl train", "reach", "walk"]
    assert row(lines, "policies/joystick_walk_default")[2] == "joystick"
    assert row(lines, "motion/default")[1] == "latentrl motion train"


def test_suites_print_each_kind(capsys):
    code, lines, _ = run(capsys, "suites")
    assert code == 0
    assert "dart_walk_long" in row(lines, "paths")[-1]
    assert "joystick_walk" in row(lines, "joystick")[-1] and "timed_walk" in row(lines, "timed")[-1]
    constraints = row(lines, "constraints")
    assert constraints[1] == "optimize SUITE" and "inbetween" in constraints[-1].split(", ")


def test_prompts_of_the_default_model_and_of_a_model_file(capsys, tmp_path, tiny_model):
    code, lines, _ = run(capsys, "prompts")
    assert code == 0 and "  walk" in lines and "  hop on left leg" in lines
    assert lines[0] == "prompts of motion model 'default' (--text):"

    from latentrl.motion.checkpoint import save_motion_model

    file = save_motion_model(tiny_model, tmp_path / "tiny.pt")
    code, lines, _ = run(capsys, "prompts", "--motion", str(file))
    assert code == 0 and len(lines) >= 2 and lines[0].startswith("prompts of motion model")


def test_no_section_prints_all_of_them(capsys):
    code, lines, _ = run(capsys)
    assert code == 0
    heads = [line.split(" ")[0] for line in lines if line and not line.startswith(" ")]
    assert heads == ["tasks", "policies", "configs", "suites", "prompts"]


@pytest.mark.parametrize("args, named", [(("bogus",), "bogus"), (("prompts", "--motion", "no/such.pt"), "no/such.pt")])
def test_bad_input_is_one_line_and_exit_2(capsys, args, named):
    code, lines, err = run(capsys, *args)
    assert code == 2 and lines == []
    assert len(err.strip().splitlines()) == 1 and named in err

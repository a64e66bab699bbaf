"""Stage 0: the generated humanoid matches latentrl's rest skeleton, weighs ~70 kg and stands under PD."""

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from latentrl.errors import ConfigError  # noqa: E402
from latentrl.motion.skeleton import JOINT_NAMES  # noqa: E402
from latentrl.physics.humanoid import MASS_PERCENT, build_humanoid  # noqa: E402
from latentrl.physics.tracker import Simulator  # noqa: E402


@pytest.mark.parametrize("height", [1.75, 1.6, 1.9])
def test_rest_forward_kinematics_equals_latentrl_rest_joints(height):
    from latentrl.datasets.body import rest_joints

    humanoid = build_humanoid(height)
    model = humanoid.model()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    bodies = np.array([data.body(name).xpos for name in JOINT_NAMES])
    assert np.abs(bodies - rest_joints(height)).max() < 1e-3


def test_mass_at_175_is_70_kg_and_segments_add_up():
    humanoid = build_humanoid(1.75)
    model = humanoid.model()
    assert abs(model.body_subtreemass[0] - 70.0) <= 5.0
    assert model.body_subtreemass[0] == pytest.approx(humanoid.mass, rel=1e-4)
    sides = {"collar", "hip", "knee", "ankle", "foot", "shoulder", "elbow", "wrist"}
    total = sum(v * (2 if k in sides else 1) for k, v in MASS_PERCENT.items())
    assert total == pytest.approx(100.0, abs=1e-6)


def test_three_hinges_per_body_joint_and_a_free_root():
    model = build_humanoid(1.75).model()
    kinds = [int(model.jnt_type[i]) for i in range(model.njnt)]
    assert kinds.count(int(mujoco.mjtJoint.mjJNT_FREE)) == 1
    assert kinds.count(int(mujoco.mjtJoint.mjJNT_HINGE)) == 63
    assert kinds.count(int(mujoco.mjtJoint.mjJNT_BALL)) == 0
    assert model.nu == 63


def test_stands_ten_seconds_under_pd_at_rest_without_assist():
    humanoid = build_humanoid(1.75)
    sim = Simulator(humanoid)
    sim.set_assist(None)
    rest = humanoid.rest_joints
    sim.set_state(rest[0], np.eye(3), np.zeros(63))
    for _ in range(10 * 300):
        mujoco.mj_step(sim.model, sim.data)
    joints = sim.joints()
    assert np.linalg.norm(joints - rest, axis=-1).max() < 0.03  # upright, feet where they were
    assert abs(joints[0, 2] - rest[0, 2]) < 0.02
    assert np.abs(sim.soles()[:, 2]).max() < 0.005  # all four foot boxes flat on the floor, neither sunk nor lifted
    assert np.abs(sim.data.xfrc_applied).max() == 0.0


@pytest.mark.parametrize("height", [0.5, 3.0, float("nan")])
def test_refuses_impossible_heights(height):
    with pytest.raises(ConfigError, match="height"):
        build_humanoid(height)

"""The observation layout: fields tile the vector, goal fields form ``goal`` and an optional ``task`` tail group."""

import pytest

from latentrl.envs.observation import ObservationLayout
from latentrl.motion.representation import FEATURE_DIM, HISTORY_LENGTH

FIELDS = (("goal_dir", 3), ("goal_dist", 1), ("seat", 2), ("phase", 4))


def test_goal_fields_form_one_group_unless_a_tail_is_the_task_group():
    one = ObservationLayout(FIELDS, 8)
    assert one.groups["goal"] == (0, 10) and "task" not in one.groups
    split = ObservationLayout(FIELDS, 8, rays=16, task_group=("seat", "phase"))
    assert split.groups["goal"] == (0, 4) and split.groups["task"] == (4, 10)
    assert list(split.groups) == ["goal", "task", "text", "motion", "scene", "scene_rays"]
    assert split.size == one.size + 16 == 10 + 8 + HISTORY_LENGTH * FEATURE_DIM + 1 + 16
    assert split.fields == ObservationLayout(FIELDS, 8, rays=16).fields  # the fields do not move


@pytest.mark.parametrize("tail", [("seat",), ("goal_dir", "goal_dist", "seat", "phase"), ("goal_dist", "phase")])
def test_a_task_group_that_is_not_a_tail_after_the_goal_is_refused(tail):
    with pytest.raises(ValueError, match="must be the goal fields' tail"):
        ObservationLayout(FIELDS, 8, task_group=tail)

"""The one skate kernel (latentrl.motion.contacts): rewards, metrics and the generator agree on a known answer."""

from __future__ import annotations

import math

import numpy as np
import torch

from latentrl.datasets.locomotion import foot_skate
from latentrl.evaluation import metrics
from latentrl.motion.contacts import foot_contacts, skate_weights, weighted_foot_slide
from latentrl.motion.skeleton import FOOT_JOINTS
from latentrl.rewards import terms

LEFT, RIGHT = FOOT_JOINTS


def hand_made(frames: int = 4) -> np.ndarray:
    """Left foot on the floor sliding 1 cm/frame; right foot 1.5 cm up sliding 2 cm/frame; the rest still."""
    joints = np.zeros((frames, 22, 3), np.float64)
    joints[:, :, 2] = 1.0
    joints[:, LEFT, 0] = 0.01 * np.arange(frames)
    joints[:, LEFT, 2] = 0.0
    joints[:, RIGHT, 0] = 0.02 * np.arange(frames)
    joints[:, RIGHT, 2] = 0.015
    return joints


# per transition: left 0.01 m x weight 1, right 0.02 m x weight 2 - 2**0.5; averaged over the feet
EXPECTED_M = (0.01 + 0.02 * (2.0 - math.sqrt(2.0))) / 2.0


def test_kernel_known_answer():
    feet = torch.as_tensor(hand_made())[:, list(FOOT_JOINTS)]
    out = weighted_foot_slide(feet)
    torch.testing.assert_close(out[:, 0], torch.full((3,), 0.01, dtype=torch.float64))
    torch.testing.assert_close(out[:, 1], torch.full((3,), 0.02 * (2 - math.sqrt(2)), dtype=torch.float64))
    heights = torch.tensor([[0.0, 0.03], [0.0, 0.1]])
    assert skate_weights(heights).tolist() == [[1.0, 0.0]]


def test_three_callers_agree():
    joints = hand_made()
    generator = foot_skate(joints)
    reward = terms.foot_skate(torch.as_tensor(joints)[None][:, :, list(FOOT_JOINTS)])
    metric = metrics.foot_skate_cm_s(torch.as_tensor(joints), fps=30.0)
    np.testing.assert_allclose(generator, EXPECTED_M, rtol=1e-12)
    assert math.isclose(-float(reward), EXPECTED_M, rel_tol=1e-12)
    assert math.isclose(float(metric), EXPECTED_M * 30 * 100, rel_tol=1e-12)


def test_contacts_rule():
    contacts = foot_contacts(torch.as_tensor(hand_made()))
    assert contacts.shape == (4, 2) and contacts.all()
    lifted = hand_made()
    lifted[:, RIGHT, 2] = 0.03  # at the threshold: weight 0, not in contact
    assert foot_contacts(torch.as_tensor(lifted))[:, 1].logical_not().all()

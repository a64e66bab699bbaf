"""DART's protocol constants, defined once (Zhao et al., ICLR 2025, and its released scripts).

Every default that means "what DART uses" reads its value from here: the sampler's guidance,
the goal radius of the reach and path tasks, the foot-contact height of the skate and floor
terms and metrics, and the observation clips of the goal.
"""

GUIDANCE_SCALE = 5.0
"""Classifier-free guidance weight of the motion model's sampler (DART's ``guidance_param``)."""

MAX_GUIDANCE = 100.0
"""Guidance weights beyond +/- this only amplify the denoiser's error into non-finite motion."""

SUCCESS_RADIUS_M = 0.3
"""A goal counts as reached when the pelvis comes closer (xy) than this, metres."""

CONTACT_HEIGHT_M = 0.03
"""A foot joint lower than this above the floor is in contact (skate, floor terms and metrics), metres."""

OBS_GOAL_ANGLE_CLIP_DEG = 60.0
"""Goal-direction cone half-width of the observation, degrees."""

OBS_GOAL_DIST_CLIP_M = 5.0
"""Goal-distance clip of the observation, metres."""

TERMINATE_DISTANCE_M = 100.0
"""Episodes end when the pelvis is farther (xy) than this from the goal, metres (``terminate_threshold``)."""

ACTION_BOUND = 4.0
"""Actions are clamped to +/- this (the ``4 tanh`` bound of DART's policy mean)."""

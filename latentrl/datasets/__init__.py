"""Motion-text datasets: the on-disk format and the procedural locomotion generator."""

from latentrl.datasets.locomotion import (
    SKILLS,
    SYNONYMS,
    TEXT_TO_SKILL,
    LocomotionConfig,
    dataset_statistics,
    generate_dataset,
    generate_sequences,
)
from latentrl.datasets.motion_text import (
    FIELDS,
    list_dataset,
    read_meta,
    read_sequence,
    validate_sequence,
    write_sequence,
)

__all__ = [
    "FIELDS",
    "SKILLS",
    "SYNONYMS",
    "TEXT_TO_SKILL",
    "LocomotionConfig",
    "dataset_statistics",
    "generate_dataset",
    "generate_sequences",
    "list_dataset",
    "read_meta",
    "read_sequence",
    "validate_sequence",
    "write_sequence",
]

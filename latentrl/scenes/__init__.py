"""Scenes: the objects a character moves among, as batched analytic SDFs, a terrain height and a JSON form."""

from latentrl.scenes.scene import FAR_M, Box, Cylinder, Scene, SceneBatch, Seat, Stairs
from latentrl.scenes.spec import (
           FORMAT,
           MAX_OBJECTS,
           load_scene,
           parse_scene,
           scene_from_json,
           scene_to_dict,
           scene_to_json,
)

__all__ = ["FAR_M", "FORMAT", "MAX_OBJECTS", "Box", "Cylinder", "Scene", "SceneBatch", "Seat", "Stairs", "load_scene",
           "parse_scene", "scene_from_json", "scene_to_dict", "scene_to_json"]

"""Synthetic office corridor with ground truth: scene, renderer, calibration targets, datasets.

The built-in default data of mrstereo (paper Sec. 5, Figs. 7 and 11-14) and randomized worlds
drawn from a seed. User guide: docs/world.md; dataset layout: docs/dataset.md.
Conventions: docs/conventions.md.
"""
from ..recordings.manifest import FrameRecord, Manifest, read_manifest, write_manifest
from .dataset import corridor_path, poses_along, write_synthetic_dataset
from .groundtruth import drop_edges, floor_heights, ground_truth_map, obstacle_footprints, occupied_footprint
from .randomize import RandomWorld, random_stereo, random_world
from .render import SensorModel, StereoFrame, camera_poses, default_stereo, render_stereo_frame, render_view
from .scene import (LABEL_CEILING, LABEL_DOOR, LABEL_FLOOR, LABEL_NAMES, LABEL_NONE, LABEL_OBSTACLE, LABEL_POSTER,
                    LABEL_SKIRTING, LABEL_WALL, Box, Cylinder, Decal, Light, Material, Scene, default_scene,
                    is_obstacle_label)
from .targets import RenderedTarget, render_calibration_views, render_paper_dot_target, target_points

__all__ = [
    "Scene", "Box", "Cylinder", "Decal", "Light", "Material", "default_scene", "is_obstacle_label",
    "LABEL_NONE", "LABEL_FLOOR", "LABEL_WALL", "LABEL_CEILING", "LABEL_DOOR", "LABEL_POSTER",
    "LABEL_SKIRTING", "LABEL_OBSTACLE", "LABEL_NAMES",
    "RandomWorld", "random_world", "random_stereo", "SensorModel",
    "StereoFrame", "default_stereo", "render_stereo_frame", "render_view", "camera_poses",
    "ground_truth_map", "occupied_footprint", "obstacle_footprints", "floor_heights", "drop_edges",
    "RenderedTarget", "render_calibration_views", "render_paper_dot_target", "target_points",
    "FrameRecord", "Manifest", "read_manifest", "write_manifest", "write_synthetic_dataset", "corridor_path",
    "poses_along",
]

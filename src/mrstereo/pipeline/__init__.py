"""The chain end to end: one pair (:mod:`.frame`), the mapper that takes pairs one at a time into a
growing map (:mod:`.mapper`), a recording to a map (:mod:`.run`), live (:mod:`.live`), many recordings
(:mod:`.batch`). Conventions: docs/conventions.md.
"""
from .batch import run_batch
from ..geometry.pair import PairObstacles, PairScan, obstacles_from_pair, scan_from_pair
from .mapper import MappedFrame, PipelineConfig, StereoMapper
from .odometry import odometry_from_manifest
from .run import MapRun, build_map, write_map_outputs

__all__ = ["PipelineConfig", "StereoMapper", "MappedFrame", "MapRun", "build_map", "write_map_outputs",
           "PairObstacles", "PairScan", "obstacles_from_pair", "scan_from_pair", "odometry_from_manifest", "run_batch"]

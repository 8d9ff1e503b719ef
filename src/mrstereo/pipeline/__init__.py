"""The chain end to end: one frame (:mod:`.frame`), a recording to a map (:mod:`.run`), its visual
odometry (:mod:`.odometry`), many recordings (:mod:`.batch`), and the ordered parallel map they run
on (:mod:`.parallel`). Conventions: docs/conventions.md.
"""
from .batch import run_batch
from .frame import PairObstacles, PairScan, obstacles_from_pair, scan_from_pair
from .odometry import odometry_from_manifest
from .run import MapRun, PipelineConfig, build_map, floor_for_run, observe_frame, write_map_outputs

__all__ = ["PipelineConfig", "MapRun", "build_map", "observe_frame", "floor_for_run", "write_map_outputs",
           "PairObstacles", "PairScan", "obstacles_from_pair", "scan_from_pair", "odometry_from_manifest", "run_batch"]

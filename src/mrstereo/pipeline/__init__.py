"""The chain end to end, orchestrated: the mapper that takes stereo pairs one at a time into a growing map
(:mod:`.mapper`; the pair half of its chain is :func:`mrstereo.geometry.pair.observe_pair`), a recording
to a map (:mod:`.run`), live (:mod:`.live`), many recordings (:mod:`.batch`). What a run leaves behind is
:mod:`mrstereo.evaluation.outputs`'s. Conventions: docs/conventions.md.
"""
from ..evaluation.outputs import MapRun, write_map_outputs
from ..geometry.pair import PairObstacles, PairScan, obstacles_from_pair, scan_from_pair
from .batch import run_batch
from .mapper import MappedFrame, PipelineConfig, StereoMapper
from .odometry import odometry_from_manifest
from .run import build_map

__all__ = ["PipelineConfig", "StereoMapper", "MappedFrame", "MapRun", "build_map", "write_map_outputs",
           "PairObstacles", "PairScan", "obstacles_from_pair", "scan_from_pair", "odometry_from_manifest", "run_batch"]

"""Recordings: what the pipeline reads (frames, stamps, poses, calibration, mount) and who writes it.

The dataset manifest (:mod:`.manifest`), ROS 1/2 bags (:mod:`.bag`) and the public sample scenes
(:mod:`.samples`). Conventions: docs/conventions.md; the manifest: docs/dataset.md.
"""
from .manifest import MANIFEST_NAME, FrameRecord, Manifest, frame_pair, read_manifest, write_manifest

__all__ = ["MANIFEST_NAME", "FrameRecord", "Manifest", "frame_pair", "read_manifest", "write_manifest"]

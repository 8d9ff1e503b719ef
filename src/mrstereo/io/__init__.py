"""File input and output: safe writes and staged folders (:mod:`.files`), images and disparity maps
(:mod:`.images`). Conventions: docs/conventions.md.
"""
from .files import (atomic_write, check_output_dir, check_outputs, no_space_error, parse_yaml, read_text, read_yaml,
                    refuse_overwrite_input, remove_stale_temporaries, staged_dir, temporary_dir)
from .images import (IMAGE_SUFFIXES, matching_image, read_disparity, read_image, read_kitti_disparity, read_pfm,
                     write_disparity, write_image, write_kitti_disparity, write_pfm)

__all__ = ["atomic_write", "check_output_dir", "check_outputs", "no_space_error", "parse_yaml", "read_text", "read_yaml",
           "refuse_overwrite_input", "remove_stale_temporaries", "staged_dir", "temporary_dir", "IMAGE_SUFFIXES", "matching_image",
           "read_disparity", "read_image", "read_kitti_disparity", "read_pfm", "write_disparity", "write_image",
           "write_kitti_disparity", "write_pfm"]

"""File input and output: protected inputs, safe writes and staged folders, bounded YAML (:mod:`.files`),
images and disparity maps (:mod:`.images`). Conventions: docs/conventions.md.
"""
from .files import (Inputs, atomic_write, check_output_dir, check_outputs, is_temporary, new_temporary_dir,
                    no_space_error, note_inputs, note_read, parse_yaml, protecting_inputs, read_text, read_yaml,
                    refuse_overwrite_input, remove_stale_temporaries, replace_dir, staged_dir, staged_new_dir,
                    temporary_dir, uninterruptible)
from .images import (IMAGE_SUFFIXES, check_image_size, decode_image, matching_image, quiet_decoders, read_disparity,
                     read_image, read_kitti_disparity, read_pfm, write_disparity, write_image, write_kitti_disparity,
                     write_pfm)

__all__ = ["Inputs", "atomic_write", "check_output_dir", "check_outputs", "is_temporary", "new_temporary_dir", "no_space_error",
           "note_inputs", "note_read", "parse_yaml", "protecting_inputs", "read_text", "read_yaml",
           "refuse_overwrite_input",
           "remove_stale_temporaries", "replace_dir", "staged_dir", "staged_new_dir", "temporary_dir",
           "uninterruptible", "IMAGE_SUFFIXES", "check_image_size", "decode_image", "matching_image",
           "quiet_decoders", "read_disparity", "read_image", "read_kitti_disparity", "read_pfm", "write_disparity",
           "write_image", "write_kitti_disparity", "write_pfm"]

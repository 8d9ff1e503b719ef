"""One view twice or swapped streams named on real pairs (rejection.streams)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mrstereo.rejection.streams import SAME_VIEW_SHARE, check_pair
from mrstereo.recordings.samples import data_root

PAIRS = {   # one real rectified pair of each kind: left, right under the data root
    "kitti06": ("kitti_odometry_06/sequences/06/image_0/000010.png", "kitti_odometry_06/sequences/06/image_1/000010.png"),
    "kitti01": ("kitti_odometry_01/sequences/01/image_0/000040.png", "kitti_odometry_01/sequences/01/image_1/000040.png"),
    "teddy": ("middlebury2003/teddy/im2.ppm", "middlebury2003/teddy/im6.ppm"),
    "cones": ("middlebury2003/cones/im2.png", "middlebury2003/cones/im6.png"),
}


def _pair(name):
    left, right = (data_root() / p for p in PAIRS[name])
    if not left.is_file():
        pytest.skip(f"sample data {left} not found: set MRSTEREO_DATA")
    return cv2.imread(str(left), cv2.IMREAD_GRAYSCALE), cv2.imread(str(right), cv2.IMREAD_GRAYSCALE)


@pytest.mark.parametrize("name", sorted(PAIRS))
def test_one_view_twice_with_noise_is_named_and_a_real_pair_is_not(name):
    left, right = _pair(name)
    real = check_pair(left, right)
    assert not real.identical and not real.swapped and real.same_view_share < SAME_VIEW_SHARE / 2
    rng = np.random.default_rng(1)
    for noise in (rng.integers(-2, 3, left.shape), rng.normal(0.0, 3.0, left.shape).round()):
        twice = np.clip(left.astype(np.int32) + noise, 0, 255).astype(np.uint8)
        check = check_pair(left, twice)
        assert check.identical_share < 0.9 and check.identical, check     # not equal, the same view all the same
        assert "textured pixels" in check.describe()
    assert check_pair(right, left).swapped                                 # and the exchanged real pair

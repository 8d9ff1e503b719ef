"""Recycled scratch buffers of the matcher (mrstereo.matching._kernels.recycled_empty)."""
from __future__ import annotations

import threading

import numpy as np

from mrstereo.matching import compute_disparity
from mrstereo.matching._kernels import recycled_empty

SHAPE = (123, 457)      # large enough to be pooled, unlikely to be used by other tests


def test_buffer_is_not_handed_out_while_referenced():
    a = recycled_empty(SHAPE, np.float32)
    b = recycled_empty(SHAPE, np.float32)
    assert a is not b
    view = a[1:, ::2]
    address = a.__array_interface__["data"][0]
    del a
    c = recycled_empty(SHAPE, np.float32)       # a's memory is still reachable through view
    assert c.__array_interface__["data"][0] != address
    assert view.base is not None


def test_buffer_is_reused_once_released():
    a = recycled_empty(SHAPE, np.float32)
    address = a.__array_interface__["data"][0]
    del a
    again = [recycled_empty(SHAPE, np.float32) for _ in range(2)]
    assert address in [x.__array_interface__["data"][0] for x in again]
    assert all(x.shape == SHAPE and x.dtype == np.float32 for x in again)


def _pair(seed: int, shift: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    texture = rng.integers(0, 256, (96, 200)).astype(np.uint8)
    return texture[:, 20:180], texture[:, 20 + shift:180 + shift]      # disparity = shift


def test_kept_results_survive_later_calls():
    first = compute_disparity(*_pair(0, 6), max_disparity_px=32)
    kept = first.disparity_px.copy()
    for seed in (1, 2):
        compute_disparity(*_pair(seed, 12), max_disparity_px=32)
    np.testing.assert_array_equal(first.disparity_px, kept)
    assert np.nanmedian(first.disparity_px) == 6


def test_threads_get_the_sequential_results():
    inputs = [_pair(seed, shift) for seed, shift in ((3, 5), (4, 9), (5, 14))]
    expected = [compute_disparity(l, r, max_disparity_px=32).disparity_px for l, r in inputs]
    failures = []

    def work(k: int) -> None:
        for it in range(4):
            i = (k + it) % len(inputs)
            got = compute_disparity(*inputs[i], max_disparity_px=32).disparity_px
            if not np.array_equal(got, expected[i], equal_nan=True):
                failures.append((k, it))

    threads = [threading.Thread(target=work, args=(k,)) for k in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert failures == []

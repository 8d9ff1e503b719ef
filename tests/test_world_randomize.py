"""Randomized worlds: reproducible seeds, realistic ranges, exact ground truth."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from mrstereo.cli import main
from mrstereo.geometry.ground import ground_from_mount
from mrstereo.mapping import GridSpec
from mrstereo.recordings.manifest import read_manifest
from mrstereo.world import (LABEL_FLOOR, LABEL_OBSTACLE, LABEL_WALL, Scene, SensorModel, ground_truth_map,
                            occupied_footprint, poses_along, random_world, render_stereo_frame)
from mrstereo.world.dataset import write_synthetic_dataset
from mrstereo.world.randomize import RANGES, _path_points
from mrstereo.world.scene import TEXTURE_STRIPES_U

SEEDS = range(30)


@pytest.fixture(scope="module")
def worlds():
    return {s: random_world(s) for s in SEEDS}


def test_same_seed_same_world_other_seed_other_world(worlds):
    again = random_world(7)
    assert again.scene == worlds[7].scene and again.summary == worlds[7].summary
    np.testing.assert_array_equal(again.stereo.right.P, worlds[7].stereo.right.P)
    np.testing.assert_array_equal(again.waypoints_xy, worlds[7].waypoints_xy)
    assert worlds[7].scene != worlds[8].scene
    assert len({w.summary["corridor_width_m"] for w in worlds.values()}) == len(worlds)


def test_drawn_quantities_stay_in_their_ranges_and_cover_the_bank(worlds):
    for w in worlds.values():
        st = w.stereo
        rig = ground_from_mount(st.mount, R_rect_from_cam=st.left.R)      # the rectified camera's height and tilt
        assert RANGES["camera_height_m"][0] <= rig.height_m <= RANGES["camera_height_m"][1]
        assert RANGES["tilt_rad"][0] <= rig.tilt_rad <= RANGES["tilt_rad"][1]
        assert RANGES["baseline_m"][0] <= st.baseline_m <= RANGES["baseline_m"][1]
        fov = math.degrees(2 * math.atan(st.size[0] / 2 / st.focal_px))
        assert RANGES["horizontal_fov_deg"][0] - 1e-9 <= fov <= RANGES["horizontal_fov_deg"][1] + 1e-9
        left, right = w.sensors
        assert left != right and left.gain != right.gain         # the two cameras differ
        lo, hi = RANGES["corridor_width_m"]
        assert lo <= 2 * w.scene.half_width_m <= hi
    kinds = {k for w in worlds.values() for k in w.summary["obstacles"]}
    assert kinds == {"box", "low", "cylinder", "pole", "table", "chair"}
    walls = {w.summary["textures"]["wall"] for w in worlds.values()}
    assert {"paint", "tiles", "stripes"} <= walls
    posters = {p for w in worlds.values() for p in w.summary["textures"]["posters"]}
    assert posters == {"poster", "chessboard", "stripes"}
    assert any(w.summary["side_openings"] for w in worlds.values())
    assert any(w.summary["doors"] for w in worlds.values())


def test_path_keeps_clear_of_every_obstacle(worlds):
    for w in worlds.values():
        pts = _path_points(w.waypoints_xy, 0.02)
        for b in w.scene.boxes:
            if b.label >= LABEL_OBSTACLE:
                dx = np.maximum(np.maximum(b.min_m[0] - pts[:, 0], pts[:, 0] - b.max_m[0]), 0)
                dy = np.maximum(np.maximum(b.min_m[1] - pts[:, 1], pts[:, 1] - b.max_m[1]), 0)
                assert np.hypot(dx, dy).min() >= 0.39
        for c in w.scene.cylinders:
            assert np.hypot(pts[:, 0] - c.centre_m[0], pts[:, 1] - c.centre_m[1]).min() - c.radius_m >= 0.39
        assert np.abs(pts[:, 1]).max() < w.scene.half_width_m - 0.3


def _on_box_surface(p, box, tol):
    lo, hi = np.array(box.min_m), np.array(box.max_m)
    inside = np.all((p >= lo - tol) & (p <= hi + tol), axis=1)
    on_face = np.min(np.minimum(np.abs(p - lo), np.abs(p - hi)), axis=1) <= tol
    return inside & on_face


def _on_cylinder_surface(p, cyl, tol):
    r = np.hypot(p[:, 0] - cyl.centre_m[0], p[:, 1] - cyl.centre_m[1])
    side = (np.abs(r - cyl.radius_m) <= tol) & (p[:, 2] >= -tol) & (p[:, 2] <= cyl.height_m + tol)
    cap = (np.abs(p[:, 2] - cyl.height_m) <= tol) & (r <= cyl.radius_m + tol)
    return side | cap


@pytest.mark.parametrize("seed", [0, 3, 6])
def test_gt_disparity_lies_on_the_labelled_geometry(worlds, seed):
    """Back-projected GT disparity lands on the surface of the primitive its label names."""
    w = worlds[seed]
    st = w.stereo
    poses = poses_along(w.waypoints_xy, 4)
    tol = 2e-3
    checked = {"floor": 0, "wall": 0, "obstacle": 0}
    for k, pan in ((1, 0.0), (2, math.pi / 4), (2, -math.pi / 4)):
        frame = render_stereo_frame(w.scene, st, pose=poses[k], pan_rad=pan, seed=1, supersample=1,
                                    sensors=w.sensors)
        v, u = np.nonzero(np.isfinite(frame.disparity_px))
        pick = np.random.default_rng(seed).choice(len(u), 3000, replace=False)
        u, v = u[pick], v[pick]
        d = frame.disparity_px[v, u].astype(np.float64)
        Z = st.focal_px * st.baseline_m / d
        pc = np.stack([(u - st.cx_px) * Z / st.focal_px, (v - st.cy_px) * Z / st.left.P[1, 1], Z, np.ones_like(Z)], 1)
        pw = (frame.T_world_from_cam @ pc.T).T[:, :3]
        labels = frame.labels[v, u]
        near = Z < 6.0          # float32 disparity: sub-millimetre up to 6 m
        floor = (labels == LABEL_FLOOR) & near
        np.testing.assert_allclose(pw[floor, 2], 0.0, atol=tol)
        checked["floor"] += floor.sum()
        wall = (labels == LABEL_WALL) & near
        on_wall = np.zeros(wall.sum(), bool)
        for b in w.scene.boxes:
            if b.label == LABEL_WALL:
                on_wall |= _on_box_surface(pw[wall], b, tol)
        assert on_wall.all()
        checked["wall"] += wall.sum()
        for lab in np.unique(labels[labels >= LABEL_OBSTACLE]):
            sel = (labels == lab) & near
            on = np.zeros(sel.sum(), bool)
            for b in w.scene.boxes:
                if b.label == lab:
                    on |= _on_box_surface(pw[sel], b, tol)
            for c in w.scene.cylinders:
                if c.label == lab:
                    on |= _on_cylinder_surface(pw[sel], c, tol)
            assert on.all(), f"obstacle label {lab}"
            checked["obstacle"] += sel.sum()
    assert min(checked.values()) > 20, checked


def test_gt_map_marks_a_placed_box_and_side_rooms(worlds):
    grid = GridSpec()
    res = grid.resolution_m
    n_boxes = n_rooms = 0
    for w in worlds.values():
        gt = ground_truth_map(w.scene, grid)
        occ = gt.occupancy
        obstacles = [b for b in w.scene.boxes if b.label >= LABEL_OBSTACLE]
        labels = [b.label for b in obstacles] + [c.label for c in w.scene.cylinders]
        for b in obstacles:
            if labels.count(b.label) != 1 or b.max_m[0] > 11.9:
                continue            # one-box obstacles (plain boxes and low objects) inside the grid
            c0 = math.floor((b.min_m[0] - grid.origin_x_m) / res)
            c1 = math.ceil((b.max_m[0] - grid.origin_x_m) / res)
            r0 = math.floor((b.min_m[1] - grid.origin_y_m) / res)
            r1 = math.ceil((b.max_m[1] - grid.origin_y_m) / res)
            assert (occ[r0:r1, c0:c1] == 1.0).all()
            alone = occupied_footprint(Scene(boxes=(b,), cylinders=(), decals=(), lights=(),
                                             materials=w.scene.materials), grid)
            expected = np.zeros(grid.shape, bool)
            expected[r0:r1, c0:c1] = True
            np.testing.assert_array_equal(alone, expected)
            n_boxes += 1
        for x0, x1, y0, y1 in w.scene.free_regions_m:
            xc, yc = (x0 + x1) / 2, (y0 + y1) / 2
            r, c = grid.cells_from_xy([xc, yc])
            if 0 <= c < grid.shape[1]:
                assert occ[r, c] == 0.0
                n_rooms += 1
    assert n_boxes >= 10 and n_rooms >= 3


def test_randomized_dataset_is_reproducible_file_for_file(tmp_path):
    a = write_synthetic_dataset(tmp_path / "a", seed=5, n_frames=2, width=64, height=48, randomize=True,
                                progress=False)
    b = write_synthetic_dataset(tmp_path / "b", seed=5, n_frames=2, width=64, height=48, randomize=True,
                                progress=False)
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert len(files) >= 14
    for rel in files:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    m = read_manifest(a)
    w = random_world(5, width=64, height=48)
    np.testing.assert_allclose(m.mount.T_base_from_cam, w.stereo.mount.T_base_from_cam, atol=1e-15)
    assert m.calibration.baseline_m == pytest.approx(w.stereo.baseline_m, rel=1e-12)
    data = yaml.safe_load((a / "manifest.yaml").read_text())
    assert data["generator"]["randomized"]["seed"] == 5


def test_sensor_model_gain_and_bad_values():
    w = random_world(2, width=64, height=48)
    pose = poses_along(w.waypoints_xy, 2)[0]
    dark = render_stereo_frame(w.scene, w.stereo, pose=pose, sensors=(SensorModel(gain=0.5, noise_sigma=0),
                                                                       SensorModel(gain=1.0, noise_sigma=0)))
    ratio = dark.raw_left.astype(float).mean() / dark.raw_right.astype(float).mean()
    assert 0.4 < ratio < 0.6
    with pytest.raises(ValueError, match="gain"):
        SensorModel(gain=0.0)
    with pytest.raises(TypeError, match="sensors"):
        render_stereo_frame(w.scene, w.stereo, pose=pose, sensors=(SensorModel(),))
    with pytest.raises(ValueError, match="seed"):
        random_world(-1)


def test_synth_randomize_cli(tmp_path):
    out = tmp_path / "ds"
    result = CliRunner().invoke(main, ["synth", "--out", str(out), "--frames", "2", "--width", "64", "--height",
                                       "48", "--seed", "3", "--randomize", "--quiet"])
    assert result.exit_code == 0, result.output
    m = read_manifest(out)
    truth = random_world(3, width=64, height=48).stereo.mount
    np.testing.assert_allclose(m.mount.T_base_from_cam, truth.T_base_from_cam, atol=1e-15)


def test_wall_texture_variant_changes_the_walls_only():
    for seed in (0, 1, 3):
        drawn = random_world(seed)
        striped = random_world(seed, wall_texture="stripes")
        a, b = dict(drawn.summary), dict(striped.summary)
        assert b["textures"]["wall"] == "stripes" and a["textures"]["wall"] != "stripes"
        a["textures"] = {**a["textures"], "wall": None}
        b["textures"] = {**b["textures"], "wall": None}
        assert a == b                                   # every other drawn quantity is the seed's
        assert drawn.scene.boxes == striped.scene.boxes and drawn.scene.decals == striped.scene.decals
        np.testing.assert_array_equal(drawn.waypoints_xy, striped.waypoints_xy)
        assert drawn.sensors == striped.sensors
        wall = next(box.material for box in drawn.scene.boxes if box.label == LABEL_WALL)
        changed = [k for k, (m0, m1) in enumerate(zip(drawn.scene.materials, striped.scene.materials)) if m0 != m1]
        assert changed == [wall]
        assert striped.scene.materials[wall].kind == TEXTURE_STRIPES_U
        assert random_world(seed, wall_texture="stripes").scene == striped.scene      # reproducible
    # a seed whose drawn walls already are of that kind stays the same world
    kind = random_world(0).summary["textures"]["wall"]
    assert random_world(0, wall_texture=kind).scene == random_world(0).scene


def test_wall_texture_bad_value_and_cli(tmp_path):
    with pytest.raises(ValueError, match="wall_texture must be one of"):
        random_world(0, wall_texture="marble")
    with pytest.raises(ValueError, match="randomize=True"):
        write_synthetic_dataset(tmp_path / "x", n_frames=1, wall_texture="stripes")
    result = CliRunner().invoke(main, ["synth", "--out", str(tmp_path / "y"), "--wall-texture", "stripes"])
    assert result.exit_code == 2 and "--wall-texture needs --randomize" in result.output
    result = CliRunner().invoke(main, ["synth", "--randomize", "--out", str(tmp_path / "z"),
                                       "--wall-texture", "marble"])
    assert result.exit_code == 2 and "--wall-texture" in result.output and "Traceback" not in result.output
    out = tmp_path / "s"
    result = CliRunner().invoke(main, ["synth", "--randomize", "--seed", "1", "--frames", "1", "--width", "64",
                                       "--height", "48", "--wall-texture", "stripes", "--quiet", "--out", str(out)])
    assert result.exit_code == 0, result.output
    generator = yaml.safe_load((out / "manifest.yaml").read_text())["generator"]
    assert generator["randomized"]["textures"]["wall"] == "stripes"

"""Control-point CSV, chessboard detection and grids."""
import numpy as np
import pytest

from mrstereo.calibration import (chessboard_views, detect_chessboard, expand_glob, parse_board, planar_grid,
                                  read_control_points)


def test_planar_grid_order_matches_opencv():
    g = planar_grid(9, 6, 0.025)
    assert g.shape == (54, 3) and np.allclose(g[1], [0.025, 0, 0]) and np.allclose(g[9], [0, 0.025, 0])
    with pytest.raises(ValueError, match="spacing_m"):
        planar_grid(9, 6, float("nan"))


def test_parse_board():
    assert parse_board("9x6") == (9, 6) and parse_board("7X5") == (7, 5)
    with pytest.raises(ValueError, match="9x6"):
        parse_board("nine")


def test_control_points_csv_units(tmp_path):
    rows = "\n".join(f"{x},{y},{z},{u},{v}" for x, y, z, u, v in
                     [(0, 0, 0, 10, 20), (100, 0, 0, 110, 21), (0, 100, 0, 11, 120), (100, 100, 0, 112, 121),
                      (50, 50, 20, 60, 70), (200, 0, 0, 210, 22)])
    p = tmp_path / "pts.csv"
    p.write_text("# units: mm\nX,Y,Z,u,v\n" + rows + "\n")
    view = read_control_points(p)
    assert np.allclose(view.points_target[1], [0.1, 0, 0]) and np.allclose(view.uv[0], [10, 20])
    assert not view.is_planar
    assert np.allclose(read_control_points(p, units="m").points_target[1], [100, 0, 0])
    q = tmp_path / "bad.csv"
    q.write_text("A,B,C\n1,2,3\n")
    with pytest.raises(ValueError, match="X, Y, Z, u, v"):
        read_control_points(q)
    q.write_text("X,Y,Z,u,v\n1,2,x,4,5\n")
    with pytest.raises(ValueError, match="not numeric"):
        read_control_points(q)
    with pytest.raises(ValueError, match="units"):
        read_control_points(p, units="inch")
    with pytest.raises(FileNotFoundError):
        read_control_points(tmp_path / "missing.csv")


def test_detect_chessboard_on_a_drawn_board():
    # a 10x7-square board (9x6 inner corners), 20 px squares, warped by a known homography
    board = np.full((7 * 20 + 40, 10 * 20 + 40), 255, np.uint8)
    for r in range(7):
        for c in range(10):
            if (r + c) % 2 == 0:
                board[20 + 20 * r: 40 + 20 * r, 20 + 20 * c: 40 + 20 * c] = 0
    import cv2
    H = np.array([[1.1, 0.08, 60.0], [-0.05, 1.05, 40.0], [1e-4, 2e-4, 1.0]])
    img = cv2.warpPerspective(board, H, (400, 300), borderValue=255)
    found = detect_chessboard(img, (9, 6))
    assert found is not None and found.shape == (54, 2)
    # square edges fall between pixels 39 and 40: x = 39.5 with pixel centres at integers
    truth = np.array([[39.5 + 20 * c, 39.5 + 20 * r] for r in range(6) for c in range(9)])
    th = np.c_[truth, np.ones(54)] @ H.T
    th = th[:, :2] / th[:, 2:]
    assert np.abs(found - th).max() < 0.3          # numbered from the top-left corner
    assert detect_chessboard(np.full((100, 120), 128, np.uint8), (9, 6)) is None


def test_glob_and_views_errors(tmp_path):
    with pytest.raises(ValueError, match="no images match"):
        expand_glob(str(tmp_path / "*.png"))
    import cv2
    cv2.imwrite(str(tmp_path / "blank.png"), np.full((60, 80), 200, np.uint8))
    with pytest.raises(ValueError, match="not found in any"):
        chessboard_views(expand_glob(str(tmp_path / "*.png")), (9, 6), 0.025)

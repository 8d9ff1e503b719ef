"""CLI: ``calibrate``, ``stereo-calibrate`` and ``rectify`` (see docs/calibration.md).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import click
from tqdm import tqdm

from ..calibration import (METHODS, MODELS, MULTIVIEW_GA, GAConfig, calibrate_camera, calibrate_stereo,
                           check_view_geometry, chessboard_pairs, chessboard_views, expand_glob, parse_board,
                           read_control_points, reprojection_residuals)
from ..calibration.report import camera_line, markdown_report, residual_figure, write_json, write_text
from ..camera import CameraInfo, read_stereo, write_camera_info, write_stereo
from ..io import IMAGE_SUFFIXES, check_output_dir, check_outputs, read_image, write_image
from ._options import CALIB_HELP, MAX_IMAGE_SIDE, SEED, Number, numbers

SQUARE = Number(0.0, 1.0, unit="m", open_low=True)
"""``--square``: the chessboard's square side."""
def _force_option():
    return click.option("--force", is_flag=True,
                        help="Write the calibration even when the fit did not converge (then a warning).")


def _converged(result, force: bool, what: str) -> None:
    """A fit that did not converge is an error, or with ``--force`` a warning: it is written either way only
    when forced."""
    if result.success:
        return
    text = f"the {what} did not converge ({' '.join(str(result.message).split())}; RMS {result.rms_px:.4g} px)"
    if not force:
        raise RuntimeError(f"{text}: nothing written; check the views (more of them, tilted boards) or give "
                           "--force to write it anyway")
    click.echo(f"mrstereo: warning: {text}; written because of --force", err=True)


def _progress_bar(total: int, desc: str):
    bar = tqdm(total=total, desc=desc, unit="gen", leave=False, mininterval=0.5)

    def update(generation: int, best: float) -> None:
        if generation < bar.n:          # the second camera of a stereo pair starts again
            bar.reset()
        bar.set_postfix_str(f"F={best:.4g} px^2", refresh=False)
        bar.update(generation - bar.n)
    return bar, update


def _residuals_path(output: Path) -> Path:
    return output.with_suffix("").with_name(output.with_suffix("").name + "_residuals.png")


def _check_report_outputs(output: Path, stem_suffix: str, inputs, extra=None) -> None:
    """The calibration file, its report files (and ``extra``) must be new names apart from the inputs."""
    outputs = {"--out": output, **{f"report {k}": p for k, p in _siblings(output, stem_suffix).items()},
               **(extra or {})}
    check_outputs(outputs, inputs, suffixes={"--out": (".yaml", ".yml")})


def _method_option():
    return click.option("--method", type=click.Choice(METHODS), default="ga+lm", show_default=True,
                        help="ga: the paper's genetic algorithm alone (k1k2 only); ga+lm: the GA's result polished "
                             "by Levenberg-Marquardt; lm: Levenberg-Marquardt from Zhang's closed form (planar "
                             "targets only).")


def _model_option():
    return click.option("--model", type=click.Choice(MODELS), default="k1k2", show_default=True,
                        help="Distortion model: k1k2 (the paper's, what the GA fits), plumb_bob (k1, k2, p1, "
                             "p2, k3), rational (k1..k6, p1, p2) or fisheye (equidistant k1..k4); the richer "
                             "models are fitted by LM from the k1k2 result.")


def _siblings(output: Path, stem_suffix: str) -> dict[str, Path]:
    base = output.with_suffix("")
    return {k: base.with_name(f"{base.name}{stem_suffix}.{k}") for k in ("json", "md", "png")}


@click.command("calibrate")
@click.option("--points", type=click.Path(dir_okay=False), help="Control points CSV (X, Y, Z, u, v).")
@click.option("--image-size", default=None, help="WxH of the images (needed with --points), e.g. 640x480.")
@click.option("--units", type=click.Choice(["m", "mm"]), default=None, help="Units of X, Y, Z in --points "
              "(default: the file's '# units:' comment, else m).")
@click.option("--images", "images_glob", help="Glob of chessboard images, e.g. 'left*.jpg'.")
@click.option("--board", default="9x6", show_default=True, help="Inner corners, columns x rows.")
@click.option("--square", type=SQUARE, default=0.025, show_default=True, help="Square size [m].")
@_method_option()
@_model_option()
@click.option("--seed", type=SEED, default=0, show_default=True, help="Seed of the GA's random numbers.")
@click.option("--generations", type=Number(1, 100_000, integer=True), default=None,
              help="GA generation limit (default 2000 for one view, 200 for several).")
@click.option("-o", "--out", "output", required=True, type=click.Path(dir_okay=False),
              help="camera_info YAML to write (.yaml or .yml).")
@_force_option()
@click.option("--quiet", is_flag=True, help="No progress bar.")
def calibrate_cmd(points, image_size, units, images_glob, board, square, method, model, seed, generations, output,
                  force, quiet):
    """Calibrate one camera from chessboards or control points.

    Fits the camera with the paper's genetic algorithm (section 2.2), its result
    polished by Levenberg-Marquardt (--method ga+lm), and writes the ROS
    camera_info YAML given by -o; beside it NAME_report.json, NAME_report.md and
    NAME_residuals.png, the reprojection residuals (paper Figs. 2-3).
    """
    if (points is None) == (images_glob is None):
        raise click.UsageError("give exactly one of --points FILE or --images GLOB")
    if method == "ga" and model != "k1k2":
        raise ValueError(f"--method ga fits the paper's k1k2 model only; --model {model} needs "
                         "--method ga+lm or lm")
    output = Path(output)
    if points is not None:
        if image_size is None:
            raise click.UsageError("--points needs --image-size WxH")
        width, height = (int(v) for v in numbers(image_size.lower().replace("x", ","), "--image-size", 2, 1,
                                                  MAX_IMAGE_SIDE, unit="px", what="'WxH', e.g. 640x480"))
        _check_report_outputs(output, "_report", [points], extra={"residuals figure": _residuals_path(output)})
        views = [read_control_points(points, units=units)]
    else:
        cols_rows = parse_board(board)
        paths = expand_glob(images_glob)
        _check_report_outputs(output, "_report", paths, extra={"residuals figure": _residuals_path(output)})
        found, (width, height) = chessboard_views(paths, cols_rows, square)
        views = [v for v in found if v is not None]
        missing = [p.name for p, v in zip(paths, found) if v is None]
        if missing:
            click.echo(f"board not found in {len(missing)} image(s): {', '.join(missing)}", err=True)
        if len(views) < MIN_BOARD_VIEWS:
            raise ValueError(f"the board was found in {len(views)} image(s) of {images_glob}: a flat board seen "
                             f"from fewer than {MIN_BOARD_VIEWS} angles does not determine a camera (focal length "
                             "and principal point trade off); take more views at different angles, or use a 3-D "
                             "control-point target (--points)")
    for view in views:
        check_view_geometry(view)          # before any progress bar: one line for degenerate points
    config = None
    if generations is not None:
        base = GAConfig() if len(views) == 1 else MULTIVIEW_GA
        config = dataclasses.replace(base, generations=generations)
    total = (config or (GAConfig() if len(views) == 1 else MULTIVIEW_GA)).generations
    bar, update = _progress_bar(total, "GA") if method != "lm" and not quiet else (None, None)
    try:
        result = calibrate_camera(views, width=width, height=height, method=method, model=model, ga_config=config,
                                  rng=seed, progress=update)
    finally:
        if bar is not None:
            bar.close()
    _converged(result, force, "calibration")
    files = _siblings(output, "_report")
    figure = _residuals_path(output)
    write_camera_info(output, CameraInfo(result.camera, name=output.stem))
    write_json(files["json"], result.summary())
    write_text(files["md"], markdown_report(result))
    residual_figure(figure, result.camera, views, residuals=reprojection_residuals(views, result.camera, result.poses))
    click.echo(f"{method}: RMS {result.rms_px:.4f} px over {len(views)} view(s); {camera_line(result.camera)}"
               + ("" if result.success else f" [NOT CONVERGED: {result.message}]"))
    if result.outlier_views:
        click.echo("outlier views: " + ", ".join(result.view_names[i] for i in result.outlier_views), err=True)
    click.echo(f"wrote {output}, {files['json'].name}, {files['md'].name}, {figure.name}")


MIN_BOARD_VIEWS = 3
"""Chessboard views a camera calibration needs at least (Zhang 2000: a plane gives two constraints per view on
the five intrinsics)."""


@click.command("stereo-calibrate")
@click.option("--left", "left_glob", required=True, help="Glob of left chessboard images.")
@click.option("--right", "right_glob", required=True, help="Glob of right chessboard images.")
@click.option("--board", default="9x6", show_default=True, help="Inner corners, columns x rows.")
@click.option("--square", type=SQUARE, default=0.025, show_default=True, help="Square size [m].")
@_method_option()
@_model_option()
@click.option("--seed", type=SEED, default=0, show_default=True, help="Seed of the GA's random numbers.")
@click.option("--alpha", type=Number(0.0, 1.0), default=0.0, show_default=True,
              help="Rectified view: 0 = valid pixels only, 1 = all raw pixels.")
@click.option("-o", "--out", "output", required=True, type=click.Path(dir_okay=False),
              help="Stereo YAML to write (.yaml or .yml).")
@_force_option()
@click.option("--quiet", is_flag=True, help="No progress bar.")
def stereo_calibrate_cmd(left_glob, right_glob, board, square, method, model, seed, alpha, output, force, quiet):
    """Calibrate a stereo rig from chessboard image pairs.

    Calibrates both cameras and their relative pose, rectifies the pair
    (Fusiello et al. 2000) and writes the stereo YAML given by -o (every
    --calib reads it) and, beside it, NAME_report.json and NAME_report.md.
    Pairs are matched by sorted file order; a pair where either board is not
    found is skipped and reported.
    """
    output = Path(output)
    if method == "ga" and model != "k1k2":
        raise ValueError(f"--method ga fits the paper's k1k2 model only; --model {model} needs "
                         "--method ga+lm or lm")
    cols_rows = parse_board(board)
    left_paths, right_paths = expand_glob(left_glob, "left images"), expand_glob(right_glob, "right images")
    if len(left_paths) != len(right_paths):
        raise ValueError(f"{len(left_paths)} left images but {len(right_paths)} right images; pairs are "
                         "matched by sorted order and must be equal in number")
    _check_report_outputs(output, "_report", left_paths + right_paths)
    found = chessboard_pairs(left_paths, right_paths, cols_rows, square)
    skipped = found.skipped
    if skipped:
        click.echo(f"skipped {len(skipped)} pair(s) without a board in both images: {', '.join(skipped)}", err=True)
    if len(found.left) < 2:
        raise ValueError(f"the board was found in both images of only {len(found.left)} pair(s); need at least 2")
    pairs = list(zip(found.left, found.right))
    size_l = found.size
    bar, update = _progress_bar(MULTIVIEW_GA.generations, "GA") if method != "lm" and not quiet else (None, None)
    try:
        result = calibrate_stereo([p[0] for p in pairs], [p[1] for p in pairs], width=size_l[0], height=size_l[1],
                                  method=method, model=model, alpha=alpha, rng=seed, progress=update)
    finally:
        if bar is not None:
            bar.close()
    _converged(result, force, "stereo calibration")
    files = _siblings(output, "_report")
    summary = result.summary()
    summary["skipped_pairs"] = skipped
    write_stereo(output, result.stereo)
    write_json(files["json"], summary)
    md = [markdown_report(result.left, title="Left camera"), markdown_report(result.right, title="Right camera"),
          "# Stereo", "", f"- success: {result.success}; {result.message}",
          f"- joint RMS: {result.rms_px:.4f} px", f"- baseline: {result.baseline_m:.5f} m",
          f"- rectified vertical error (mean |y_l - y_r|): {result.vertical_error_px:.4f} px",
          f"- skipped pairs: {', '.join(skipped) or 'none'}", ""]
    write_text(files["md"], "\n".join(md))
    click.echo(f"{len(pairs)} pairs: RMS {result.rms_px:.4f} px, baseline {result.baseline_m:.4f} m, "
               f"rectified vertical error {result.vertical_error_px:.4f} px"
               + ("" if result.success else f" [NOT CONVERGED: {result.message}]"))
    click.echo(f"wrote {output}, {files['json'].name}, {files['md'].name}")


@click.command("rectify")
@click.option("--calib", required=True, type=click.Path(dir_okay=False), help=CALIB_HELP)
@click.argument("left", type=click.Path(dir_okay=False))
@click.argument("right", type=click.Path(dir_okay=False))
@click.option("-o", "--out", "output", required=True, type=click.Path(file_okay=False), help="Output folder.")
def rectify_cmd(calib, left, right, output):
    """Undistort and rectify a raw stereo pair.

    Writes the rectified images into the folder given by -o under the names
    of LEFT and RIGHT.
    """
    out_dir = Path(output)
    names = [Path(left).name, Path(right).name]
    if names[0] == names[1]:
        names = ["left_" + names[0], "right_" + names[1]]
    targets = [out_dir / n for n in names]
    stereo = read_stereo(calib)
    check_output_dir("--out", out_dir, may_hold_inputs=True)
    check_outputs({f"--out {t}": t for t in targets}, [left, right, calib],
                  suffixes={f"--out {t}": IMAGE_SUFFIXES for t in targets})
    img_l, img_r = read_image(left), read_image(right)
    rect_l, rect_r = stereo.rectify(img_l, img_r)
    for t, img in zip(targets, (rect_l, rect_r)):
        write_image(t, img)
    click.echo(f"wrote {targets[0]} and {targets[1]}")


COMMANDS = [calibrate_cmd, stereo_calibrate_cmd, rectify_cmd]

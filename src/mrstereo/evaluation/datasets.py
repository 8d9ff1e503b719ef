"""Readers for stereo scenes with ground truth (Middlebury, KITTI, mrstereo datasets).

:func:`load_scene` recognizes a scene folder's layout from its file names and returns a
:class:`Scene` (rectified pair, ground-truth disparity in pixels with NaN unknown, the
non-occluded mask when there is one, the search range); :func:`load_scenes` returns one scene per
frame of an mrstereo dataset. The layouts, their ground-truth encodings and how the Middlebury
2001/2003 scale is decided: docs/evaluation.md, "Scene folders". Disparity ``d = x_left -
x_right`` (docs/conventions.md).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from .. import _checks
from ..io import read_image, read_kitti_disparity, read_pfm

__all__ = ["Scene", "load_scene", "load_scenes", "LAYOUTS", "photometric_error", "search_range_px"]

LAYOUTS = ("middlebury2001", "middlebury2003", "middlebury2005", "middlebury2014", "kitti2012", "kitti2015",
           "mrstereo")

_EXPECTED = (
    "one of: Middlebury v2 bundle (imL.png, imR.png, groundtruth.png, info.txt); Middlebury 2001 Tsukuba (scene1.row3.col3.ppm, scene1.row3.col4.ppm, truedisp.row3.col3.pgm); "
    "Middlebury 2001/2003 (im2, im6, disp2 as .ppm/.pgm/.png); Middlebury 2005/2006 (view1.png, view5.png, "
    "disp1.png); Middlebury 2014 (im0.png, im1.png, disp0.pfm); KITTI 2012 (image_0/, image_1/, disp_noc/ or "
    "disp_occ/); KITTI 2015 (image_2/, image_3/, disp_noc_0/ or disp_occ_0/); an mrstereo dataset "
    "(manifest.yaml with gt_disparity per frame, as `mrstereo synth` writes)"
)


@dataclass(frozen=True)
class Scene:
    """One rectified stereo pair with ground truth.

    ``name`` (folder or frame), ``left``/``right`` as stored (BGR colour), ``gt_disparity_px``
    (float32, NaN unknown), ``nonocc_mask`` (None: every ground-truth pixel is evaluated),
    ``max_disparity_px`` (``ndisp``, else the smallest multiple of 16 above the largest true
    disparity), ``layout`` (one of :data:`LAYOUTS`), ``directory`` and ``gt_description`` (which file
    and how it was decoded).
    """

    name: str
    left: np.ndarray = field(repr=False)
    right: np.ndarray = field(repr=False)
    gt_disparity_px: np.ndarray = field(repr=False)
    nonocc_mask: np.ndarray | None = field(repr=False)
    max_disparity_px: int
    layout: str
    directory: Path
    gt_description: str = ""

    @property
    def shape(self) -> tuple[int, int]:
        """Image size ``(H, W)``."""
        return self.gt_disparity_px.shape


def search_range_px(gt_disparity_px: np.ndarray) -> int:
    """Smallest multiple of 16 strictly above the largest ground-truth disparity.

    A matcher searching ``numDisparities = n`` covers ``0 .. n - 1``; the
    result therefore always contains ``ceil(max)``.
    """
    finite = gt_disparity_px[np.isfinite(gt_disparity_px)]
    top = float(finite.max()) if finite.size else 0.0
    return int(16 * (math.floor(top) // 16 + 1))


def photometric_error(left: np.ndarray, right: np.ndarray, disparity_px: np.ndarray) -> float:
    """Mean absolute grey difference between the left view and the right view warped by ``d``.

    The right view is sampled at ``x - d`` (bilinear); pixels with unknown
    ``d`` or sampling outside the image are ignored. Used to check or choose
    the scale of a ground-truth map: the true scale gives by far the lowest error.
    """
    gray_l = _gray(_checks.image("left", left))
    gray_r = _gray(_checks.image("right", right))
    _checks.same_shape("left", gray_l, "right", gray_r)
    disparity_px = np.asarray(disparity_px, dtype=np.float32)
    if disparity_px.shape != gray_l.shape:
        raise ValueError(f"disparity_px must have the images' shape {gray_l.shape}, got {disparity_px.shape}")
    height, width = gray_l.shape
    valid = np.isfinite(disparity_px)
    map_x = np.arange(width, dtype=np.float32)[None, :] - np.where(valid, disparity_px, 0).astype(np.float32)
    map_y = np.repeat(np.arange(height, dtype=np.float32)[:, None], width, axis=1)
    warped = cv2.remap(gray_r, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=-1)
    use = valid & (map_x >= 0) & (map_x <= width - 1) & (warped >= 0)
    if not use.any():
        return math.inf
    return float(np.mean(np.abs(gray_l[use] - warped[use])))


def load_scene(directory, *, frame: str | None = None) -> Scene:
    """Read one benchmark scene, detecting its layout from the file names (docs/evaluation.md).

    ``frame`` picks a frame of a KITTI folder (``"000070_10"``) or of an mrstereo dataset (the stem
    of its ``gt_disparity``, ``"000003"``); default: the only frame with ground truth.
    FileNotFoundError for a missing folder; ValueError, listing the expected files, for a folder
    that matches no layout or whose files disagree in size.
    """
    path = _directory(directory)
    if (path / _MANIFEST).is_file():
        return _one_dataset_frame(path, frame)
    for reader in (_read_kitti, _read_middlebury2014, _read_middlebury2005, _read_tsukuba,
                   _read_middlebury_im2_im6, _read_middlebury_v2_bundle):
        scene = reader(path, frame)
        if scene is not None:
            return _check_sizes(scene)
    raise ValueError(f"{path} matches no known stereo dataset layout; expected {_EXPECTED}")


def load_scenes(directory) -> list[Scene]:
    """Every scene of ``directory``: one per frame with ground-truth disparity for an mrstereo
    dataset (in manifest order, named ``<dataset folder>/<frame>``), else ``[load_scene(directory)]``.

    Raises as :func:`load_scene`; an mrstereo dataset without any ``gt_disparity`` is a ``ValueError``.
    """
    path = _directory(directory)
    if (path / _MANIFEST).is_file():
        return [_dataset_scene(path, manifest, record) for manifest, record in _dataset_frames(path)]
    return [load_scene(path)]


def _directory(directory) -> Path:
    path = Path(directory)
    if not path.exists():
        raise FileNotFoundError(f"scene directory not found: {path}")
    if not path.is_dir():
        raise ValueError(f"scene must be a directory, got the file {path}")
    return path


# --------------------------------------------------------------------------- mrstereo datasets

_MANIFEST = "manifest.yaml"


def _dataset_frames(path: Path) -> list:
    """(manifest, frame record) of every frame with ground-truth disparity."""
    from ..recordings.manifest import read_manifest

    manifest = read_manifest(path)
    frames = [(manifest, f) for f in manifest.frames if f.gt_disparity is not None]
    if not frames:
        raise ValueError(f"{path}: the mrstereo dataset has no frame with ground-truth disparity "
                         f"(gt_disparity in {_MANIFEST}); nothing to evaluate")
    return frames


def _one_dataset_frame(path: Path, frame: str | None) -> Scene:
    frames = _dataset_frames(path)
    names = [record.gt_disparity.stem for _, record in frames]
    if frame is None:
        if len(frames) != 1:
            raise ValueError(f"{path}: the dataset has {len(frames)} frames with ground truth "
                             f"({', '.join(names[:3])}{', ...' if len(names) > 3 else ''}); pass frame= "
                             "or use load_scenes")
        return _dataset_scene(path, *frames[0])
    if frame not in names:
        raise ValueError(f"{path}: no frame {frame!r} with ground truth; frames: "
                         f"{', '.join(names[:5])}{', ...' if len(names) > 5 else ''}")
    return _dataset_scene(path, *frames[names.index(frame)])


def _dataset_scene(path: Path, manifest, record) -> Scene:
    """One frame of an mrstereo dataset: the rectified pair (rectified here from the raw pair and the
    dataset's calibration when the frame has no rectified images) and its PFM ground truth."""
    if record.has_rectified:
        left, right = _uint8_view(record.left_rect), _uint8_view(record.right_rect)
        how = "rectified pair"
    else:
        left, right = _uint8_view(record.left), _uint8_view(record.right)
        if not manifest.calibration.is_rectified:
            left, right = manifest.calibration.rectify(left, right)
        how = "raw pair rectified with the dataset's calibration"
    gt = read_pfm(record.gt_disparity)
    if gt.ndim != 2:
        raise ValueError(f"{record.gt_disparity}: expected a single-channel PFM disparity map, got shape {gt.shape}")
    gt = np.where(np.isfinite(gt), gt, np.nan).astype(np.float32)
    return _check_sizes(Scene(name=f"{path.name}/{record.gt_disparity.stem}", left=left, right=right,
                          gt_disparity_px=gt, nonocc_mask=None, max_disparity_px=search_range_px(gt),
                          layout="mrstereo", directory=path,
                          gt_description=f"{record.gt_disparity.relative_to(manifest.root)} (pixels); {how}"))


# --------------------------------------------------------------------------- helpers

def _gray(img: np.ndarray) -> np.ndarray:
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    return img.astype(np.float32)


def _first(directory: Path, names: tuple[str, ...]) -> Path | None:
    for name in names:
        candidate = directory / name
        if candidate.is_file():
            return candidate
    return None


def _uint8_view(path: Path) -> np.ndarray:
    img = read_image(path)
    if img.dtype != np.uint8:
        if img.dtype == np.uint16:
            img = (img >> 8).astype(np.uint8)
        else:
            raise ValueError(f"{path}: expected an 8-bit image, got dtype {img.dtype}")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    return img


def _eight_bit_gt(path: Path) -> np.ndarray:
    return read_image(path, gray=True).astype(np.float32)


def _scaled(raw: np.ndarray, scale: float, offset: float = 0.0) -> np.ndarray:
    out = raw / np.float32(scale) + np.float32(offset)
    out[raw == 0] = np.nan
    return out.astype(np.float32)


def _mask_255(path: Path | None) -> np.ndarray | None:
    if path is None:
        return None
    return read_image(path, gray=True) == 255


def _check_sizes(scene: Scene) -> Scene:
    shapes = {"left": scene.left.shape[:2], "right": scene.right.shape[:2],
              "ground truth": scene.gt_disparity_px.shape}
    if scene.nonocc_mask is not None:
        shapes["mask"] = scene.nonocc_mask.shape
    if len(set(shapes.values())) != 1:
        sizes = ", ".join(f"{k} {v[1]}x{v[0]}" for k, v in shapes.items())
        raise ValueError(f"{scene.directory}: views and ground truth differ in size ({sizes})")
    return scene


def _best_scale(left, right, raw: np.ndarray, candidates: dict[float, str]) -> float:
    errors = {scale: photometric_error(left, right, _scaled(raw, scale)) for scale in candidates}
    return min(errors, key=errors.get)


# --------------------------------------------------------------------------- Middlebury

def _read_tsukuba(path: Path, frame) -> Scene | None:
    left_p = path / "scene1.row3.col3.ppm"
    right_p = path / "scene1.row3.col4.ppm"
    gt_p = path / "truedisp.row3.col3.pgm"
    if not (left_p.is_file() and right_p.is_file() and gt_p.is_file()):
        return None
    left, right = _uint8_view(left_p), _uint8_view(right_p)
    gt = _scaled(_eight_bit_gt(gt_p), 16.0)  # col3 -> col4: value / 16 (value / 8 is col3 -> col5)
    return Scene(name=path.name, left=left, right=right, gt_disparity_px=gt,
                 nonocc_mask=_mask_255(_first(path, ("nonocc.png",))),
                 max_disparity_px=search_range_px(gt), layout="middlebury2001", directory=path,
                 gt_description=f"{gt_p.name} / 16 (col3 -> col4)")


_SIZE_2003 = {(375, 450): 4.0, (750, 900): 2.0}


def _read_middlebury_im2_im6(path: Path, frame) -> Scene | None:
    left_p = _first(path, ("im2.ppm", "im2.png"))
    right_p = _first(path, ("im6.ppm", "im6.png"))
    gt_p = _first(path, ("disp2.pgm", "disp2.png"))
    if left_p is None or right_p is None or gt_p is None:
        return None
    left, right = _uint8_view(left_p), _uint8_view(right_p)
    raw = _eight_bit_gt(gt_p)
    scale = _SIZE_2003.get(raw.shape)
    how = "image size"
    if scale is None:
        scale = _best_scale(left, right, raw, {8.0: "2001", 4.0: "2003 quarter", 2.0: "2003 half"})
        how = "photometric check"
    gt = _scaled(raw, scale)
    layout = "middlebury2001" if scale == 8.0 else "middlebury2003"
    return Scene(name=path.name, left=left, right=right, gt_disparity_px=gt,
                 nonocc_mask=_mask_255(_first(path, ("nonocc.png",))),
                 max_disparity_px=search_range_px(gt), layout=layout, directory=path,
                 gt_description=f"{gt_p.name} / {scale:g} (scale from {how})")


def _read_middlebury_v2_bundle(path: Path, frame) -> Scene | None:
    """Middlebury v2 scenes as bundled by LocalExpStereo: imL/imR/groundtruth.png + info.txt (scale, max d)."""
    left_p, right_p, gt_p = path / "imL.png", path / "imR.png", path / "groundtruth.png"
    if not (left_p.is_file() and right_p.is_file() and gt_p.is_file()):
        return None
    left, right = _uint8_view(left_p), _uint8_view(right_p)
    raw = _eight_bit_gt(gt_p)
    info_p = path / "info.txt"
    max_listed = None
    if info_p.is_file():
        try:
            numbers = [float(v) for v in info_p.read_text().split()]
            scale, max_listed = numbers[0], numbers[1]
        except (ValueError, IndexError):
            raise ValueError(f"{info_p}: expected two numbers (GT scale, max disparity)") from None
        if scale <= 0:
            raise ValueError(f"{info_p}: GT scale must be > 0, got {scale:g}")
        how = "info.txt"
    else:
        scale = _best_scale(left, right, raw, {16.0: "", 8.0: "", 4.0: "", 2.0: ""})
        how = "photometric check"
    gt = _scaled(raw, scale)
    max_d = search_range_px(gt)
    if max_listed is not None:
        max_d = max(max_d, int(16 * math.ceil((max_listed + 1) / 16)))
    layout = "middlebury2001" if scale >= 8 else "middlebury2003"
    return Scene(name=path.name, left=left, right=right, gt_disparity_px=gt,
                 nonocc_mask=_mask_255(_first(path, ("nonocc.png",))), max_disparity_px=max_d,
                 layout=layout, directory=path, gt_description=f"groundtruth.png / {scale:g} (scale from {how})")


def _read_middlebury2005(path: Path, frame) -> Scene | None:
    left_p, right_p, gt_p = path / "view1.png", path / "view5.png", path / "disp1.png"
    if not (left_p.is_file() and right_p.is_file() and gt_p.is_file()):
        return None
    left, right = _uint8_view(left_p), _uint8_view(right_p)
    raw = _eight_bit_gt(gt_p)
    height = raw.shape[0]
    scale = 1.0 if height > 800 else 2.0 if height > 450 else 3.0  # full ~1110, half ~555, third ~370 rows
    offset = 0.0
    note = ""
    dmin_p = path / "dmin.txt"
    if scale == 1.0 and dmin_p.is_file():
        # Full-size maps may be stored offset by dmin; keep the reading that matches the images.
        dmin = float(dmin_p.read_text().split()[0])
        if photometric_error(left, right, _scaled(raw, 1.0, dmin)) < photometric_error(left, right, _scaled(raw, 1.0)):
            offset = dmin
            note = f" + dmin {dmin:g}"
    gt = _scaled(raw, scale, offset)
    size = {1.0: "full", 2.0: "half", 3.0: "third"}[scale]
    return Scene(name=path.name, left=left, right=right, gt_disparity_px=gt,
                 nonocc_mask=_mask_255(_first(path, ("nonocc.png", "nonocc1.png"))),
                 max_disparity_px=search_range_px(gt), layout="middlebury2005", directory=path,
                 gt_description=f"disp1.png / {scale:g} ({size} size){note}")


def _read_calib_txt(path: Path) -> dict[str, str]:
    values = {}
    for line in path.read_text().splitlines():
        key, sep, value = line.partition("=")
        if sep:
            values[key.strip()] = value.strip()
    return values


def _read_middlebury2014(path: Path, frame) -> Scene | None:
    left_p, right_p = path / "im0.png", path / "im1.png"
    gt_p = _first(path, ("disp0.pfm", "disp0GT.pfm"))
    if not (left_p.is_file() and right_p.is_file()) or gt_p is None:
        return None
    left, right = _uint8_view(left_p), _uint8_view(right_p)
    gt = read_pfm(gt_p)
    if gt.ndim != 2:
        raise ValueError(f"{gt_p}: expected a single-channel PFM disparity map, got shape {gt.shape}")
    max_d = search_range_px(gt)
    calib_p = path / "calib.txt"
    described = f"{gt_p.name} (pixels)"
    if calib_p.is_file():
        ndisp = _read_calib_txt(calib_p).get("ndisp")
        if ndisp is not None:
            max_d = max(16, int(16 * math.ceil(int(float(ndisp)) / 16)))
            described += f", ndisp {ndisp} from calib.txt"
    return Scene(name=path.name, left=left, right=right, gt_disparity_px=gt,
                 nonocc_mask=_mask_255(_first(path, ("mask0nocc.png",))),
                 max_disparity_px=max_d, layout="middlebury2014", directory=path,
                 gt_description=described)


# --------------------------------------------------------------------------- KITTI

_KITTI = {
    "kitti2012": ((("image_0", "image_1"), ("colored_0", "colored_1")), "disp_noc", "disp_occ"),
    "kitti2015": ((("image_2", "image_3"),), "disp_noc_0", "disp_occ_0"),
}


def _read_kitti(path: Path, frame: str | None) -> Scene | None:
    for layout, (view_dirs, noc_dir, occ_dir) in _KITTI.items():
        views = next(((path / a, path / b) for a, b in view_dirs
                      if (path / a).is_dir() and (path / b).is_dir()), None)
        gt_dirs = [path / d for d in (occ_dir, noc_dir) if (path / d).is_dir()]
        if views is None or not gt_dirs:
            continue
        name = frame if frame is not None else _single_kitti_frame(path, gt_dirs)
        left_p, right_p = views[0] / f"{name}.png", views[1] / f"{name}.png"
        occ_p, noc_p = path / occ_dir / f"{name}.png", path / noc_dir / f"{name}.png"
        if not (left_p.is_file() and right_p.is_file()) or not (occ_p.is_file() or noc_p.is_file()):
            raise ValueError(f"{path}: frame {name} needs {left_p.relative_to(path)}, "
                             f"{right_p.relative_to(path)} and {occ_dir}/ or {noc_dir}/{name}.png")
        noc = read_kitti_disparity(noc_p) if noc_p.is_file() else None
        if occ_p.is_file():
            gt = read_kitti_disparity(occ_p)
            described = f"{occ_dir}/{name}.png / 256"
        else:
            gt = noc
            described = f"{noc_dir}/{name}.png / 256"
        mask = None
        if noc is not None:
            # The non-occluded map is KITTI's reference on its pixels (a few hundred differ from the
            # all-pixel map by up to 0.4 px); the all-pixel map fills the occluded rest.
            mask = np.isfinite(noc)
            gt = np.where(mask, noc, gt).astype(np.float32)
            described += f", {noc_dir} values on its non-occluded pixels (the evaluated region)"
        return Scene(name=name,
                     left=_uint8_view(left_p), right=_uint8_view(right_p), gt_disparity_px=gt,
                     nonocc_mask=mask, max_disparity_px=search_range_px(gt), layout=layout,
                     directory=path, gt_description=described)
    return None


def _single_kitti_frame(path: Path, gt_dirs: list[Path]) -> str:
    names = sorted({p.stem for d in gt_dirs for p in d.glob("*_10.png")})
    if not names:
        names = sorted({p.stem for d in gt_dirs for p in d.glob("*.png")})
    if len(names) != 1:
        found = f"{len(names)} frames ({', '.join(names[:3])}{', ...' if len(names) > 3 else ''})" \
            if names else "no ground-truth PNG"
        raise ValueError(f"{path}: expected one KITTI frame with ground truth, found {found}; "
                         f"pass frame=")
    if not re.fullmatch(r"[\w.-]+", names[0]):
        raise ValueError(f"{path}: unexpected KITTI frame name {names[0]!r}")
    return names[0]

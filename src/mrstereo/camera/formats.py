"""Calibration files of other tools, detected from their content (not their names).

Every reader produces what a ROS ``sensor_msgs/CameraInfo`` holds per camera and, for a raw
pair, the extrinsics ``x_right = R x_left + T`` (metres); a raw pair is rectified with
:func:`~mrstereo.camera.rectification.rectify_fusiello`, a pair with rectified ``P`` is used as
it is. The formats (mrstereo/ROS stereo YAML, two ROS camera_info files, Kalibr camchain, OpenCV
FileStorage, ASL/EuRoC sensor.yaml, OpenLORIS sensors.yaml), detection rules and field
mappings: docs/calibration-formats.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
import re
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..io import parse_yaml, read_text
from .camera_info import (BASELINE_RANGE_M, ROTATION_TOL, CameraInfo, StereoCamera, _rotation_error, camera_from_ros,
                          check_stereo, numbers)
from .model import Camera
from .rectification import check_not_swapped, rectify_fusiello

__all__ = ["FORMATS", "ImportedCalibration", "import_calibration", "read_stereo"]

#: The formats tried, in the words of the error message.
FORMATS = ("mrstereo/ROS stereo YAML", "two ROS camera_info YAMLs", "Kalibr camchain.yaml",
           "OpenCV FileStorage stereo (M1/D1/M2/D2/R/T)", "two ASL/EuRoC sensor.yaml",
           "OpenLORIS sensors.yaml (+ trans_matrix.yaml)")


@dataclass(frozen=True)
class ImportedCalibration:
    """Result of :func:`import_calibration`: the ``stereo`` every command reads, the ``format`` detected
    (one of :data:`FORMATS`) and ``rectified_here``, True when mrstereo rectified a raw pair (Fusiello).
    """

    stereo: StereoCamera
    format: str
    rectified_here: bool


@dataclass(frozen=True)
class _Raw:
    """A raw pair: two cameras and ``x_right = R x_left + T`` [m]."""

    left: Camera
    right: Camera
    R: np.ndarray
    T: np.ndarray


def read_stereo(paths, *, image_size: tuple[int, int] | None = None, alpha: float = 0.0) -> StereoCamera:
    """The :class:`StereoCamera` of a calibration in any supported format (:func:`import_calibration`).

    ``paths`` is the stereo YAML, a file of another tool, or two per-camera files as
    ``"left.yaml,right.yaml"`` or a sequence of two paths. Raw calibrations are rectified.
    """
    return import_calibration(paths, image_size=image_size, alpha=alpha).stereo


def import_calibration(paths, *, image_size: tuple[int, int] | None = None,
                       alpha: float = 0.0) -> ImportedCalibration:
    """Read one calibration file, or two per-camera files, detecting the format from the content.

    ``paths``: one file, two files as a sequence, or ``"left.yaml,right.yaml"``; ``image_size``
    ``(width, height)`` for formats that may not store it (OpenCV FileStorage; a stored size must
    agree); ``alpha`` the free scaling of a rectification mrstereo computes (0: only valid pixels, 1:
    all raw pixels). FileNotFoundError for a missing file; ValueError naming the file (and the
    field) when the content fits no format, a field is missing or out of range, the views look
    swapped or the rectified views do not overlap.
    """
    files = _split(paths)
    where = ",".join(str(p) for p in files)
    docs = [_load(p) for p in files]
    if len(docs) == 1:
        fmt, result = _read_one(files[0], docs[0], image_size)
    else:
        fmt, result = _read_two(files, docs, image_size)
    rectified_here = not isinstance(result, StereoCamera)
    stereo = _rectify(result, where=where, alpha=alpha) if rectified_here else result
    if fmt != FORMATS[0]:                              # StereoCamera.from_dict has checked its own
        stereo = check_stereo(stereo, where=where)
    return ImportedCalibration(stereo, fmt, rectified_here)


# --------------------------------------------------------------------------- files

def _split(paths) -> list[Path]:
    if isinstance(paths, (str, os.PathLike)):
        text = os.fspath(paths)
        parts = [text] if ("," not in text or Path(text).exists()) else [p.strip() for p in text.split(",")]
    else:
        parts = [os.fspath(p) for p in paths]
    if not 1 <= len(parts) <= 2 or any(not p for p in parts):
        raise ValueError(f"calibration: give one file or two separated by a comma, got {paths!s}")
    files = [Path(p) for p in parts]
    for path in files:
        if not path.exists():
            raise FileNotFoundError(f"stereo calibration not found: {path}")
        if not path.is_file():
            raise ValueError(f"stereo calibration {path} is not a file")
    return files


_OPENCV_MATRIX = "tag:yaml.org,2002:opencv-matrix"      # OpenCV's !!opencv-matrix, read as its mapping
MAX_CALIBRATION_BYTES = 16 << 20
"""A calibration file larger than this is refused unread (the largest real ones are a few KB)."""


def _load(path: Path) -> dict:
    """The file's content as plain Python (dicts, lists, numbers, strings, arrays)."""
    text = read_text(path, "stereo calibration", max_bytes=MAX_CALIBRATION_BYTES)
    if "\x00" in text:
        raise ValueError(f"stereo calibration {path} is not a text file (binary)")
    head = text.lstrip()[:64]
    if head.startswith("<?xml") or head.startswith("<opencv_storage"):
        return _load_filestorage(path)
    if head.startswith("%YAML"):                  # OpenCV writes %YAML:1.0 (OpenCV 4) or %YAML 1.2 (5)
        try:
            return _load_filestorage(path)
        except ValueError as exc:
            opencv_error = exc
        text = re.sub(r"\A\s*%YAML[^\n]*\n", "", text)       # PyYAML reads YAML 1.1 only
    else:
        opencv_error = None
    try:
        data = parse_yaml(text, "stereo calibration", path, tags=(_OPENCV_MATRIX,))
    except ValueError:
        if opencv_error is not None:
            raise opencv_error from None
        raise
    if not isinstance(data, dict):
        raise _unknown(path, "not a mapping of fields")
    return data


def _load_filestorage(path: Path) -> dict:
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        if not fs.isOpened():
            raise _unknown(path, "OpenCV FileStorage cannot open it")
        root = fs.root()
        data = _node(root) if root.isMap() else None
        fs.release()
    except (cv2.error, SystemError) as exc:
        reason = next((line for line in str(exc).splitlines() if "error:" in line), str(exc).strip())
        reason = reason.split("error:", 1)[-1].strip()
        raise _unknown(path, f"OpenCV FileStorage cannot parse it: {reason}") from None
    if not isinstance(data, dict):
        raise _unknown(path, "OpenCV FileStorage without top-level fields")
    return data


def _node(node):
    """An OpenCV FileNode as plain Python; ``!!opencv-matrix`` nodes as arrays."""
    if node.isMap():
        keys = list(node.keys())
        if {"rows", "cols", "dt", "data"} <= set(keys):
            try:
                mat = node.mat()
                if mat is not None:
                    return np.asarray(mat, dtype=np.float64)
            except (cv2.error, SystemError):
                pass           # non-numeric data: keep the mapping so the field gets named
        return {k: _node(node.getNode(k)) for k in keys}
    if node.isSeq():
        return [_node(node.at(i)) for i in range(node.size())]
    if node.isInt():
        return int(node.real())
    if node.isReal():
        return float(node.real())
    if node.isString():
        return node.string()
    return None


def _unknown(path, reason: str | None = None) -> ValueError:
    detail = f" ({reason})" if reason else ""
    return ValueError(f"{path}: not a calibration mrstereo can read{detail}; formats tried: "
                      + ", ".join(FORMATS))


# --------------------------------------------------------------------------- detection

def _kind(data: dict) -> str | None:
    """What one file holds, from its fields."""
    if "left" in data or "right" in data:
        return "stereo"
    if ("camera_matrix" in data and "image_width" in data) or _message_fields(data) is not None:
        return "camera_info"
    if isinstance(data.get("cam0"), dict) and "intrinsics" in data["cam0"]:
        return "kalibr"
    if isinstance(data.get("trans_matrix"), list):
        return "trans_matrix"
    if "T_BS" in data and "intrinsics" in data:
        return "euroc"
    if sum(1 for v in data.values() if isinstance(v, dict) and v.get("sensor_type") == "camera") >= 2:
        return "openloris"
    if _opencv_key(data, "K", 1) is not None or _opencv_key(data, "D", 1) is not None:
        return "opencv"
    if _opencv_key(data, "R", 0) is not None and _opencv_key(data, "T", 0) is not None:
        return "opencv_extrinsics"
    return None


def _message_fields(data: dict) -> dict | None:
    """A dumped sensor_msgs/CameraInfo message (ROS 1 ``K D R P``, ROS 2 ``k d r p``) as camera_info fields."""
    for k, d, r, p in (("K", "D", "R", "P"), ("k", "d", "r", "p")):
        if {"width", "height", k, p} <= set(data) and "intrinsics" not in data:
            return {"image_width": data["width"], "image_height": data["height"], "camera_matrix": data[k],
                    "distortion_model": data.get("distortion_model") or "plumb_bob",
                    "distortion_coefficients": data.get(d),
                    "rectification_matrix": data.get(r), "projection_matrix": data[p],
                    "camera_name": str((data.get("header") or {}).get("frame_id", "camera"))
                    if isinstance(data.get("header"), dict) else "camera"}
    return None


def _camera_info(data: dict, where: str) -> CameraInfo:
    return CameraInfo.from_dict(_message_fields(data) or data, where=where)


def _read_one(path: Path, data: dict, image_size):
    kind = _kind(data)
    where = str(path)
    if kind == "stereo":
        return FORMATS[0], StereoCamera.from_dict(data, where=where)
    if kind == "kalibr":
        return FORMATS[2], _kalibr(data, where)
    if kind == "opencv":
        return FORMATS[3], _opencv(data, where, image_size)
    if kind == "openloris":
        sibling = path.with_name("trans_matrix.yaml")
        poses = _load(sibling) if sibling.is_file() else None
        return FORMATS[5], _openloris(data, poses, where, str(sibling))
    if kind == "camera_info":
        raise ValueError(f"{path} holds one camera (camera_matrix, no extrinsics): give both cameras of a "
                         "stereo calibration, --calib left.yaml,right.yaml (ROS camera_info)")
    if kind == "euroc":
        raise ValueError(f"{path} is one camera's EuRoC sensor.yaml: give both cameras, "
                         f"--calib cam0/sensor.yaml,cam1/sensor.yaml")
    if kind == "opencv_extrinsics":
        raise ValueError(f"{path} holds OpenCV stereo extrinsics (R, T) without the cameras: give "
                         f"the intrinsics too, --calib intrinsics.yml,extrinsics.yml")
    if kind == "trans_matrix":
        raise ValueError(f"{path} holds OpenLORIS camera poses only: give sensors.yaml too, "
                         f"--calib sensors.yaml,trans_matrix.yaml")
    raise _unknown(path)


def _read_two(files: list[Path], docs: list[dict], image_size):
    kinds = [_kind(d) for d in docs]
    where = ",".join(str(p) for p in files)
    for path, kind in zip(files, kinds):
        if kind is None:
            raise _unknown(path)
    if kinds == ["camera_info", "camera_info"]:
        left, right = _camera_info(docs[0], str(files[0])), _camera_info(docs[1], str(files[1]))
        if right.P[0, 3] == 0 and left.P[0, 3] == 0:
            raise ValueError(f"{where}: two camera_info files without stereo extrinsics (the right "
                             "projection_matrix P[0,3] is 0); use the files of a stereo calibration "
                             "(ROS camera_calibration writes P[0,3] = -fx * baseline_m for the right camera)")
        try:
            return FORMATS[1], StereoCamera(left=left, right=right)
        except ValueError as exc:
            raise ValueError(f"{files[1]}: {exc}") from None
    if kinds == ["euroc", "euroc"]:
        return FORMATS[4], _euroc(docs, [str(p) for p in files])
    if sorted(kinds) == ["openloris", "trans_matrix"]:
        i = kinds.index("openloris")
        return FORMATS[5], _openloris(docs[i], docs[1 - i], str(files[i]), str(files[1 - i]))
    if sorted(kinds) == ["opencv", "opencv_extrinsics"]:
        merged = {**docs[kinds.index("opencv")], **docs[kinds.index("opencv_extrinsics")]}
        return FORMATS[3], _opencv(merged, where, image_size)
    names = {"stereo": "a stereo YAML", "camera_info": "a ROS camera_info", "kalibr": "a Kalibr camchain",
             "opencv": "an OpenCV stereo calibration", "opencv_extrinsics": "OpenCV extrinsics",
             "euroc": "a EuRoC sensor.yaml", "openloris": "an OpenLORIS sensors.yaml",
             "trans_matrix": "an OpenLORIS trans_matrix.yaml"}
    raise ValueError(f"{where}: {files[0]} is {names[kinds[0]]} and {files[1]} is {names[kinds[1]]}; "
                     "two files must be two ROS camera_info, two EuRoC sensor.yaml, OpenLORIS "
                     "sensors.yaml + trans_matrix.yaml, or OpenCV intrinsics + extrinsics")


def _rectify(raw: _Raw, *, where: str, alpha: float) -> StereoCamera:
    R = numbers(raw.R, where=where, field="R", shape=(3, 3))
    if _rotation_error(R) > ROTATION_TOL:
        raise ValueError(f"{where}: the rotation between the cameras is not a rotation (orthonormal, "
                         f"det +1; its det is {np.linalg.det(R):.4g})")
    T = numbers(raw.T, where=where, field="T", shape=(3,))
    baseline_m = float(np.linalg.norm(T))
    if not BASELINE_RANGE_M[0] <= baseline_m <= BASELINE_RANGE_M[1]:
        raise ValueError(f"{where}: the translation between the cameras is {baseline_m:.4g} m, outside the "
                         f"plausible {BASELINE_RANGE_M[0]:g}..{BASELINE_RANGE_M[1]:g} m (in metres?)")
    check_not_swapped(R, T, where=where)
    try:
        return rectify_fusiello(raw.left, raw.right, R, T, alpha=alpha).stereo
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


# --------------------------------------------------------------------------- readers

def _field(data: dict, key: str, where: str):
    if key not in data:
        raise ValueError(f"{where}: missing field '{key}'")
    return data[key]


def _size(value, *, where: str, field: str) -> tuple[int, int]:
    arr = numbers(value, where=where, field=field, sizes=[2])
    if np.any(arr != np.round(arr)):
        raise ValueError(f"{where}: field '{field}' must be two integers [width, height], got {arr.tolist()}")
    return int(arr[0]), int(arr[1])


def _pose(value, *, where: str, field: str) -> np.ndarray:
    """A 4x4 rigid transform; its rotation block must be a rotation."""
    M = numbers(value, where=where, field=field, shape=(4, 4))
    if _rotation_error(M[:3, :3]) > ROTATION_TOL or np.abs(M[3] - [0, 0, 0, 1]).max() > 1e-9:
        raise ValueError(f"{where}: field '{field}' is not a rigid transform (rotation block orthonormal "
                         "with det +1, last row 0 0 0 1)")
    return M


def _raw_from_pose(left: Camera, right: Camera, T_left_from_right: np.ndarray) -> _Raw:
    """Extrinsics ``x_right = R x_left + T`` from the right camera's pose in the left frame."""
    R = T_left_from_right[:3, :3].T
    return _Raw(left, right, R, -R @ T_left_from_right[:3, 3])


def _kalibr(data: dict, where: str) -> _Raw:
    cams = []
    for name in ("cam0", "cam1"):
        cam = data.get(name)
        here = f"{where}: {name}"
        if not isinstance(cam, dict):
            raise ValueError(f"{where}: missing '{name}' (a Kalibr camchain needs cam0 and cam1)")
        model = str(_field(cam, "camera_model", here))
        if model != "pinhole":
            raise ValueError(f"{here}: camera_model '{model}' is not supported (pinhole only)")
        fu, fv, pu, pv = numbers(_field(cam, "intrinsics", here), where=here, field="intrinsics", sizes=[4])
        width, height = _size(_field(cam, "resolution", here), where=here, field="resolution")
        dist = str(_field(cam, "distortion_model", here))
        D = numbers(cam.get("distortion_coeffs", []), where=here, field="distortion_coeffs")
        if dist in ("radtan", "equidistant"):
            D = numbers(D, where=here, field="distortion_coeffs", sizes=[4])
        elif dist == "none":
            dist, D = "plumb_bob", np.zeros(5)
        else:
            raise ValueError(f"{here}: distortion_model '{dist}' is not supported (radtan, equidistant)")
        K = [[fu, 0, pu], [0, fv, pv], [0, 0, 1]]
        cams.append(camera_from_ros(width, height, K, dist, D, where=here))
    T = _pose(_field(data["cam1"], "T_cn_cnm1", f"{where}: cam1"), where=f"{where}: cam1", field="T_cn_cnm1")
    return _Raw(cams[0], cams[1], T[:3, :3], T[:3, 3])          # x_cam1 = T x_cam0


def euroc_body_from_camera(path) -> np.ndarray:
    """``T_BS`` of one ASL/EuRoC ``sensor.yaml``: the camera's pose in the body frame (4, 4)."""
    path = Path(path)
    data = _load(path)
    if _kind(data) != "euroc":
        raise ValueError(f"{path} is not an ASL/EuRoC sensor.yaml (needs intrinsics and T_BS)")
    return _pose(data["T_BS"], where=str(path), field="T_BS")


def _euroc(docs: list[dict], paths: list[str]) -> _Raw:
    cams, poses = [], []
    for data, where in zip(docs, paths):
        model = str(data.get("camera_model", "pinhole"))
        if model != "pinhole":
            raise ValueError(f"{where}: camera_model '{model}' is not supported (pinhole)")
        fu, fv, cu, cv = numbers(_field(data, "intrinsics", where), where=where, field="intrinsics", sizes=[4])
        width, height = _size(_field(data, "resolution", where), where=where, field="resolution")
        D = numbers(data.get("distortion_coefficients", [0.0] * 4), where=where,
                    field="distortion_coefficients")
        cams.append(camera_from_ros(width, height, [[fu, 0, cu], [0, fv, cv], [0, 0, 1]],
                                    data.get("distortion_model", "radial-tangential"), D, where=where))
        poses.append(_pose(_field(data, "T_BS", where), where=where, field="T_BS"))
    return _raw_from_pose(cams[0], cams[1], np.linalg.inv(poses[0]) @ poses[1])


_OPENCV_NAMES = {
    "K": ("m{i}", "k{i}", "cm{i}", "mtx{i}", "cameramatrix{i}", "cameramatrix{s}", "mtx{s}", "k{s}",
          "m{s}", "intrinsic{i}", "intrinsics{i}", "camera{i}matrix"),
    "D": ("d{i}", "dist{i}", "distcoeffs{i}", "distcoeff{i}", "distortion{i}", "distortioncoefficients{i}",
          "dist{s}", "distcoeffs{s}", "d{s}", "distortion{s}", "camera{i}distortion"),
    "R": ("r", "rotation", "rot"),
    "T": ("t", "translation", "trans"),
    "R_rect": ("r{i}", "rect{i}", "rectification{i}", "r{s}"),
    "P_rect": ("p{i}", "proj{i}", "projection{i}", "p{s}"),
}


def _norm(key: str) -> str:
    return re.sub(r"[^a-z0-9]", "", key.lower())


def _opencv_key(data: dict, what: str, index: int) -> str | None:
    """The key of ``data`` that holds ``what`` (K, D, R, T, R_rect, P_rect) of camera ``index`` (1, 2)."""
    side = {1: ("l", "left"), 2: ("r", "right")}.get(index, ("",))
    wanted = {p.format(i=index, s=s) for p in _OPENCV_NAMES[what] for s in side}
    if what in ("R", "T"):
        wanted = set(_OPENCV_NAMES[what])
    by_norm = {_norm(k): k for k in data if isinstance(k, str)}
    for name in sorted(wanted):
        if name in by_norm:
            return by_norm[name]
    return None


def _opencv_size(data: dict, where: str, image_size) -> tuple[int, int]:
    by_norm = {_norm(k): k for k in data if isinstance(k, str)}
    stored = None
    for name in ("imagesize", "imgsize", "size", "resolution"):
        if name in by_norm:
            stored = _size(data[by_norm[name]], where=where, field=by_norm[name])
            break
    for w, h in (("imagewidth", "imageheight"), ("width", "height")):
        if stored is None and w in by_norm and h in by_norm:
            stored = _size([data[by_norm[w]], data[by_norm[h]]], where=where, field=f"{by_norm[w]}/{by_norm[h]}")
    if image_size is not None:
        size = tuple(int(v) for v in image_size)
        if stored is not None and stored != size:
            raise ValueError(f"{where}: the file says the images are {stored[0]}x{stored[1]}, "
                             f"the image size given is {size[0]}x{size[1]}")
        return size
    if stored is None:
        raise ValueError(f"{where}: OpenCV calibration without the image size: add 'image_width: W' and "
                         "'image_height: H' to it, or convert it once: mrstereo calib convert FILE "
                         "--image-size WxH -o stereo.yaml")
    return stored


def _opencv_model(data: dict, n_coeffs: int, where: str) -> str:
    for key, value in data.items():
        if _norm(str(key)) in ("model", "distortionmodel", "cameramodel") and isinstance(value, str):
            if _norm(value) in ("fisheye", "equidistant", "kannalabrandt"):
                return "equidistant"
            if _norm(value) in ("rationalpolynomial", "rational"):
                return "rational_polynomial"
    if n_coeffs in (4, 5):
        return "plumb_bob"
    if n_coeffs in (8, 12, 14):
        return "rational_polynomial"
    raise ValueError(f"{where}: {n_coeffs} distortion coefficients fit no OpenCV model (4, 5, 8, 12 or 14)")


def _opencv(data: dict, where: str, image_size) -> _Raw | StereoCamera:
    keys = {(w, i): _opencv_key(data, w, i) for w in ("K", "D", "R_rect", "P_rect") for i in (1, 2)}
    for (what, i), key in keys.items():
        if key is None and what in ("K", "D"):
            name = f"camera matrix M{i}/K{i}/cameraMatrix{i}" if what == "K" else f"distortion D{i}/distCoeffs{i}"
            raise ValueError(f"{where}: OpenCV stereo calibration without the {name}; it has "
                             + ", ".join(str(k) for k in data))
    rect = [keys[("R_rect", 1)], keys[("R_rect", 2)], keys[("P_rect", 1)], keys[("P_rect", 2)]]
    k_R, k_T = _opencv_key(data, "R", 0), _opencv_key(data, "T", 0)
    if (k_R is None or k_T is None) and not all(k is not None for k in rect):
        raise ValueError(f"{where}: OpenCV intrinsics without stereo extrinsics (no R and T between the "
                         "cameras); give the file with cv2.stereoCalibrate's R and T too, "
                         "--calib intrinsics.yml,extrinsics.yml")
    width, height = _opencv_size(data, where, image_size)
    cams = []
    for i in (1, 2):
        D = numbers(data[keys[("D", i)]], where=where, field=keys[("D", i)])
        K = numbers(data[keys[("K", i)]], where=where, field=keys[("K", i)], shape=(3, 3))
        model = _opencv_model(data, D.size, where)
        if model == "equidistant":
            D = numbers(D[:4] if np.all(D[4:] == 0) else D, where=where, field=keys[("D", i)], sizes=[4])
        cams.append(camera_from_ros(width, height, K, model, D, where=f"{where}: camera {i}"))
    if all(k is not None for k in rect):
        R1, R2 = (numbers(data[k], where=where, field=k, shape=(3, 3)) for k in rect[:2])
        P1, P2 = (numbers(data[k], where=where, field=k, shape=(3, 4)) for k in rect[2:])
        infos = []
        for cam, R, P, k_r, name in ((cams[0], R1, P1, rect[0], "left"), (cams[1], R2, P2, rect[1], "right")):
            try:
                infos.append(CameraInfo(cam, R=R, P=P, name=name))
            except ValueError as exc:
                raise ValueError(f"{where}: field '{k_r}': {exc}") from None
        try:
            return StereoCamera(left=infos[0], right=infos[1])
        except ValueError as exc:
            raise ValueError(f"{where}: {rect[3]}: {exc}") from None
    R = numbers(data[k_R], where=where, field=k_R, sizes=[3, 9])
    if R.size == 3:                                   # a Rodrigues vector
        R = cv2.Rodrigues(R)[0]
    return _Raw(cams[0], cams[1], R.reshape(3, 3), numbers(data[k_T], where=where, field=k_T, sizes=[3]))


def _openloris_camera(entry: dict, where: str) -> Camera:
    fx, cx, fy, cy = numbers(_field(entry, "intrinsics", where), where=where, field="intrinsics", sizes=[4])
    width, height = _field(entry, "width", where), _field(entry, "height", where)
    model = str(entry.get("distortion_model", "radial-tangential"))
    D = numbers(entry.get("distortion_coefficients", [0.0] * 5), where=where, field="distortion_coefficients")
    if str(entry.get("model", "pinhole")).lower() == "fisheye" or model.lower() in ("kannala-brandt", "equidistant"):
        if D.size > 4 and np.any(D[4:] != 0):
            raise ValueError(f"{where}: field 'distortion_coefficients' of a Kannala-Brandt camera has "
                             f"{D.size} values; only k1..k4 (and zeros after them) are supported")
        model, D = "equidistant", D[:4]
    return camera_from_ros(width, height, [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], model, D, where=where)


def _openloris(sensors: dict, poses: dict | None, where: str, poses_where: str) -> _Raw:
    cams = {k: v for k, v in sensors.items() if isinstance(v, dict) and v.get("sensor_type") == "camera"}
    groups: dict[str, list[str]] = {}
    for name in cams:
        groups.setdefault(re.sub(r"\d+", "#", name), []).append(name)
    pairs = [sorted(g) for g in groups.values() if len(g) == 2]
    if len(pairs) != 1:
        raise ValueError(f"{where}: expected one numbered camera pair (like t265_fisheye1/t265_fisheye2), "
                         f"found cameras {', '.join(cams) or 'none'}")
    left_name, right_name = pairs[0]
    left = _openloris_camera(cams[left_name], f"{where}: {left_name}")
    right = _openloris_camera(cams[right_name], f"{where}: {right_name}")
    if poses is None:
        raise ValueError(f"{where}: the camera poses are in trans_matrix.yaml, not found at {poses_where}; "
                         "give it: --calib sensors.yaml,trans_matrix.yaml")
    return _raw_from_pose(left, right, _transform_between(poses, left_name, right_name, poses_where))


def _transform_between(poses: dict, frame_a: str, frame_b: str, where: str) -> np.ndarray:
    """``T_a_from_b`` from a trans_matrix list of parent/child poses (chained, inverted as needed)."""
    edges: dict[str, list[tuple[str, np.ndarray]]] = {}
    for k, entry in enumerate(poses.get("trans_matrix") or []):
        if not isinstance(entry, dict):
            raise ValueError(f"{where}: trans_matrix entry {k} is not a mapping")
        parent, child = str(_field(entry, "parent_frame", where)), str(_field(entry, "child_frame", where))
        M = _pose(_field(entry, "matrix", where), where=where, field=f"matrix {parent} -> {child}")
        edges.setdefault(parent, []).append((child, M))                       # T_parent_from_child
        edges.setdefault(child, []).append((parent, np.linalg.inv(M)))
    todo, seen = deque([(frame_a, np.eye(4))]), {frame_a}
    while todo:
        frame, T_a_from_frame = todo.popleft()
        if frame == frame_b:
            return T_a_from_frame
        for other, T_frame_from_other in edges.get(frame, []):
            if other not in seen:
                seen.add(other)
                todo.append((other, T_a_from_frame @ T_frame_from_other))
    raise ValueError(f"{where}: no chain of trans_matrix poses between {frame_a} and {frame_b}")

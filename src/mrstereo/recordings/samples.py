"""Sample data: the public stereo scenes the tests, the ``evaluate`` examples and the benchmarks use.

Every file has a name, source and SHA-256 in :mod:`mrstereo.recordings._registry`. With
``MRSTEREO_DATA`` set the files are read from that folder as they are; otherwise :func:`fetch`
downloads the missing ones into pooch's cache and checks them. Command line (``mrstereo data``),
where the files come from and their licences: docs/evaluation.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

from ._registry import FILES, SCENES

__all__ = ["ENV_VAR", "NAMES", "SampleScene", "data_root", "scene", "local_path", "is_available",
           "missing_files", "fetch", "verify"]

ENV_VAR = "MRSTEREO_DATA"
NAMES = tuple(SCENES)

_DESCRIPTIONS = {
    "tsukuba": "Middlebury 2001 Tsukuba, 384x288, GT disparity + masks (cite Scharstein & Szeliski 2002)",
    "venus": "Middlebury 2001 Venus, 434x383, GT disparity + masks (cite Scharstein & Szeliski 2002)",
    "teddy": "Middlebury 2003 Teddy, quarter size 450x375, GT + masks (cite Scharstein & Szeliski 2003)",
    "cones": "Middlebury 2003 Cones, quarter size 450x375, GT + masks (cite Scharstein & Szeliski 2003)",
    "kitti2012-000070": "KITTI 2012 training frame 000070, 1241x376, sparse GT (CC BY-NC-SA 3.0)",
    "kitti2015-000000": "KITTI 2015 training frame 000000, 1242x375, sparse GT (CC BY-NC-SA 3.0)",
    "opencv-stereo-chessboard": "OpenCV samples: 13 stereo pairs of a 9x6 chessboard, 640x480",
    "openloris-sample": "OpenLORIS-Scene: 4 T265 fisheye stereo frames, calibration, odometry (research use)",
    "kitti-raw-sample": "KITTI raw drive 2011_09_26_drive_0005, 5 frames in the raw layout, OXTS (CC BY-NC-SA 3.0)",
    "euroc-asl-sample": "EuRoC MAV V1_01_easy, 5 stereo frames in the ASL folder layout (cite Burri et al. 2016)",
}


@dataclass(frozen=True)
class SampleFile:
    path: str            # under the data root, e.g. "middlebury2001/tsukuba/all.png"
    repository: str      # GitHub owner/name
    commit: str
    source_path: str     # path inside the repository
    sha256: str
    derived: str = ""    # "listed rows": the repository's CSV cut to the rows of the scene's images (sha256 of the cut)

    @property
    def url(self) -> str:
        return f"https://raw.githubusercontent.com/{self.repository}/{self.commit}/{self.source_path}"


@dataclass(frozen=True)
class SampleScene:
    """One named scene of the registry: its folder under the data root and its files."""

    name: str
    folder: str
    description: str
    files: tuple[SampleFile, ...]


_FILES = tuple(SampleFile(*row) for row in FILES)


def scene(name: str) -> SampleScene:
    """The registry entry of ``name`` (one of :data:`NAMES`)."""
    if not isinstance(name, str):
        raise TypeError(f"name must be a str, got {type(name).__name__}")
    if name not in SCENES:
        raise ValueError(f"unknown sample data {name!r}; known: {', '.join(NAMES)}")
    folder = SCENES[name]
    files = tuple(f for f in _FILES if f.path.startswith(folder + "/"))
    return SampleScene(name=name, folder=folder, description=_DESCRIPTIONS.get(name, ""), files=files)


def data_root() -> Path:
    """``$MRSTEREO_DATA`` when set, else pooch's cache folder for mrstereo (nothing is created)."""
    value = os.environ.get(ENV_VAR, "").strip()
    if value:
        return Path(value).expanduser()
    import pooch

    return Path(pooch.os_cache("mrstereo"))


def local_path(name: str) -> Path:
    """Where the scene ``name`` is, or would be after :func:`fetch`, on this machine (no download)."""
    return data_root() / scene(name).folder


def missing_files(name: str) -> list[Path]:
    """Files of ``name`` not present under :func:`data_root` (empty when the scene is complete)."""
    root = data_root()
    return [root / f.path for f in scene(name).files if not (root / f.path).is_file()]


def is_available(name: str) -> bool:
    """True when every file of ``name`` is present locally (sizes and hashes are not checked)."""
    return not missing_files(name)


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def verify(name: str) -> list[str]:
    """Check every local file of ``name`` against its SHA-256; return one line per problem."""
    root = data_root()
    problems = []
    for f in scene(name).files:
        path = root / f.path
        if not path.is_file():
            problems.append(f"missing: {path}")
        elif _sha256(path) != f.sha256:
            problems.append(f"SHA-256 differs from the registry: {path}")
    return problems


def fetch(name: str, *, progress: bool = False) -> Path:
    """Make the scene ``name`` available locally and return its folder.

    With ``MRSTEREO_DATA`` set a missing file raises ``FileNotFoundError``; otherwise missing files
    are downloaded into pooch's cache and checked (a SHA-256 mismatch raises ``ValueError``).
    """
    entry = scene(name)
    if os.environ.get(ENV_VAR, "").strip():
        missing = missing_files(name)
        if missing:
            raise FileNotFoundError(f"{ENV_VAR}={os.environ[ENV_VAR]} has no {missing[0]} (sample data "
                                    f"{name!r}, {len(missing)} file(s) missing); unset {ENV_VAR} to download "
                                    f"into the cache, or copy the scene there")
        return local_path(name)
    import pooch

    root = data_root()
    pooch.get_logger().setLevel("INFO" if progress else "WARNING")
    direct = [f for f in entry.files if not f.derived]
    fetcher = pooch.create(path=root, base_url="", registry={f.path: f"sha256:{f.sha256}" for f in direct},
                           urls={f.path: _url(f) for f in direct}, retry_if_failed=2)
    for f in direct:
        fetcher.fetch(f.path, progressbar=progress)
    for f in entry.files:
        if f.derived and not (root / f.path).is_file():
            _fetch_listed_rows(f, root, entry, progress)
    return root / entry.folder


def _fetch_listed_rows(f: SampleFile, root: Path, entry: SampleScene, progress: bool) -> None:
    """Download a CSV of the repository and keep its comment lines and the rows that name an image of the
    scene (``data/<name>`` beside it), checked against the registry's SHA-256 of the cut file."""
    import tempfile

    import pooch

    listed = {Path(g.path).name for g in entry.files if Path(g.path).parent == Path(f.path).parent / "data"}
    with tempfile.TemporaryDirectory(prefix=".mrstereo-fetch-", dir=root) as tmp:
        whole = Path(pooch.retrieve(_url(f), known_hash=None, path=tmp, progressbar=progress))
        lines = whole.read_bytes().splitlines(keepends=True)
        kept = b"".join(line for line in lines if line.startswith(b"#")
                        or line.split(b",")[-1].strip().decode("utf-8", "replace") in listed)
        if hashlib.sha256(kept).hexdigest() != f.sha256:
            raise ValueError(f"{f.path}: the rows of {_url(f)} do not give the registry's SHA-256 (hash differs)")
        target = root / f.path
        target.parent.mkdir(parents=True, exist_ok=True)
        (Path(tmp) / "cut").write_bytes(kept)
        os.replace(Path(tmp) / "cut", target)


def _url(f: SampleFile) -> str:
    """The download URL of one file (a function so that tests can serve the files locally)."""
    return f.url

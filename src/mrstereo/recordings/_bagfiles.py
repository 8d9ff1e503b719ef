"""The files of a ROS bag, checked before a reader trusts them.

:func:`bag_inputs` names a bag's files (no output is written into them); :func:`check_bag_file`
refuses records longer than the file and chunks decompressing beyond ``MRSTEREO_MAX_MESSAGE_BYTES``;
:func:`bag_errors` turns a reader's failure into one ``ValueError`` naming the bag (docs/errors.md).
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import bz2
import contextlib
import os
import struct
import traceback
from collections.abc import Iterator
from pathlib import Path

from .. import _limits
from ..io import Inputs

__all__ = ["bag_inputs", "check_bag_file", "bag_errors"]

_ROS1_MAGIC = b"#ROSBAG V2.0\n"
_MCAP_MAGIC = b"\x89MCAP0\r\n"


def bag_inputs(path: str | os.PathLike) -> Inputs:
    """What reading the bag at ``path`` reads: a ROS 1 file, or a ROS 2 bag folder as a whole (a storage
    file given inside it stands for its folder)."""
    path = Path(path)
    if path.is_file() and path.suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file():
        path = path.parent
    if path.is_dir():
        return Inputs(files=[p for p in path.iterdir() if p.is_file()], folders=[path], kind="bag")
    return Inputs(files=[path])


def _fail(path: Path, message: str) -> ValueError:
    return ValueError(f"cannot read bag {path}: {message}")


def _drain(decompressor, data: bytes, what: str, path: Path) -> int:
    """Bytes ``data`` decompresses to, in pieces of at most 8 MiB (never more than ``MRSTEREO_MAX_MESSAGE_BYTES``)."""
    total, piece, chunk = 0, 8 << 20, data
    while True:
        out = decompressor.decompress(chunk, max_length=piece)
        chunk = b""
        total += len(out)
        _limits.within("MRSTEREO_MAX_MESSAGE_BYTES", total, f"bag {path}: {what} decompresses to more")
        if getattr(decompressor, "eof", False) or (not out and getattr(decompressor, "needs_input", True)):
            return total


def _decompressor(kind: str):
    if kind == "bz2":
        return bz2.BZ2Decompressor()
    if kind == "lz4":
        import lz4.frame

        return lz4.frame.LZ4FrameDecompressor()
    if kind == "zstd":
        try:
            from compression import zstd
        except ImportError:
            from backports import zstd
        return zstd.ZstdDecompressor()
    return None


def _check_size(path: Path, declared: int, what: str) -> None:
    _limits.within("MRSTEREO_MAX_MESSAGE_BYTES", declared, f"bag {path}: {what} claims")


def _ros1_records(path: Path, fh, size: int) -> None:
    pos = len(_ROS1_MAGIC)
    while pos < size:
        fh.seek(pos)
        head = fh.read(4)
        if len(head) < 4:
            raise _fail(path, f"truncated record header at byte {pos}")
        header_len = struct.unpack("<I", head)[0]
        if header_len > size - pos - 4:
            raise _fail(path, f"the record at byte {pos} claims a {header_len}-byte header, more than the "
                              f"{size - pos - 4} bytes left in the file")
        header = fh.read(header_len)
        fields, k = {}, 0
        while k + 4 <= len(header):
            n = struct.unpack_from("<I", header, k)[0]
            name, _, value = header[k + 4:k + 4 + n].partition(b"=")
            fields[name] = value
            k += 4 + n
        data_pos = pos + 4 + header_len + 4
        raw = fh.read(4)
        if len(raw) < 4:
            raise _fail(path, f"truncated record at byte {pos}")
        data_len = struct.unpack("<I", raw)[0]
        if data_len > size - data_pos:
            raise _fail(path, f"the record at byte {pos} claims {data_len} bytes of data, more than the "
                              f"{size - data_pos} bytes left in the file")
        if fields.get(b"op") == b"\x05":                                      # a chunk
            compression = fields.get(b"compression", b"none").decode("ascii", "replace")
            declared = struct.unpack("<I", fields[b"size"])[0] if len(fields.get(b"size", b"")) == 4 else 0
            _check_size(path, declared, f"the chunk at byte {pos}")
            decompressor = _decompressor(compression)
            if decompressor is not None:
                fh.seek(data_pos)
                _drain(decompressor, fh.read(data_len), f"the chunk at byte {pos}", path)
        pos = data_pos + data_len


def _mcap_string(buf: bytes, k: int) -> tuple[str, int]:
    n = struct.unpack_from("<I", buf, k)[0]
    return buf[k + 4:k + 4 + n].decode("utf-8", "replace"), k + 4 + n


def _mcap_records(path: Path, fh, size: int) -> None:
    pos = len(_MCAP_MAGIC)
    while pos + 9 <= size:
        fh.seek(pos)
        opcode, length = struct.unpack("<BQ", fh.read(9))
        if length > size - pos - 9:
            if opcode == 0x02 or length == 0:
                return
            raise _fail(path, f"the record at byte {pos} claims {length} bytes, more than the "
                              f"{size - pos - 9} bytes left in the file")
        if opcode == 0x02:                                                    # footer
            return
        if opcode == 0x06:                                                    # chunk
            body = fh.read(length)
            declared = struct.unpack_from("<Q", body, 16)[0]
            _check_size(path, declared, f"the chunk at byte {pos}")
            compression, k = _mcap_string(body, 28)
            records_len = struct.unpack_from("<Q", body, k)[0]
            decompressor = _decompressor(compression) if compression else None
            if decompressor is not None:
                _drain(decompressor, body[k + 8:k + 8 + records_len], f"the chunk at byte {pos}", path)
        elif opcode == 0x08:                                                  # chunk index
            body = fh.read(length)
            k = 32
            k += 4 + struct.unpack_from("<I", body, k)[0] + 8                 # message index offsets, length
            _, k = _mcap_string(body, k)
            declared = struct.unpack_from("<Q", body, k + 8)[0]
            _check_size(path, declared, f"the chunk index at byte {pos}")
        pos += 9 + length


def check_bag_file(path: str | os.PathLike) -> None:
    """Walk the records of a ROS 1 bag or an MCAP file (ROS 2 folders: each ``.mcap`` in them) and refuse,
    naming the byte offset, a record longer than the file or a chunk beyond ``MRSTEREO_MAX_MESSAGE_BYTES``;
    a ROS 2 ``metadata.yaml`` beyond ``MRSTEREO_MAX_BAG_METADATA_BYTES``.
    Other files (sqlite3 storage) are left to the reader."""
    path = Path(path)
    if path.is_dir() and (path / "metadata.yaml").is_file():       # parsed by rosbags' pure-Python YAML reader
        _limits.within("MRSTEREO_MAX_BAG_METADATA_BYTES", (path / "metadata.yaml").stat().st_size,
                       f"bag {path}: metadata.yaml has more bytes")
    files = sorted(path.glob("*.mcap")) if path.is_dir() else [path]
    for file in files:
        size = file.stat().st_size
        with open(file, "rb") as fh:
            magic = fh.read(len(_ROS1_MAGIC))
            try:
                if magic.startswith(_ROS1_MAGIC):
                    _ros1_records(file, fh, size)
                elif magic.startswith(_MCAP_MAGIC):
                    _mcap_records(file, fh, size)
            except ValueError:              # the refusals above
                raise
            except OSError as exc:
                if exc.errno is not None:   # the disk, not the data
                    raise
                raise _fail(file, f"a compressed chunk is damaged ({exc})") from None
            except Exception as exc:        # struct.error, a decompressor's error: damaged data
                raise _fail(file, f"damaged records ({type(exc).__name__}: {exc})") from None


def _from_reader(exc: BaseException) -> bool:
    """Whether ``exc`` was raised while the bag reader (rosbags, or a decompressor it called) ran."""
    return any("rosbags" in frame.filename for frame in traceback.extract_tb(exc.__traceback__))


@contextlib.contextmanager
def bag_errors(path: str | os.PathLike) -> Iterator[None]:
    """Whatever the bag reader raises on a damaged file (``struct.error``, its own errors, a decompressor's)
    becomes one ``ValueError`` naming the bag and the first line of the reason."""
    try:
        yield
    except (KeyboardInterrupt, MemoryError):
        raise
    except Exception as exc:
        if not _from_reader(exc) and not type(exc).__module__.startswith("rosbags"):
            raise
        first = next((line for line in str(exc).strip().splitlines() if line.strip()), type(exc).__name__)
        raise ValueError(f"cannot read bag {path}: {first}") from None

"""Image sizes read from file headers, before anything is decoded.

A few hundred bytes of a PNG can claim 100000 x 100000 pixels and a 1 MB file can decode to gigabytes;
the header says so before the decoder allocates anything. :func:`image_size` reads the width and height
of every format OpenCV decodes in its standard builds (PNG, JPEG, PBM/PGM/PPM/PAM/PFM, BMP, TIFF and
BigTIFF, WebP, GIF, Radiance HDR, Sun raster, JPEG 2000, OpenEXR); other data gives None and is left to
OpenCV's own limit (``OPENCV_IO_MAX_IMAGE_PIXELS``). Conventions: docs/conventions.md.
"""
from __future__ import annotations

import re
import struct

__all__ = ["image_size"]

_PNM = re.compile(rb"\A(P[1-6Ff])(?:\s|#[^\n]*\n)+(\d+)(?:\s|#[^\n]*\n)+(\d+)")
_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def _png(data: bytes):
    if len(data) >= 24 and data[12:16] in (b"IHDR", b"CgBI"):
        if data[12:16] == b"CgBI":              # Apple's variant: IHDR follows the extra chunk
            data = data[:8] + data[8 + 12 + struct.unpack(">I", data[8:12])[0]:]
        if len(data) >= 24:
            return struct.unpack(">II", data[16:24])
    return None


def _jpeg(data: bytes):
    k, n = 2, len(data)
    while k + 4 <= n:
        if data[k] != 0xFF:
            return None
        marker = data[k + 1]
        if marker == 0xFF:                       # fill byte
            k += 1
            continue
        if marker in (0x01, *range(0xD0, 0xD9)):  # markers without a length
            k += 2
            continue
        length = struct.unpack(">H", data[k + 2:k + 4])[0]
        if marker in _JPEG_SOF and k + 9 <= n:
            height, width = struct.unpack(">HH", data[k + 5:k + 9])
            return width, height
        if marker == 0xDA or length < 2:         # start of scan before any frame header
            return None
        k += 2 + length
    return None


def _pnm(data: bytes):
    if data[:2] == b"P7":                        # PAM: WIDTH and HEIGHT lines
        head = data[:4096]
        width, height = re.search(rb"\nWIDTH\s+(\d+)", head), re.search(rb"\nHEIGHT\s+(\d+)", head)
        return (int(width.group(1)), int(height.group(1))) if width and height else None
    match = _PNM.match(data[:4096])
    return (int(match.group(2)), int(match.group(3))) if match else None


def _bmp(data: bytes):
    if len(data) < 26:
        return None
    header = struct.unpack("<I", data[14:18])[0]
    if header == 12:
        return struct.unpack("<HH", data[18:22])
    width, height = struct.unpack("<ii", data[18:26])
    return abs(width), abs(height)


def _tiff(data: bytes):
    order = "<" if data[:2] == b"II" else ">"
    version = struct.unpack(order + "H", data[2:4])[0]
    big = version == 43
    try:
        if big:
            offset = struct.unpack(order + "Q", data[8:16])[0]
            count = struct.unpack(order + "Q", data[offset:offset + 8])[0]
            start, size = offset + 8, 20
        else:
            offset = struct.unpack(order + "I", data[4:8])[0]
            count = struct.unpack(order + "H", data[offset:offset + 2])[0]
            start, size = offset + 2, 12
        found = {}
        for i in range(min(count, 4096)):
            entry = data[start + i * size:start + (i + 1) * size]
            tag, kind = struct.unpack(order + "HH", entry[:4])
            if tag in (256, 257):
                value = entry[12:20] if big else entry[8:12]
                if kind == 3:
                    found[tag] = struct.unpack(order + "H", value[:2])[0]
                elif kind == 4:
                    found[tag] = struct.unpack(order + "I", value[:4])[0]
                elif kind == 16 and big:
                    found[tag] = struct.unpack(order + "Q", value)[0]
        return (found[256], found[257]) if 256 in found and 257 in found else None
    except (struct.error, IndexError):
        return None


def _webp(data: bytes):
    chunk = data[12:16]
    if chunk == b"VP8 " and len(data) >= 30:
        width, height = struct.unpack("<HH", data[26:30])
        return width & 0x3FFF, height & 0x3FFF
    if chunk == b"VP8L" and len(data) >= 25:
        bits = struct.unpack("<I", data[21:25])[0]
        return (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
    if chunk == b"VP8X" and len(data) >= 30:
        return int.from_bytes(data[24:27], "little") + 1, int.from_bytes(data[27:30], "little") + 1
    return None


def _hdr(data: bytes):
    match = re.search(rb"\n\n([-+])Y\s+(\d+)\s+([-+])X\s+(\d+)", data[:65536])
    if match is None:
        match = re.search(rb"\n\n([-+])X\s+(\d+)\s+([-+])Y\s+(\d+)", data[:65536])
        return (int(match.group(2)), int(match.group(4))) if match else None
    return int(match.group(4)), int(match.group(2))


def _jp2(data: bytes):
    at = data.find(b"ihdr", 0, 65536)
    if at >= 0 and len(data) >= at + 12:
        height, width = struct.unpack(">II", data[at + 4:at + 12])
        return width, height
    return None


def _j2k(data: bytes):
    if len(data) >= 24 and data[2:4] == b"\xff\x51":     # SIZ: Xsiz, Ysiz, XOsiz, YOsiz
        x, y, x0, y0 = struct.unpack(">IIII", data[8:24])
        return x - x0, y - y0
    return None


def _exr(data: bytes):
    at = data.find(b"dataWindow\x00box2i\x00", 0, 65536)
    if at >= 0:
        start = at + len(b"dataWindow\x00box2i\x00") + 4
        if len(data) >= start + 16:
            x0, y0, x1, y1 = struct.unpack("<iiii", data[start:start + 16])
            return x1 - x0 + 1, y1 - y0 + 1
    return None


def image_size(data: bytes) -> tuple[int, int] | None:
    """``(width, height)`` claimed by the header of an encoded image; None for data of no known format."""
    head = bytes(data[:16])
    try:
        if head.startswith(b"\x89PNG\r\n\x1a\n"):
            return _png(bytes(data[:4096]))
        if head.startswith(b"\xff\xd8"):
            return _jpeg(data)
        if head[:1] == b"P" and head[1:2] in b"1234567Ff":
            return _pnm(bytes(data[:4096]))
        if head.startswith(b"BM"):
            return _bmp(bytes(data[:64]))
        if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
            return _tiff(data)
        if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
            return _webp(bytes(data[:64]))
        if head[:6] in (b"GIF87a", b"GIF89a"):
            return struct.unpack("<HH", head[6:10])
        if head.startswith(b"#?"):
            return _hdr(bytes(data[:65536]))
        if head[:4] == b"\x59\xa6\x6a\x95":
            return struct.unpack(">II", head[4:12])
        if head.startswith(b"\x00\x00\x00\x0cjP  \r\n\x87\n"):
            return _jp2(bytes(data[:65536]))
        if head[:2] == b"\xff\x4f":
            return _j2k(bytes(data[:64]))
        if head[:4] == b"\x76\x2f\x31\x01":
            return _exr(bytes(data[:65536]))
    except (struct.error, ValueError, IndexError, TypeError):
        return None
    return None

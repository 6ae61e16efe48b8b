"""Image I/O: linear float32 arrays in, OpenEXR / PNG out.

- ``read_image``: EXR (OpenEXR 3.x bindings) as stored; PNG / JPEG / TIFF via OpenCV,
  decoded from sRGB to linear, reordered from OpenCV's BGR to RGB. Alpha is dropped.
  Returns (H, W, 1) or (H, W, 3) float32.
- ``read_mask``: instance-id PNGs, values untouched, (H, W) uint16.
- ``write_exr``, ``write_png_preview``, ``write_mask``: atomic (see ``atomic.py``).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import OpenEXR

from .atomic import atomic_path
from .types import SceneError

__all__ = [
    "read_image",
    "check_finite",
    "read_mask",
    "write_exr",
    "write_png_preview",
    "write_mask",
    "srgb_to_linear",
    "linear_to_srgb",
]

EXR_SUFFIXES = {".exr"}


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """The sRGB electro-optical transfer function (IEC 61966-2-1), x in [0, 1]."""
    x = np.asarray(x, np.float64)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """Inverse of ``srgb_to_linear``; input clipped to [0, 1]."""
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


_LUT8 = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)


def _decode(path: Path, what: str) -> np.ndarray:
    """OpenCV's decoding of an image file; an empty or undecodable file is one SceneError (OpenCV
    raises on an empty buffer and returns None on a broken one)."""
    if not path.is_file():
        raise SceneError(path, "(file)", "an existing image file")
    data = np.fromfile(path, np.uint8)
    try:
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    except cv2.error:
        img = None
    if img is None:
        raise SceneError(path, "(file)", what)
    return img


def _read_exr(path: Path) -> np.ndarray:
    if not path.is_file():
        raise SceneError(path, "(file)", "an existing EXR file")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {name: ch.pixels for name, ch in exr.channels().items()}
    except Exception as exc:  # OpenEXR raises plain RuntimeError / ValueError
        raise SceneError(path, "(file)", f"a readable OpenEXR image ({exc})") from None
    names = set(channels)
    if {"R", "G", "B"} <= names:
        order = ["R", "G", "B"]
    elif "Y" in names:
        order = ["Y"]
    elif len(names) == 1:
        order = list(names)
    else:
        raise SceneError(path, "channels", f"R,G,B or Y or a single channel, got {','.join(sorted(names))}")
    planes = [np.asarray(channels[name], dtype=np.float32) for name in order]
    shapes = {p.shape for p in planes}
    if len(shapes) != 1 or len(planes[0].shape) != 2:
        raise SceneError(path, "channels", "full-resolution channels (no subsampling)")
    return np.stack(planes, axis=-1)


def check_finite(image: np.ndarray, path) -> np.ndarray:
    """Refuse an image with a NaN or infinite value, naming the first bad pixel (row-major) and
    its channel: one would make every loss and gradient it touches NaN."""
    bad = ~np.isfinite(image)
    if bad.any():
        y, x, c = (int(i) for i in np.argwhere(bad.reshape(image.shape[0], image.shape[1], -1))[0])
        value = image.reshape(image.shape[0], image.shape[1], -1)[y, x, c]
        raise SceneError(
            path,
            f"pixel (x {x}, y {y}) channel {c}",
            f"finite values, got {value} ({int(bad.sum())} non-finite values)",
        )
    return image


def block_mean(image: np.ndarray, factor: int) -> np.ndarray:
    """The mean of each ``factor`` x ``factor`` block of pixels (H, W, ...); the right and bottom
    remainders are cut, as ``cameras.binned_camera`` cuts its image."""
    h, w = image.shape[0] // factor, image.shape[1] // factor
    return image[: h * factor, : w * factor].reshape(h, factor, w, factor, *image.shape[2:]).mean(axis=(1, 3))


def read_image(path, finite: bool = True) -> np.ndarray:
    """Read an image as linear float32 (H, W, C), C = 1 or 3, RGB order.

    EXR values are returned as stored (assumed linear). 8- and 16-bit PNG / JPEG / TIFF
    values are decoded from sRGB to linear. Alpha channels are dropped. Every input (a capture,
    a map, an environment) must be finite; ``finite=False`` reads outputs that may hold inf (the
    depth AOV of a miss).
    """
    path = Path(path)
    if path.suffix.lower() in EXR_SUFFIXES:
        image = _read_exr(path)
        return check_finite(image, path) if finite else image
    img = _decode(path, "an image OpenCV can decode (PNG, JPEG, TIFF, EXR)")
    if img.ndim == 2:
        img = img[:, :, None]
    if img.shape[2] == 4:
        img = img[:, :, :3]
    elif img.shape[2] == 2:  # grey + alpha
        img = img[:, :, :1]
    if img.shape[2] == 3:
        img = img[:, :, ::-1]  # OpenCV decodes to BGR
    if img.dtype == np.uint8:
        out = _LUT8[img]
    elif img.dtype == np.uint16:
        out = srgb_to_linear(img / 65535.0).astype(np.float32)
    elif img.dtype in (np.float32, np.float64, np.float16):  # float TIFF etc.: linear already
        out = img.astype(np.float32)
    else:
        raise SceneError(path, "pixel type", f"8-bit, 16-bit or float pixels, got {img.dtype}")
    out = np.ascontiguousarray(out, dtype=np.float32)
    return check_finite(out, path) if finite else out


def read_mask(path) -> np.ndarray:
    """Read an instance-id mask (single-channel 8- or 16-bit PNG) as (H, W) uint16, unchanged."""
    path = Path(path)
    img = _decode(path, "a PNG instance mask OpenCV can decode")
    if img.ndim != 2:
        raise SceneError(path, "channels", f"a single-channel mask, got {img.shape[2]} channels")
    if img.dtype not in (np.uint8, np.uint16):
        raise SceneError(path, "pixel type", f"8- or 16-bit unsigned ids, got {img.dtype}")
    return img.astype(np.uint16)


def write_exr(path, array, half: bool = False) -> None:
    """Write (H, W), (H, W, 1) or (H, W, 3) as EXR: channel Y, or R, G, B. Float32 unless half;
    unsigned integer arrays (ids) are written exactly, as 32-bit UINT channels."""
    path = Path(path)
    a = np.asarray(array)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if np.issubdtype(a.dtype, np.integer) and a.min(initial=0) < 0:
        raise ValueError(f"write_exr({path}): ids must be >= 0 (UINT channels)")
    dtype = np.uint32 if np.issubdtype(a.dtype, np.integer) else (np.float16 if half else np.float32)
    if a.ndim == 2:
        channels = {"Y": np.ascontiguousarray(a, dtype=dtype)}
    elif a.ndim == 3 and a.shape[2] == 3:
        channels = {c: np.ascontiguousarray(a[:, :, i], dtype=dtype) for i, c in enumerate("RGB")}
    else:
        raise ValueError(f"write_exr({path}): expected (H, W), (H, W, 1) or (H, W, 3), got {a.shape}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp:
        with OpenEXR.File(header, channels) as exr:
            exr.write(str(tmp))


def _write_png(path: Path, img: np.ndarray) -> None:
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise ValueError(f"could not encode {path} as PNG")
    with atomic_path(path) as tmp:
        buf.tofile(tmp)


def write_png_preview(path, linear_rgb, exposure: float | None = None, percentile: float = 99.0) -> float:
    """Write an sRGB-encoded 8-bit PNG preview of a linear image; return the exposure used.

    ``exposure`` multiplies the linear values before encoding. If None, it maps the
    ``percentile``-th percentile of the luminance (max channel) to 1 (no change if that is 0).
    """
    a = np.asarray(linear_rgb, np.float32)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"write_png_preview({path}): expected (H, W) or (H, W, 1|3), got {a.shape}")
    a = np.nan_to_num(a, nan=0.0, posinf=0.0, neginf=0.0)
    if exposure is None:
        level = float(np.percentile(a.max(axis=2), percentile)) if a.size else 0.0
        exposure = 1.0 / level if level > 0 else 1.0
    srgb = np.round(linear_to_srgb(a * exposure) * 255.0).astype(np.uint8)
    _write_png(Path(path), np.ascontiguousarray(srgb[:, :, ::-1]))  # RGB -> OpenCV's BGR
    return float(exposure)


def write_mask(path, mask) -> None:
    """Write an (H, W) instance-id mask as a 16-bit single-channel PNG."""
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ValueError(f"write_mask({path}): expected (H, W), got {m.shape}")
    if m.size and (m.min() < 0 or m.max() > 65535):
        raise ValueError(f"write_mask({path}): ids must be in [0, 65535]")
    _write_png(Path(path), np.ascontiguousarray(m, dtype=np.uint16))

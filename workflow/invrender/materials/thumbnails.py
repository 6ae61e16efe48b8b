"""Thumbnails of the library: one contact sheet, each preset's kd (its thumbnail transform) with
its name below, so a user can see what retrieval chooses among (the paper's rendered thumbnails
of its procedural materials, section 4.4)."""

from __future__ import annotations

import numpy as np
import torch
from PIL import Image, ImageDraw

from ..scene.images import write_png_preview
from .base import single_thread
from .library import PRESETS

__all__ = ["contact_sheet", "write_contact_sheet"]

_LABEL_HEIGHT = 14
_MARGIN = 4
_BACKGROUND = 0.02  # linear: near black, so that light swatches stand out


def _label(text: str, width: int) -> np.ndarray:
    """The name as a (_LABEL_HEIGHT, width) coverage mask in [0, 1] (PIL's built-in font)."""
    canvas = Image.new("L", (width, _LABEL_HEIGHT), 0)
    ImageDraw.Draw(canvas).text((2, 1), text, fill=255)
    return np.asarray(canvas, np.float32) / 255.0


def contact_sheet(presets=PRESETS, size: int = 128, columns: int = 5) -> np.ndarray:
    """A linear RGB sheet (H, W, 3): a grid of size x size swatches, labelled."""
    rows = -(-len(presets) // columns)
    cell_h, cell_w = size + _LABEL_HEIGHT + _MARGIN, size + _MARGIN
    sheet = np.full((rows * cell_h + _MARGIN, columns * cell_w + _MARGIN, 3), _BACKGROUND, np.float32)
    with single_thread(), torch.no_grad():
        for i, p in enumerate(presets):
            y, x = _MARGIN + (i // columns) * cell_h, _MARGIN + (i % columns) * cell_w
            sheet[y : y + size, x : x + size] = p.type.image(size, p.params(), p.thumbnail).numpy()
            label = _label(p.name, size)[..., None]
            band = sheet[y + size : y + size + _LABEL_HEIGHT, x : x + size]
            band[:] = band * (1 - label) + label  # white text
    return sheet


def write_contact_sheet(path, presets=PRESETS, size: int = 128, columns: int = 5) -> tuple[int, int]:
    """Write the sheet as an sRGB PNG (atomically); returns its (height, width)."""
    sheet = contact_sheet(presets, size, columns)
    write_png_preview(path, sheet, exposure=1.0)
    return sheet.shape[:2]

"""The evaluation's figures, drawn with OpenCV (matplotlib is not a dependency of the project).

- ``maps_<name>.png``: recovered | truth at the same surface points | |error|, in the recovered
  atlas (kg: the six cube faces side by side, both on the finer cube);
- ``novel_<view>.png`` and ``insertion_<view>.png``: render | reference | |error| on the tone
  mapping the metrics use;
- ``accuracy_vs_time.png``: the snapshot table, map errors (log scale) and novel-view PSNR
  against minutes of training.

Error panels are |difference| averaged over channels on the inferno colour map, scaled so that
the colour bar's top is the largest error; the scale is written under the panel.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..scene.atomic import atomic_path
from ..scene.images import linear_to_srgb
from .metrics import reference_exposure, tone_map

__all__ = ["triptych", "map_figure", "kg_figure", "render_figure", "accuracy_plot"]

MIN_PANEL = 256  # small atlases and renders are enlarged (nearest) to at least this height
LABEL_H = 22
WHITE, BLACK, GREY = (255, 255, 255), (0, 0, 0), (160, 160, 160)
FONT = cv2.FONT_HERSHEY_SIMPLEX


def _write(path, image_bgr: np.ndarray) -> None:
    ok, buf = cv2.imencode(".png", image_bgr)
    if not ok:
        raise ValueError(f"could not encode {path} as PNG")
    with atomic_path(Path(path)) as tmp:
        buf.tofile(tmp)


def _rgb8(display) -> np.ndarray:
    """[0, 1] display values (H, W) or (H, W, 3) -> 8-bit BGR."""
    a = np.clip(np.nan_to_num(np.asarray(display, np.float64)), 0, 1)
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    return np.ascontiguousarray(np.round(a * 255).astype(np.uint8)[..., ::-1])


def _error_panel(a, b, mask=None) -> tuple[np.ndarray, float]:
    error = np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))
    error = error.mean(axis=-1) if error.ndim == 3 else error
    if mask is not None:
        error = np.where(mask, error, 0.0)
    top = float(error.max()) if error.size else 0.0
    scaled = np.round(255 * error / top).astype(np.uint8) if top > 0 else np.zeros(error.shape, np.uint8)
    panel = cv2.applyColorMap(scaled, cv2.COLORMAP_INFERNO)
    if mask is not None:
        panel[~mask] = GREY
    return panel, top


def _labelled(panel: np.ndarray, title: str, note: str = "") -> np.ndarray:
    scale = max(1, int(np.ceil(MIN_PANEL / panel.shape[0])))
    panel = cv2.resize(panel, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    head = np.full((LABEL_H, panel.shape[1], 3), 255, np.uint8)
    cv2.putText(head, title, (4, LABEL_H - 7), FONT, 0.5, BLACK, 1, cv2.LINE_AA)
    foot = np.full((LABEL_H, panel.shape[1], 3), 255, np.uint8)
    cv2.putText(foot, note, (4, LABEL_H - 7), FONT, 0.45, BLACK, 1, cv2.LINE_AA)
    return np.vstack([head, panel, foot])


def triptych(path, left, right, titles: tuple[str, str], mask=None, error_of=None, note: str = "") -> None:
    """[left | right | |error|]: left and right are [0, 1] display images; the error is of
    ``error_of`` (a pair of arrays) if given, else of the displayed images."""
    error, top = _error_panel(*(error_of or (left, right)), mask)
    panels = [_labelled(_rgb8(left), titles[0], note), _labelled(_rgb8(right), titles[1])]
    panels.append(_labelled(error, "|error|", f"colour bar top {top:.3g}"))
    _write(path, np.hstack(panels))


def _map_display(name: str, values: np.ndarray, scale: float) -> np.ndarray:
    """Albedos as sRGB; ka as sqrt (Beckmann alpha, closer to what the eye sees); emission
    divided by ``scale``; kw as it is."""
    if name in ("kd", "ks"):
        return linear_to_srgb(values)
    if name == "ka":
        return np.sqrt(np.clip(values, 0, 1))
    if name == "ke":
        return linear_to_srgb(values / scale)
    return values


def map_figure(path, name: str, recovered, truth, mask) -> None:
    """One atlas map: recovered | truth at the same surface points | |error| over covered texels."""
    scale = 1.0
    if name == "ke":
        level = float(np.asarray(truth)[mask].max()) if mask.any() else 0.0
        scale = level if level > 0 else 1.0
    left = np.where(_expand(mask, recovered), _map_display(name, recovered, scale), 0.0)
    right = np.where(_expand(mask, truth), _map_display(name, truth, scale), 0.0)
    note = f"{name}" + (f" / {scale:.3g}" if name == "ke" else "")
    triptych(path, left, right, ("recovered", "truth"), mask=mask, error_of=(recovered, truth), note=note)


def _expand(mask, values) -> np.ndarray:
    return mask[..., None] if np.ndim(values) == 3 else mask


def _faces_row(kg: np.ndarray) -> np.ndarray:
    return np.hstack(list(kg))  # faces +X, -X, +Y, -Y, +Z, -Z left to right


def kg_figure(path, recovered, truth) -> None:
    """kg on a common cube (both (6, N, N, 3)), faces side by side, on the truth's exposure."""
    exposure = reference_exposure(truth.reshape(-1, 1, 3))
    a, b = _faces_row(recovered), _faces_row(truth)
    triptych(path, tone_map(a, exposure), tone_map(b, exposure), ("recovered kg", "truth kg"), error_of=(a, b))


def render_figure(path, test_linear, reference_linear, titles: tuple[str, str], exposure: float) -> None:
    """A render against its reference on the metrics' tone mapping."""
    left, right = tone_map(test_linear, exposure), tone_map(reference_linear, exposure)
    triptych(path, left, right, titles, note=f"exposure {exposure:.3g}, sRGB")


# ------------------------------------------------------------------------------------- plots

PLOT_W, PLOT_H, MARGIN = 560, 380, 60
COLOURS = [(200, 90, 30), (40, 40, 200), (40, 150, 40), (150, 40, 150)]  # BGR


def _ticks(lo: float, hi: float, log: bool) -> list[float]:
    if log:
        return [10.0**e for e in range(int(np.floor(lo)), int(np.ceil(hi)) + 1)]
    step = 10 ** np.floor(np.log10(max(hi - lo, 1e-12)))
    if (hi - lo) / step < 3:
        step /= 2
    return list(np.arange(np.ceil(lo / step) * step, hi + 1e-9, step))


def _tick_label(t: float, lo: float, hi: float, log: bool) -> str:
    """A tick's text with as many decimals as the ticks' spacing needs (22.35 and 22.40 apart)."""
    if log:
        return f"{t:.3g}"
    ticks = _ticks(lo, hi, False)
    step = ticks[1] - ticks[0] if len(ticks) > 1 else max(abs(t), 1.0)
    return f"{t:.{max(0, int(-np.floor(np.log10(step) + 1e-9)))}f}"


def _panel(title: str, x, series: dict, ylabel: str, log: bool, targets: dict) -> np.ndarray:
    """One plot: each series (label -> y values over x), dashed horizontal target lines."""
    img = np.full((PLOT_H, PLOT_W, 3), 255, np.uint8)
    x = np.asarray(x, np.float64)
    ys = [np.asarray(v, np.float64) for v in series.values()] + [np.array(list(targets.values()), np.float64)]
    ally = np.concatenate([y[np.isfinite(y) & ((y > 0) if log else True)] for y in ys])
    tf = (lambda v: np.log10(v)) if log else (lambda v: v)
    ylo, yhi = (tf(ally.min()), tf(ally.max())) if ally.size else (0.0, 1.0)
    if yhi - ylo < 1e-9:
        ylo, yhi = ylo - (1 if log else 0.5), yhi + (1 if log else 0.5)
    pad = 0.05 * (yhi - ylo)
    ylo, yhi = ylo - pad, yhi + pad
    xlo, xhi = (float(x.min()), float(x.max())) if x.size else (0.0, 1.0)
    if xhi - xlo < 1e-9:
        xlo, xhi = xlo - 0.5, xhi + 0.5
    left, right, top, bottom = MARGIN, PLOT_W - 20, 30, PLOT_H - 45
    px = lambda v: int(round(left + (v - xlo) / (xhi - xlo) * (right - left)))
    py = lambda v: int(round(bottom - (tf(v) - ylo) / (yhi - ylo) * (bottom - top)))
    cv2.rectangle(img, (left, top), (right, bottom), BLACK, 1)
    for t in _ticks(ylo, yhi, log):
        if ylo <= tf(t) <= yhi:
            cv2.line(img, (left - 4, py(t)), (left, py(t)), BLACK, 1)
            cv2.putText(img, _tick_label(t, ylo, yhi, log), (4, py(t) + 4), FONT, 0.35, BLACK, 1, cv2.LINE_AA)
    for t in _ticks(xlo, xhi, False):
        cv2.line(img, (px(t), bottom), (px(t), bottom + 4), BLACK, 1)
        cv2.putText(img, _tick_label(t, xlo, xhi, False), (px(t) - 10, bottom + 16), FONT, 0.35, BLACK, 1, cv2.LINE_AA)
    cv2.putText(img, title, (left, 20), FONT, 0.5, BLACK, 1, cv2.LINE_AA)
    cv2.putText(img, "training time (minutes)", (left + 150, PLOT_H - 10), FONT, 0.4, BLACK, 1, cv2.LINE_AA)
    cv2.putText(img, ylabel, (left + 5, top + 14), FONT, 0.35, GREY, 1, cv2.LINE_AA)
    for k, (label, y) in enumerate(series.items()):
        y = np.asarray(y, np.float64)
        colour = COLOURS[k % len(COLOURS)]
        keep = np.isfinite(y) & ((y > 0) if log else True)
        points = np.array([(px(a), py(b)) for a, b in zip(x[keep], y[keep])], np.int32)
        if len(points) > 1:
            cv2.polylines(img, [points], False, colour, 2, cv2.LINE_AA)
        for p in points:
            cv2.circle(img, tuple(int(c) for c in p), 3, colour, -1, cv2.LINE_AA)
        cv2.putText(img, label, (left + 10, bottom - 10 - 16 * k), FONT, 0.4, colour, 1, cv2.LINE_AA)
        if label in targets and (not log or targets[label] > 0):
            yt = py(targets[label])
            for xs in range(left, right, 12):
                cv2.line(img, (xs, yt), (min(xs + 6, right), yt), colour, 1)
    return img


def accuracy_plot(path, table: list[dict], targets: dict) -> None:
    """Map errors (log) and, where measured, novel-view PSNR against minutes of training."""
    minutes = [row["wall_time_s"] / 60.0 for row in table]
    errors = {k: [row[k] for row in table] for k in ("light_maps_mse", "material_mse")}
    panels = [_panel("map errors (dashed: the paper's)", minutes, errors, "MSE", True, targets)]
    psnr = [row.get("novel_view_psnr_db") for row in table]
    if any(v is not None for v in psnr):
        values = {"novel_view_psnr_db": [np.nan if v is None else v for v in psnr]}
        panels.append(_panel("novel-view PSNR (low spp)", minutes, values, "dB", False, {}))
    _write(path, np.hstack(panels))

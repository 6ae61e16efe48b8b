"""Error against time on log-log axes, one figure per family: every configuration's curve, the
Pareto front, the configured default (a star), the knee (a ring) and the named floors."""

from __future__ import annotations

from pathlib import Path

from ..scene.atomic import atomic_path
from .front import pareto

# family -> (file, [(error key, axis label)], time label)
PANELS = {
    "forward": (
        "accuracy_forward.png",
        [("rmse", "RMSE vs reference"), ("rel_mse", "relative MSE")],
        "wall seconds per image",
    ),
    "gradients": (
        "accuracy_gradients.png",
        [("grad_rel_error", "gradient relative error (median over maps)")],
        "wall seconds per backward pass",
    ),
    "recovery": (
        "accuracy_recovery.png",
        [
            ("recovery_error", None),
            ("light_maps_mse", "light maps MSE"),
            ("novel_view_mse", "novel-view MSE (10^(-PSNR/10))"),
            ("env_mse", "sky MSE (kg, SfD's)"),  # a duplicates run's
            ("relighting_mse", "relighting MSE (10^(-PSNR/10))"),
        ],
        "training wall seconds",
    ),
}


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_family(out_dir, family_name: str, rows: list[dict], knee: dict | None, floors: list[dict]) -> Path:
    """Draw one family's figure into ``out_dir``; returns its path."""
    plt = pyplot()
    name, panels, xlabel = PANELS[family_name]
    panels = [(key, label) for key, label in panels if any(r.get(key) is not None for r in rows)]
    fig, axes = plt.subplots(1, len(panels), figsize=(6.4 * len(panels), 4.8), squeeze=False)
    for ax, (key, label) in zip(axes[0], panels):
        _panel(ax, rows, key, label or rows[0].get("error_name", key), xlabel, knee, floors)
    title = {"forward": "forward rendering", "gradients": "gradients", "recovery": "recovery"}[family_name]
    fig.suptitle(f"accuracy against time: {title}")
    fig.tight_layout()
    path = Path(out_dir) / name
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return path


def _panel(ax, rows, key, label, xlabel, knee, floors):
    import matplotlib

    points = [r for r in rows if r.get(key) is not None and r[key] > 0]
    colours = matplotlib.colormaps["tab20"].colors  # more curves than the default cycle's ten
    for k, curve_label in enumerate(dict.fromkeys(r["label"] for r in points)):
        curve = sorted((r for r in points if r["label"] == curve_label), key=lambda r: r["time_s"])
        colour = colours[(2 * k) % 20 + (k // 10) % 2]  # the dark shades first, then the light ones
        times, errors = [r["time_s"] for r in curve], [r[key] for r in curve]
        ax.loglog(times, errors, "o-", ms=3, lw=1, alpha=0.8, color=colour, label=curve_label)
    front = pareto(points, key)
    ax.step([r["time_s"] for r in front], [r[key] for r in front], "k--", where="post", lw=1.2, label="Pareto front")
    for r in (r for r in points if r.get("default")):
        ax.loglog(r["time_s"], r[key], "*", ms=16, mec="k", mfc="gold", zorder=5, label="configured default")
    if knee and knee["error_key"] == key:
        r = knee["row"]
        ax.loglog(
            r["time_s"],
            r[key],
            "o",
            ms=14,
            mfc="none",
            mec="red",
            mew=2,
            zorder=6,
            label=f"knee (within {knee['factor']:g}x of the best)",
        )
    for floor in floors:
        if floor["error_key"] == key and floor["floor"] > 0:
            ax.axhline(floor["floor"], color="grey", ls=":", lw=0.8)
            ax.annotate(floor["label"], (ax.get_xlim()[0], floor["floor"]), fontsize=6, color="dimgrey", va="bottom")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(label)
    ax.grid(True, which="both", alpha=0.2)
    ax.legend(fontsize=6, loc="best")

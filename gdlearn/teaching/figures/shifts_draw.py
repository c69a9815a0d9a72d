"""Drawings of the chapter "Shift mappings": the cross-section scene of :mod:`gdlearn.teaching.figures.shifts`
with a base path and the offset path gdlearn's shifts made from it, and failure-rate maps."""
from __future__ import annotations

import numpy as np

from gdlearn.teaching.figures.shifts import LIGHT, Section

BASE_STYLE = dict(color="black", lw=1.4, marker="o", ms=3.5, zorder=3)
OFFSET_STYLE = dict(color="tab:orange", lw=1.4, ls="--", marker="o", ms=3.5, zorder=4)


def draw_section(ax, sc: Section, xlim=None, ylim=None):
    """Floor, back wall, sphere, light and camera of the section (x horizontal, z up)."""
    import matplotlib.patches as mpatches

    ax.plot([sc.floor_x0, sc.wall_x], [0, 0], color="0.45", lw=2)
    ax.plot([sc.wall_x, sc.wall_x, sc.floor_x0], [0, sc.top, sc.top], color="0.45", lw=2)
    ax.plot(sc.light[:2], [sc.light[2]] * 2, color="gold", lw=5, solid_capstyle="butt")
    face = "#cfe8ff" if sc.sphere == "glass" else "#d9d9d9"
    ax.add_patch(mpatches.Circle((sc.center[0], sc.center[2]), sc.radius, facecolor=face, edgecolor="0.3", lw=1))
    ax.plot(sc.camera[0], sc.camera[2], marker="s", color="tab:blue", ms=7)
    ax.set_aspect("equal")
    ax.set_xlim(*(xlim or (sc.floor_x0 - 0.1, sc.wall_x + 0.1)))
    ax.set_ylim(*(ylim or (-0.15, sc.top + 0.1)))
    ax.set_xticks([])
    ax.set_yticks([])


def draw_path(ax, verts, label=None, **style):
    """A vertex list as a polyline in the x-z plane."""
    p = np.array([v.pos for v in verts])
    ax.plot(p[:, 0], p[:, 2], label=label, **style)


def draw_shift(ax, sc: Section, base, result, title: str, **limits):
    """One panel: the section, the base path (solid) and the offset path (dashed); a failed shift is
    marked with a red cross at the last offset vertex and its reason in the legend."""
    draw_section(ax, sc, **limits)
    draw_path(ax, base, label="base", **BASE_STYLE)
    if len(result.offset) > 1:
        draw_path(ax, result.offset, label="offset", **OFFSET_STYLE)
    if not result.ok:
        last = result.offset[-1].pos
        ax.plot(last[0], last[2], marker="x", color="red", ms=10, mew=2.5, zorder=5,
                label=f"failed: {result.reason}")
    elif base[-1].surface == LIGHT and result.offset[-1].surface != LIGHT:
        last = result.offset[-1].pos
        ax.plot(last[0], last[2], marker="o", mfc="none", color="red", ms=11, mew=1.5, zorder=5,
                label="offset misses the light: contributes 0")
    actions = " > ".join(result.actions) or "-"
    ax.set_title(f"{title}\n{actions}", fontsize=8.5)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(0.16, 0.99), frameon=False)   # right of the camera


def draw_rates(ax, rates, films, deltas, title: str, fig=None):
    """A failure-rate map: film coordinate across, shift distance (pixels) down, colour = rate."""
    im = ax.imshow(rates, aspect="auto", cmap="magma", vmin=0.0, vmax=1.0, interpolation="nearest",
                   extent=(films[0], films[-1], len(deltas) - 0.5, -0.5))
    ax.set_yticks(range(len(deltas)))
    ax.set_yticklabels([f"{d:g}" for d in deltas], fontsize=7)
    ax.set_title(title, fontsize=9)
    ax.tick_params(labelsize=7)
    if fig is not None:
        fig.colorbar(im, ax=ax, shrink=0.85)
    return im



__all__ = ["draw_section", "draw_path", "draw_shift", "draw_rates", "BASE_STYLE", "OFFSET_STYLE"]

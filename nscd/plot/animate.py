"""A quick look at a run without ParaView: a GIF or MP4 of the blocks moving (matplotlib).

2D results are drawn as they are (x right, y up); 3D results as the outlines of the
blocks projected on a vertical plane (``view="xz"``: seen from -y, the default; ``"yz"``:
seen from +x). Each frame carries the time and, when the scene has a driven base, a
strip below with the base acceleration and a cursor at the frame's time; with ``contacts=True`` and stored impulses
(``simulate(..., store_impulses=True)``) the normal contact impulses are drawn as arrows.

GIFs are written with Pillow (no external program); MP4 needs ``ffmpeg`` on the PATH.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["animate", "frame_steps", "movie_writer"]

#: Length of the arrow of a large (95th percentile) normal contact impulse, as a fraction of the view's size.
_ARROW_FRACTION = 0.15

#: The projection plane of a 3D view: (horizontal axis, vertical axis) of world coordinates.
_VIEWS = {"xz": (0, 2), "yz": (1, 2)}


def frame_steps(time: np.ndarray, fps: float, speed: float) -> np.ndarray:
    """Indices of the stored times shown in the frames, ``speed`` simulated s per wall s.

    The frame times are 0, speed / fps, 2 speed / fps, ... up to the last stored time,
    each mapped to the latest stored time not after it; the last stored time always ends
    the film.
    """
    step_of_frame = speed / fps
    frames = np.arange(0.0, time[-1] + 1e-12 * max(1.0, time[-1]), step_of_frame)
    steps = np.searchsorted(time, frames + 1e-9 * step_of_frame, side="right") - 1
    steps = np.unique(np.clip(steps, 0, len(time) - 1))
    return steps if steps[-1] == len(time) - 1 else np.append(steps, len(time) - 1)


def movie_writer(path: Path, fps: float) -> Any:
    """The matplotlib movie writer for the suffix of ``path``; checked before any frame is drawn."""
    from matplotlib import animation

    suffix = path.suffix.lower()
    if suffix == ".gif":
        return animation.PillowWriter(fps=fps)
    if suffix == ".mp4":
        if not animation.writers.is_available("ffmpeg"):
            raise ValueError(f"{path}: writing .mp4 needs ffmpeg on the PATH (not found); "
                             "write a .gif instead (Pillow, no external program).")
        return animation.FFMpegWriter(fps=fps)
    raise ValueError(f"path == {str(path)!r}, must end with .gif or .mp4.")


def _outlines(result, step: int, plane: tuple[int, int] | None) -> list[np.ndarray]:
    """Closed outline (k, 2) of every body at ``step``: 2D polygons, or 3D projected hulls, m."""
    from scipy.spatial import ConvexHull

    from nscd.rotation import quaternion_to_matrix, rotation_2d

    q = result.q[step]
    out = []
    for body, vertices in enumerate(result.shapes):
        if result.dim == 2:
            out.append(vertices @ rotation_2d(q[body, 2]).T + q[body, :2])
            continue
        placed = vertices @ quaternion_to_matrix(q[body, 3:]).T + q[body, :3]
        projected = placed[:, list(plane)]
        out.append(projected[ConvexHull(projected).vertices])
    return out


def _base_acceleration(result) -> tuple[np.ndarray, np.ndarray] | None:
    """(times, acceleration m/s^2) of the first driven body along its main direction of motion,
    the mean over each stored interval (difference of stored velocities); None without one."""
    driven = [i for i, kind in enumerate(result.body_kinds) if kind == "driven"]
    if not driven or len(result.time) < 2:
        return None
    velocity = result.v[:, driven[0], :result.dim]
    axis = int(np.argmax(np.ptp(velocity, axis=0)))
    acceleration = np.diff(velocity[:, axis]) / np.diff(result.time)
    return 0.5 * (result.time[1:] + result.time[:-1]), acceleration


def animate(result, path: str | Path, *, fps: float = 25.0, speed: float = 1.0, contacts: bool = True,
            view: str = "xz", dpi: int = 100) -> Path:
    """Write a film of ``result`` to ``path`` (``.gif`` or ``.mp4``).

    Parameters
    ----------
    result : nscd.Result
    path : str or Path
        ``*.gif`` (Pillow) or ``*.mp4`` (needs ffmpeg). The parent folder must exist;
        the file is replaced atomically.
    fps : float
        Frames per second of the film, > 0.
    speed : float
        Simulated seconds per second of film, > 0 (0.25: four times slower than real time).
    contacts : bool
        Draw the normal contact impulses as arrows, when the result stored them.
    view : {"xz", "yz"}
        3D only: the vertical plane the blocks are projected on.
    dpi : int
        Resolution of the 6.4 x 4.8 inch frames.

    Returns
    -------
    Path
        ``path``; the film has ``len(frame_steps(result.time, fps, speed))`` frames.
    """
    import matplotlib
    from matplotlib.animation import FuncAnimation
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Polygon

    path = Path(path)
    for name, value in (("fps", fps), ("speed", speed)):
        if not np.isfinite(value) or value <= 0.0:
            raise ValueError(f"{name} == {value!r}, must be > 0.")
    if view not in _VIEWS:
        raise ValueError(f"view == {view!r}, must be one of {sorted(_VIEWS)}.")
    if not path.parent.is_dir():
        raise ValueError(f"path == {str(path)!r}: folder {str(path.parent)!r} does not exist.")
    writer = movie_writer(path, fps)
    plane = None if result.dim == 2 else _VIEWS[view]
    steps = frame_steps(result.time, fps, speed)

    # the view: every outline of every frame, with a margin
    everything = np.vstack([np.vstack(_outlines(result, s, plane)) for s in steps])
    low, high = everything.min(axis=0), everything.max(axis=0)
    margin = 0.05 * float(np.max(high - low))
    base = _base_acceleration(result)
    fig = Figure(figsize=(6.4, 4.8), dpi=dpi, layout="constrained")   # no pyplot: no window, no global state
    FigureCanvasAgg(fig)
    if base is None:
        ax, strip = fig.subplots(), None
    else:
        ax, strip = fig.subplots(2, 1, height_ratios=[4, 1])
    ax.set_aspect("equal")
    ax.set_xlim(low[0] - margin, high[0] + margin)
    ax.set_ylim(low[1] - margin, high[1] + margin)
    labels = ("x (m)", "y (m)") if result.dim == 2 else ("xyz"[plane[0]] + " (m)", "z (m)")
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    if result.dim == 3:
        ax.set_title(f"projected on the {view} plane", fontsize=9)

    colours = matplotlib.colormaps["tab10"]
    patches = []
    for body, outline in enumerate(_outlines(result, steps[0], plane)):
        dynamic = result.body_kinds[body] == "dynamic" if result.body_kinds else True
        patch = Polygon(outline, closed=True, edgecolor="k", linewidth=0.8,
                        facecolor=colours(body % 10) if dynamic else "0.75", alpha=0.9 if dynamic else 1.0)
        ax.add_patch(patch)
        patches.append(patch)
    stamp = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", family="monospace")

    arrows: list = []   # the quiver of the current frame (matplotlib cannot change its arrow count)
    stored = result.contacts if contacts and result.contacts is not None else None
    if stored is not None:
        # scaled on the 95th percentile: an impact's impulse (orders larger) would shrink the others
        impulses = np.concatenate([np.abs(np.asarray(c["impulse"], float)[:, 0]) for c in stored] + [np.zeros(1)])
        typical = float(np.percentile(impulses[impulses > 0.0], 95)) if np.any(impulses > 0.0) else 0.0
        arrow_scale = _ARROW_FRACTION * float(np.max(high - low)) / typical if typical > 0.0 else 0.0
        ax.plot([], [], color="tab:red", label="normal contact impulse")
        ax.legend(loc="upper right", fontsize=8, frameon=False)

    cursor = None
    if strip is not None:
        strip.plot(base[0], base[1], color="0.3", lw=0.7)
        strip.set_xlim(result.time[0], result.time[-1])
        strip.set_xlabel("t (s)")
        strip.set_ylabel("base acc.\n" + r"(m/s$^2$)", fontsize=8)
        strip.tick_params(labelsize=8)
        cursor = strip.axvline(result.time[0], color="tab:red", lw=0.8)

    def draw(frame: int):
        step = steps[frame]
        for patch, outline in zip(patches, _outlines(result, step, plane)):
            patch.set_xy(outline)
        stamp.set_text(f"t = {result.time[step]:.3f} s")
        if cursor is not None:
            cursor.set_xdata([result.time[step], result.time[step]])
        while arrows:
            arrows.pop().remove()
        # contacts[k] belongs to the step ending at time[k + 1]; t = 0 has none
        record = stored[step - 1] if stored is not None and step > 0 else None
        if record is not None and len(record["point"]):
            shown = [0, 1] if result.dim == 2 else list(plane)
            point = np.asarray(record["point"], float)[:, shown]
            frame = np.asarray(record["frame"], float)
            vector = arrow_scale * (np.asarray(record["impulse"], float)[:, :1] * frame[:, 0])[:, shown]
            arrows.append(ax.quiver(point[:, 0], point[:, 1], vector[:, 0], vector[:, 1], angles="xy",
                                    scale_units="xy", scale=1.0, color="tab:red", width=0.004))
        return [*patches, stamp]

    film = FuncAnimation(fig, draw, frames=len(steps), blit=False)
    partial = path.with_name(f".{path.stem}.partial{path.suffix}")
    try:
        film.save(partial, writer=writer, dpi=dpi)
        partial.replace(path)
    finally:
        partial.unlink(missing_ok=True)
    return path

"""``cnc-interp plot``: a picture of a plan (matplotlib, imported only here, Agg backend).

Left: the tool path in the plane of the two axes that move most, coloured by the planned
feed (paper 001, figure 4). Right, against time: the feed, then every axis's velocity,
acceleration and jerk divided by the machine's limit, with the ±1 bounds (paper 001,
figures 6 and 8) when a machine is given.

Long plans are drawn decimated: the path keeps every n-th sample, the ratio curves keep
each bin's minimum and maximum (so no peak disappears from the picture).
"""

from __future__ import annotations

import os

import numpy as np

from ..constants import LINEAR_AXES


#: most tool-path points a plot draws (longer plans are decimated for the picture only)
PLOT_MAX_PATH_POINTS = 100_000

#: time bins of the min/max envelope a plot draws for long plans
PLOT_ENVELOPE_BINS = 2000

#: the feed panel turns logarithmic when the fastest move is this many times the median
#: moving feed (a mill's rapids against its cutting feeds)...
PLOT_RAPID_FACTOR = 10.0
#: ...linear below this feed, mm/s (so rest, 0, stays on the axis)
PLOT_FEED_LINEAR_BELOW = 1.0

_KIND_LABELS = (("velocity", "v / vmax"), ("acceleration", "a / amax"), ("jerk", "j / jmax"))


def plot_file(path: str, machine_spec: str | None, out: str | None = None) -> str:
    """Plot the plan at ``path`` (CSV or MCAP) to ``out`` (default: ``path`` with ``.png``).

    Without ``machine_spec`` the machine an MCAP plan names gives the limits (see
    ``verify_file.plan_machine``). The image format follows ``out``'s extension (png,
    svg, pdf); ``out`` is never one of the inputs. Returns the file written.
    """
    from ..outfile import check_writable
    from .verify_file import plan_machine, read_plan

    if out is None:
        out = os.path.splitext(os.fspath(path))[0] + ".png"
    check_writable(out, inputs=(os.fspath(path), machine_spec))
    machine = plan_machine(path, machine_spec, required=False)
    # a one-sample plan shows no period; any period draws its single point
    traj = read_plan(path, machine.dt_s if machine is not None else 1.0)
    title = os.path.basename(os.fspath(path))
    plot_trajectory(traj, machine, out, title=title)
    return out


def plot_trajectory(traj, machine, out: str, title: str = "") -> str:
    """Draw ``traj`` (and its limit ratios when ``machine`` is given) into ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.backend_bases import FigureCanvasBase

    from ..outfile import atomic_write

    fmt = os.path.splitext(out)[1].lstrip(".").lower() or "png"
    supported = FigureCanvasBase.get_supported_filetypes()
    if fmt not in supported:
        from ..errors import SourceLocation, UsageError

        raise UsageError(
            f"cannot write a .{fmt} image; use one of {', '.join(sorted(supported))}", SourceLocation(file=out)
        )
    with plt.rc_context(_STYLE):
        fig = _figure(plt, traj, machine, title)
        try:
            with atomic_write(out) as fh:
                # No dates or versions in the file: the same plan gives the same image.
                fig.savefig(fh, format=fmt, dpi=_DPI, metadata=_metadata(fmt))
        finally:
            plt.close(fig)
    return out


_DPI = 110
_STYLE = {
    "font.size": 9,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "axes.titlesize": 10,
    "axes.labelsize": 9,
    "legend.fontsize": 8,
    "svg.hashsalt": "cnc-interp",
}


def _metadata(fmt: str) -> dict | None:
    if fmt == "png":
        return {"Software": None}
    if fmt == "pdf":
        return {"Creator": None, "Producer": None, "CreationDate": None}
    if fmt == "svg":
        return {"Creator": None, "Date": None}
    return None


def _figure(plt, traj, machine, title):
    from matplotlib.gridspec import GridSpec

    n_right = 4 if machine is not None else 2
    fig = plt.figure(figsize=(14, 7.5) if machine is not None else (13, 5.5))
    gs = GridSpec(
        n_right,
        2,
        figure=fig,
        width_ratios=(1.0, 1.15),
        wspace=0.3,
        hspace=0.12,
        left=0.06,
        right=0.98,
        top=0.9,
        bottom=0.08,
    )
    z_axis = _z_view_axis(traj)
    ax_path = fig.add_subplot(gs[:-1, 0] if z_axis is not None else gs[:, 0])
    _draw_path(fig, ax_path, traj)

    ax_feed = fig.add_subplot(gs[0, 1] if machine is not None else gs[:, 1])
    t_f, f_lo, f_hi = _envelope(traj.t, traj.feed[:, None])
    ax_feed.fill_between(t_f, f_lo[:, 0], f_hi[:, 0], color="tab:blue", lw=0.6, alpha=0.9)
    ax_feed.plot(t_f, f_hi[:, 0], color="tab:blue", lw=0.6)
    ax_feed.set_ylabel("feed (mm/s)")
    t_end = float(traj.t[-1]) if traj.t.size > 1 else float(traj.dt_s)  # one sample: one period wide
    ax_feed.set_xlim(float(traj.t[0]) if traj.t.size else 0.0, t_end)
    _scale_to_cutting_feeds(ax_feed, traj.feed)
    if z_axis is not None:
        ax_z = fig.add_subplot(gs[-1, 0])
        t_z, z_lo, z_hi = _envelope(traj.t, traj.q[:, z_axis : z_axis + 1])
        ax_z.fill_between(t_z, z_lo[:, 0], z_hi[:, 0], color="tab:green", lw=0.6)
        ax_z.set_xlim(ax_feed.get_xlim())
        ax_z.set_ylabel(f"{traj.axes[z_axis]} (mm)")
        ax_z.set_xlabel("time (s)")
    axes_right = [ax_feed]
    if machine is not None:
        axes_right += _draw_ratios(fig, gs, traj, machine, ax_feed)
    for ax in axes_right[:-1]:
        ax.tick_params(labelbottom=False)
    axes_right[-1].set_xlabel("time (s)")

    who = "CSV plan" if traj.planner == "csv" else f"{traj.planner} planner"
    sub = f"{who}, {traj.n_samples:,} samples at dt = {traj.dt_s * 1e3:g} ms, cycle time {traj.duration_s:.3f} s"
    if machine is not None:
        sub += f", machine: {machine.name}"
    if traj.status != "ok":
        sub += f" [{traj.status}]"
    fig.suptitle(f"{title}\n{sub}" if title else sub, fontsize=10)
    return fig


def _scale_to_cutting_feeds(ax, feed: np.ndarray) -> None:
    """A symmetric-log feed axis when the fastest moves (rapids) are far above the typical
    moving feed: on a linear scale a 200 mm/s rapid flattens cutting at 1-15 mm/s into a
    line; on the log part every feed keeps its own height, and rest (0) is still drawn."""
    f = feed[np.isfinite(feed) & (feed > 0)]
    if f.size < 10:
        return
    typical = float(np.median(f))
    if typical > 0 and float(f.max()) > PLOT_RAPID_FACTOR * typical:
        ax.set_yscale("symlog", linthresh=PLOT_FEED_LINEAR_BELOW, linscale=0.5)
        ax.set_ylim(0.0, float(f.max()) * 1.5)
        ax.text(
            0.995,
            0.94,
            "log scale above 1 mm/s",
            transform=ax.transAxes,
            ha="right",
            va="top",
            fontsize=8,
            bbox={"facecolor": "white", "alpha": 0.75, "lw": 0},
        )


def _z_view_axis(traj) -> int | None:
    """The Z column when Z moves but the path view does not show it (a mill's top view)."""
    if "Z" not in traj.axes or traj.n_samples == 0:
        return None
    iz = traj.axes.index("Z")
    if iz in _plane_axes(traj) or not np.ptp(traj.q[:, iz]) > 0:
        return None
    return iz


def _plane_axes(traj) -> tuple[int, int]:
    """Indices of the axes to draw the path in, in machine order: X and Y when both move
    (the top view of a mill, as in paper 001), else the two that move most (linear axes
    first: X and Z on a lathe)."""
    q = traj.q
    n = q.shape[1]
    if n == 1:
        return 0, 0
    span = np.ptp(q, axis=0) if q.shape[0] else np.zeros(n)
    span = np.where(np.isfinite(span), span, 0.0)
    if "X" in traj.axes and "Y" in traj.axes:
        ix, iy = traj.axes.index("X"), traj.axes.index("Y")
        if span[ix] > 0 and span[iy] > 0:
            return ix, iy
    linear = np.array([a in LINEAR_AXES for a in traj.axes])
    # Rank linear axes ahead of rotary ones, then by how far they move.
    order = sorted(range(n), key=lambda i: (not linear[i] or span[i] == 0, -span[i], i))
    i, j = sorted(order[:2])
    return i, j


def _draw_path(fig, ax, traj) -> None:
    from matplotlib.collections import LineCollection
    from matplotlib.colors import PowerNorm

    i, j = _plane_axes(traj)
    K = traj.n_samples
    step = max(1, -(-K // PLOT_MAX_PATH_POINTS))
    idx = np.arange(0, K, step)
    if K and idx[-1] != K - 1:
        idx = np.append(idx, K - 1)
    x = traj.q[idx, i]
    y = traj.q[idx, j] if j != i else np.zeros(idx.size)
    feed = traj.feed
    # Colour each drawn piece by the fastest feed it covers, so short bursts stay visible.
    seg_feed = np.maximum.reduceat(np.nan_to_num(feed), idx[:-1]) if idx.size > 1 else feed[:0]
    pts = np.column_stack([x, y]).reshape(-1, 1, 2)
    segs = np.concatenate([pts[:-1], pts[1:]], axis=1)
    fmax = float(np.nanmax(feed)) if K and np.isfinite(feed).any() else 1.0
    # A square-root colour scale: rapids are often ten times the cutting feed, and on a
    # linear scale every cutting feed would get the same dark colour.
    norm = PowerNorm(gamma=0.5, vmin=0.0, vmax=fmax if fmax > 0 else 1.0)
    lc = LineCollection(segs, cmap="turbo", norm=norm, linewidths=1.4, capstyle="round")
    lc.set_array(seg_feed)
    ax.add_collection(lc)
    if K:
        ax.plot(x[:1], y[:1], "o", ms=5, color="k", label="start")
        ax.plot(x[-1:], y[-1:], "s", ms=5, color="k", mfc="none", label="end")
        ax.legend(loc="best", framealpha=0.8)
    ax.autoscale()
    if j != i:
        ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"{traj.axes[i]} ({_unit(traj.axes[i])})")
    ax.set_ylabel(f"{traj.axes[j]} ({_unit(traj.axes[j])})" if j != i else "")
    ax.set_title(f"tool path in {traj.axes[i]}{traj.axes[j] if j != i else ''}, coloured by feed")
    cb = fig.colorbar(lc, ax=ax, fraction=0.046, pad=0.02)
    cb.set_label("feed (mm/s)")


def _draw_ratios(fig, gs, traj, machine, share):
    from .ratios import limit_ratios

    axes = "".join(a for a in traj.axes if a in machine.axes)
    it = [traj.axes.index(a) for a in axes]
    im = [machine.axes.index(a) for a in axes]
    ratios = limit_ratios(traj.q[:, it], traj.dt_s, machine.limits()[:, im])
    colors = [f"C{k}" for k in range(len(axes))]
    out = []
    for kind, (name, label) in enumerate(_KIND_LABELS):
        ax = fig.add_subplot(gs[kind + 1, 1], sharex=share)
        t_e, lo, hi = _envelope(traj.t, ratios[kind])
        moved = np.abs(ratios[kind]).max(axis=0) > 0 if traj.n_samples else np.zeros(0, bool)
        for c, a in enumerate(axes):
            if not moved[c]:
                continue
            if t_e.size == traj.n_samples:
                ax.plot(t_e, hi[:, c], lw=0.8, color=colors[c], label=a)
            else:
                ax.fill_between(t_e, lo[:, c], hi[:, c], color=colors[c], lw=0.4, alpha=0.55, label=a)
        for bound in (-1.0, 1.0):
            ax.axhline(bound, color="red", ls="--", lw=0.9)
        worst = float(np.nanmax(np.abs(ratios[kind]))) if ratios[kind].size else 0.0
        top = max(1.4, min(worst * 1.3, 10.0))  # headroom for the legend and the label
        ax.set_ylim(-top, top)
        ax.set_ylabel(label)
        ax.text(
            0.995,
            0.94,
            f"worst |{label.split(' ')[0]}|/limit = {worst:.3f}",
            transform=ax.transAxes,
            ha="right",
            va="top",
            fontsize=8,
            color="red" if worst > 1.0 else "black",
            bbox={"facecolor": "white", "alpha": 0.75, "lw": 0},
        )
        if kind == 0 and ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper left", ncol=len(axes), framealpha=0.8)
        out.append(ax)
    return out


def _envelope(t: np.ndarray, y: np.ndarray):
    """Per-bin (time, min, max) of ``y`` (K, m): the samples themselves when K is small."""
    K = t.shape[0]
    if K <= 2 * PLOT_ENVELOPE_BINS:
        return t, y, y
    bins = PLOT_ENVELOPE_BINS
    edges = np.linspace(0, K, bins + 1).astype(int)
    lo = np.minimum.reduceat(y, edges[:-1], axis=0)
    hi = np.maximum.reduceat(y, edges[:-1], axis=0)
    return t[edges[:-1]], lo, hi


def _unit(axis: str) -> str:
    return "mm" if axis in LINEAR_AXES else "deg"

"""``cnc-interp plot``: a picture of a plan (matplotlib, imported only here, Agg backend).

Left: the tool path in the plane of the two linear axes that move most, coloured by the
planned feed (paper 001, figure 4); below it, against time, Z when the path view does not
show it and the rotary axes (deg) when any turns. Right, against time: the feed, then
every axis's velocity, acceleration and jerk divided by the machine's limit, with the ±1
bounds (paper 001, figures 6 and 8), and which limit binds over time
(``plan.breakdown``'s classes: an axis's velocity, acceleration or jerk at 95 % or more
of its limit, else below the limits, or at rest) when a machine is given.

A time window (``--from``/``--to``, s) restricts every panel to the samples in it.
Long plans are drawn decimated: the path keeps every n-th sample, the curves against time
keep each pixel column's minimum and maximum (so no peak disappears from the picture and
the curve is a line, not a solid band, wherever it is smooth at that scale).
"""

from __future__ import annotations

import os

import numpy as np

from ..constants import LINEAR_AXES, ROTARY_AXES


#: most tool-path points a plot draws (longer plans are decimated for the picture only)
PLOT_MAX_PATH_POINTS = 100_000

#: time bins of the min/max envelope a plot draws for long plans when the panel's width
#: in pixels is not known (a panel uses one bin per pixel column)
PLOT_ENVELOPE_BINS = 2000

#: the path is drawn in X and Y (a mill's top view) while the less moving of the two
#: moves at least this share of the other (else the view is a flat line); else in the
#: two linear axes that move most (a lathe's or a rotary job's XZ)
PLOT_TOP_VIEW_MIN_SHARE = 0.05

#: the feed panel turns logarithmic when the fastest move is this many times the median
#: moving feed (a mill's rapids against its cutting feeds)...
PLOT_RAPID_FACTOR = 10.0
#: ...linear below this feed, mm/s (so rest, 0, stays on the axis)
PLOT_FEED_LINEAR_BELOW = 1.0

_KIND_LABELS = (("velocity", "v / vmax"), ("acceleration", "a / amax"), ("jerk", "j / jmax"))


def plot_file(
    path: str, machine_spec: str | None, out: str | None = None, t_from: float | None = None, t_to: float | None = None
) -> str:
    """Plot the plan at ``path`` (CSV or MCAP) to ``out`` (default: ``path`` with ``.png``),
    the samples from ``t_from`` to ``t_to`` s (default: the whole plan; see ``plot_window``).

    Without ``machine_spec`` the machine an MCAP plan names gives the limits, else the
    default preset (``verify_file.resolve_plan_machine``). The image format follows
    ``out``'s ending (png, svg, pdf, ...: ``image_format``); ``out`` is never one of the
    inputs. Returns the file written.
    """
    from ..outfile import check_writable
    from .verify_file import plan_machine, read_plan

    if out is None:
        out = os.path.splitext(os.fspath(path))[0] + ".png"
    check_writable(out, inputs=(os.fspath(path), machine_spec))
    image_format(out)  # an unknown ending: exit 2 before the plan is read
    machine = plan_machine(path, machine_spec)
    # a one-sample plan shows no period; any period draws its single point
    traj = read_plan(path, machine.dt_s if machine is not None else 1.0)
    span = plot_window(traj, t_from, t_to, os.fspath(path))
    title = os.path.basename(os.fspath(path))
    plot_trajectory(traj, machine, out, title=title, span=span)
    return out


def plot_window(traj, t_from: float | None, t_to: float | None, path: str = "plot") -> tuple[int, int]:
    """The samples ``[i0, i1)`` of ``traj`` whose time lies in ``[t_from, t_to]`` s (a
    bound left ``None`` is the plan's start or end). A bound that is not finite, lies
    outside the plan, or a ``t_from`` not before ``t_to`` is a ``UsageError`` on ``path``."""
    from ..errors import SourceLocation, UsageError

    loc = SourceLocation(file=path)
    K = traj.n_samples
    if t_from is None and t_to is None:
        return 0, K
    end = float(traj.t[-1]) if K else 0.0
    for name, v in (("--from", t_from), ("--to", t_to)):
        if v is not None and not np.isfinite(v):
            raise UsageError(f"{name} must be a finite time in seconds, not {v}", loc)
        if v is not None and not 0.0 <= v <= end:
            raise UsageError(f"{name} {v:g} s lies outside the plan (0 to {end:g} s)", loc)
    a = 0.0 if t_from is None else float(t_from)
    b = end if t_to is None else float(t_to)
    if not a < b:
        raise UsageError(f"--from {a:g} s must come before --to {b:g} s", loc)
    i0 = int(np.searchsorted(traj.t, a, side="left"))
    i1 = int(np.searchsorted(traj.t, b, side="right"))
    if i1 - i0 < 2:
        raise UsageError(f"the window {a:g} to {b:g} s holds fewer than 2 samples (dt = {traj.dt_s:g} s)", loc)
    return i0, i1


def plot_trajectory(traj, machine, out: str, title: str = "", span: tuple[int, int] | None = None) -> str:
    """Draw ``traj`` (and its limit ratios when ``machine`` is given) into ``out``; only
    the samples ``span = (i0, i1)`` when given (``plot_window``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.backend_bases import FigureCanvasBase

    from ..outfile import atomic_write

    fmt = image_format(out, FigureCanvasBase.get_supported_filetypes())
    with plt.rc_context(_STYLE):
        fig = _figure(plt, traj, machine, title, span)
        try:
            with atomic_write(out) as fh:
                # No dates or versions in the file: the same plan gives the same image.
                fig.savefig(fh, format=fmt, dpi=_DPI, metadata=_metadata(fmt))
        finally:
            plt.close(fig)
    return out


def image_format(out: str, supported=None) -> str:
    """The image format of ``out`` by its ending (any case): one matplotlib writes (png
    first, the format of a device or FIFO); another ending, or none, is a ``UsageError``
    naming the accepted ones (``outfile.output_format``)."""
    from ..outfile import output_format

    if supported is None:
        import matplotlib

        matplotlib.use("Agg")
        from matplotlib.backend_bases import FigureCanvasBase

        supported = FigureCanvasBase.get_supported_filetypes()
    formats = {".png": "png"} | {"." + k: k for k in sorted(supported)}
    return output_format(out, formats, "a plot")


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


def _figure(plt, full, machine, title, span: tuple[int, int] | None = None):
    from dataclasses import replace

    from matplotlib.gridspec import GridSpec

    i0, i1 = span if span is not None else (0, full.n_samples)
    windowed = (i0, i1) != (0, full.n_samples)
    traj = full
    if windowed:
        traj = replace(
            full, t=full.t[i0:i1], s=full.s[i0:i1], feed=full.feed[i0:i1], q=full.q[i0:i1], line=full.line[i0:i1]
        )
    z_axis = _z_view_axis(traj)
    rotary = _rotary_axes(traj)
    left_extra = (z_axis is not None) + bool(rotary)
    n_right = 5 if machine is not None else 2
    rows = n_right if left_extra < n_right else 4  # the path keeps at least half the height
    fig = plt.figure(figsize=(14, 8.8) if rows == 5 else (13, 5.5))
    gs = GridSpec(
        rows,
        2,
        figure=fig,
        width_ratios=(1.0, 1.15),
        wspace=0.3,
        hspace=0.2 if left_extra else 0.12,
        left=0.06,
        right=0.98,
        top=0.9,
        bottom=0.08,
    )
    ax_path = fig.add_subplot(gs[: rows - left_extra, 0])
    _draw_path(fig, ax_path, traj)

    ax_feed = fig.add_subplot(gs[0, 1] if machine is not None else gs[:, 1])
    t_f, f_lo, f_hi = _envelope(traj.t, traj.feed[:, None], _columns(fig, ax_feed))
    ax_feed.fill_between(t_f, f_lo[:, 0], f_hi[:, 0], color="tab:blue", lw=0.6, alpha=0.9)
    ax_feed.plot(t_f, f_hi[:, 0], color="tab:blue", lw=0.6)
    ax_feed.set_ylabel("feed (mm/s)")
    t0 = float(traj.t[0]) if traj.t.size else 0.0
    t_end = float(traj.t[-1]) if traj.t.size > 1 else t0 + float(traj.dt_s)  # one sample: one period wide
    ax_feed.set_xlim(t0, t_end)
    _scale_to_cutting_feeds(ax_feed, traj.feed)
    row = rows - left_extra
    if z_axis is not None:
        ax_z = fig.add_subplot(gs[row, 0])
        row += 1
        t_z, z_lo, z_hi = _envelope(traj.t, traj.q[:, z_axis : z_axis + 1], _columns(fig, ax_z))
        ax_z.fill_between(t_z, z_lo[:, 0], z_hi[:, 0], color="tab:green", lw=0.6)
        ax_z.plot(t_z, z_hi[:, 0], color="tab:green", lw=0.6)
        ax_z.set_xlim(ax_feed.get_xlim())
        ax_z.set_ylabel(f"{traj.axes[z_axis]} (mm)")
        ax_z.set_xlabel("time (s)")
    if rotary:
        ax_r = fig.add_subplot(gs[row, 0])
        t_r, r_lo, r_hi = _envelope(traj.t, traj.q[:, rotary], _columns(fig, ax_r))
        for c, k in enumerate(rotary):
            color = f"C{k % 10}"  # the colour of the axis in the ratio panels
            ax_r.fill_between(t_r, r_lo[:, c], r_hi[:, c], color=color, lw=0.4, alpha=0.55)
            ax_r.plot(t_r, r_hi[:, c], color=color, lw=0.7, label=traj.axes[k])
        ax_r.set_xlim(ax_feed.get_xlim())
        ax_r.set_ylabel("rotary (deg)")
        ax_r.set_xlabel("time (s)")
        ax_r.legend(loc="upper left", ncol=len(rotary), framealpha=0.8)
        if z_axis is not None:
            ax_z.set_xlabel("")
            ax_z.tick_params(labelbottom=False)
    axes_right = [ax_feed]
    if machine is not None:
        axes, q, ratios = _span_ratios(full, machine, (i0, i1))
        t = full.t[i0:i1]
        axes_right += _draw_ratios(fig, gs, t, axes, ratios, ax_feed)
        axes_right.append(_draw_binding(fig, fig.add_subplot(gs[4, 1], sharex=ax_feed), t, axes, q, ratios))
    for ax in axes_right[:-1]:
        ax.tick_params(labelbottom=False)
    axes_right[-1].set_xlabel("time (s)")

    who = "CSV plan" if traj.planner == "csv" else f"{traj.planner} planner"
    sub = f"{who}, {full.n_samples:,} samples at dt = {full.dt_s * 1e3:g} ms, cycle time {full.duration_s:.3f} s"
    if windowed:
        sub += f"; shown: {t0:.3f} to {t_end:.3f} s"
    if machine is not None:
        sub += f", machine: {machine.name}"
    if traj.status != "ok":
        sub += f" [{traj.status}]"
    fig.suptitle(f"{title}\n{sub}" if title else sub, fontsize=10)
    return fig


def _columns(fig, ax) -> int:
    """The width of ``ax`` in pixel columns (at the saved resolution)."""
    return max(16, int(round(ax.get_position().width * fig.get_figwidth() * _DPI)))


def _rotary_axes(traj) -> list[int]:
    """The columns of the rotary axes (A, B, C) that turn."""
    if traj.n_samples == 0:
        return []
    span = np.ptp(traj.q, axis=0)
    return [i for i, a in enumerate(traj.axes) if a in ROTARY_AXES and np.isfinite(span[i]) and span[i] > 0]


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
    (the top view of a mill, as in paper 001) and the less moving of them moves at least
    ``PLOT_TOP_VIEW_MIN_SHARE`` of the other; else the two linear axes that move most (X
    and Z on a lathe or an XZA rotary job), then rotary ones."""
    q = traj.q
    n = q.shape[1]
    if n == 1:
        return 0, 0
    span = np.ptp(q, axis=0) if q.shape[0] else np.zeros(n)
    span = np.where(np.isfinite(span), span, 0.0)
    linear = np.array([a in LINEAR_AXES for a in traj.axes])
    if "X" in traj.axes and "Y" in traj.axes:
        ix, iy = traj.axes.index("X"), traj.axes.index("Y")
        small, large = sorted((float(span[ix]), float(span[iy])))
        if small > 0 and small >= PLOT_TOP_VIEW_MIN_SHARE * large:
            return ix, iy
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


def _span_ratios(full, machine, span: tuple[int, int]):
    """``(axes, q, ratios)`` of the samples ``span`` of the plan ``full`` on the machine's
    axes: ``q`` (back + K, n) the samples with up to 3 before the window (the stencils'),
    ``ratios`` (3, K, n) the signed v, a, j ratios, which reach back before the window as
    in the whole plan."""
    from .ratios import limit_ratios

    i0, i1 = span
    axes = "".join(a for a in full.axes if a in machine.axes)
    it = [full.axes.index(a) for a in axes]
    im = [machine.axes.index(a) for a in axes]
    back = min(i0, 3)
    q = full.q[i0 - back : i1][:, it]
    return axes, q, limit_ratios(q, full.dt_s, machine.limits()[:, im])[:, back:]


def _draw_ratios(fig, gs, t, axes, ratios, share):
    """The v, a, j ratio panels of ``ratios`` (``_span_ratios``) against times ``t``."""
    K = t.shape[0]
    colors = [f"C{k}" for k in range(len(axes))]
    out = []
    for kind, (name, label) in enumerate(_KIND_LABELS):
        ax = fig.add_subplot(gs[kind + 1, 1], sharex=share)
        t_e, lo, hi = _envelope(t, ratios[kind], _columns(fig, ax))
        moved = np.abs(ratios[kind]).max(axis=0) > 0 if K else np.zeros(0, bool)
        for c, a in enumerate(axes):
            if not moved[c]:
                continue
            if t_e.size == K:
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


def _draw_binding(fig, ax, t, axes, q, signed):
    """Which limit binds at each sample (``plan.breakdown.codes_of`` of the ratios
    ``signed``, ``_span_ratios``'), one row per class that occurs; long plans show every
    class met in each pixel column."""
    from ..plan.breakdown import CODE_LIMIT0, CODE_REST, CODE_TRANSITION, code_names, codes_of

    K = t.shape[0]
    back = q.shape[0] - K
    ratios = np.abs(signed).transpose(1, 0, 2)
    moving = np.zeros(K, dtype=bool)
    if K:
        prev = q[back - 1] if back else q[0]
        moving[0] = bool(np.any(q[back] != prev))
        moving[1:] = np.any(q[back + 1 :] != q[back:-1], axis=1)
    codes = codes_of(np.nan_to_num(ratios, nan=np.inf), moving).astype(np.int64)
    names = code_names(axes)
    bins = _columns(fig, ax)
    if K > 2 * bins:  # the classes met in each pixel column
        col = np.arange(K) * bins // K
        pairs = np.unique(col * len(names) + codes)
        col, codes = np.divmod(pairs, len(names))
        t0, t1 = float(t[0]), float(t[-1])
        x = t0 + (col + 0.5) * (t1 - t0) / bins
    else:
        x = t
    present = np.unique(codes) if codes.size else np.zeros(0, dtype=np.int64)
    row = {c: r for r, c in enumerate(present)}
    y = np.array([row[c] for c in codes.tolist()]) if codes.size else np.zeros(0)
    colors = [
        f"C{(c - CODE_LIMIT0) // 3}" if c >= CODE_LIMIT0 else ("0.75" if c == CODE_REST else "0.45")
        for c in codes.tolist()
    ]
    ax.scatter(x, y, c=colors, marker="|", s=40, linewidths=0.8)
    ax.set_yticks(range(len(present)), [names[c] if c != CODE_TRANSITION else "below limits" for c in present.tolist()])
    ax.tick_params(axis="y", labelsize=7)
    ax.set_ylim(-0.7, max(len(present), 1) - 0.3)
    ax.set_ylabel("binds")
    return ax


def _envelope(t: np.ndarray, y: np.ndarray, bins: int = PLOT_ENVELOPE_BINS):
    """Per-bin (time, min, max) of ``y`` (K, m) over ``bins`` equal bins (one per pixel
    column): the samples themselves when K is small."""
    K = t.shape[0]
    if K <= 2 * bins:
        return t, y, y
    edges = np.linspace(0, K, bins + 1).astype(int)
    lo = np.minimum.reduceat(y, edges[:-1], axis=0)
    hi = np.maximum.reduceat(y, edges[:-1], axis=0)
    return t[edges[:-1]], lo, hi


def _unit(axis: str) -> str:
    return "mm" if axis in LINEAR_AXES else "deg"

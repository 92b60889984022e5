"""Figures a user reads (apps/plots): one panel per joint in a grid of sane size for any arm,
error axes set by the converged part with the 2-sigma band inside them, long lines cut to
the pixels without losing a spike, legends that say what a line is, and the ``--no-plots``
hint when the figures take more than a quarter of a command."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amsfe_sym.apps.plots.cost import SHARE, FigureClock, hint_line
from amsfe_sym.apps.plots.style import (
    DPI,
    LOG_SUBS_UP_TO,
    PANEL,
    Canvas,
    collect_once,
    converged_limit,
    envelope,
    figure,
    joint_grid,
    logscale,
    pyplot,
    save,
    symlog,
    title,
    window_start,
)


@pytest.mark.parametrize("n", [1, 2, 6, 7, 12])
def test_one_panel_per_joint_in_a_grid_of_sane_size(n: int, tmp_path: Path) -> None:
    """7 joints: 4 + 3 panels (not 14 in two rows); a PNG of at most 1600 px a side."""
    fig, cells = joint_grid(n, (3.8, 1.9), rows_per_joint=2)
    assert len(cells) == n and all(len(c) == 2 for c in cells)
    cols = min(n, 4)
    rows = -(-n // cols)
    assert len(fig.axes) == 2 * n
    for j, (top, _bottom) in enumerate(cells):
        spec = top.get_subplotspec()
        assert spec.colspan.start == j % cols and spec.rowspan.start == 2 * (j // cols)
        assert spec.get_gridspec().nrows == 2 * rows
    path = save(fig, tmp_path / "grid.png")
    img = pyplot().imread(path)
    h, w = img.shape[:2]
    assert w <= 1600 and h <= 1600 and w == round(fig.get_figwidth() * DPI)


def _draw_a(cells: list, t: np.ndarray) -> None:
    """A figure that sets everything a grid can carry: symlog, fixed limits, a legend, a
    band, labels, a title on one axes."""
    for j, (ax,) in enumerate(cells):
        ax.fill_between(t, -1 - j, 1 + j, color="0.85", lw=0, label="band")
        ax.plot(t, 0.3 * np.sin(7 * t) * 10**-j, label="line")
        symlog(ax, 1e-3)
        ax.set_ylim(-5, 5)
        ax.set_ylabel(f"a{j}")
        ax.set_title("only in A")
    cells[0][0].legend()


def _draw_b(fig, cells: list, t: np.ndarray) -> None:
    for j, (ax,) in enumerate(cells):
        ax.plot(t, (j + 1) * 1e-4 * np.cos(3 * t), lw=0.7)
        ax.set_ylabel(f"b{j} [rad]", fontsize=8)
        ax.grid(alpha=0.3)
    title(fig, "B")


def _assert_b_drawn_alike(folder: Path) -> None:
    """b_reused.png and b_new.png are the same pixels, and not a.png's."""
    imread = pyplot().imread
    reused, new = imread(folder / "b_reused.png"), imread(folder / "b_new.png")
    assert reused.shape == new.shape
    assert np.array_equal(reused, new)
    assert not np.array_equal(imread(folder / "a.png"), new)


def test_a_reused_grid_draws_what_a_new_one_draws(tmp_path: Path) -> None:
    """Canvas hands the previous grid back emptied: a figure drawn on it after another is
    the same PNG, pixel for pixel, as the figure drawn on a new grid (no line, band, legend,
    title, scale or limit of the first is left)."""
    t = np.linspace(0.0, 5.0, 3000)
    canvas = Canvas()
    fig, cells = canvas.joint_grid(7, PANEL)
    _draw_a(cells, t)
    save(fig, tmp_path / "a.png")
    fig2, cells2 = canvas.joint_grid(7, PANEL)
    assert fig2 is fig  # reused
    _draw_b(fig2, cells2, t)
    save(fig2, tmp_path / "b_reused.png")
    fresh, fresh_cells = Canvas().joint_grid(7, PANEL)
    assert fresh is not fig
    _draw_b(fresh, fresh_cells, t)
    save(fresh, tmp_path / "b_new.png")
    _assert_b_drawn_alike(tmp_path)
    assert canvas.joint_grid(6, PANEL)[0] is not fig  # another shape: a new grid


def _draw_tracking(fig, axes: list, t: np.ndarray, j: int) -> None:
    """What the paper's Figs. 6-7 draw: a dashed reference, lines, a symlog lower axis, a
    legend and fixed y limits on the upper one."""
    axes[0].plot(t, np.sin(t + j), "k--", lw=1.2, label="desired")
    axes[0].plot(t, np.sin(t + j) + 0.1 * j, lw=0.9, label=f"line {j}")
    axes[1].plot(t, 10.0 ** -(j + 2) * np.cos(9 * t), lw=0.9)
    axes[0].set_ylabel(f"q{j + 1} [rad]")
    symlog(axes[1], 1e-3)
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=8)
    axes[0].legend(fontsize=8)
    axes[0].set_ylim(-1.5 - j, 1.5 + j)
    title(fig, f"tracking {j}")


def test_a_reused_stack_draws_what_a_new_one_draws(tmp_path: Path) -> None:
    """Canvas.stack hands the previous figure of stacked axes back emptied: Fig. 7 drawn on
    Fig. 6's figure is the same PNG, pixel for pixel, as on a new one."""
    t = np.linspace(0.0, 10.0, 5000)
    canvas = Canvas()
    fig, axes = canvas.stack((8, 6), 2)
    _draw_tracking(fig, axes, t, 0)
    save(fig, tmp_path / "a.png")
    fig2, axes2 = canvas.stack((8, 6), 2)
    assert fig2 is fig and len(axes2) == 2  # reused
    _draw_tracking(fig2, axes2, t, 1)
    save(fig2, tmp_path / "b_reused.png")
    fresh, fresh_axes = Canvas().stack((8, 6), 2)
    _draw_tracking(fresh, fresh_axes, t, 1)
    save(fresh, tmp_path / "b_new.png")
    _assert_b_drawn_alike(tmp_path)
    assert canvas.stack((8, 5), 2)[0] is not fig  # another size: a new figure


def test_ticks_are_made_only_where_they_are_seen(tmp_path: Path) -> None:
    """Matplotlib makes a tick (three lines, two texts) for every location its locator
    gives, and its locators give one or two outside the view on each side: a grid's
    locators give the same locations inside the view and no others, so every tick made is
    drawn (linear, symlog and log axes)."""
    from matplotlib.ticker import LogLocator, MaxNLocator, SymmetricalLogLocator

    t = np.linspace(0.0, 30.0, 3000)
    fig, cells = joint_grid(3, PANEL)
    (lin,), (sym,), (log,) = cells
    lin.plot(t, 1e-4 * np.sin(t))
    lin.set_ylim(-2.2e-4, 2.2e-4)
    sym.plot(t, 0.3 * np.sin(t) * np.exp(-t))
    symlog(sym, 1e-3)
    log.plot(t, 1e-3 + np.exp(-t / 3))
    logscale(log)
    save(fig, tmp_path / "ticks.png")
    references = {
        id(lin.yaxis): MaxNLocator(4),
        id(sym.yaxis): SymmetricalLogLocator(linthresh=1e-3, base=10, subs=[1.0]),
        id(log.yaxis): LogLocator(base=10, subs=(1.0,), numticks=7),
    }
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            reference = references.get(id(axis), MaxNLocator(3 if axis is ax.xaxis else 4))
            reference.set_axis(axis)
            seen = [v for v in reference.tick_values(lo, hi) if lo <= v <= hi]
            locs = list(axis.get_majorticklocs())
            assert locs == seen and len(locs) >= 2
            assert len(axis.majorTicks) == len(locs)  # none made outside the view


def test_axis_labels_stand_clear_of_the_tick_labels_and_line_up(tmp_path: Path) -> None:
    """A grid's axis labels are placed once (not from the tick labels' boxes at each draw):
    each y label stands left of its widest tick labels (symlog's "-1e-3") and right of
    the panel before it, at the same offset in every panel; each x label below its tick
    labels and inside the figure."""
    t = np.linspace(0.0, 5.0, 500)
    fig, cells = joint_grid(7, PANEL)
    for j, (ax,) in enumerate(cells):
        ax.plot(t, 0.5 * np.sin(3 * t) * 10.0**-j)
        symlog(ax, 1e-3)
        ax.set_ylabel(f"q{j + 1} − q{j + 1},d [rad]", fontsize=8)
    save(fig, tmp_path / "labels.png")
    r = fig.canvas.get_renderer()
    offsets = set()
    for j, (ax,) in enumerate(cells):
        label = ax.yaxis.label.get_window_extent(r)
        ticks = [b.get_window_extent(r) for b in ax.get_yticklabels() if b.get_text()]
        assert ticks and label.x1 < min(b.x0 for b in ticks)
        assert label.x0 > (cells[j - 1][0].bbox.x1 if j % 4 else 0)
        offsets.add(round(ax.bbox.x0 - label.x1, 6))
        if ax.get_xlabel():
            xlabel = ax.xaxis.label.get_window_extent(r)
            xticks = [b.get_window_extent(r) for b in ax.get_xticklabels() if b.get_text()]
            assert xticks and xlabel.y1 < min(b.y0 for b in xticks) and xlabel.y0 > 0
    assert len(offsets) == 1


def test_a_wide_log_axis_is_labelled_at_its_decades(tmp_path: Path) -> None:
    """A log axis over many decades gets its decades alone (1, 2 and 5 a decade over six
    decades were 18 crowded labels); over a few decades 1, 2 and 5 times each."""
    fig = figure((6.0, 4.0))
    wide, narrow = fig.subplots(2, 1)
    wide.plot([0.0, 1.0], [2e-5, 20.0], ".")
    logscale(wide)
    narrow.plot([0.0, 1.0], [3.0, 40.0], ".")
    logscale(narrow)
    save(fig, tmp_path / "log.png")
    decades = np.log10(wide.yaxis.get_majorticklocs())
    assert np.allclose(decades, np.round(decades)) and 4 <= decades.size <= 7
    labels = [tick.get_text() for tick in narrow.get_yticklabels()]
    assert np.log10(40.0 / 3.0) <= LOG_SUBS_UP_TO
    assert {"5", "10", "20"} <= set(labels)
    assert all("$" not in label for label in labels)  # plain text, not TeX math


def test_figures_are_drawn_with_the_collector_paused_and_collected_once(tmp_path: Path) -> None:
    """While a command's figures are drawn the cyclic garbage collector is off and what
    lives on is frozen; after, it is on again, nothing is left frozen, and the figures
    (reference cycles) are gone; an error in the drawing leaves the collector as it was."""
    import gc
    import weakref

    seen: dict = {}

    @collect_once
    def draw(path: Path, fail: bool = False) -> Path:
        seen["enabled"], seen["frozen"] = gc.isenabled(), gc.get_freeze_count()
        fig, cells = joint_grid(2, PANEL)
        cells[0][0].plot([0.0, 1.0], [0.0, 1.0])
        seen["figure"] = weakref.ref(fig)
        if fail:
            raise KeyboardInterrupt
        return save(fig, path)

    assert gc.isenabled() and gc.get_freeze_count() == 0
    assert draw(tmp_path / "a.png").is_file()
    assert seen["enabled"] is False and seen["frozen"] > 0
    assert gc.isenabled() and gc.get_freeze_count() == 0
    assert seen["figure"]() is None  # collected at the end
    with pytest.raises(KeyboardInterrupt):
        draw(tmp_path / "b.png", fail=True)
    assert gc.isenabled() and gc.get_freeze_count() == 0  # (the traceback holds the figure)


def test_the_error_axis_is_set_by_the_converged_part() -> None:
    """A start transient 1000x the converged error does not set the axis: the limit covers
    the 2nd-98th percentile of the last 80 % and the 2-sigma band there, and no more than
    1.3x the larger of them."""
    rng = np.random.default_rng(0)
    K = 5000
    e = 1e-4 * rng.standard_normal(K)
    e[:50] = 0.1 * np.exp(-np.arange(50) / 10)  # the start
    band = np.full(K, 3e-4)
    band[:100] = 1.0
    lim = converged_limit(e, band)
    w = window_start(K)
    late = float(np.percentile(np.abs(e[w:]), 98))
    assert lim >= max(late, 3e-4) and lim <= 1.3 * max(late, 3e-4) * (1 + 1e-12)
    assert np.mean(np.abs(e[w:]) <= lim) >= 0.98
    assert lim < 1e-2 < float(np.max(np.abs(e)))
    assert converged_limit(np.zeros(10)) > 0  # an all-zero line stays drawable
    assert converged_limit(np.full(10, np.nan)) > 0


def test_envelope_keeps_every_spike_and_cuts_to_the_pixels() -> None:
    t = np.arange(60001) * 1e-3
    rng = np.random.default_rng(1)
    y = rng.standard_normal(t.size)
    y[12345], y[40000] = 50.0, -70.0  # one-tick spikes
    y2 = np.cos(t)
    y2[7] = np.nan
    tc, yc, y2c = envelope(t, y, y2, pixels=800)
    assert tc.size == yc.size == y2c.size == 1600
    assert np.nanmax(yc) == 50.0 and np.nanmin(yc) == -70.0
    assert np.all(np.diff(tc) >= 0)
    assert np.nanmax(y2c) == pytest.approx(np.nanmax(y2)) and np.isfinite(y2c).all()
    # a run that stopped early (4875 ticks): its last samples are drawn too
    t3 = np.arange(4875) * 1e-3
    tc3, yc3 = envelope(t3, np.where(t3 > 4.8, 9.0, 0.0), pixels=500)
    assert tc3[-1] > t3[-1] - 4.875 / 500 and np.nanmax(yc3) == 9.0  # within a column
    short = np.arange(100.0)
    out = envelope(short, short, pixels=800)
    assert out[0] is short and out[1] is short


def test_the_frames_rug_is_a_tick_at_each_arrival() -> None:
    """The camera frames' rug of estimate.png, one line broken by NaN: a vertical tick from
    0 to its height at each arrival, and nothing between two ticks."""
    from amsfe_sym.apps.plots.log import _rug

    at = np.array([0.1, 0.4, 2.5])
    x, y = _rug(at, height=0.04)
    assert x.shape == y.shape == (9,)
    np.testing.assert_array_equal(x.reshape(3, 3)[:, :2], np.repeat(at, 2).reshape(3, 2))
    np.testing.assert_array_equal(y.reshape(3, 3)[:, :2], [[0.0, 0.04]] * 3)
    assert np.isnan(x[2::3]).all() and np.isnan(y[2::3]).all()


def test_legends_name_the_law_not_truth() -> None:
    """``truth`` in a legend is the amsfe law on the true state; every controller's label
    says what its law acts on."""
    from types import SimpleNamespace

    from amsfe_sym.apps.plots.run import controller_label
    from amsfe_sym.scenario import load_scenario

    sc = load_scenario("paper-sim")
    res = SimpleNamespace(scenario=sc, diverged_at=None)
    assert controller_label(res, "truth") == "amsfe law on the true state (oracle)"  # type: ignore[arg-type]
    assert "oosm estimate" in controller_label(res, "amsfe")  # type: ignore[arg-type]
    assert "motor encoders" in controller_label(res, "dtsmc")  # type: ignore[arg-type]
    res.diverged_at = 0.89
    assert controller_label(res, "dtsmc").endswith("diverged at 0.89 s")  # type: ignore[arg-type]


def test_the_no_plots_hint_past_a_quarter() -> None:
    assert SHARE == 0.25
    line = hint_line(3.0, 4.0)
    assert line is not None and "--no-plots" in line and "3.0 of 4.0 s (75 %)" in line
    assert hint_line(0.9, 4.0) is None
    clock = FigureClock(started_s=1000.0)  # a long command: figures a small share
    assert clock.timed(lambda x: x + 1)(1) == 2 and clock.seconds >= 0.0
    assert clock.hint() is None


def test_run_figures_of_a_simulation(tmp_path: Path) -> None:
    """``plot_run`` of a 1 s paper-sim run: the three PNGs; each q-error axis is set by the
    converged part (it clips the start) and holds the 2-sigma band of the last 80 %."""
    from amsfe_sym.apps.plots.run import error_rows, estimation_error_axes, plot_run
    from amsfe_sym.codegen import library_for
    from amsfe_sym.scenario import load_scenario
    from amsfe_sym.sim.loop import run

    sc = load_scenario("paper-sim").with_overrides(controller="amsfe", duration=1.0, seed=4)
    res = run(sc, library_for(sc), runtime="compiled")
    paths = plot_run(res, tmp_path)
    assert sorted(p.name for p in paths) == ["estimation_errors.png", "theta.png", "tracking.png"]
    n = res.lib.n
    fig, cells = joint_grid(n, rows_per_joint=error_rows(n))
    estimation_error_axes(res, cells)
    L = res.lib.layout
    w = window_start(res.t.size)
    for j, axes in enumerate(cells):
        c = L["q"].start + j
        lo, hi = axes[0].get_ylim()
        e = res.x_true[:, c] - res.x_hat[:, c]
        band = 2 * np.sqrt(res.P_diag[w:, c])
        assert hi == -lo and hi >= float(np.percentile(band, 98))
        assert hi < float(np.max(np.abs(e)))  # the start transient is clipped
    pyplot().close(fig)


def test_log_figures_without_truth_show_deflection_and_residual(tmp_path: Path) -> None:
    """A driver's log (no truth): ``estimate.png`` has a panel per joint with the spring
    deflection and the encoder residual, and a row below them with the NIS and its
    chi-square band (green, drawn nowhere else: absent without a NIS report)."""
    from amsfe_sym.apps.plots.log import NisSeries, plot_log
    from amsfe_sym.codegen import library_for
    from amsfe_sym.logs.read import RobotLog
    from amsfe_sym.logs.replay import estimate_log
    from amsfe_sym.scenario import load_scenario
    from amsfe_sym.sim.builders import build_run
    from amsfe_sym.sim.loop import run

    sc = load_scenario("paper-sim").with_overrides(controller="amsfe", duration=1.0, seed=6)
    lib = library_for(sc)
    res = run(sc, lib, runtime="compiled")
    log = RobotLog(Path("drive.bag"), lib.T, 0, res.z_enc, res.u, [])
    est = estimate_log(log, build_run(sc, lib, compiled=True).estimator, progress=False)
    nis = {"encoders": {"dof": 4, "band_95": [0.48, 11.14]}}
    paths = plot_log(log, est.x_hat, est.P_diag, "oosm", NisSeries(nis, est.encoder_nis), tmp_path)
    assert [p.name for p in paths] == ["estimate.png"]
    with_nis = _band_rows(paths[0])
    bare = tmp_path / "bare"
    bare.mkdir()
    plot_log(log, est.x_hat, est.P_diag, "oosm", NisSeries({}), bare)
    without = _band_rows(bare / "estimate.png")
    row = round(2.3 * DPI)  # the NIS row: one joint panel high
    assert with_nis.size == without.size + row
    assert not without.any()
    assert with_nis[-row:].sum() > row // 4 and not with_nis[:-row].any()


def _band_rows(png: Path) -> np.ndarray:
    """Per pixel row of ``png``: whether it holds the chi-square band's colour (green at
    alpha 0.12 on white: R = B ~ 225, G ~ 240)."""
    from PIL import Image

    rgb = np.asarray(Image.open(png).convert("RGB"), dtype=int)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    band = (abs(r - 225) <= 3) & (abs(b - 225) <= 3) & (abs(g - 240) <= 3)
    return np.asarray(band.sum(axis=1) > 20)


@pytest.mark.slow
def test_an_arms_comparison_draws_what_is_read_and_the_rest_with_all_plots(
    tmp_path: Path,
) -> None:
    """A 7-joint comparison draws the estimation errors, theta and the tracking grid; the
    sliding variable and torque (a panel per joint and controller each) only with
    ``--all-plots``."""
    from amsfe_sym.apps.cli import main

    args = ["simulate", "panda-control", "--compare", "amsfe,truth", "--duration", "0.3"]
    args += ["--no-progress"]
    read = {"fig04_estimation_errors.png", "fig05_theta_error.png", "tracking.png"}
    assert main([*args, "--out", str(tmp_path / "few")]) == 0
    assert {p.name for p in (tmp_path / "few").glob("*.png")} == read
    assert main([*args, "--all-plots", "--out", str(tmp_path / "all")]) == 0
    drawn = {p.name for p in (tmp_path / "all").glob("*.png")}
    assert drawn == read | {"sliding_surface.png", "torque.png"}
    assert main([*args, "--all-plots", "--no-plots", "--out", str(tmp_path / "none")]) == 0
    assert not list((tmp_path / "none").glob("*.png"))


def test_no_plots_imports_no_matplotlib(tmp_path: Path) -> None:
    """``amsfe simulate --no-plots`` leaves matplotlib unimported (its import alone is
    0.3-0.7 s of CPU)."""
    import subprocess
    import sys

    code = (
        "import sys; from amsfe_sym.apps.cli import main; "
        "code = main(sys.argv[1:]); "
        "assert code == 0 and 'matplotlib' not in sys.modules, sorted(sys.modules)"
    )
    args = ["simulate", "--controller", "amsfe", "--duration", "0.05"]
    args += ["--no-progress", "--no-plots", "--out", str(tmp_path / "run")]
    subprocess.run([sys.executable, "-c", code, *args], check=True, capture_output=True)

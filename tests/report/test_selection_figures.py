"""A sweep's selection figures, on hand-made sweep folders: the rank matrix (an image and
its colour bar, one row per material in the clustered material order) and the Pareto plot
(two panels, titled with the materials every model has), every label inside the canvas
and level tick labels apart."""

from __future__ import annotations

import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from brdffit.report.selection_figures import pareto_figure, rank_matrix_figure
from brdffit.selection.crossrank import material_order, matrices
from brdffit.selection.pareto import error_vs_time
from brdffit.selection.sweep_results import load_sweep
from tests.sweep_fixtures import make_sweep


def _texts_outside(fig) -> list[str]:
    """Texts (tick labels in view, axis labels, titles, annotations, colour-bar label)
    that leave the canvas, and level tick labels of one axis that overlap each other
    (the boxes of slanted labels overlap whatever their spacing)."""
    canvas = FigureCanvasAgg(fig)  # the figures are not registered with pyplot
    canvas.draw()
    r = canvas.get_renderer()
    box, bad = fig.bbox, []

    def out(b) -> bool:
        return b.x0 < box.x0 - 1 or b.y0 < box.y0 - 1 or b.x1 > box.x1 + 1 or b.y1 > box.y1 + 1

    for ax in fig.axes:
        texts = [ax.title, ax.xaxis.label, ax.yaxis.label, *ax.texts]
        bad += [t.get_text() for t in texts if t.get_text() and out(t.get_window_extent(r))]
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            ticks = [
                t
                for t in axis.get_major_ticks() + axis.get_minor_ticks()
                if lo <= t.get_loc() <= hi and t.label1.get_visible() and t.label1.get_text()
            ]
            boxes = [t.label1.get_window_extent(r) for t in ticks]
            bad += [t.label1.get_text() for t, b in zip(ticks, boxes, strict=True) if out(b)]
            level = [b for t, b in zip(ticks, boxes, strict=True) if t.label1.get_rotation() == 0]
            bad += [
                f"tick labels overlap: {a.extents} {b.extents}"
                for i, a in enumerate(level)
                for b in level[i + 1 :]
                if a.overlaps(b)
            ]
    return bad


@pytest.fixture
def long_labels(tmp_path):
    """Three materials, six models with long labels, fit times over a decade."""
    models_ = ["lambert", "walter", "disney[subsurface=false,clearcoat=false]"]
    models_ += ["lafortune[n_lobes=2]", "cook_torrance", "ashikhmin_shirley[anisotropic=true]"]
    names = ["acrylic_felt_green_rgb", "cc_nothern_aurora_rgb", "vch_silver_sticker_rgb"]
    table = {
        n: {
            m: (1.0 + i + 0.6 * j, 0.5 + 1.0 * j, 10.0 * (j + 1), True)
            for j, m in enumerate(models_)
        }
        for i, n in enumerate(names)
    }
    return load_sweep(make_sweep(tmp_path, table=table))


# --------------------------------------------------------------------------- rank matrix


def test_rank_matrix_is_an_image_and_a_colour_bar_with_rows_in_material_order(tmp_path):
    mx = matrices(load_sweep(make_sweep(tmp_path)), "low_e2")
    fig = rank_matrix_figure(mx)
    assert len(fig.axes) == 2  # image and colour bar
    order = [mx.materials[i] for i in material_order(mx)]
    assert order != list(mx.materials)  # grouped by family, not in manifest order
    labels = [t.get_text() for t in fig.axes[0].get_yticklabels()]
    assert [t.split(": ")[1] for t in labels] == order


def test_rank_matrix_labels_stay_inside_the_canvas(long_labels):
    fig = rank_matrix_figure(matrices(long_labels, "low_e2"))
    assert _texts_outside(fig) == []
    cbar = fig.axes[1]
    label = cbar.yaxis.label.get_window_extent(FigureCanvasAgg(fig).get_renderer())
    assert label.height <= cbar.bbox.height  # the colour bar holds its label


# --------------------------------------------------------------------------- Pareto plot


def test_pareto_figure_has_two_panels_titled_with_the_materials_every_model_has(tmp_path):
    # c3: only a has a result there; the medians are over c1 and c2
    table = {
        "c1": {"a": (2.0, 0.1, 1.0, True), "b": (3.0, 0.2, 2.0, True)},
        "c2": {"a": (4.0, 0.1, 1.0, True), "b": (5.0, 0.2, 2.0, True)},
        "c3": {"a": (1000.0, 0.1, 1.0, True)},
    }
    fig = pareto_figure(error_vs_time(load_sweep(make_sweep(tmp_path, table=table)), "low_e2"))
    assert len(fig.axes) == 2  # error against wall time and against evaluation cost
    assert "the 2 materials every model has" in fig.get_suptitle()


def test_pareto_labels_stay_inside_the_canvas_and_apart(long_labels):
    assert _texts_outside(pareto_figure(error_vs_time(long_labels, "low_e2"))) == []

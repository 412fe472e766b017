"""The placement map (``map.png``) and the network map (``network.png``) are readable: no label
covers another label or a symbol, and the figure follows the view's aspect ratio, so little of
it is blank."""

from __future__ import annotations

import itertools
import json

import matplotlib
import matplotlib.image
import numpy as np
import pytest
from matplotlib.collections import PathCollection

from planner.outputs.plan_map import LABEL_PAD_PX, symbol_boxes
from tests.cli.invoke import run_cli

WIDE_BOUNDARY = ('{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": '
                 '{}, "geometry": {"type": "Polygon", "coordinates": [[[-20, -6], [20, -6], '
                 '[20, 6], [-20, 6], [-20, -6]]]}}]}')


@pytest.fixture
def figures(monkeypatch):
    """The figures the code under test closes, kept open for inspection."""
    import matplotlib.pyplot as plt

    kept = []
    monkeypatch.setattr(plt, "close", kept.append)
    yield kept
    monkeypatch.undo()
    for fig in kept:
        plt.close(fig)


def check_labels(fig, n_expected: int) -> None:
    """Labels (gid ``label``) overlap neither each other nor any scatter symbol."""
    ax = fig.axes[0]
    renderer = fig.canvas.get_renderer()
    labels = [t for t in ax.texts if t.get_gid() == "label"]
    assert len(labels) == n_expected
    boxes = [t.get_window_extent(renderer) for t in labels]
    for a, b in itertools.combinations(boxes, 2):
        assert not a.overlaps(b)
    symbols = [b for c in ax.collections if isinstance(c, PathCollection)
               for b in symbol_boxes(ax, c)]
    for box in boxes:
        for sym in symbols:
            assert not box.overlaps(sym.padded(-0.5 * LABEL_PAD_PX))


def blank_fraction(png) -> float:
    """Fraction of the image's pixels that are white (the map itself is hillshade).

    The default site's map is 24 % white; before the figure followed the view's aspect, the
    map of a 44 m x 16 m view was 70 % white (now 39 %)."""
    img = matplotlib.image.imread(png)[..., :3]
    return float(np.all(img > 0.99, axis=2).mean())


def axes_fraction(fig) -> float:
    """Area of the drawn (equal-aspect) axes over the figure's area."""
    renderer = fig.canvas.get_renderer()
    box = fig.axes[0].get_window_extent(renderer)
    return box.width * box.height / (fig.bbox.width * fig.bbox.height)


@pytest.mark.parametrize("wide", [False, True], ids=["default", "wide-site"])
def test_plan_map_labels_are_clear_and_the_figure_is_filled(wide, figures, tmp_path, capsys,
                                                             monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ["plan", "--out", "out"]
    if wide:
        (tmp_path / "wide.geojson").write_text(WIDE_BOUNDARY)
        args += ["--boundary", "wide.geojson", "--station-ids", "S1,S2,S5"]
    code, _, err = run_cli(capsys, args)
    assert code == 0, err
    fig = figures[-1]
    doc = json.loads((tmp_path / "out" / "plan.json").read_text())
    check_labels(fig, len(doc["stations"]) + doc["n_markers"])
    assert axes_fraction(fig) >= 0.5
    assert blank_fraction(tmp_path / "out" / "map.png") <= 0.45


def test_network_map_labels_are_clear_and_the_figure_is_filled(figures, tmp_path):
    from planner.network.files import write_network_files
    from tests.planner.test_network_report import hand_built

    write_network_files(tmp_path, hand_built())
    fig = figures[-1]
    check_labels(fig, 2 + 3)
    assert axes_fraction(fig) >= 0.6  # its background is white: no blank_fraction


def test_maps_are_byte_identical_on_a_second_run(tmp_path):
    from planner.network.files import write_network_files
    from tests.planner.test_network_report import hand_built

    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        write_network_files(tmp_path / name, hand_built())
    assert (tmp_path / "a" / "network.png").read_bytes() == \
        (tmp_path / "b" / "network.png").read_bytes()


def test_crowded_labels_move_out_with_a_leader_or_are_left_out():
    """Twenty labels on four close points: none overlaps, the far ones get a leader line, the
    rest are left out; the same call places them the same way."""
    import matplotlib.pyplot as plt

    from planner.outputs.plan_map import MARKER_LABEL_STYLE, place_labels

    placements = []
    for _ in range(2):
        fig, ax = plt.subplots(figsize=(3.0, 3.0), dpi=100)
        ax.set_xlim(0, 10)
        ax.set_ylim(0, 10)
        xy = np.array([[5.0, 5.0], [5.2, 5.0], [5.0, 5.2], [5.2, 5.2]])
        sc = ax.scatter(xy[:, 0], xy[:, 1], s=90)
        labels = [(f"C{k:05d}", xy[k % 4], MARKER_LABEL_STYLE) for k in range(20)]
        placed = place_labels(fig, ax, labels, [sc])
        check_labels(fig, len(placed))
        leaders = [t for t in ax.texts if t.get_gid() != "label"]
        assert 4 < len(placed) < 20 and leaders
        placements.append([(t.get_text(), t.xyann) for t in placed])
        plt.close(fig)
    assert placements[0] == placements[1]

"""Pure figure and scene functions of the report and the rerun recording."""

from __future__ import annotations

import numpy as np

from pipeline.models.jig import stepped_block
from pipeline.report.artefacts import residual_components
from pipeline.report.diagnosis import find_plots
from pipeline.report.figures import display, parameter_rows, rms
from pipeline.visualize import scene


def test_jig_blocks_of_the_stepped_block():
    mins, sizes = scene.jig_blocks(stepped_block())
    order = np.argsort(mins[:, 0])
    np.testing.assert_allclose(mins[order], [[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]])
    np.testing.assert_allclose(sizes[order], [[0.1, 0.2, 0.06], [0.1, 0.2, 0.1], [0.1, 0.2, 0.14]])


def test_face_outline_lies_on_its_plane():
    for f in stepped_block().faces:
        o = scene.face_outline(f)
        assert o.shape == (5, 3) and np.all(o[:, f.axis_index] == f.coordinate)
        np.testing.assert_array_equal(o[0], o[-1])


def test_touch_residual_vectors_and_decimation():
    v = scene.touch_residual_vectors(np.array([1e-3, -2e-3]), np.array([2, 0]))
    np.testing.assert_allclose(v, [[0, 0, -1e-3], [2e-3, 0, 0]])
    t = np.arange(0, 2_000_000_000, 4_000_000)  # 250 Hz for 2 s
    idx = scene.decimate(t, 5.0)
    assert idx.size == 10 and np.all(np.diff(t[idx]) == 200_000_000)
    assert list(scene.pick_poses(3, 5)) == [0, 1, 2] and len(scene.pick_poses(100, 5)) == 5


def test_parameter_rows_display_units():
    fit = {"names": ["a.x", "a.rz"], "units": ["m", "rad"], "nominal": [0.1, 0.0], "x": [0.1005, np.pi / 180],
           "std": [1e-5, 1e-4], "free": [True, False], "reasons": {"a.rz": "fixed by the user"}}
    rows = parameter_rows(fit)
    assert rows[0]["unit"] == "mm" and abs(rows[0]["change"] - 0.5) < 1e-9 and abs(rows[0]["std"] - 0.01) < 1e-12
    assert rows[1]["unit"] == "deg" and abs(rows[1]["estimate"] - 1.0) < 1e-12
    assert rows[1]["std"] is None and rows[1]["reason"] == "fixed by the user"
    assert display(0.002, "m") == (2.0, "mm") and display(3.0, "N") == (3.0, "N")


def test_residual_components_numeric_order_and_rms():
    res = {"before_10": 1, "before_2": 1, "before_0": 1, "before_x": 1, "after_0": 1}
    assert residual_components(res, "before") == ["before_0", "before_2", "before_10"]
    assert rms(np.array([3.0, np.nan, -3.0])) == 3.0 and rms(np.array([np.nan])) is None


def test_find_plots_in_any_diagnosis_layout():
    doc = {"findings": [{"effect": "backlash", "plot": {"x": [1, 2, 3], "before_m": [1e-4, 0, -1e-4],
                                                        "after_m": [0, 0, 0], "x_label": "dir J3"}}],
           "extra": {"series": {"r_m": [1, 2]}, "x": [0, 1]}, "not_a_plot": {"x": [1, 2], "y": [1]}}
    plots = find_plots(doc)
    assert [p.title for p in plots] == ["backlash", "diagnosis: extra"]
    assert set(plots[0].series) == {"before_m", "after_m"} and plots[0].lengths and plots[0].x_label == "dir J3"

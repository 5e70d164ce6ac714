"""Target declarations: geometry as OpenCV's boards define it, and one-line errors for bad strings."""

import numpy as np
import pytest

from pipeline.camera.targets import parse
from pipeline.errors import RobocalError


def test_chessboard_geometry():
    t = parse("chessboard:9x6:0.025")
    assert t.n_corners == 54 and t.pattern_size == (9, 6)
    np.testing.assert_allclose(t.points[10], [0.025, 0.025, 0.0])  # row 1, column 1
    np.testing.assert_allclose(t.points[-1], [8 * 0.025, 5 * 0.025, 0.0])


def test_charuco_and_grid_use_opencv_boards():
    c = parse("charuco:7x5:0.04:0.03:5X5_100")
    assert c.dictionary == "DICT_5X5_100" and c.n_corners == 6 * 4
    np.testing.assert_allclose(c.points, np.asarray(c.board.getChessboardCorners()).reshape(-1, 3))
    g = parse("aprilgrid:6x4:0.04:0.3")
    assert g.dictionary == "DICT_APRILTAG_36h11" and g.n_corners == 4 * 24
    # tag 1's first corner sits one tag plus one gap (0.3 × tag) to the right of tag 0's
    np.testing.assert_allclose(g.points[4] - g.points[0], [0.04 * 1.3, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("spec, words", [
    ("checkerboard:9x6:0.02", "expected chessboard"),
    ("chessboard:9by6:0.02", "is not COLSxROWS"),
    ("chessboard:9x6", "takes 3 fields"),
    ("chessboard:9x6:25", "not a plausible size"),
    ("chessboard:9x6:abc", "is not a number"),
    ("charuco:7x5:0.04:0.05:DICT_5X5_100", "must be smaller"),
    ("charuco:7x5:0.04:0.03:DICT_9X9_1", "unknown ArUco dictionary"),
    ("aprilgrid:6x4:0.04:5", "spacing ratio"),
])
def test_bad_declarations_are_one_line_errors(spec, words):
    with pytest.raises(RobocalError) as e:
        parse(spec)
    assert words in str(e.value) and "\n" not in str(e.value) and spec in str(e.value)

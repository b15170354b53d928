"""benchmarks/panda_camera_views.py: the cube's width from the pinhole projection of its corners agrees with the
width MuJoCo's renderer draws it (segmentation), in every camera where the cube is not hidden."""

import json
import sys
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytest.importorskip("gym_hil")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import panda_camera_views


def test_projected_width_matches_rendered_width(tmp_path):
    out = tmp_path / "views.png"
    assert panda_camera_views.main(["--task", "lift-cube", "--image-size", "96", "--out", str(out)]) == 0
    record = json.loads(out.with_suffix(".json").read_text())
    assert out.exists() and record["rows"][0]["placement"] == "centre"
    checked = 0
    for row in record["rows"]:
        for cam, c in row["cameras"].items():
            if c["corners_in_view"] == 8 and c["visible_px"] > 0.5 * c["width_px"] ** 2:
                # pixel-centre rasterisation: the drawn extent is the projected one, +-1 px at each side
                assert abs(c["visible_width_px"] - c["width_px"]) <= 2.0, (row["placement"], cam, c)
                checked += 1
    # the front camera sees the cube at every placement
    assert all(r["cameras"]["front"]["visible_px"] > 0 for r in record["rows"])
    assert checked >= 5

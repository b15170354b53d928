"""lerobot_rnd.embodiment: the embodiment's JSON round trip, validation against features, the preset registry.

References are independent of the code under test: hand-written feature dicts and JSON files.
"""

import json
import subprocess
import sys

import pytest

from lerobot_rnd.embodiment import (
    EMBODIMENT_FILE_IN_DATASET,
    Embodiment,
    load_embodiment,
    register_embodiment_preset,
)
from tests.helpers import REPO_ROOT, small_embodiment


def test_embodiment_json_round_trip(tmp_path):
    emb = small_embodiment()
    path = emb.save_json(tmp_path / EMBODIMENT_FILE_IN_DATASET)
    back = Embodiment.load_json(path)
    assert back.camera_mesh == emb.camera_mesh and back.action_adapter == emb.action_adapter
    assert back.to_dict() == json.loads(json.dumps(emb.to_dict()))
    assert load_embodiment(tmp_path).to_dict() == back.to_dict()  # dataset folder
    assert load_embodiment(str(path)).to_dict() == back.to_dict()
    with pytest.raises(FileNotFoundError, match="preset"):
        load_embodiment(tmp_path / "nothing.json")
    d = emb.ee_pose_dict()
    assert d["rotation"] == "quat_wxyz" and d["rotation_indices"] == [4, 5, 6, 7] and d["gripper_index"] == 3


def _policy_features(front=(3, 96, 128), wrist=(3, 96, 128), state=(8,), extra=None):
    from lerobot.configs.types import FeatureType, PolicyFeature

    feats = {
        "observation.images.front": PolicyFeature(FeatureType.VISUAL, front),
        "observation.images.wrist": PolicyFeature(FeatureType.VISUAL, wrist),
        "observation.state": PolicyFeature(FeatureType.STATE, state),
        "action": PolicyFeature(FeatureType.ACTION, (4,)),
    }
    if extra:
        feats[extra] = PolicyFeature(FeatureType.VISUAL, (3, 96, 128))
    return feats


def test_validate_against_features():
    emb = small_embodiment()
    emb.validate_against(_policy_features())
    dataset_feats = {
        "observation.images.front": {
            "dtype": "image",
            "shape": (96, 128, 3),
            "names": ["height", "width", "channels"],
        },
        "observation.images.wrist": {
            "dtype": "video",
            "shape": (96, 128, 3),
            "names": ["height", "width", "channels"],
        },
        "observation.state": {"dtype": "float32", "shape": (8,), "names": None},
    }
    emb.validate_against(dataset_feats)
    with pytest.raises(ValueError, match=r"resized\(64, 64\)"):
        emb.validate_against(_policy_features(front=(3, 64, 64)))
    emb.with_image_size(64, 64, keys=["observation.images.front"]).validate_against(
        _policy_features(front=(3, 64, 64))
    )
    with pytest.raises(ValueError, match="no camera calibration for image feature"):
        emb.validate_against(_policy_features(extra="observation.images.side"))
    emb.validate_against(_policy_features(extra="observation.images.side"), require_all_cameras=False)
    feats = _policy_features()
    del feats["observation.images.wrist"]
    with pytest.raises(ValueError, match="not a feature.*rename"):
        emb.validate_against(feats)
    with pytest.raises(ValueError, match="reads index 7"):
        emb.validate_against(_policy_features(state=(4,)))


def test_embodiment_validation():
    emb = small_embodiment()
    with pytest.raises(ValueError, match="is not a mesh"):
        Embodiment(emb.cameras, emb.meshes, camera_mesh={"observation.images.front": "palm"})
    with pytest.raises(ValueError, match="no calibration"):
        Embodiment(emb.cameras, emb.meshes, camera_mesh={"observation.images.side": "full"})
    with pytest.raises(ValueError, match="'type'"):
        Embodiment(emb.cameras, emb.meshes, action_adapter={"scale": 0.01})


def test_preset_registry(tmp_path, monkeypatch):
    monkeypatch.setattr("lerobot_rnd.embodiment.PRESET_MODULES", ())  # no simulator presets in this test
    monkeypatch.setattr("lerobot_rnd.embodiment.EMBODIMENT_PRESETS", {})
    from lerobot_rnd import embodiment

    def tiny():
        return small_embodiment()

    register_embodiment_preset("tiny", tiny)
    register_embodiment_preset("tiny", tiny)  # the same factory again: a no-op
    assert load_embodiment("tiny").to_dict() == small_embodiment().to_dict()
    with pytest.raises(ValueError, match="already registered"):
        register_embodiment_preset("tiny", lambda: small_embodiment())
    with pytest.raises(TypeError, match="callable"):
        register_embodiment_preset("bad", small_embodiment())
    with pytest.raises(FileNotFoundError, match=r"neither a preset \(tiny\)"):
        load_embodiment("tinny")
    assert embodiment.EMBODIMENT_PRESETS == {"tiny": tiny}


def test_simulator_presets_are_found_by_name_without_importing_the_simulators_first():
    """A user naming a simulator preset gets it (lerobot_rnd.sim is imported on demand); an unknown name lists
    the known ones. Fresh process: nothing has imported lerobot_rnd.sim yet."""
    code = (
        "import sys\n"
        "from lerobot_rnd.embodiment import EMBODIMENT_PRESETS, load_embodiment\n"
        "assert 'lerobot_rnd.sim' not in sys.modules and not EMBODIMENT_PRESETS\n"
        "try:\n"
        "    load_embodiment('metaworld_sawyr')\n"
        "except FileNotFoundError as e:\n"
        "    print(e)\n"
        "assert 'lerobot_rnd.sim' in sys.modules\n"
        "print(sorted(EMBODIMENT_PRESETS))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=REPO_ROOT
    )
    assert out.returncode == 0, out.stderr[-3000:]
    for name in ("metaworld_sawyer", "metaworld_sawyer_lerobot", "panda_robotiq"):
        assert name in out.stdout.splitlines()[0]  # the error message lists it
    assert "'metaworld_sawyer'" in out.stdout.splitlines()[-1]

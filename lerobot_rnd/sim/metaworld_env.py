"""MetaWorld (V3, Sawyer) as a gymnasium env for LeRobot with two fast 128x128 cameras and exact placement.

``gym.make("gym_rnd_metaworld/reach-v3")`` (registered by ``import lerobot_rnd.sim``), or
``lerobot-eval --env.type=rnd_mw --env.task=reach-v3``. The embodiment presets ``metaworld_sawyer`` (this env)
and ``metaworld_sawyer_lerobot`` (LeRobot's ``--env.type=metaworld``) are defined and registered here.

Observation (LeRobot's ``preprocess_observation`` maps it to ``observation.images.<cam>`` and
``observation.state``)::

    {"pixels": {"corner2": uint8 (H, W, 3), "behindGripper": uint8 (H, W, 3)},
     "agent_pos": float32 (8,) = [hand x, y, z (m, world), gripper opening, hand quat w, x, y, z]}

- hand xyz: position of MuJoCo body "hand" (= MetaWorld ``obs[:3]``, LeRobot's ``agent_pos[:3]``); the
  R&D EE frame is this body's frame (:data:`SAWYER_EE_BODY`).
- gripper opening: finger distance / 0.1 m clipped to [0, 1] (MetaWorld ``obs[3]``; 1 = open, about
  0.3 when closed on nothing).
- hand quaternion (wxyz, w >= 0): MetaWorld commands a fixed orientation (mocap quat [1, 0, 1, 0]) but
  the soft weld lets the hand tilt by a few degrees, so the true orientation is part of the state.

Action: MetaWorld's 4-D action: xyz in [-1, 1] moves the mocap target by 0.01 m per unit (world frame),
gripper in [-1 (open), 1 (close)].

Placement (object / goal positions, MetaWorld's ``rand_vec``): ``reset(options={"placement": vec})``
for an exact placement; otherwise ``placement="random"`` draws from the task's range with the env's
seeded RNG (``reset(seed=...)`` makes it reproducible) or ``placement="fixed"`` cycles through
``placements``. Vectors that MetaWorld would reject (object and goal too close, where its reset would
loop forever) are detected and resampled (random) or refused (explicit).
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from importlib.util import find_spec
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from lerobot.envs.configs import EnvConfig

from lerobot_rnd.arrays import mujoco_pose
from lerobot_rnd.embodiment import (
    CameraCalibration,
    EEPoseSource,
    Embodiment,
    GripperMesh,
    camera_from_mujoco,
    register_embodiment_preset,
)
from lerobot_rnd.sim.mujoco_env import (
    RnDMuJoCoEnv,
    RnDSimEnvConfig,
    default_headless_gl,
    register_gym_envs,
)

METAWORLD_V3_TASKS = (
    "assembly-v3", "basketball-v3", "bin-picking-v3", "box-close-v3", "button-press-topdown-v3",
    "button-press-topdown-wall-v3", "button-press-v3", "button-press-wall-v3", "coffee-button-v3",
    "coffee-pull-v3", "coffee-push-v3", "dial-turn-v3", "disassemble-v3", "door-close-v3", "door-lock-v3",
    "door-open-v3", "door-unlock-v3", "hand-insert-v3", "drawer-close-v3", "drawer-open-v3", "faucet-open-v3",
    "faucet-close-v3", "hammer-v3", "handle-press-side-v3", "handle-press-v3", "handle-pull-side-v3",
    "handle-pull-v3", "lever-pull-v3", "pick-place-wall-v3", "pick-out-of-hole-v3", "pick-place-v3",
    "plate-slide-v3", "plate-slide-side-v3", "plate-slide-back-v3", "plate-slide-back-side-v3",
    "peg-insert-side-v3", "peg-unplug-side-v3", "soccer-v3", "stick-push-v3", "stick-pull-v3", "push-v3",
    "push-wall-v3", "push-back-v3", "reach-v3", "reach-wall-v3", "shelf-place-v3", "sweep-into-v3",
    "sweep-v3", "window-open-v3", "window-close-v3",
)  # fmt: skip
logger = logging.getLogger(__name__)
GYM_NAMESPACE = "gym_rnd_metaworld"
DEFAULT_CAMERAS = ("corner2", "behindGripper")
STATE_NAMES = ["hand_x", "hand_y", "hand_z", "gripper_open", "hand_qw", "hand_qx", "hand_qy", "hand_qz"]
MOCAP_STATE_NAMES = ["mocap_x", "mocap_y", "mocap_z"]
STATE_LAYOUTS = {"pos_grip_quat": STATE_NAMES, "pos_grip_quat_mocap": STATE_NAMES + MOCAP_STATE_NAMES}
ACTION_NAMES = ["dx", "dy", "dz", "gripper"]
METAWORLD_FPS = 80  # frame_skip 5 x timestep 2.5 ms
MAX_PATH_LENGTH = 500  # MetaWorld refuses to step further

#: MetaWorld Sawyer EE frame: body "hand" (its position is MetaWorld's ``obs[:3]``, i.e. LeRobot's
#: ``agent_pos[:3]``; fingers point along its +x axis, the fingers open along its y axis).
SAWYER_EE_BODY = "hand"
#: corner2 position used by LeRobot's MetaWorld env (closer than MetaWorld's own, arXiv:2206.14244).
LEROBOT_CORNER2_POS = (0.75, 0.075, 0.7)
#: Nominal hand orientation (MetaWorld's fixed mocap quaternion [1, 0, 1, 0] normalised, wxyz).
SAWYER_HAND_QUAT_WXYZ = (math.sqrt(0.5), 0.0, math.sqrt(0.5), 0.0)


# --------------------------------------------------------------------------------------------------
# MetaWorld fixes and helpers
# --------------------------------------------------------------------------------------------------
_PATCHED = False


def patch_metaworld_for_mujoco() -> None:
    """Make metaworld 3.0.0 work with MuJoCo >= 3.4 / 4.x.

    metaworld 3.0.0 writes an 11-number weld ``eq_data`` row; newer MuJoCo rows have 12 numbers and the
    assignment fails ("could not broadcast input array from shape (11,) into shape (12,)"). This
    writes the same 11 numbers into the first 11 entries and keeps MuJoCo's value for the rest.
    Idempotent. Applied when this package builds a MetaWorld env, not on import: LeRobot's own
    ``--env.type=metaworld`` still fails with these versions (docs/CALIBRATION.md).
    """
    global _PATCHED
    if _PATCHED:
        return
    import metaworld.sawyer_xyz_env as sxe
    import mujoco

    def reset_mocap_welds(self) -> None:
        if self.model.nmocap > 0 and self.model.eq_data is not None:
            weld = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 5.0])
            for i in range(self.model.eq_data.shape[0]):
                if self.model.eq_type[i] == mujoco.mjtEq.mjEQ_WELD:
                    n = min(len(weld), self.model.eq_data.shape[1])
                    self.model.eq_data[i, :n] = weld[:n]

    sxe.SawyerMocapBase.reset_mocap_welds = reset_mocap_welds
    _PATCHED = True


@cache
def lerobot_metaworld_config() -> dict:
    """LeRobot's ``envs/metaworld_config.json`` (task descriptions, scripted policy names), or {}."""
    spec = find_spec("lerobot")
    if spec is not None and spec.submodule_search_locations:
        cfg = Path(next(iter(spec.submodule_search_locations))) / "envs" / "metaworld_config.json"
        if cfg.exists():
            return json.loads(cfg.read_text())
    return {}


def task_description(task: str) -> str:
    return lerobot_metaworld_config().get("TASK_DESCRIPTIONS", {}).get(task) or task


class PlacementRejected(ValueError):
    """MetaWorld's reset would loop forever on this placement (object and goal too close)."""


def _check_task(task: str) -> str:
    task = task.replace("metaworld-", "")
    if task not in METAWORLD_V3_TASKS:
        raise ValueError(f"unknown MetaWorld V3 task {task!r}; tasks: {', '.join(METAWORLD_V3_TASKS)}")
    return task


def make_metaworld_task_env(task: str):
    """The raw MetaWorld env for ``task`` with the goal observable (the scripted experts need it)."""
    task = _check_task(task)
    patch_metaworld_for_mujoco()
    from metaworld import env_dict

    cls = env_dict.ALL_V3_ENVIRONMENTS[task]
    env = cls()  # no render_mode: we render with our own fast renderer
    kwargs = dict(env_dict.ML1_args_kwargs[task]["kwargs"])
    kwargs.pop("task_id", None)
    env._set_task_called = True
    if env._partially_observable:
        env._partially_observable = False
        env.__dict__.pop("sawyer_observation_space", None)  # cached_property
    env._set_task_inner(**kwargs)
    env._freeze_rand_vec = True
    env._last_rand_vec = None
    return env


# --------------------------------------------------------------------------------------------------
# The env
# --------------------------------------------------------------------------------------------------
class RnDMetaWorldEnv(RnDMuJoCoEnv):
    """MetaWorld task with multi-camera pixels + EE state observations (see the module docstring).

    Args:
        task: MetaWorld V3 task name, e.g. "reach-v3".
        camera_names: MuJoCo cameras to observe ("corner2", "behindGripper", "corner", "corner3",
            "topview", "gripperPOV").
        flip_cameras: cameras whose images are turned by 180 degrees (as LeRobot does for corner2).
        corner2_pos: world position of corner2 (default: LeRobot's); None keeps MetaWorld's.
        episode_length: steps before truncation (<= 500).
        state_layout: "pos_grip_quat" (8-D, see the module docstring) or "pos_grip_quat_mocap" (+ mocap xyz).
        **settings: the other settings of :class:`~lerobot_rnd.sim.mujoco_env.RnDMuJoCoEnv` (image size,
            placements, rendering; ``fast_render``: ~7 ms per 128x128 camera on CPU).
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": METAWORLD_FPS}

    def __init__(
        self,
        task: str = "reach-v3",
        camera_names: Sequence[str] = DEFAULT_CAMERAS,
        flip_cameras: Sequence[str] = (),
        corner2_pos: Sequence[float] | None = LEROBOT_CORNER2_POS,
        episode_length: int = 300,
        state_layout: str = "pos_grip_quat",
        **settings: Any,
    ):
        super().__init__(
            camera_names=camera_names, flip_cameras=flip_cameras, episode_length=episode_length,
            max_episode_length=MAX_PATH_LENGTH, **settings,
        )  # fmt: skip
        import mujoco

        self.task = _check_task(task)
        self.task_description = task_description(self.task)
        if state_layout not in STATE_LAYOUTS:
            raise ValueError(f"state_layout must be one of {sorted(STATE_LAYOUTS)}, got {state_layout!r}")
        self.state_layout = state_layout
        self.state_names = list(STATE_LAYOUTS[state_layout])
        self.corner2_pos = None if corner2_pos is None else tuple(float(v) for v in corner2_pos)

        self._env = make_metaworld_task_env(self.task)
        self.model, self.data = self._env.model, self._env.data
        for cam in set(self.camera_names) | {self.render_camera}:
            if mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_CAMERA, cam) < 0:
                names = [self.model.camera(i).name for i in range(self.model.ncam)]
                raise ValueError(f"unknown MetaWorld camera {cam!r}; cameras: {names}")
        if self.corner2_pos is not None:
            self.model.cam_pos[mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_CAMERA, "corner2")] = (
                self.corner2_pos
            )
        if self.fast_render:
            self.model.vis.quality.offsamples = 0
        self._hand_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, SAWYER_EE_BODY)
        self._rclaw = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "rightclaw")
        self._lclaw = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "leftclaw")
        self._rand_calls = 0
        self._raw_obs: np.ndarray | None = None
        self._metaworld_info: dict = {}

        orig = self._env._get_state_rand_vec

        def guarded_rand_vec():  # MetaWorld re-calls this in a while loop until object/goal are apart
            self._rand_calls += 1
            if self._rand_calls > 8:
                raise PlacementRejected(
                    f"placement {self._env._last_rand_vec} rejected by {self.task}'s reset"
                )
            return orig()

        self._env._get_state_rand_vec = guarded_rand_vec
        self._setup_spaces(state_dim=len(self.state_names), action_dim=4)

    # ------------------------------------------------------------------ placements
    @property
    def placement_space(self) -> spaces.Box:
        """The task's placement (rand_vec) range."""
        return self._env._random_reset_space

    def is_valid_placement(self, placement: Sequence[float]) -> bool:
        """Whether MetaWorld's reset accepts the placement (object and goal far enough apart).

        A dry run of the task's ``reset_model`` without the 50 hand-settling steps (about 1 ms); the
        env must be reset again before stepping.
        """
        vec = np.asarray(placement, dtype=np.float64)
        self._check_placement_shape(vec)
        inner = self._env
        if getattr(inner, "init_tcp", None) is None:  # normally set by _reset_hand
            inner.init_tcp = inner.tcp_center
        inner._freeze_rand_vec = True
        inner._last_rand_vec = vec.copy()
        self._rand_calls = 0
        inner._reset_hand = lambda *a, **k: None  # instance attribute shadows the method
        try:
            inner.reset_model()
        except PlacementRejected:
            return False
        finally:
            del inner._reset_hand
            self._raw_obs = None  # force a real reset before stepping
        return True

    def _check_placement_shape(self, vec: np.ndarray) -> None:
        sp = self.placement_space
        if vec.shape != sp.low.shape:
            raise ValueError(
                f"{self.task}: placement must have {sp.low.shape[0]} numbers, got shape {vec.shape}"
            )

    def _reset_inner(self, vec: np.ndarray) -> np.ndarray:
        self._check_placement_shape(vec)
        self._env._freeze_rand_vec = True
        self._env._last_rand_vec = vec.copy()
        self._rand_calls = 0
        raw_obs, _ = self._env.reset()
        return raw_obs

    # ------------------------------------------------------------------ gym API
    def reset(self, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = options or {}
        explicit = options.get("placement")
        if explicit is not None:
            vec = np.asarray(explicit, dtype=np.float64)
            try:
                raw = self._reset_inner(vec)
            except PlacementRejected as e:
                raise ValueError(
                    f"{self.task}: MetaWorld rejects placement {vec.tolist()} (object and goal too close)"
                ) from e
        elif self.placement_mode == "fixed":
            vec = self._next_fixed_placement()
            raw = self._reset_inner(vec)
        else:
            for _ in range(1000):
                vec = self.sample_placement()
                try:
                    raw = self._reset_inner(vec)
                    break
                except PlacementRejected:
                    continue
            else:  # pragma: no cover
                raise RuntimeError(f"{self.task}: no valid placement found in 1000 draws")
        self._placement = vec.copy()
        self._raw_obs = raw
        self._metaworld_info = {}
        self._steps = 0
        obs = self._observation()
        return obs, {"is_success": False}

    def step(self, action):
        action = np.asarray(action, dtype=np.float32)
        if action.shape != (4,):
            raise ValueError(f"expected a (4,) action, got shape {action.shape}")
        if self._raw_obs is None:
            raise RuntimeError("call reset() before step()")
        raw, reward, _, _, info = self._env.step(np.clip(action, -1.0, 1.0))
        self._raw_obs = raw
        self._metaworld_info = dict(info)
        self._steps += 1
        is_success = bool(info.get("success", 0.0))
        terminated, truncated = self._episode_end(is_success)
        obs = self._observation()
        out_info = {"is_success": is_success, "task": self.task}
        return obs, float(reward), terminated, truncated, out_info

    def close(self):
        super().close()
        self._env.close()

    # ------------------------------------------------------------------ observations
    @property
    def raw_observation(self) -> np.ndarray:
        """MetaWorld's own 39-D observation (goal visible) for the scripted experts."""
        return self._raw_obs

    @property
    def tcp_center(self) -> np.ndarray:
        """World position (3,) of the gripper's centre between the finger pads, where MetaWorld measures reach."""
        return np.asarray(self._env.tcp_center, dtype=np.float64)

    @property
    def metaworld_info(self) -> dict:
        """MetaWorld's own info dict of the last step (``obj_to_target``, ``success``, ...; empty after reset)."""
        return self._metaworld_info

    @property
    def success_now(self) -> bool:
        return bool(self._env.evaluate_state(self._raw_obs, np.zeros(4, np.float32))[1]["success"])

    def state(self) -> np.ndarray:
        d = self.data
        pos = np.asarray(d.xpos[self._hand_id], dtype=np.float64)
        grip = np.clip(np.linalg.norm(d.xpos[self._rclaw] - d.xpos[self._lclaw]) / 0.1, 0.0, 1.0)
        q = np.asarray(d.xquat[self._hand_id], dtype=np.float64)
        q = q / np.linalg.norm(q)
        if q[0] < 0:
            q = -q
        parts = [pos, [grip], q]
        if self.state_layout == "pos_grip_quat_mocap":
            parts.append(self.mocap_pos())
        return np.concatenate(parts).astype(np.float32)

    def ee_pose(self) -> np.ndarray:
        """World-from-EE (body "hand") 4x4 pose."""
        return mujoco_pose(self.data.xmat[self._hand_id], self.data.xpos[self._hand_id])

    def mocap_pos(self) -> np.ndarray:
        """The mocap target position (what the xyz action moves)."""
        return np.asarray(self.data.mocap_pos[0], dtype=np.float64).copy()

    # ------------------------------------------------------------------ calibration
    def embodiment(self, max_faces: int = 1500) -> Embodiment:
        """The :class:`~lerobot_rnd.embodiment.Embodiment` matching this env's cameras and state."""
        return metaworld_sawyer_embodiment(
            self.camera_names, self.image_size, flipped=self.flip_cameras, max_faces=max_faces,
            model=self.model, data=self.data,
            notes=(
                f"{GYM_NAMESPACE}/{self.task}: cameras {list(self.camera_names)} at "
                f"{self.image_size[0]}x{self.image_size[1]}, flipped {list(self.flip_cameras)}, "
                f"corner2_pos {None if self.corner2_pos is None else list(self.corner2_pos)}; "
                f"state {self.state_names}; EE frame = body 'hand'"
            ),
        )  # fmt: skip


# --------------------------------------------------------------------------------------------------
# Embodiment presets
# --------------------------------------------------------------------------------------------------
def metaworld_xml_path(task: str = "reach-v3") -> str:
    """Path of a MetaWorld task's MJCF (all Sawyer tasks share the robot and cameras)."""
    import importlib.util

    spec = importlib.util.find_spec("metaworld")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("metaworld is not installed (pip install 'lerobot[metaworld]')")
    root = Path(next(iter(spec.submodule_search_locations))) / "assets" / "sawyer_xyz"
    name = "sawyer_" + task.replace("-", "_") + ".xml"
    path = root / name
    if not path.exists():
        path = root / "sawyer_reach_v3.xml"
    return str(path)


def sawyer_gripper_meshes(model=None, max_faces: int = 1500, texture: bool = False) -> dict[str, GripperMesh]:
    """MetaWorld Sawyer gripper meshes in the "hand" frame at the open gripper (qpos0).

    "full": body "right_hand" subtree (gripper base mesh, black flange cylinder, rail, finger pads);
    "fingers": the finger bodies "rightclaw" / "leftclaw" (their visible pads). Symmetry texture on
    the hand's y axis (the fingers' opening direction) with ``texture=True`` (the policy textures the
    meshes itself, so the stored meshes keep MuJoCo's colours).
    """
    import mujoco

    if model is None:
        default_headless_gl()
        model = mujoco.MjModel.from_xml_path(metaworld_xml_path())
    full = GripperMesh.from_mjcf_body(model, "right_hand", ee_body=SAWYER_EE_BODY, name="full")
    fingers = GripperMesh.concatenate(
        [
            GripperMesh.from_mjcf_body(model, "rightclaw", ee_body=SAWYER_EE_BODY),
            GripperMesh.from_mjcf_body(model, "leftclaw", ee_body=SAWYER_EE_BODY),
        ],
        name="fingers",
    )
    full = full.simplified(max_faces)
    fingers = fingers.simplified(max_faces)
    if texture:
        full, fingers = full.with_symmetry_texture(axis=1), fingers.with_symmetry_texture(axis=1)
    return {"full": full, "fingers": fingers}


def metaworld_ee_pose_source(state_layout: str = "pos_grip_quat") -> EEPoseSource:
    """EE pose source for the MetaWorld state vectors.

    "pos_grip_quat" (this package's ``gym_rnd_metaworld`` env, 8-D): [hand xyz, gripper opening,
    hand quat wxyz]; "pos_grip" (LeRobot's MetaWorld env, 4-D): [hand xyz, gripper opening] with the
    nominal fixed hand orientation. Gripper opening: finger distance / 0.1 m clipped to [0, 1]
    (1 = open; about 0.3 when closed on nothing).
    """
    if state_layout == "pos_grip_quat":
        return EEPoseSource(
            format="quat_wxyz", position_indices=[0, 1, 2], rotation_indices=[4, 5, 6, 7], gripper_index=3
        )
    if state_layout == "pos_grip":
        return EEPoseSource(
            format="none",
            position_indices=[0, 1, 2],
            fixed_rotation=list(SAWYER_HAND_QUAT_WXYZ),
            gripper_index=3,
        )
    raise ValueError(f"unknown MetaWorld state layout {state_layout!r} (pos_grip_quat | pos_grip)")


def sawyer_cameras_from_mujoco(
    model,
    data,
    camera_names: Sequence[str],
    image_size: tuple[int, int],
    flipped: bool | Sequence[str] = False,
    camera_keys: Mapping[str, str] | None = None,
) -> dict[str, CameraCalibration]:
    """Calibrations of MetaWorld cameras keyed by LeRobot feature key (``observation.images.<name>``).

    Cameras on the hand body ("behindGripper", "gripperPOV") are EE-mounted (mode "track": they follow
    the hand position with a fixed world orientation, ``ee_follow_rotation=False``, exact).
    """
    import mujoco

    flip_set = set(camera_names) if flipped is True else (set() if flipped is False else set(flipped))
    hand = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, SAWYER_EE_BODY)
    cams = {}
    for cname in camera_names:
        cid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, cname)
        if cid < 0:
            raise ValueError(f"unknown MetaWorld camera '{cname}'")
        bid = int(model.cam_bodyid[cid])
        moving = bid != 0 and int(model.body_weldid[bid]) != 0
        if moving and bid != hand:
            raise ValueError(f"camera '{cname}' moves with body '{model.body(bid).name}', not the hand")
        key = (camera_keys or {}).get(cname, f"observation.images.{cname}")
        cams[key] = camera_from_mujoco(
            model,
            data,
            cname,
            image_size,
            mounted_on_body=SAWYER_EE_BODY if moving else None,
            flipped=cname in flip_set,
            name=cname,
        )
    return cams


def metaworld_sawyer_embodiment(
    camera_names: Sequence[str] = ("corner2", "behindGripper"),
    image_size: tuple[int, int] = (128, 128),
    flipped: bool | Sequence[str] = False,
    corner2_pos: Sequence[float] | None = LEROBOT_CORNER2_POS,
    state_layout: str = "pos_grip_quat",
    camera_keys: Mapping[str, str] | None = None,
    max_faces: int = 1500,
    wrist_cameras: Sequence[str] = ("gripperPOV",),
    model=None,
    data=None,
    notes: str | None = None,
) -> Embodiment:
    """Embodiment of MetaWorld's Sawyer as rendered by ``lerobot_rnd.sim`` (defaults) or LeRobot.

    - This package's env (``gym_rnd_metaworld/<task>``): the defaults (corner2 moved to LeRobot's
      position, no flips, 8-D state); preset ``metaworld_sawyer``.
    - LeRobot's ``--env.type=metaworld`` (one 480x480 corner2 image turned by 180 degrees, key
      ``observation.image``, 4-D state): :func:`metaworld_sawyer_lerobot_embodiment`, preset
      ``metaworld_sawyer_lerobot``.
    ``corner2_pos=None`` keeps MetaWorld's own corner2 position. Cameras in ``wrist_cameras`` render
    only the fingers mesh; the others the full gripper. ``model`` / ``data``: an env's MuJoCo model and
    data to calibrate from (its cameras as they are; ``corner2_pos`` is then not applied).
    """
    import mujoco

    if model is None:
        default_headless_gl()
        model = mujoco.MjModel.from_xml_path(metaworld_xml_path())
        if corner2_pos is not None:
            model.cam_pos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "corner2")] = np.asarray(
                corner2_pos
            )
    if data is None:
        data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    cams = sawyer_cameras_from_mujoco(model, data, camera_names, image_size, flipped, camera_keys)
    meshes = sawyer_gripper_meshes(model, max_faces=max_faces)
    camera_mesh = {k: ("fingers" if c.name in wrist_cameras else "full") for k, c in cams.items()}
    return Embodiment(
        cameras=cams,
        meshes=meshes,
        camera_mesh=camera_mesh,
        ee_pose_source=metaworld_ee_pose_source(state_layout),
        action_adapter=metaworld_action_adapter(),
        symmetry_axis=1,
        name="metaworld_sawyer",
        notes=notes
        or (
            "MetaWorld Sawyer; EE frame = body 'hand' (fingers along +x, opening along y); "
            f"state layout {state_layout}; corner2_pos={None if corner2_pos is None else list(corner2_pos)}"
        ),
    )


def metaworld_sawyer_lerobot_embodiment() -> Embodiment:
    """Embodiment of LeRobot's own ``--env.type=metaworld``: one 480x480 corner2 image turned by 180 degrees
    (key ``observation.image``), 4-D state without the hand orientation."""
    return metaworld_sawyer_embodiment(
        ("corner2",), (480, 480), flipped=True, state_layout="pos_grip",
        camera_keys={"corner2": "observation.image"},
    )  # fmt: skip


def metaworld_action_adapter() -> dict[str, Any]:
    """Action adapter spec for MetaWorld's 4-D action (``lerobot_rnd.action_adapters``)."""
    return {"type": "ee_position_delta", "scale": 0.01, "clip": True, "clip_limit": 1.0}



register_embodiment_preset("metaworld_sawyer", metaworld_sawyer_embodiment)  # this env / lerobot-rnd-record
register_embodiment_preset("metaworld_sawyer_lerobot", metaworld_sawyer_lerobot_embodiment)


# --------------------------------------------------------------------------------------------------
# Gym registration and LeRobot EnvConfig
# --------------------------------------------------------------------------------------------------
register_gym_envs(GYM_NAMESPACE, METAWORLD_V3_TASKS, "lerobot_rnd.sim.metaworld_env:RnDMetaWorldEnv")


@EnvConfig.register_subclass("rnd_mw")
@dataclass
class RnDMetaWorldEnvConfig(RnDSimEnvConfig):
    """``--env.type=rnd_mw``: MetaWorld with the cameras and state R&D needs (lerobot_rnd.sim)."""

    task: str | None = "reach-v3"
    fps: int = METAWORLD_FPS
    episode_length: int = 300
    camera_names: list[str] = field(default_factory=lambda: list(DEFAULT_CAMERAS))
    flip_cameras: list[str] = field(default_factory=list)
    use_lerobot_corner2_pos: bool = True
    placements: list[list[float]] | None = None  # MetaWorld rand_vecs cycled through with placement="fixed"
    state_layout: str = "pos_grip_quat"

    gym_namespace: ClassVar[str] = GYM_NAMESPACE
    action_dim: ClassVar[int] = 4

    def state_dim(self) -> int:
        return len(STATE_LAYOUTS[self.state_layout])

    def __post_init__(self):
        if self.state_layout not in STATE_LAYOUTS:
            raise ValueError(
                f"state_layout must be one of {sorted(STATE_LAYOUTS)}, got {self.state_layout!r}"
            )
        super().__post_init__()

    @property
    def gym_kwargs(self) -> dict:
        return {
            **super().gym_kwargs,
            "flip_cameras": list(self.flip_cameras),
            "corner2_pos": LEROBOT_CORNER2_POS if self.use_lerobot_corner2_pos else None,
            "placements": self.placements,
            "state_layout": self.state_layout,
        }

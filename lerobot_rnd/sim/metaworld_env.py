"""MetaWorld (V3, Sawyer) as a gymnasium env for LeRobot with two fast 128x128 cameras and exact placement.

``gym.make("gym_rnd_metaworld/reach-v3")`` (registered by ``import lerobot_rnd.sim``), or
``lerobot-eval --env.type=rnd_mw --env.task=reach-v3``.

Observation (LeRobot's ``preprocess_observation`` maps it to ``observation.images.<cam>`` and
``observation.state``)::

    {"pixels": {"corner2": uint8 (H, W, 3), "behindGripper": uint8 (H, W, 3)},
     "agent_pos": float32 (8,) = [hand x, y, z (m, world), gripper opening, hand quat w, x, y, z]}

- hand xyz: position of MuJoCo body "hand" (= MetaWorld ``obs[:3]``, LeRobot's ``agent_pos[:3]``); the
  R&D EE frame is this body's frame (``lerobot_rnd.embodiment.SAWYER_EE_BODY``).
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
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib.util import find_spec
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

from lerobot_rnd.embodiment import LEROBOT_CORNER2_POS, SAWYER_EE_BODY

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


# --------------------------------------------------------------------------------------------------
# MetaWorld fixes and helpers
# --------------------------------------------------------------------------------------------------
_PATCHED = False


def patch_metaworld_for_mujoco() -> None:
    """Make metaworld 3.0.0 work with MuJoCo >= 3.4 / 4.x.

    metaworld 3.0.0 writes an 11-number weld ``eq_data`` row; newer MuJoCo rows have 12 numbers and the
    assignment fails ("could not broadcast input array from shape (11,) into shape (12,)"). This
    writes the same 11 numbers into the first 11 entries and keeps MuJoCo's value for the rest.
    Idempotent; also fixes LeRobot's own MetaWorld env once ``lerobot_rnd.sim`` is imported.
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


def task_description(task: str) -> str:
    spec = find_spec("lerobot")
    if spec is not None and spec.submodule_search_locations:
        cfg = Path(next(iter(spec.submodule_search_locations))) / "envs" / "metaworld_config.json"
        if cfg.exists():
            desc = json.loads(cfg.read_text()).get("TASK_DESCRIPTIONS", {}).get(task)
            if desc:
                return desc
    return task


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
class RnDMetaWorldEnv(gym.Env):
    """MetaWorld task with multi-camera pixels + EE state observations (see the module docstring).

    Args:
        task: MetaWorld V3 task name, e.g. "reach-v3".
        camera_names: MuJoCo cameras to observe ("corner2", "behindGripper", "corner", "corner3",
            "topview", "gripperPOV").
        observation_height, observation_width: image size.
        flip_cameras: cameras whose images are turned by 180 degrees (as LeRobot does for corner2).
        corner2_pos: world position of corner2 (default: LeRobot's); None keeps MetaWorld's.
        episode_length: steps before truncation (<= 500).
        placement: "random" (seeded, from the task's range) or "fixed" (cycle through ``placements``).
        placements: list of MetaWorld rand_vecs for "fixed".
        terminate_on_success: end the episode at the first success.
        fast_render: no multisampling, shadows or reflections (~7 ms per 128x128 camera on CPU).
        render_mode: "rgb_array"; ``render()`` returns the last observation's images side by side
            (no extra rendering), or a ``visualization_height`` x ``visualization_width`` render of
            ``render_camera`` when those are set.
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": METAWORLD_FPS}

    def __init__(
        self,
        task: str = "reach-v3",
        camera_names: Sequence[str] = DEFAULT_CAMERAS,
        observation_height: int = 128,
        observation_width: int = 128,
        flip_cameras: Sequence[str] = (),
        corner2_pos: Sequence[float] | None = LEROBOT_CORNER2_POS,
        episode_length: int = 300,
        placement: str = "random",
        placements: Sequence[Sequence[float]] | None = None,
        terminate_on_success: bool = True,
        fast_render: bool = True,
        render_mode: str | None = "rgb_array",
        render_camera: str | None = None,
        visualization_height: int | None = None,
        visualization_width: int | None = None,
        obs_type: str = "pixels_agent_pos",
        state_layout: str = "pos_grip_quat",
    ):
        super().__init__()
        import mujoco

        self.task = _check_task(task)
        self.task_description = task_description(self.task)
        if obs_type != "pixels_agent_pos":
            raise ValueError(f"obs_type must be 'pixels_agent_pos', got {obs_type!r}")
        self.obs_type = obs_type
        if state_layout not in STATE_LAYOUTS:
            raise ValueError(f"state_layout must be one of {sorted(STATE_LAYOUTS)}, got {state_layout!r}")
        self.state_layout = state_layout
        self.state_names = list(STATE_LAYOUTS[state_layout])
        self.camera_names = tuple(camera_names)
        if not self.camera_names:
            raise ValueError("camera_names is empty")
        self.image_size = (int(observation_height), int(observation_width))
        self.flip_cameras = tuple(flip_cameras)
        unknown_flip = set(self.flip_cameras) - set(self.camera_names)
        if unknown_flip:
            raise ValueError(
                f"flip_cameras {sorted(unknown_flip)} are not in camera_names {self.camera_names}"
            )
        self.corner2_pos = None if corner2_pos is None else tuple(float(v) for v in corner2_pos)
        if not 0 < int(episode_length) <= MAX_PATH_LENGTH:
            raise ValueError(f"episode_length must be in 1..{MAX_PATH_LENGTH}, got {episode_length}")
        self._max_episode_steps = int(episode_length)
        if placement not in ("random", "fixed"):
            raise ValueError(f"placement must be 'random' or 'fixed', got {placement!r}")
        self.placement_mode = placement
        self.placements = (
            None if placements is None else [np.asarray(p, dtype=np.float64) for p in placements]
        )
        if placement == "fixed" and not self.placements:
            raise ValueError("placement='fixed' needs a non-empty list of placements")
        self.terminate_on_success = bool(terminate_on_success)
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be 'rgb_array' or None, got {render_mode!r}")
        self.render_mode = render_mode
        self.render_camera = render_camera or self.camera_names[0]
        self.visualization_size = (
            None if visualization_height is None or visualization_width is None
            else (int(visualization_height), int(visualization_width))
        )  # fmt: skip

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
        self.fast_render = bool(fast_render)
        if self.fast_render:
            self.model.vis.quality.offsamples = 0
        self._hand_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, SAWYER_EE_BODY)
        self._rclaw = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "rightclaw")
        self._lclaw = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "leftclaw")
        self._renderers: dict[tuple[int, int], Any] = {}
        self._fixed_cursor = 0
        self._rand_calls = 0
        self._steps = 0
        self._raw_obs: np.ndarray | None = None
        self._last_pixels: dict[str, np.ndarray] | None = None
        self._placement: np.ndarray | None = None

        orig = self._env._get_state_rand_vec

        def guarded_rand_vec():  # MetaWorld re-calls this in a while loop until object/goal are apart
            self._rand_calls += 1
            if self._rand_calls > 8:
                raise PlacementRejected(
                    f"placement {self._env._last_rand_vec} rejected by {self.task}'s reset"
                )
            return orig()

        self._env._get_state_rand_vec = guarded_rand_vec

        H, W = self.image_size
        self.observation_space = spaces.Dict(
            {
                "pixels": spaces.Dict(
                    {c: spaces.Box(0, 255, shape=(H, W, 3), dtype=np.uint8) for c in self.camera_names}
                ),
                "agent_pos": spaces.Box(-np.inf, np.inf, shape=(len(self.state_names),), dtype=np.float32),
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)

    # ------------------------------------------------------------------ placements
    @property
    def placement_space(self) -> spaces.Box:
        """The task's placement (rand_vec) range."""
        return self._env._random_reset_space

    @property
    def placement(self) -> np.ndarray | None:
        """The current episode's placement (MetaWorld rand_vec)."""
        return None if self._placement is None else self._placement.copy()

    def sample_placement(self, rng: np.random.Generator | None = None) -> np.ndarray:
        """A uniform placement from the task's range (not checked; see :meth:`is_valid_placement`)."""
        rng = self.np_random if rng is None else rng
        sp = self.placement_space
        return rng.uniform(sp.low, sp.high).astype(np.float64)

    def is_valid_placement(self, placement: Sequence[float]) -> bool:
        """Whether MetaWorld's reset accepts the placement (object and goal far enough apart).

        A dry run of the task's ``reset_model`` without the 50 hand-settling steps (about 1 ms); the
        env must be reset again before stepping.
        """
        vec = np.asarray(placement, dtype=np.float64)
        sp = self.placement_space
        if vec.shape != sp.low.shape:
            raise ValueError(
                f"{self.task}: placement must have {sp.low.shape[0]} numbers, got shape {vec.shape}"
            )
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

    def _reset_inner(self, vec: np.ndarray) -> np.ndarray:
        sp = self.placement_space
        if vec.shape != sp.low.shape:
            raise ValueError(
                f"{self.task}: placement must have {sp.low.shape[0]} numbers, got shape {vec.shape}"
            )
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
            vec = self.placements[self._fixed_cursor % len(self.placements)]
            self._fixed_cursor += 1
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
        self._steps += 1
        is_success = bool(info.get("success", 0.0))
        terminated = is_success and self.terminate_on_success
        truncated = (not terminated) and self._steps >= self._max_episode_steps
        obs = self._observation()
        out_info = {"is_success": is_success, "task": self.task}
        return obs, float(reward), terminated, truncated, out_info

    def render(self):
        if self.render_mode is None:
            return None
        if self.visualization_size is None:
            if self._last_pixels is None:
                return np.zeros((*self.image_size, 3), dtype=np.uint8)
            return np.concatenate([self._last_pixels[c] for c in self.camera_names], axis=1)
        return self.render_camera_image(self.render_camera, self.visualization_size)

    def close(self):
        for r in self._renderers.values():
            try:
                r.close()
            except Exception as e:  # noqa: BLE001
                logger.debug("closing a MuJoCo renderer failed: %s", e)
        self._renderers.clear()
        self._env.close()

    # ------------------------------------------------------------------ observations
    @property
    def raw_observation(self) -> np.ndarray:
        """MetaWorld's own 39-D observation (goal visible) for the scripted experts."""
        return self._raw_obs

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

    def hand_pose(self) -> np.ndarray:
        """World-from-EE (body "hand") 4x4 pose."""
        T = np.eye(4)
        T[:3, :3] = np.asarray(self.data.xmat[self._hand_id]).reshape(3, 3)
        T[:3, 3] = self.data.xpos[self._hand_id]
        return T

    def mocap_pos(self) -> np.ndarray:
        """The mocap target position (what the xyz action moves)."""
        return np.asarray(self.data.mocap_pos[0], dtype=np.float64).copy()

    def _renderer(self, size: tuple[int, int]):
        r = self._renderers.get(size)
        if r is None:
            import mujoco

            r = mujoco.Renderer(self.model, height=size[0], width=size[1])
            if self.fast_render:
                r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
                r.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
            self._renderers[size] = r
        return r

    def render_camera_image(self, camera: str, size: tuple[int, int] | None = None) -> np.ndarray:
        """uint8 (H, W, 3) image of a MuJoCo camera (flipped if the camera is in ``flip_cameras``)."""
        r = self._renderer(tuple(size) if size is not None else self.image_size)
        r.update_scene(self.data, camera=camera)
        img = r.render()
        if camera in self.flip_cameras:
            img = np.ascontiguousarray(img[::-1, ::-1])
        return img

    def _observation(self) -> dict[str, Any]:
        pixels = {c: self.render_camera_image(c) for c in self.camera_names}
        self._last_pixels = pixels
        return {"pixels": pixels, "agent_pos": self.state()}

    # ------------------------------------------------------------------ calibration
    def embodiment(self, max_faces: int = 1500):
        """The :class:`~lerobot_rnd.embodiment.Embodiment` matching this env's cameras and state."""
        import mujoco

        from lerobot_rnd.embodiment import (
            Embodiment,
            metaworld_action_adapter,
            metaworld_ee_pose_source,
            sawyer_cameras_from_mujoco,
            sawyer_gripper_meshes,
        )

        mujoco.mj_forward(self.model, self.data)
        cams = sawyer_cameras_from_mujoco(
            self.model, self.data, self.camera_names, self.image_size, flipped=self.flip_cameras
        )
        meshes = sawyer_gripper_meshes(self.model, max_faces=max_faces)
        return Embodiment(
            cameras=cams,
            meshes=meshes,
            camera_mesh={k: ("fingers" if c.name == "gripperPOV" else "full") for k, c in cams.items()},
            ee_pose_source=metaworld_ee_pose_source("pos_grip_quat"),
            action_adapter=metaworld_action_adapter(),
            name="metaworld_sawyer",
            notes=(
                f"{GYM_NAMESPACE}/{self.task}: cameras {list(self.camera_names)} at "
                f"{self.image_size[0]}x{self.image_size[1]}, flipped {list(self.flip_cameras)}, "
                f"corner2_pos {None if self.corner2_pos is None else list(self.corner2_pos)}; "
                f"state {self.state_names}; EE frame = body 'hand'"
            ),
        )


def register_gym_envs() -> None:
    """Register ``gym_rnd_metaworld/<task>`` for every MetaWorld V3 task (idempotent)."""
    from gymnasium.envs.registration import registry

    for task in METAWORLD_V3_TASKS:
        env_id = f"{GYM_NAMESPACE}/{task}"
        if env_id not in registry:
            gym.register(
                id=env_id, entry_point="lerobot_rnd.sim.metaworld_env:RnDMetaWorldEnv", kwargs={"task": task}
            )


# --------------------------------------------------------------------------------------------------
# LeRobot EnvConfig
# --------------------------------------------------------------------------------------------------
@EnvConfig.register_subclass("rnd_mw")
@dataclass
class RnDMetaWorldEnvConfig(EnvConfig):
    """``--env.type=rnd_mw``: MetaWorld with the cameras and state R&D needs (lerobot_rnd.sim)."""

    task: str | None = "reach-v3"
    fps: int = METAWORLD_FPS
    episode_length: int = 300
    obs_type: str = "pixels_agent_pos"
    render_mode: str = "rgb_array"
    camera_names: list[str] = field(default_factory=lambda: list(DEFAULT_CAMERAS))
    observation_height: int = 128
    observation_width: int = 128
    flip_cameras: list[str] = field(default_factory=list)
    use_lerobot_corner2_pos: bool = True
    placement: str = "random"
    placements: list[list[float]] | None = None  # MetaWorld rand_vecs cycled through with placement="fixed"
    terminate_on_success: bool = True
    state_layout: str = "pos_grip_quat"
    features: dict[str, PolicyFeature] = field(
        default_factory=lambda: {ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(4,))}
    )
    features_map: dict[str, str] = field(default_factory=lambda: {ACTION: ACTION, "agent_pos": OBS_STATE})

    def __post_init__(self):
        if self.state_layout not in STATE_LAYOUTS:
            raise ValueError(
                f"state_layout must be one of {sorted(STATE_LAYOUTS)}, got {self.state_layout!r}"
            )
        self.features["agent_pos"] = PolicyFeature(
            type=FeatureType.STATE, shape=(len(STATE_LAYOUTS[self.state_layout]),)
        )
        for cam in self.camera_names:
            self.features[f"pixels/{cam}"] = PolicyFeature(
                type=FeatureType.VISUAL, shape=(self.observation_height, self.observation_width, 3)
            )
            self.features_map[f"pixels/{cam}"] = f"{OBS_IMAGES}.{cam}"

    @property
    def package_name(self) -> str:
        return "lerobot_rnd.sim"

    @property
    def gym_id(self) -> str:
        return f"{GYM_NAMESPACE}/{self.task}"

    @property
    def gym_kwargs(self) -> dict:
        return {
            "camera_names": list(self.camera_names),
            "observation_height": self.observation_height,
            "observation_width": self.observation_width,
            "flip_cameras": list(self.flip_cameras),
            "corner2_pos": LEROBOT_CORNER2_POS if self.use_lerobot_corner2_pos else None,
            "episode_length": self.episode_length,
            "placement": self.placement,
            "placements": self.placements,
            "terminate_on_success": self.terminate_on_success,
            "render_mode": self.render_mode,
            "obs_type": self.obs_type,
            "state_layout": self.state_layout,
        }

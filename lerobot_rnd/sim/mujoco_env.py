"""What this package's MuJoCo environments (MetaWorld, Panda) share: the gymnasium env base (camera pixels +
EE state observations, placements, episode ends, MuJoCo rendering), the LeRobot ``EnvConfig`` base, gym
registration and the headless OpenGL default.

Observation of every env (LeRobot's ``preprocess_observation`` maps it to ``observation.images.<cam>`` and
``observation.state``)::

    {"pixels": {<camera>: uint8 (H, W, 3), ...}, "agent_pos": float32 (D,)}
"""

from __future__ import annotations

import json
import logging
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

logger = logging.getLogger(__name__)


def default_headless_gl() -> None:
    """Pick ``MUJOCO_GL=egl`` on a machine without a display unless the user chose a backend.

    MuJoCo reads the variable when it is first imported: the envs call this before importing it. Set
    ``MUJOCO_GL=osmesa`` (or anything else) yourself to override."""
    if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"


def register_gym_envs(namespace: str, tasks: Sequence[str], entry_point: str) -> None:
    """Register ``<namespace>/<task>`` for every task with ``entry_point`` (idempotent).

    Without gymnasium's order-enforcing wrapper, so that ``gym.make`` returns the env itself and LeRobot's
    ``add_envs_task`` finds its ``task_description`` (a wrapper hides it: the policy would get ``task=""``)."""
    from gymnasium.envs.registration import registry

    for task in tasks:
        env_id = f"{namespace}/{task}"
        if env_id not in registry:
            gym.register(
                id=env_id, entry_point=entry_point, kwargs={"task": task}, order_enforce=False, disable_env_checker=True
            )


class RnDMuJoCoEnv(gym.Env):
    """Base of the MuJoCo envs: validated settings, spaces, placements, episode ends and camera rendering.

    Args (the settings every env takes; subclasses add their own):
        camera_names: cameras to observe (named as in the observation; see :meth:`mujoco_camera_name`).
        observation_height, observation_width: image size.
        episode_length: steps before truncation (at most ``max_episode_length`` when the subclass sets one).
        placement: "random" (seeded, from the task's range) or "fixed" (cycle through ``placements``).
        placements: list of placement vectors for "fixed".
        terminate_on_success: end the episode at the first success.
        fast_render: no multisampling, shadows or reflections.
        render_mode: "rgb_array"; ``render()`` returns the last observation's images side by side (no extra
            rendering), or a ``visualization_height`` x ``visualization_width`` render of ``render_camera``
            when those are set.
        obs_type: "pixels_agent_pos" (the only one).
        flip_cameras: cameras whose images are turned by 180 degrees.

    Subclasses call ``super().__init__(...)`` before importing MuJoCo (it picks the headless GL backend),
    build ``self.model`` / ``self.data``, call :meth:`_setup_spaces` and define ``state()``, ``ee_pose()``,
    ``reset()``, ``step()``, ``placement_space``, ``success_now`` and ``embodiment()``.
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(
        self,
        *,
        camera_names: Sequence[str],
        observation_height: int = 128,
        observation_width: int = 128,
        episode_length: int = 100,
        max_episode_length: int | None = None,
        placement: str = "random",
        placements: Sequence[Sequence[float]] | None = None,
        terminate_on_success: bool = True,
        fast_render: bool = True,
        render_mode: str | None = "rgb_array",
        render_camera: str | None = None,
        visualization_height: int | None = None,
        visualization_width: int | None = None,
        obs_type: str = "pixels_agent_pos",
        flip_cameras: Sequence[str] = (),
    ):
        super().__init__()
        default_headless_gl()
        self.model: Any = None
        self.data: Any = None
        self._renderers: dict[tuple[int, int], Any] = {}
        self._fixed_cursor = 0
        self._steps = 0
        self._last_pixels: dict[str, np.ndarray] | None = None
        self._placement: np.ndarray | None = None
        if obs_type != "pixels_agent_pos":
            raise ValueError(f"obs_type must be 'pixels_agent_pos', got {obs_type!r}")
        self.obs_type = obs_type
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
        if max_episode_length is not None and not 0 < int(episode_length) <= max_episode_length:
            raise ValueError(f"episode_length must be in 1..{max_episode_length}, got {episode_length}")
        if int(episode_length) <= 0:
            raise ValueError(f"episode_length must be positive, got {episode_length}")
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
        self.fast_render = bool(fast_render)

    def _setup_spaces(self, state_dim: int, action_dim: int) -> None:
        H, W = self.image_size
        self.observation_space = spaces.Dict(
            {
                "pixels": spaces.Dict(
                    {c: spaces.Box(0, 255, shape=(H, W, 3), dtype=np.uint8) for c in self.camera_names}
                ),
                "agent_pos": spaces.Box(-np.inf, np.inf, shape=(state_dim,), dtype=np.float32),
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=(action_dim,), dtype=np.float32)

    # ------------------------------------------------------------------ placements and episodes
    @property
    def placement_space(self) -> spaces.Box:
        """The task's placement range."""
        raise NotImplementedError

    @property
    def placement(self) -> np.ndarray | None:
        """The current episode's placement."""
        return None if self._placement is None else self._placement.copy()

    def sample_placement(self, rng: np.random.Generator | None = None) -> np.ndarray:
        """A uniform placement from the task's range (not checked; see ``is_valid_placement``)."""
        rng = self.np_random if rng is None else rng
        sp = self.placement_space
        return rng.uniform(sp.low, sp.high).astype(np.float64)

    def _next_fixed_placement(self) -> np.ndarray:
        """The next of ``placements`` (cycled) for ``placement="fixed"``."""
        vec = self.placements[self._fixed_cursor % len(self.placements)]
        self._fixed_cursor += 1
        return vec

    @property
    def steps(self) -> int:
        """Steps taken since the last reset."""
        return self._steps

    def _episode_end(self, is_success: bool) -> tuple[bool, bool]:
        """(terminated, truncated) after a step."""
        terminated = is_success and self.terminate_on_success
        return terminated, (not terminated) and self._steps >= self._max_episode_steps

    # ------------------------------------------------------------------ rendering
    def mujoco_camera_name(self, camera: str) -> str:
        """The model's name of an observed camera."""
        return camera

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
        """uint8 (H, W, 3) image of a camera (turned by 180 degrees if it is in ``flip_cameras``)."""
        r = self._renderer(tuple(size) if size is not None else self.image_size)
        r.update_scene(self.data, camera=self.mujoco_camera_name(camera))
        img = r.render()
        if camera in self.flip_cameras:
            img = np.ascontiguousarray(img[::-1, ::-1])
        return img

    def _observation(self) -> dict[str, Any]:
        pixels = {c: self.render_camera_image(c) for c in self.camera_names}
        self._last_pixels = pixels
        return {"pixels": pixels, "agent_pos": self.state()}

    def state(self) -> np.ndarray:
        """The ``agent_pos`` observation (D,) float32."""
        raise NotImplementedError

    def ee_pose(self) -> np.ndarray:
        """World-from-EE 4x4 pose (float64) of the R&D EE frame."""
        raise NotImplementedError

    def render(self):
        """The last observation's images side by side, or a ``visualization_height`` x ``visualization_width``
        render of ``render_camera`` when those are set."""
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


def task_of_checkpoint_in_argv(argv: list[str]) -> tuple[str | None, str | None]:
    """(task, checkpoint) when the command line names a local checkpoint (``--policy.path``) but no
    ``--env.task``, and the checkpoint's train_config.json records its env task; else (None, None)."""
    if any(a == "--env.task" or a.startswith("--env.task=") for a in argv):
        return None, None
    paths = [a.split("=", 1)[1] for a in argv if a.startswith("--policy.path=")]
    if not paths:
        return None, None
    train_config = Path(paths[-1]) / "train_config.json"
    try:
        task = (json.loads(train_config.read_text()).get("env") or {}).get("task")
    except (OSError, ValueError):
        return None, None
    return (task, paths[-1]) if isinstance(task, str) else (None, None)


@dataclass
class RnDSimEnvConfig(EnvConfig):
    """Fields and LeRobot feature mapping shared by ``--env.type=rnd_mw`` and ``rnd_panda`` (not an env type).

    Subclasses set ``gym_namespace`` and ``action_dim`` and define ``state_dim()``."""

    episode_length: int = 100
    obs_type: str = "pixels_agent_pos"
    render_mode: str = "rgb_array"
    camera_names: list[str] = field(default_factory=list)
    observation_height: int = 128
    observation_width: int = 128
    placement: str = "random"
    terminate_on_success: bool = True
    features_map: dict[str, str] = field(default_factory=lambda: {ACTION: ACTION, "agent_pos": OBS_STATE})

    gym_namespace: ClassVar[str] = ""
    action_dim: ClassVar[int] = 0

    def state_dim(self) -> int:
        raise NotImplementedError

    def __post_init__(self):
        trained_task, checkpoint = task_of_checkpoint_in_argv(sys.argv[1:])
        if trained_task is not None and trained_task != self.task:
            logging.getLogger(__name__).warning(
                "No --env.task given: evaluating on %r, the task the checkpoint %s was trained on (not the "
                "default %r). Pass --env.task to choose another.",
                trained_task, checkpoint, self.task,
            )  # fmt: skip
            self.task = trained_task
        self.features.setdefault(ACTION, PolicyFeature(type=FeatureType.ACTION, shape=(self.action_dim,)))
        self.features["agent_pos"] = PolicyFeature(type=FeatureType.STATE, shape=(self.state_dim(),))
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
        return f"{self.gym_namespace}/{self.task}"

    @property
    def gym_kwargs(self) -> dict:
        return {
            "camera_names": list(self.camera_names),
            "observation_height": self.observation_height,
            "observation_width": self.observation_width,
            "episode_length": self.episode_length,
            "placement": self.placement,
            "terminate_on_success": self.terminate_on_success,
            "render_mode": self.render_mode,
            "obs_type": self.obs_type,
        }

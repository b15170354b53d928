"""A tiny synthetic reaching task recorded as a LeRobot dataset: for the tests, the examples that run anywhere
(`examples/visualize_denoising.py`) and the benchmark scripts that need no simulator.

A two-finger box gripper (fixed orientation, tilted) moves towards a target in steps of at most 1 cm
(MetaWorld-style actions: xyz deltas / 0.01 m plus a gripper value). A static camera and a camera on the
end effector see a grey table, a red target blob and the gripper, drawn by plain NumPy projection of the
target (not by the renderer under test).
"""

from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from lerobot_rnd.arrays import look_at  # noqa: F401  (re-exported: scripts import it from here)
from lerobot_rnd.embodiment import (
    EMBODIMENT_FILE_IN_DATASET,
    CameraCalibration,
    EEPoseSource,
    Embodiment,
    GripperMesh,
)

IMAGE_SIZE = (64, 64)
FPS = 10
R_WORLD_EE = Rotation.from_euler("xyz", [180, 0, 20], degrees=True).as_matrix()  # pointing down, yawed


def toy_gripper() -> GripperMesh:
    palm = trimesh.creation.box(extents=(0.02, 0.08, 0.02))
    palm.apply_translation((0, 0, -0.04))
    left = trimesh.creation.box(extents=(0.015, 0.012, 0.05))
    left.apply_translation((0, 0.03, 0.0))
    right = trimesh.creation.box(extents=(0.015, 0.012, 0.05))
    right.apply_translation((0, -0.03, 0.0))
    return GripperMesh.from_trimesh(trimesh.util.concatenate([palm, left, right]), color=(0.7, 0.7, 0.7))


def toy_fingers() -> GripperMesh:
    left = trimesh.creation.box(extents=(0.015, 0.012, 0.05))
    left.apply_translation((0, 0.03, 0.0))
    right = trimesh.creation.box(extents=(0.015, 0.012, 0.05))
    right.apply_translation((0, -0.03, 0.0))
    return GripperMesh.from_trimesh(trimesh.util.concatenate([left, right]), color=(0.7, 0.7, 0.7))


def toy_embodiment(image_size=IMAGE_SIZE) -> Embodiment:
    h, w = image_size
    f = 0.9 * w
    K = [[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]
    T_ee_cam = np.eye(4)
    T_ee_cam[:3, 3] = (0.0, 0.0, -0.12)  # behind the palm, looking along the EE z axis (down)
    return Embodiment(
        cameras={
            "observation.images.front": CameraCalibration(
                "front", K, image_size, T_world_cam=look_at((0.55, 0.0, 0.45), (0.0, 0.0, 0.05))
            ),
            "observation.images.wrist": CameraCalibration("wrist", K, image_size, T_ee_cam=T_ee_cam),
        },
        meshes={"full": toy_gripper(), "fingers": toy_fingers()},
        camera_mesh={"observation.images.front": "full", "observation.images.wrist": "fingers"},
        ee_pose_source=EEPoseSource(
            format="none", position_indices=[0, 1, 2], fixed_rotation=R_WORLD_EE, gripper_index=3,
            gripper_open_value=1.0, gripper_closed_value=-1.0,
        ),
        action_adapter={"type": "ee_position_delta", "scale": 0.01},
        name="toy",
    )


RED, BLUE = (220, 30, 30), (30, 30, 220)


def _draw(embodiment: Embodiment, T_world_ee: np.ndarray, blobs) -> dict[str, np.ndarray]:
    """uint8 images (H, W, 3) per camera key: table colour and `blobs`, (world point (3,), colour, radius px) each,
    projected by NumPy; T_world_ee (4, 4) places the cameras mounted on the end effector."""
    out = {}
    for key, cam in embodiment.cameras.items():
        h, w = cam.image_size
        T_world_cam = cam.T_world_cam if cam.is_static else T_world_ee @ cam.T_ee_cam
        img = np.full((h, w, 3), (90, 110, 90), dtype=np.uint8)
        vv, uu = np.mgrid[0:h, 0:w]
        for point, colour, radius in blobs:
            p_cam = np.linalg.inv(T_world_cam) @ np.append(point, 1.0)
            if p_cam[2] <= 1e-3:
                continue
            u, v = (cam.K @ (p_cam[:3] / p_cam[2]))[:2]
            img[(uu - u) ** 2 + (vv - v) ** 2 <= radius**2] = colour
        out[key] = img
    return out


TOY_TASK = "reach the red target"


def record_toy_dataset(root: Path, n_episodes: int = 3, episode_len: int = 16, seed: int = 0,
                       repo_id: str = "local/toy_reach", tasks: tuple[str, ...] = (TOY_TASK,)):
    """Write a LeRobot v3 dataset with PNG images plus its embodiment JSON; returns its root.

    With several `tasks`, every drawn start and target is recorded once per task: the first task moves towards the
    target, every other one away from it (its deltas negated), so paired episodes start from identical observations
    and only the `task` string says which way to go."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    embodiment = toy_embodiment()
    h, w = IMAGE_SIZE
    features = {
        **{
            key: {"dtype": "image", "shape": (h, w, 3), "names": ["height", "width", "channels"]}
            for key in embodiment.cameras
        },
        "observation.state": {"dtype": "float32", "shape": (4,), "names": ["x", "y", "z", "gripper"]},
        "action": {"dtype": "float32", "shape": (4,), "names": ["dx", "dy", "dz", "gripper"]},
    }
    ds = LeRobotDataset.create(repo_id, fps=FPS, features=features, root=root, use_videos=False)
    rng = np.random.default_rng(seed)
    for _ in range(n_episodes):
        start = np.array([0.0, 0.0, 0.2]) + rng.uniform(-0.05, 0.05, 3)
        target = np.array([rng.uniform(-0.08, 0.08), rng.uniform(-0.08, 0.08), 0.06])
        for task_number, task in enumerate(tasks):
            direction = 1.0 if task_number == 0 else -1.0
            ee = start.copy()
            for t in range(episode_len):
                delta = direction * np.clip((target - ee) / 0.01, -1, 1) * 0.8
                grip = 1.0 if t >= episode_len // 2 else -1.0
                T_world_ee = np.eye(4)
                T_world_ee[:3, :3] = R_WORLD_EE
                T_world_ee[:3, 3] = ee
                images = _draw(embodiment, T_world_ee, [(target, RED, 3.0), (ee, BLUE, 2.0)])
                frame = {key: img for key, img in images.items()}
                frame["observation.state"] = np.append(ee, -grip).astype(np.float32)
                frame["action"] = np.append(delta, grip).astype(np.float32)
                frame["task"] = task
                ds.add_frame(frame)
                ee = ee + delta * 0.01
            ds.save_episode()
    ds.finalize()
    embodiment.save_json(Path(root) / EMBODIMENT_FILE_IN_DATASET)
    return Path(root)


def toy_so101_embodiment(image_size=IMAGE_SIZE) -> Embodiment:
    """The SO-101 embodiment (joint-space state and actions, FK pose source, joint_positions adapter) seen by a
    camera above the arm and one on its gripper (synthetic intrinsics and poses)."""
    from lerobot_rnd import so101

    h, w = image_size
    f = 0.9 * w
    K = [[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]
    T_ee_cam = np.eye(4)
    T_ee_cam[:3, 3] = (0.03, 0.0, -0.08)
    cameras = {
        "observation.images.front": CameraCalibration(
            "front", K, image_size, T_world_cam=look_at((0.55, 0.0, 0.45), (0.2, 0.0, 0.05))
        ),
        "observation.images.wrist": CameraCalibration("wrist", K, image_size, T_ee_cam=T_ee_cam),
    }
    return so101.so101_embodiment(cameras, camera_mesh={"observation.images.wrist": "fingers"}, name="toy_so101")


def record_toy_so101_dataset(root: Path, n_episodes: int = 3, episode_len: int = 16, seed: int = 0,
                             repo_id: str = "local/toy_so101"):
    """Write a LeRobot v3 dataset of an SO-101 moving its joints (LeRobot units: degrees, gripper 0-100) from a
    random start towards a random goal, 4 degrees per step at most, with its embodiment JSON; returns its root.
    The images show the goal's gripper position as a red blob (NumPy projection of its FK)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_rnd import so101

    embodiment = toy_so101_embodiment()
    h, w = IMAGE_SIZE
    names = list(so101.JOINT_NAMES)
    features = {
        **{
            key: {"dtype": "image", "shape": (h, w, 3), "names": ["height", "width", "channels"]}
            for key in embodiment.cameras
        },
        "observation.state": {"dtype": "float32", "shape": (6,), "names": names},
        "action": {"dtype": "float32", "shape": (6,), "names": names},
    }
    ds = LeRobotDataset.create(repo_id, fps=FPS, features=features, root=root, use_videos=False)
    rng = np.random.default_rng(seed)
    centre = np.array([0.0, -20.0, 20.0, 60.0, 0.0])  # degrees: the gripper above the table in front of the base
    for _ in range(n_episodes):
        q = centre + rng.uniform(-10, 10, 5)
        goal = centre + rng.uniform(-25, 25, 5)
        T_goal = so101.forward_kinematics(np.append(goal, 50.0)).numpy()
        for t in range(episode_len):
            step = np.clip(goal - q, -4.0, 4.0)
            grip = 10.0 if t >= episode_len // 2 else 90.0  # closes half-way
            T_world_ee = so101.forward_kinematics(np.append(q, 90.0)).numpy()
            frame = _draw(embodiment, T_world_ee, [(T_goal[:3, 3], RED, 3.0)])
            frame["observation.state"] = np.append(q, 90.0 if t <= episode_len // 2 else 10.0).astype(np.float32)
            frame["action"] = np.append(q + step, grip).astype(np.float32)
            frame["task"] = "move to the goal"
            ds.add_frame(frame)
            q = q + step
        ds.save_episode()
    ds.finalize()
    embodiment.save_json(Path(root) / EMBODIMENT_FILE_IN_DATASET)
    return Path(root)

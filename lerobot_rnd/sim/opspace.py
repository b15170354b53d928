"""Operational-space controller of the Panda suite: a port of gym-hil's ``gym_hil.controllers.opspace`` that
also runs on MuJoCo 4 (where ``MjData.qM`` is gone)."""

from __future__ import annotations

import math

import numpy as np

from lerobot_rnd.sim.quaternions import matrix_to_quat, quat_mul


def full_inertia(model, data, out: np.ndarray) -> np.ndarray:
    """Dense joint-space inertia matrix (MuJoCo >= 3.5 / 4: ``mj_fullM(m, d, dst)``; older:
    ``mj_fullM(m, dst, d.qM)``)."""
    import mujoco

    if hasattr(data, "qM"):
        mujoco.mj_fullM(model, out, data.qM)
    else:
        mujoco.mj_fullM(model, data, out)
    return out


def _quat_err_axisangle(quat: np.ndarray, quat_des: np.ndarray) -> np.ndarray:
    """Rotation vector of quat * quat_des^-1 (gym-hil's ``quat_to_axisangle(quat_diff_active(...))``)."""
    conj = np.array([quat_des[0], -quat_des[1], -quat_des[2], -quat_des[3]])
    qe = quat_mul(quat, conj)
    n = np.linalg.norm(qe)
    if n < 1e-10:
        return np.zeros(3)
    qe = qe / n
    angle = 2.0 * math.acos(min(1.0, max(-1.0, qe[0])))
    s = math.sqrt(max(0.0, 1.0 - qe[0] * qe[0]))
    if s < 1e-10:
        return angle * qe[1:]
    return angle * qe[1:] / s


def opspace(
    model,
    data,
    site_id: int,
    dof_ids: np.ndarray,
    pos: np.ndarray | None = None,
    ori: np.ndarray | None = None,
    joint: np.ndarray | None = None,
    pos_gains=(200.0, 200.0, 200.0),
    ori_gains=(200.0, 200.0, 200.0),
    damping_ratio: float = 1.0,
    nullspace_stiffness: float = 0.5,
    max_pos_acceleration: float | None = None,
    max_ori_acceleration: float | None = None,
    gravity_comp: bool = True,
    _buffers: dict | None = None,
) -> np.ndarray:
    """Joint torques of gym-hil's operational-space controller (``gym_hil.controllers.opspace.opspace``:
    same signature, gains and equations: task-space PD on the site pose, critically damped, null-space PD
    towards ``joint``, gravity compensation), for MuJoCo 3 and 4 (gym-hil 0.1.14 reads ``data.qM``,
    which MuJoCo 4 removed). ``ori``: wxyz quaternion or 3x3 matrix."""
    import mujoco

    dof_ids = np.asarray(dof_ids)
    x_des = data.site_xpos[site_id] if pos is None else np.asarray(pos)
    if ori is None:
        quat_des = matrix_to_quat(data.site_xmat[site_id])
    else:
        ori = np.asarray(ori, dtype=np.float64)
        quat_des = matrix_to_quat(ori) if ori.shape == (3, 3) else ori
    q_des = data.qpos[dof_ids] if joint is None else np.asarray(joint)
    kp_p = np.asarray(pos_gains, dtype=np.float64)
    kd_p = damping_ratio * 2 * np.sqrt(kp_p)
    kp_o = np.asarray(ori_gains, dtype=np.float64)
    kd_o = damping_ratio * 2 * np.sqrt(kp_o)
    kp_j = nullspace_stiffness
    kd_j = damping_ratio * 2 * math.sqrt(nullspace_stiffness)
    b = _buffers if _buffers is not None else {}
    if "Jv" not in b:
        b["Jv"], b["Jw"] = np.zeros((3, model.nv)), np.zeros((3, model.nv))
        b["M"], b["ix"] = np.zeros((model.nv, model.nv)), np.ix_(dof_ids, dof_ids)

    q, dq = data.qpos[dof_ids], data.qvel[dof_ids]
    mujoco.mj_jacSite(model, data, b["Jv"], b["Jw"], site_id)
    J_v, J_w = b["Jv"][:, dof_ids], b["Jw"][:, dof_ids]
    J = np.concatenate([J_v, J_w], axis=0)
    ddx = -kp_p * (data.site_xpos[site_id] - x_des)
    if max_pos_acceleration and np.linalg.norm(ddx) > max_pos_acceleration:
        ddx *= max_pos_acceleration / np.linalg.norm(ddx)
    ddx -= kd_p * (J_v @ dq)
    cur = matrix_to_quat(data.site_xmat[site_id])
    if cur @ quat_des < 0.0:
        cur = -cur
    dw = -kp_o * _quat_err_axisangle(cur, quat_des)
    if max_ori_acceleration and np.linalg.norm(dw) > max_ori_acceleration:
        dw *= max_ori_acceleration / np.linalg.norm(dw)
    dw -= kd_o * (J_w @ dq)
    M = full_inertia(model, data, b["M"])[b["ix"]]
    M_inv = np.linalg.inv(M)
    Mx_inv = J @ M_inv @ J.T
    Mx = np.linalg.inv(Mx_inv) if abs(np.linalg.det(Mx_inv)) >= 1e-2 else np.linalg.pinv(Mx_inv, rcond=1e-2)
    tau = J.T @ Mx @ np.concatenate([ddx, dw])
    ddq = -kp_j * (q - q_des) - kd_j * dq
    Jnull = M_inv @ J.T @ Mx
    tau += (np.eye(len(dof_ids)) - J.T @ Jnull.T) @ ddq
    if gravity_comp:
        tau += data.qfrc_bias[dof_ids]
    return tau


class OpSpaceController:
    """:func:`opspace` with gym-hil's default gains for one site, null-space target ``home``."""

    def __init__(self, model, site_id: int, dof_ids: np.ndarray, home: np.ndarray):
        self.model, self.site_id = model, int(site_id)
        self.dof_ids, self.home = np.asarray(dof_ids), np.asarray(home, dtype=np.float64)
        self._buffers: dict = {}

    def torques(self, data, pos: np.ndarray, quat: np.ndarray) -> np.ndarray:
        return opspace(
            self.model, data, self.site_id, self.dof_ids, pos=pos, ori=quat, joint=self.home,
            _buffers=self._buffers,
        )  # fmt: skip

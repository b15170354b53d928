"""lerobot_rnd.embodiment_binding: the embodiment as the policy's config fields and buffers.

Reference: the geometry of the mesh buffers themselves (which side of the symmetry plane each vertex lies on).
"""

import numpy as np
import pytest
import torch

from tests.helpers import make_policy
from lerobot_rnd.testing import toy_embodiment


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_mesh_buffers_are_textured_about_the_embodiments_symmetry_axis(toy_dataset_root, tmp_path, axis):
    emb = toy_embodiment()
    emb.symmetry_axis = axis
    path = emb.save_json(tmp_path / "embodiment.json")
    policy, _ = make_policy(toy_dataset_root, embodiment=str(path))
    meshes = policy.model.meshes
    # red on the positive side, blue on the negative (the paper's figures)
    side_pos, side_neg = torch.tensor([1.0, 0.1, 0.1]), torch.tensor([0.1, 0.3, 1.0])
    for i in range(meshes.vertices.shape[0]):  # "full", "fingers"
        used = torch.unique(meshes.faces[i][meshes.face_valid[i]])
        v, c = meshes.vertices[i][used], meshes.colors_textured[i][used]
        coord = v[:, axis]
        pos, neg = coord > 1e-6, coord < -1e-6
        # the toy gripper lies on both sides of every axis-aligned plane through the EE origin
        assert pos.any() and neg.any()
        torch.testing.assert_close(c[pos], side_pos.expand_as(c[pos]))
        torch.testing.assert_close(c[neg], side_neg.expand_as(c[neg]))
        # faces never straddle the plane: each is one colour
        f = meshes.faces[i][meshes.face_valid[i]]
        face_colors = meshes.colors_textured[i][f]
        assert np.allclose((face_colors.amax(1) - face_colors.amin(1)).numpy(), 0.0)

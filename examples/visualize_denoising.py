#!/usr/bin/env python
"""Show how R&D denoises an action chunk as gripper renders in the camera images (like the paper's Figure 8).

Loads a policy (``--policy-path`` of a saved checkpoint, e.g. ``outputs/train/.../pretrained_model``; without
it an untrained tiny R&D is built on the toy embodiment of ``lerobot_rnd/testing.py`` so the script runs anywhere),
takes one observation (frame ``--frame`` of a LeRobot dataset given by ``--dataset-root``/``--repo-id``, or of
the toy dataset generated on the fly), runs the sampler ``RnDModel.denoise(..., record=[])`` and writes

* a PNG strip (``--out``, default ``outputs/denoising.png``): one row per camera; columns are the network
  input of the current frame (gripper rendered at the current end-effector pose), then every denoising pass
  (4 DDIM steps + the final action-space pass by default), then the output chunk and, when the frame has
  actions, the demonstration's chunk. In each denoising cell all T future gripper renders are drawn over the
  current image, coloured from early (t+1, dark) to late (t+T, bright) (``--style overlay``), or with the
  renderer's own symmetry texture and a coloured outline (``--style textured``);
* optionally a video (``--video outputs/denoising.mp4`` or ``.gif``): one frame per column of the strip,
  cameras side by side.

    python examples/visualize_denoising.py                                  # untrained toy policy
    python examples/visualize_denoising.py \\
        --policy-path outputs/train/<run>/checkpoints/last/pretrained_model \\
        --dataset-root data/<dataset> --repo-id local/<dataset> --frame 20 --video outputs/denoising.mp4
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np
import torch
from PIL import Image, ImageDraw, ImageFont

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))

from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

TOY_REPO_ID = "local/toy_reach"
BG = (255, 255, 255)
FG = (20, 20, 20)


# ----------------------------------------------------------------------------------------------------------
# Policy and observation.
def build_toy_policy(dataset_root: Path, seed: int):
    """An untrained tiny R&D-AI on the toy embodiment, with target statistics fitted on the toy dataset."""
    from lerobot.configs.types import FeatureType
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.datasets.utils import dataset_to_policy_features

    from lerobot_rnd.configuration_rnd import RnDConfig
    from lerobot_rnd.modeling_rnd import RnDPolicy

    torch.manual_seed(seed)
    meta = LeRobotDatasetMetadata(TOY_REPO_ID, root=dataset_root)
    feats = dataset_to_policy_features(meta.features)
    cfg = RnDConfig(
        device="cpu",
        dim_model=64,
        n_layers=2,
        n_heads=4,
        image_size=(64, 64),
        chunk_size=8,
        n_action_steps=8,
        stats_num_samples=64,
    )
    cfg.output_features = {k: f for k, f in feats.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in feats.items() if k not in cfg.output_features}
    return RnDPolicy(cfg, dataset_meta=meta)


def load_frame(policy, root: Path, repo_id: str, index: int) -> dict:
    """One dataset item with the policy's observation history and action chunk, batched (B = 1)."""
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    meta = LeRobotDatasetMetadata(repo_id, root=root)
    missing = [k for k in policy.config.image_features if k not in meta.features]
    if missing:
        raise SystemExit(
            f"The dataset {root} has no {missing} (cameras: "
            f"{[k for k in meta.features if k.startswith(OBS_IMAGES)]}): pass the dataset the policy was "
            "trained on "
            "with --dataset-root/--repo-id."
        )
    ds = LeRobotDataset(repo_id, root=root, delta_timestamps=resolve_delta_timestamps(policy.config, meta))
    if not 0 <= index < len(ds):
        raise SystemExit(f"--frame {index} is outside the dataset's {len(ds)} frames.")
    item = ds[index]
    return {k: v[None] for k, v in item.items() if isinstance(v, torch.Tensor)}


@torch.no_grad()
def run_sampler(policy, batch: dict, seed: int) -> dict:
    """Denoise one chunk, recording the composite network inputs of every pass."""
    model = policy.model
    cfg = policy.config
    device = next(model.parameters()).device
    batch = {k: v.to(device) for k, v in batch.items()}
    stacked = policy._stack_images(batch)
    images, state = stacked[OBS_IMAGES], stacked[OBS_STATE]
    if images.ndim == 5:  # no history in the batch
        images = images[:, None].expand(-1, cfg.n_obs_steps, -1, -1, -1, -1)
        state = state[:, None].expand(-1, cfg.n_obs_steps, -1)
    images, T_world_ee, gripper = model.prepare_observation(images, state)
    noise = torch.randn(1, cfg.chunk_size, model.action_dim, generator=torch.Generator().manual_seed(seed)).to(device)
    record: list = []
    a0, logits = model.denoise(images, T_world_ee, gripper, noise, record=record, state_now=state[:, -1])

    def composite_for(T_ee_target):
        return model._network_inputs(images, T_world_ee, gripper, T_ee_target, full_composite=True)["composite"]

    out = {
        "images": images,
        "record": record,
        "output": composite_for(model.diffusion_space(state[:, -1]).to_pose(a0)),
        "a0": a0,
        "gripper_logits": logits,
        "demo": None,
    }
    if ACTION in batch and batch[ACTION].ndim == 3 and batch[ACTION].shape[1] == cfg.chunk_size:
        T_ee_target, _ = model.action_adapter.to_rnd(
            batch[ACTION].float(), T_world_ee[:, -1], state=state[:, -1]
        )
        out["demo"] = composite_for(T_ee_target)
    return out


# ----------------------------------------------------------------------------------------------------------
# Drawing.
def step_colors(t: int) -> np.ndarray:
    """(T, 3) colours in [0, 1] from early (dark purple) to late (yellow)."""
    try:
        from matplotlib import colormaps

        return np.asarray(colormaps["plasma"](np.linspace(0.05, 0.9, t)))[:, :3]
    except Exception:  # noqa: BLE001 - matplotlib is optional
        s = np.linspace(0, 1, t)[:, None]
        return (1 - s) * np.array([0.25, 0.0, 0.55]) + s * np.array([1.0, 0.85, 0.1])


def upscale(x: np.ndarray, s: int) -> np.ndarray:
    return np.repeat(np.repeat(x, s, axis=0), s, axis=1)


def outline(mask: np.ndarray, width: int) -> np.ndarray:
    """Pixels of `mask` within `width` pixels of its border (mask is already upscaled)."""
    inner = mask.copy()
    for _ in range(width):
        shrunk = inner.copy()
        shrunk[1:] &= inner[:-1]
        shrunk[:-1] &= inner[1:]
        shrunk[:, 1:] &= inner[:, :-1]
        shrunk[:, :-1] &= inner[:, 1:]
        inner = shrunk
    return mask & ~inner


def to_hwc(x: torch.Tensor) -> np.ndarray:
    return x.detach().float().clamp(0, 1).permute(1, 2, 0).cpu().numpy()


def future_cell(composites: torch.Tensor, current: torch.Tensor, scale: int, style: str) -> np.ndarray:
    """All T future renders of one camera over its current image.

    composites: (T, 3, h, w) network inputs of the future frames; current: (3, h, w) the camera image.
    The render masks are where a composite differs from the camera image
    (composite = where(mask, render, image)).
    """
    t = composites.shape[0]
    base = upscale(to_hwc(current), scale)
    base = 0.35 + 0.65 * base  # lighten the scene so the renders stand out
    colors = step_colors(t)
    width = max(1, scale // 3)
    out = base.copy()
    for j in reversed(range(t)):  # late first: the early steps end up on top
        comp = composites[j]
        mask = ((comp - current).abs().sum(0) > 1e-6).cpu().numpy()
        if not mask.any():
            continue
        m = upscale(mask, scale)
        rgb = upscale(to_hwc(comp), scale)
        if style == "overlay":
            out[m] = 0.4 * rgb[m] + 0.6 * colors[j]
        else:
            out[m] = rgb[m]
        out[outline(m, width)] = colors[j]
    return out


def current_cell(composite: torch.Tensor, current: torch.Tensor, scale: int) -> np.ndarray:
    """The network input of the current frame (gripper rendered at the current EE pose), scene lightened."""
    mask = upscale(((composite - current).abs().sum(0) > 1e-6).cpu().numpy(), scale)
    out = 0.35 + 0.65 * upscale(to_hwc(current), scale)
    out[mask] = upscale(to_hwc(composite), scale)[mask]
    return out


def get_font(size: int):
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1
        return ImageFont.load_default()


def build_columns(res: dict, policy, scale: int, style: str) -> list[tuple[str, str, list[np.ndarray]]]:
    """[(title, subtitle, [cell per camera])] in display order."""
    cfg = policy.config
    model = policy.model
    n_obs = cfg.n_obs_steps
    images = res["images"][0]  # (H, C, 3, h, w)
    current = images[-1]
    cams = range(current.shape[0])
    record = res["record"]
    columns = [
        (
            "observation",
            "current EE render",
            [current_cell(record[0][0, n_obs - 1, c], current[c], scale) for c in cams],
        )
    ]
    timesteps = list(model.inference_timesteps)
    n_ddim = len(timesteps)
    for i, comp in enumerate(record):
        fut = comp[0, n_obs:]  # (T, C, 3, h, w)
        if i < n_ddim:
            title, sub = f"DDIM step {i + 1}/{n_ddim}", f"input at k = {timesteps[i]}"
        else:
            title, sub = "final pass", "input at k = 0"
        columns.append((title, sub, [future_cell(fut[:, c], current[c], scale, style) for c in cams]))
    columns.append(
        (
            "output a0",
            "predicted chunk",
            [future_cell(res["output"][0, n_obs:, c], current[c], scale, style) for c in cams],
        )
    )
    if res["demo"] is not None:
        columns.append(
            (
                "demonstration",
                "dataset actions",
                [future_cell(res["demo"][0, n_obs:, c], current[c], scale, style) for c in cams],
            )
        )
    return columns


LEGEND_NOTE = "(t+1 = first action of the chunk, drawn on top)"


def draw_strip(
    columns,
    camera_names: list[str],
    t: int,
    cell: int,
    title: str,
    label_w: int | None = None,
    note: bool = True,
) -> Image.Image:
    """Grid of cells: a header per column (title, subtitle), a label per row, and the step-colour legend."""
    pad = max(4, cell // 40)
    font = get_font(max(13, cell // 13))
    small = get_font(max(11, cell // 17))
    label_w = max(70, cell // 3) if label_w is None else label_w
    title_h = max(24, cell // 9) if title else pad
    head_h = max(40, cell // 5)
    legend_h = max(34, cell // 7)
    sw = max(18, cell // 10)
    n_cols, n_rows = len(columns), len(camera_names)
    legend_w = (
        int(small.getlength("future step:"))
        + 2 * pad
        + t * (sw + 2)
        + (2 * pad + int(small.getlength(LEGEND_NOTE)) if note else 0)
    )
    width = max(label_w + n_cols * (cell + pad) + pad, label_w + legend_w + 2 * pad)
    height = title_h + head_h + n_rows * (cell + pad) + legend_h + pad
    img = Image.new("RGB", (width, height), BG)
    draw = ImageDraw.Draw(img)
    draw.text((pad, pad), title, fill=FG, font=font)
    for j, (name, sub, cells) in enumerate(columns):
        x = label_w + j * (cell + pad)
        draw.text((x + cell / 2, title_h + head_h * 0.32), name, fill=FG, font=font, anchor="mm")
        draw.text((x + cell / 2, title_h + head_h * 0.75), sub, fill=(90, 90, 90), font=small, anchor="mm")
        for r, arr in enumerate(cells):
            y = title_h + head_h + r * (cell + pad)
            img.paste(Image.fromarray((np.clip(arr, 0, 1) * 255).astype(np.uint8)), (x, y))
    for r, cam in enumerate(camera_names):
        y = title_h + head_h + r * (cell + pad) + cell / 2
        draw.text((label_w / 2, y), cam, fill=FG, font=font, anchor="mm")
    # Legend: the colours of the future steps.
    y0 = title_h + head_h + n_rows * (cell + pad) + pad
    colors = (step_colors(t) * 255).astype(int)
    x = label_w
    draw.text((x, y0 + legend_h / 2 - 2), "future step:", fill=FG, font=small, anchor="lm")
    x += int(small.getlength("future step:")) + 2 * pad
    for j in range(t):
        draw.rectangle([x, y0 + 4, x + sw, y0 + legend_h - 8], fill=tuple(colors[j]))
        draw.text(
            (x + sw / 2, y0 + legend_h / 2 - 2),
            f"{j + 1}",
            fill=(255, 255, 255) if j < t // 2 else FG,
            font=small,
            anchor="mm",
        )
        x += sw + 2
    if note:
        draw.text(
            (x + 2 * pad, y0 + legend_h / 2 - 2), LEGEND_NOTE, fill=(90, 90, 90), font=small, anchor="lm"
        )
    return img


def write_video(columns, camera_names, t: int, cell: int, path: Path, seconds_per_frame: float) -> None:
    try:
        import imageio.v2 as imageio
    except ImportError:
        print("imageio is not installed: no video written (pip install imageio imageio-ffmpeg).")
        return
    frames = []
    for name, sub, cells in columns:
        # One frame per column of the strip, with the cameras side by side.
        per_camera = [(cam, "", [c]) for cam, c in zip(camera_names, cells, strict=True)]
        frames.append(
            np.asarray(draw_strip(per_camera, [""], t, cell, f"{name}: {sub}", label_w=8, note=False))
        )
    h = max(f.shape[0] for f in frames)
    w = max(f.shape[1] for f in frames)
    h, w = -(-h // 16) * 16, -(-w // 16) * 16  # codec-friendly size
    padded = []
    for f in frames:
        canvas = np.full((h, w, 3), 255, dtype=np.uint8)
        canvas[: f.shape[0], : f.shape[1]] = f
        padded.append(canvas)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        imageio.mimsave(path, padded, duration=seconds_per_frame * 1000, loop=0)
    else:
        fps = 10
        repeat = max(1, round(seconds_per_frame * fps))
        with imageio.get_writer(path, fps=fps, macro_block_size=16) as writer:
            for f in padded:
                for _ in range(repeat):
                    writer.append_data(f)
    print(f"wrote {path}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--policy-path",
        default=None,
        help="saved checkpoint dir (pretrained_model); default: "
        "an untrained tiny policy on the toy embodiment",
    )
    parser.add_argument("--dataset-root", default=None, help="LeRobot dataset root (default: a toy dataset)")
    parser.add_argument(
        "--repo-id", default=None, help="dataset repo id (default: the folder name under local/)"
    )
    parser.add_argument("--frame", type=int, default=4, help="dataset frame index")
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of the initial noise (and of the toy policy)"
    )
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--style", choices=["overlay", "textured"], default="overlay")
    parser.add_argument(
        "--cell", type=int, default=256, help="displayed size of one image in pixels (approx.)"
    )
    parser.add_argument("--out", default="outputs/denoising.png")
    parser.add_argument("--video", default=None, help="also write a video: path ending in .mp4 or .gif")
    parser.add_argument("--seconds-per-frame", type=float, default=1.0)
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        if args.dataset_root is None:
            from lerobot_rnd.testing import record_toy_dataset

            print("recording the toy dataset ...")
            root = record_toy_dataset(
                Path(tmp) / "toy_reach", n_episodes=2, episode_len=16, repo_id=TOY_REPO_ID
            )
            repo_id = TOY_REPO_ID
        else:
            root = Path(args.dataset_root)
            repo_id = args.repo_id or f"local/{root.name}"
        if args.policy_path is None:
            print(
                "building an untrained tiny R&D-AI on the toy embodiment "
                "(pass --policy-path for a trained one)"
            )
            if args.dataset_root is not None:
                raise SystemExit(
                    "--dataset-root needs --policy-path (the toy policy only fits the toy dataset)."
                )
            policy = build_toy_policy(root, args.seed)
            title_policy = "untrained toy R&D-AI"
        else:
            from lerobot_rnd.modeling_rnd import RnDPolicy

            policy = RnDPolicy.from_pretrained(args.policy_path)
            title_policy = Path(args.policy_path).as_posix()[-60:]
        policy.to(args.device).eval()
        batch = load_frame(policy, root, repo_id, args.frame)

    res = run_sampler(policy, batch, args.seed)
    cfg = policy.config
    h, w = cfg.image_size
    scale = max(1, round(args.cell / max(h, w)))
    columns = build_columns(res, policy, scale, args.style)
    cams = [k.removeprefix(f"{OBS_IMAGES}.") for k in cfg.image_features]
    title = (
        f"R&D-{cfg.variant} denoising - {title_policy} - frame {args.frame}, noise seed {args.seed}, "
        f"T = {cfg.chunk_size}"
    )
    strip = draw_strip(columns, cams, cfg.chunk_size, scale * max(h, w), title)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    strip.save(out)
    print(f"wrote {out} ({strip.width}x{strip.height}): {len(columns)} columns x {len(cams)} cameras")
    grip = torch.where(res["gripper_logits"] > 0, 1, -1)[0].tolist()
    print("a0 (normalised, first 3 steps):", np.round(res["a0"][0, :3].cpu().numpy(), 3).tolist())
    print("gripper (+1 closed):", grip)
    if args.video:
        write_video(
            columns, cams, cfg.chunk_size, scale * max(h, w), Path(args.video), args.seconds_per_frame
        )


if __name__ == "__main__":
    main()

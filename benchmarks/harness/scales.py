"""What the benchmark runs: the methods, the per-scale defaults and the per-method lerobot-train arguments."""

from __future__ import annotations

from . import REPO_ROOT

CONFIG_DIR = REPO_ROOT / "policies_config" / "metaworld"

METHODS = {  # name -> (config file, label)
    "rnd_ai": ("rnd_ai.json", "R&D-AI"),
    "rnd_a": ("rnd_a.json", "R&D-A"),
    "rnd_i": ("rnd_i.json", "R&D-I"),
    "act": ("act.json", "ACT"),
    "diffusion": ("diffusion.json", "Diffusion Policy"),
}
RND_METHODS = ("rnd_ai", "rnd_a", "rnd_i")

# Per-scale defaults (CLI flags override) and per-method lerobot-train overrides.
SCALES: dict[str, dict] = {
    "smoke": dict(
        tasks="reach-v3", demos="3", device="cpu", steps=2, batch_size=2, save_freq=0, log_freq=1,
        num_workers=0, eval_episodes=2, eval_chunk=0, eval_batch_size=2, episode_length=16, grid=3,
        min_train_slice_s=30,
        method_args={
            "rnd": ["--policy.dim_model=64", "--policy.n_layers=1", "--policy.n_heads=4",
                    "--policy.stats_num_samples=16"],
            "act": ["--policy.dim_model=64", "--policy.n_heads=4", "--policy.dim_feedforward=128",
                    "--policy.n_encoder_layers=1", "--policy.n_decoder_layers=1",
                    "--policy.n_vae_encoder_layers=1", "--policy.latent_dim=8"],
            "diffusion": ["--policy.down_dims=[32,64]", "--policy.diffusion_step_embed_dim=32",
                          "--policy.spatial_softmax_num_keypoints=8"],
        },
    ),
    "gpu": dict(
        tasks="reach-v3,push-v3", demos="10,20", device="cuda", steps=25000, batch_size=32, save_freq=1000,
        log_freq=200, num_workers=4, eval_episodes=50, eval_chunk=10, eval_batch_size=10, episode_length=300,
        grid=8, min_train_slice_s=180,
        method_args={
            "rnd": [],  # paper size from the config: 8 layers x 1024, 16 heads (107M)
            "act": ["--policy.dim_model=768", "--policy.n_heads=12", "--policy.dim_feedforward=3072",
                    "--policy.n_encoder_layers=6"],  # 92M
            "diffusion": ["--policy.down_dims=[640,1280]"],  # 107M
        },
    ),
}
SCALES["cpu"] = dict(
    tasks="reach-v3,button-press-topdown-v3,drawer-close-v3", demos="10", device="cpu", steps=2000, batch_size=8,
    save_freq=250, log_freq=50, num_workers=2, eval_episodes=50, eval_chunk=10, eval_batch_size=10,
    episode_length=300, grid=5, min_train_slice_s=120,
    # Each method at its own CPU size (policies_config/metaworld/*_cpu.json): R&D's CPU tier (patch 32 with a
    # strided-conv RGB patch embedding, 4 gripper patches per future frame, width 256 x 4 layers, bf16 autocast:
    # 6.0M; 6.5M with the linear embedding used before), ACT as configured for
    # MetaWorld (51.6M, mostly its ResNet-18), DP with a [128, 256, 512] U-Net (29.5M incl. its ResNet-18).
    config_files={"rnd_ai": "rnd_ai_cpu.json", "rnd_a": "rnd_ai_cpu.json", "rnd_i": "rnd_ai_cpu.json",
                  "act": "act_cpu.json", "diffusion": "diffusion_cpu.json"},
    # DP's U-Net halves the horizon once per level: 3 levels need a multiple of 8 (its config's 16, not 12).
    method_args={"rnd": [], "act": [], "diffusion": ["--policy.horizon=16"],
                 "rnd_a": ["--policy.variant=A"], "rnd_i": ["--policy.variant=I"]},
)
# Applied at every scale: matched horizons, no downloads, no Hub.
COMMON_METHOD_ARGS = {
    "rnd": ["--policy.n_obs_steps=2", "--policy.chunk_size=8", "--policy.n_action_steps=8"],
    "act": ["--policy.n_obs_steps=1", "--policy.chunk_size=8", "--policy.n_action_steps=8",
            "--policy.pretrained_backbone_weights=null"],
    "diffusion": ["--policy.n_obs_steps=2", "--policy.horizon=12", "--policy.n_action_steps=8",
                  "--policy.pretrained_backbone_weights=null"],
}  # fmt: skip


# The suites (--suite): env type, config folder, dataset names and what differs from the scales above (the
# matched training settings -- steps, batch, seeds, horizons, per-method arguments -- are the scale's for both).
_PANDA_CPU_FILES = {"rnd_ai": "rnd_ai_cpu.json", "rnd_a": "rnd_ai_cpu.json", "rnd_i": "rnd_ai_cpu.json",
                    "act": "act_cpu.json", "diffusion": "diffusion_cpu.json"}  # fmt: skip
SUITES: dict[str, dict] = {
    "metaworld": dict(
        env_type="rnd_mw", config_dir=CONFIG_DIR, dataset_prefix="mw", record_args=[],
        # --protocol spatial: the recorder's fps (first demo = the pool point nearest the pool's mean, every
        # coordinate); the grid: linspace over the range, edges included, other coordinates at the centre
        fps_mode="fps", grid_layout="edges", grid_others="centre",
        scales={},
    ),
    "panda": dict(
        env_type="rnd_panda", config_dir=REPO_ROOT / "policies_config" / "panda", dataset_prefix="panda",
        record_args=["--suite", "panda"],
        # --protocol spatial: furthest-point sampling over (x, y, yaw mod 90 degrees) from the centre of the range (the
        # recorder's fps-centre); the grid: cell centres over x, y and yaw; the target (push-block, pick-place)
        # drawn uniformly from its range by a seeded generator until valid (10 cm or more from the object;
        # push-block: 22 cm or less), for demos (the recording seed) and grid cells (cell i: eval_seed + i) alike;
        # slide-block's target follows the block (RLBench's slide-block-to-target), so yaw is not taken mod 90 there
        fps_mode="fps-centre", grid_layout="cells", grid_others="seeded", grid_dims=(0, 1, 2),
        scales={
            # episode_length: the recorder's limit for the expert (as MetaWorld's 300): 2.2 x the 54 steps the
            # expert needs for pick-place, 4-7 x the other tasks' 17-30 (benchmarks/results/panda_env_speed.json)
            "smoke": dict(tasks="lift-cube", episode_length=16, grid=3, grid_yaws=3, config_files=_PANDA_CPU_FILES),
            "cpu": dict(tasks="lift-cube,push-block,press-button,pick-place,slide-block", episode_length=120, grid=3,
                        grid_yaws=3, config_files=_PANDA_CPU_FILES),
        },
    ),
    "so101": dict(
        env_type="rnd_so101", config_dir=REPO_ROOT / "policies_config" / "so101", dataset_prefix="so101",
        record_args=["--suite", "so101"],
        # the demos' embodiment: cameras measured by lerobot-rnd-calibrate on a simulated calibration session
        # (--calibration measured, the default) or MuJoCo's exact ones (--calibration exact)
        calibration=True,
        fps_mode="fps-centre", grid_layout="cells", grid_others="seeded", grid_dims=(0, 1, 2),
        scales={
            # episode_length: 1.6 x the 94 steps the expert needs for pick-cube (30 for reach-target)
            "smoke": dict(tasks="reach-target", episode_length=16, grid=3, grid_yaws=3, config_files=_PANDA_CPU_FILES),
            "cpu": dict(tasks="reach-target,pick-cube", episode_length=150, grid=3, grid_yaws=3,
                        config_files=_PANDA_CPU_FILES),
        },
    ),
}  # fmt: skip


def suite_scale_defaults(suite: str, scale: str) -> dict:
    """The per-scale defaults of ``scale`` for ``suite`` (the scale's, with the suite's changes)."""
    if suite not in SUITES:
        raise ValueError(f"unknown suite {suite!r}; suites: {', '.join(SUITES)}")
    per_suite = SUITES[suite]["scales"]
    if suite != "metaworld" and scale not in per_suite:
        raise ValueError(f"the {suite} suite has the scales {', '.join(per_suite)} (policies_config/{suite}/ has "
                         f"no configs for the {scale} scale)")  # fmt: skip
    return {"grid_yaws": 1, **SCALES[scale], **per_suite.get(scale, {})}


def method_family(method: str) -> str:
    return "rnd" if method in RND_METHODS else method

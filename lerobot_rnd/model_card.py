"""Hub publishing of R&D checkpoints: the model card (LeRobot's template does not know plugin policy types)
and a check, before training starts, that the push at its end can succeed."""

import os
import shlex
import sys

from huggingface_hub import ModelCard, ModelCardData

PAPER_URL = "https://arxiv.org/abs/2405.18196"
VARIANT_TEXT = {
    "A": "R&D-A (denoises in action space; the renders are inputs only)",
    "I": "R&D-I (denoises in image space; actions recovered by SVD from per-pixel displacements)",
    "AI": "R&D-AI (denoises in image and action space; the paper's best variant)",
}

TEMPLATE = """---
{{ card_data }}
---

# {{ title }}

This is a **Render and Diffuse (R&D)** policy, trained with [LeRobot](https://github.com/huggingface/lerobot) and
the `lerobot_policy_rnd` plugin. R&D draws the robot's gripper into every camera image at the poses its candidate
actions would reach and denoises those actions in image space and action space together
([Vosylius et al., RSS 2024]({{ paper_url }})).

- **Variant:** {{ variant }}
- **Cameras:** {{ cameras }}
- **Observation history / horizon:** {{ n_obs_steps }} / {{ chunk_size }} steps ({{ n_action_steps }} executed per query)
- **Network:** ViT, {{ n_layers }} layers, width {{ dim_model }}, {{ n_heads }} heads, patch {{ patch_size }}, images {{ image_size }}
- **Sampler:** {{ num_inference_steps }} DDIM steps{{ final_step }}
- **Dataset:** {{ dataset }}

Camera calibration and gripper meshes are stored in this checkpoint (`config.json` and `model.safetensors`),
so evaluating it needs nothing else.

## Trained with

```bash
{{ command }}
```

## Use

```bash
pip install lerobot_policy_rnd   # or: pip install -e . in a clone of the plugin
lerobot-eval --policy.path={{ repo_id }} --env.type=<env> --eval.n_episodes=50
```
"""


def training_command() -> str:
    """The command line of this process, as a user would retype it."""
    argv = list(sys.argv)
    if argv and argv[0].endswith(("lerobot-train", "lerobot_train.py")):
        argv[0] = "lerobot-train"
    return " ".join(shlex.quote(a) for a in argv)


def make_rnd_model_card(config, dataset_repo_id, license: str | None, tags: list[str] | None) -> ModelCard:  # noqa: A002
    card_data = ModelCardData(
        license=license or "apache-2.0",
        library_name="lerobot",
        pipeline_tag="robotics",
        tags=sorted(set(tags or []) | {"robotics", "lerobot", "rnd", "render-and-diffuse", "diffusion-policy"}),
        model_name="rnd",
        datasets=dataset_repo_id,
    )
    return ModelCard.from_template(
        card_data,
        template_str=TEMPLATE,
        title=f"Render and Diffuse ({config.variant}) policy",
        paper_url=PAPER_URL,
        variant=VARIANT_TEXT[config.variant],
        cameras=", ".join(config.image_features) or "none",
        n_obs_steps=config.n_obs_steps,
        chunk_size=config.chunk_size,
        n_action_steps=config.n_action_steps,
        n_layers=config.n_layers,
        dim_model=config.dim_model,
        n_heads=config.n_heads,
        patch_size=config.patch_size,
        image_size="x".join(str(s) for s in config.image_size),
        num_inference_steps=config.num_inference_steps,
        final_step=" + a final action-space step" if config.final_action_step and config.variant != "I" else "",
        dataset=dataset_repo_id or "not recorded in this checkpoint (see train_config.json)",
        command=training_command(),
        repo_id=config.repo_id or "<repo_id>",
    )


def check_hub_push_ready(config) -> None:
    """Raise before training if `--policy.push_to_hub=true` could only fail after it (LeRobot pushes at the end).

    Checks that the Hub is not switched off (HF_HUB_OFFLINE) and that the repo `config.repo_id` exists or can
    be created with the current token. Does nothing without push_to_hub or repo_id.
    """
    if not getattr(config, "push_to_hub", False) or not getattr(config, "repo_id", None):
        return
    from huggingface_hub import HfApi, constants

    offline = getattr(constants, "is_offline_mode", None)
    if (offline() if callable(offline) else constants.HF_HUB_OFFLINE) or os.environ.get("HF_HUB_OFFLINE") == "1":
        raise RuntimeError(
            f"--policy.push_to_hub=true (repo {config.repo_id!r}) but the Hugging Face Hub is switched off "
            "(HF_HUB_OFFLINE=1): the push at the end of training would fail. Train with --policy.push_to_hub=false "
            "and push the checkpoint later (huggingface-cli upload <repo_id> <output_dir>/checkpoints/last/"
            "pretrained_model), or unset HF_HUB_OFFLINE."
        )
    try:
        HfApi().create_repo(repo_id=config.repo_id, private=getattr(config, "private", None), exist_ok=True)
    except Exception as err:  # network, auth and permission errors alike
        raise RuntimeError(
            f"--policy.push_to_hub=true: the Hub repo {config.repo_id!r} cannot be reached or created ({err}). "
            "Checked before training so that no run ends without its push: log in (huggingface-cli login), fix "
            "--policy.repo_id, or train with --policy.push_to_hub=false and push the checkpoint later."
        ) from err

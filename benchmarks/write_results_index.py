#!/usr/bin/env python
"""Write benchmarks/results/INDEX.md: every result under benchmarks/results, current or archived, from its JSON.

    python benchmarks/write_results_index.py           # rewrite benchmarks/results/INDEX.md
    python benchmarks/write_results_index.py --check   # exit 1 when INDEX.md is not what the JSON gives

An *entry* is a JSON file directly in `benchmarks/results/` or `benchmarks/results/archive/` (a PNG of the same
stem belongs to it) or a folder there (a `run_benchmark.py` results folder with its run JSONs). `STATUS` below is
the one place that says whether an entry is current (it measures a config that ships in `policies_config/`, and is
the latest measurement of its kind) or archived (superseded or exploratory), with one line of what it is or why it
was superseded. Current entries live in `benchmarks/results/`, archived ones in `benchmarks/results/archive/`
under the same name; the script refuses an entry on disk that `STATUS` does not classify, one that `STATUS` names
but is not on disk, and one that lies in the wrong place for its status. The command and the code commit / config
of each entry are read from its JSON ("not recorded" where the JSON has none).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"
ARCHIVE = "archive"
INDEX = "INDEX.md"
TAG = "ablation-switches-2026-12"

CURRENT, ARCHIVED = "current", "archived"
# entry name -> (status, one line: what it measures (current) or why it was superseded (archived))
STATUS: dict[str, tuple[str, str]] = {
    # ---- current: the shipped configs (policies_config/), the latest measurement of each kind ----
    "one_step_sampling_test.json": (CURRENT, "The CPU benchmark's R&D-AI checkpoints (drawer-close, button-press, reach-v3 "
                                    "training seed 1) sampled with 1 and with 4 denoising steps on the test seeds: the "
                                    "1-step rows are the shipped CPU tier's headline numbers."),
    "cpu_3000_drawer": (CURRENT, "drawer-close-v3, 10 demos, 3,000 steps: the headline's ACT and Diffusion Policy runs; its "
                        "R&D-AI run was sampled with 4 steps (its 1-step result: one_step_sampling_test.json)."),
    "cpu_3000_button": (CURRENT, "button-press-topdown-v3, 10 demos, 3,000 steps: the headline's ACT and Diffusion Policy "
                        "runs; its R&D-AI run was sampled with 4 steps (its 1-step result: one_step_sampling_test.json)."),
    "cpu_3000": (CURRENT, "reach-v3, 10 demos, 3,000 steps: the headline's ACT and Diffusion Policy runs; its R&D-AI row "
                 "is the earlier linear patch embedding, superseded by one_step_sampling_test.json."),
    "cpu_3000_reach_seeds": (CURRENT, "reach-v3, 10 demos: a second training seed of R&D-AI and ACT (seed 0 read from "
                             "archive/cpu_3000_conv and cpu_3000); R&D-AI sampled with 4 steps, its seed-1 checkpoint "
                             "with 1 step in one_step_sampling_test.json."),
    "cpu_3000_reach_n20": (CURRENT, "reach-v3, 20 demos, 3,000 steps, all three methods (R&D-AI sampled with 4 steps)."),
    "cpu_6000_reach_n20": (CURRENT, "ACT on reach-v3, 20 demos, trained 6,000 steps."),
    "reach_n20_6000steps_test.json": (CURRENT, "R&D-AI (CPU tier, 1 denoising step) on reach-v3, 20 demos, trained "
                                      "6,000 steps, test seeds."),
    "quickstart_drawer_cpu.json": (CURRENT, "examples/quickstart.sh on drawer-close-v3 with the shipped CPU tier "
                                   "(1 denoising step)."),
    "train_step_cpu.json": (CURRENT, "Where a training step goes: the shipped CPU configs (and the legacy speed "
                            "reference) in one run on an AVX-512 bf16 CPU."),
    "train_step_cpu_avx2.json": (CURRENT, "The same on an AVX2-only CPU (float32)."),
    "train_step_cpu_suites_avx2.json": (CURRENT, "R&D-AI and ACT training steps on SO-101 pick-cube demos beside "
                                        "MetaWorld door-close, one run on an idle AVX2 CPU (issue 34's cost question)."),
    "train_step_panda_patch16.json": (CURRENT, ("The Panda R&D-AI config's 16-px patches against the MetaWorld "
                                       "config's 32-px (otherwise equal) and ACT, one paired run on Panda lift-cube "
                                       "8-demo data, idle AVX-512 bf16 CPU.")),
    "inference_cpu_tier_avx512.json": (CURRENT, "One action chunk at inference (batch 1): the shipped CPU tier (1 "
                                       "denoising step), ACT and Diffusion Policy in one run on an AVX-512 bf16 CPU."),
    "render_cpu.json": (CURRENT, "Rasteriser throughput on CPU (benchmarks/bench_render.py); the only measurement "
                        "of it."),
    "panda_env_speed.json": (CURRENT, "Speed of the Panda suite's environments and scripted experts (no policy)."),
    "so101_random": (CURRENT, "Simulated SO-101 (issue 34), cameras measured by lerobot-rnd-calibrate, 10 random "
                     "demos, 3,000 steps, 50 test episodes from seed 1000: reach-target (the ball on its post) "
                     "R&D-AI 2/50, ACT 5/50; pick-cube R&D-AI 0/50, ACT 1/50; with 20 demos, reach-target "
                     "R&D-AI 0/50, ACT 6/50 (pick-cube not run). R&D-AI's chunks start from the last joint "
                     "command (lerobot_rnd/anchor.py); its earlier runs are archived (archive/so101_measured_anchor); "
                     "Diffusion Policy not run. The reach-target runs on the floating ball are archived "
                     "(archive/so101_reach_floating_ball)."),
    "so101_exact_calibration": (CURRENT, "SO-101 reach-target (the ball on its post), R&D-AI trained on the same 10 "
                                "demos as so101_random but with MuJoCo's exact cameras (--calibration exact), chunks "
                                "from the last joint command, 3,000 steps, 50 test episodes from seed 1000: 2/50, the "
                                "same as with the measured cameras. pick-cube not run. The JSON's commands name the "
                                "outputs/diag paths they were run in."),
    "trace_so101_reach_rnd_ai.json": (CURRENT, "Closed loop on validation seeds 100-119, R&D-AI reach-target (the "
                                       "ball on its post, 10 demos) trained with chunks that start from the last "
                                       "joint command (lerobot_rnd/anchor.py), the checkpoint so101_random reports: "
                                       "2/20; slopes at step 30 x 0.15, y 0.24, z 0.36 (the demos 0.76-0.79); it ends "
                                       "a median 13 cm from the ball, within 3 cm of the table in 18 of 20 episodes. "
                                       "The JSON's command names the outputs/diag path it was written to."),
    "trace_so101_reach_rnd_ai_hold40.json": (CURRENT, ("The same for R&D-AI trained on demos that hold at the ball "
                                             "40 frames after the expert's first success (run_benchmark.py "
                                             "--extra-steps 40; 703 frames against 403): 2/20, slopes x 0.01, y "
                                             "-0.02, z 0.18, a median 15 cm from the ball at the end, within 3 cm of "
                                             "the table in 17 of 20: holding demos change nothing.")),
    "trace_so101_reach_rnd_ai_6000.json": (CURRENT, ("The same for R&D-AI trained 6,000 steps instead of 3,000 on "
                                           "the same 10 demos (loss 0.036 against 0.083): 2/20, slopes x 0.11, y "
                                           "0.21, z 0.38, a median 13 cm from the ball at the end, within 3 cm of "
                                           "the table in 17 of 20: longer training changes nothing.")),
    "train_placements_so101_reach_n10.json": (CURRENT, ("The so101_random reach-target checkpoints (10 demos) on "
                                              "their own 10 demo placements: R&D-AI 5/10, ACT 5/10. Neither "
                                              "reproduces its demos.")),
    "trace_so101_reach_act_n20.json": (CURRENT, "The same for the so101_random ACT reach-target checkpoint with 20 "
                                       "demos: 0/20, slopes x 0.18, y 0.38, z -0.06, a median 12 cm from the ball at "
                                       "the end, within 3 cm of the table in 11 of 20 episodes."),
    "so101_reach_ray.json": (CURRENT, "SO-101 reach-target's balls on one viewing ray of the front camera, floating "
                             "and on the post: 19 cm apart yet on the same pixel, 7.0 against 12.7 px wide at 128 "
                             "px; the post's length tells them apart (docs/images/so101_reach_ray.png)."),
    "trace_so101_reach_act.json": (CURRENT, "The same for the so101_random ACT reach-target checkpoint (the ball on "
                                   "its post): 2/20, slopes x 0.13, y 0.13, z -0.04, a median 10 cm from the ball at "
                                   "the end. The JSON's command names the outputs/diag path it was written to."),
    "so101_ik_study.json": (CURRENT, "SO-101 inverse kinematics per orientation weight on recorded pick-cube joint "
                            "targets perturbed as a prediction error would (position vs rotation error)."),
    "so101_env_speed.json": (CURRENT, "The simulated SO-101's scripted experts (30/30 on each task, seeds 0-29) and "
                             "its speed per control step (no policy)."),
    "loss_parity_before.json": (CURRENT, "First 20 training losses of every shipped rnd config before the config "
                                "was made lean (benchmarks/loss_parity.py)."),
    "loss_parity_after.json": (CURRENT, "The same after it: equal to loss_parity_before.json."),
    "cpu_3000_door": (CURRENT, "door-close-v3, 10 demos, 3,000 steps: the one-task runs of the fourth task of issue 35's "
                      "multi-task comparison; so far R&D-AI (1 denoising step): 49/50; ACT not run yet."),
    "cpu_3000_multitask": (CURRENT, "Issue 35, in progress: one R&D-AI policy (task-conditioned) trained on drawer-close, "
                           "button-press-topdown, reach and door-close together (10 demos of each, 3,000 steps), "
                           "evaluated on each task (50 episodes per task, seeds 1000-1049): 83/200, against 173/200 "
                           "for one policy per task; ACT multi-task (no task input), same data and steps: 80/200."),
    "panda_multitask_pair": (CURRENT, ("Issue 35, in progress: the Panda pair whose tasks share a scene (lift-red-cube, "
                             "lift-blue-cube: a red and a blue cube in every image; the task names the cube to "
                             "lift), one policy for both, 10 random demos of each, 3,000 steps, 50 test episodes "
                             "per task from seed 1000: R&D-AI (task-conditioned) 1/50 and 0/50; ACT multi-task (no "
                             "task input) 0/50 and 0/50. Neither method learns the pair at this budget; the "
                             "single-task control, R&D-AI on lift-red-cube alone (panda_pair_single), lifts the red "
                             "cube in 3/50. ACT's training "
                             "time (62.7 min) includes about 13 minutes in which an open-loop diagnostic shared the "
                             "2 cores (median logged update 0.97 s against about 0.9 s alone).")),
    "panda_random": (CURRENT, ("Issue 33's random protocol on the Panda suite (10 random demos, 3,000 steps, 50 test "
                     "episodes from seed 1000), in progress: pick-place R&D-AI 0/50 (ACT stopped before training); press-button R&D-AI 4/50, ACT "
                     "19/50, a significant loss for R&D-AI.")),
    "train_placements_panda_press_n10.json": (CURRENT, ("The panda_random press-button checkpoints (10 random "
                                              "demos) on their own 10 demo placements: R&D-AI 0/10, ACT 8/10. "
                                              "R&D-AI does not fit its demos; ACT does.")),
    "chunk_goal_response_panda_press_rnd_ai_n10.json": (CURRENT, ("The panda_random R&D-AI press-button checkpoint "
                                                        "on its own demos, open loop: the first chunk hardly reads "
                                                        "where the button is (slopes x 0.48, y 0.14, yaw 0.17 at "
                                                        "frame 0), then follows x and y (0.85, 0.78 at frame 8).")),
    "chunk_goal_response_panda_press_act_n10.json": (CURRENT, ("The same for the panda_random ACT press-button "
                                                       "checkpoint: slopes x 1.03, y 1.01, yaw 1.00 at frame 0.")),
    "denoiser_goal_response_panda_press_n10.json": (CURRENT, ("The panda_random R&D-AI press-button checkpoint's "
                                                      "sampler split into its parts, on its own demos: at frame 0 "
                                                      "the network's own clean estimate from pure noise follows the "
                                                      "demos' x by 0.65 and y by 0.22 (the sampler 0.47, 0.16), so "
                                                      "the network itself does not read the button's y; at frame 8 "
                                                      "the estimate follows x, y, z (0.99, 0.94, 0.67) but the "
                                                      "image-space path the one-step sampler uses loses z (0.22; "
                                                      "sampler 0.17).")),
    "denoiser_goal_response_panda_press_n10_no_wrist.json": (CURRENT, ("The same with the wrist camera fed as a "
                                                               "uniform grey image (--blank-camera): the network's "
                                                               "estimate moves by at most 0.006 in any slope at frames "
                                                               "0 and 8, the sampler's translation and yaw by at most "
                                                               "0.013: the network does not use the wrist view.")),
    "denoiser_goal_response_panda_press_n10_no_front.json": (CURRENT, ("The same with the front camera blanked: no "
                                                               "goal response at frame 0 (slopes -0.02 to 0.06); at "
                                                               "frame 8 the network's estimate still follows x 0.60, "
                                                               "y 1.10, from what it has left (the wrist view, the "
                                                               "rendered past gripper).")),
    "denoiser_goal_response_so101_reach_n10.json": (CURRENT, ("The so101_random R&D-AI reach-target checkpoint split "
                                                      "the same way, on its own demos: the network's estimate "
                                                      "follows the demos' chunk end with slopes 0.85-1.22 at frame 0 "
                                                      "and 0.67-0.89 at frame 8, the sampler as closely: on the "
                                                      "SO-101 the first chunk reads the ball; the failure builds up "
                                                      "in closed loop.")),
    "denoiser_goal_response_so101_reach_n10_no_wrist.json": (CURRENT, ("The same with the wrist camera blanked: "
                                                               "frame-0 slopes 0.09-0.15 lower, frame 8 within "
                                                               "0.07: this network uses the wrist view somewhat.")),
    "panda_pair_single": (CURRENT, ("Issue 35: the Panda pair's single-task control, R&D-AI trained on lift-red-cube "
                          "alone (10 random demos, the two-cube scene, 3,000 steps), 50 test episodes from seed 1000: "
                          "3/50 (loss 0.166). The two-cube scene is not learned from 10 demos even without a second "
                          "task; the multi-task policy's 1/50 on this task is within the intervals of it.")),
    "chunk_goal_response_panda_pair_rnd_ai.json": (CURRENT, ("Open loop at frame 0 of its 20 demos, the "
                                                   "panda_multitask_pair R&D-AI checkpoint (4 draws), each observation "
                                                   "also fed the other task's string with the same noise: its first "
                                                   "chunk does not follow the demos (slopes x -0.02, y -0.00, z -0.06; "
                                                   "the one-cube lift-cube checkpoint: 0.87, 0.53, 0.63), and the task "
                                                   "string moves it by 0.005-0.023 per position axis against a spread "
                                                   "over draws of 0.19-0.22: the task token barely acts.")),
    "panda_spatial_6000": (CURRENT, ("Issue 33: Panda lift-cube, 8 furthest-point demos, the panda_spatial set-up "
                           "trained 6,000 steps instead of 3,000 (ACT's loss was still falling), the same 27 test "
                           "cells: R&D-AI 22/27 (21/27 at 3,000 steps; loss 0.068), ACT 3/27 (4/27 at 3,000; "
                           "loss 0.129 -> 0.059). ACT's training cost counts only steps 2,000-6,000 (the first 2,000 "
                           "ran in an earlier session, and the run resumed from their checkpoint).")),
    "cpu_3000_button_spatial": (CURRENT, ("Issue 33, in progress: MetaWorld button-press-topdown-v3, spatial protocol "
                                "(furthest-point demos over the button's x, y; a 5 x 5 test grid over both, edges "
                                "included), 3,000 steps, R&D-AI and ACT with 2, 4, 8 and 16 demos; one call per method "
                                "and demo count, joined into one report: with 2 demos R&D-AI 12/25, ACT 9/25; with 4 "
                                "demos R&D-AI 17/25, ACT 7/25; with 8 demos R&D-AI 24/25; with 16 demos R&D-AI 25/25.")),
    "panda_spatial": (CURRENT, ("Issue 33, in progress: Panda lift-cube and push-block, spatial protocol (furthest-point demos from the "
                      "centre, yaw compared modulo the cube's 90-degree symmetry; 27-cell x/y/yaw grid), 3,000 steps, "
                      "front camera framed on the placement range, 60-degree wrist camera, expert approaching at 0.4 "
                      "of full speed, R&D-AI with 16-px patches: with 8 demos R&D-AI 21/27, ACT 4/27; with 2 demos "
                      "R&D-AI 3/27, ACT 0/27; with 4 demos R&D-AI 6/27, ACT 0/27; with 16 demos R&D-AI 13/27, ACT 6/27 "
                      "(its loss still falling, 0.23); push-block (a random target per "
                      "episode, demos and test cells alike; the earlier rule is archived as "
                      "archive/panda_spatial_push_centre_target) with 8 demos R&D-AI 0/27, ACT 0/27, with 2 demos both 0/27, with 4 and 16 both 0/27; slide-block (the target 10 cm along the block's +y axis, RLBench's "
                      "slide-block-to-target) with 8 demos R&D-AI 1/27, ACT 1/27, with 16 demos R&D-AI 0/27; "
                      "on their own 8 "
                      "demo placements (train_placements_lift-cube_n8.json) R&D-AI 5/8, ACT 7/8, Diffusion Policy "
                      "0/8; Diffusion Policy with 8 lift-cube demos 0/27. The R&D-AI run is "
                      "the 16-px diagnostic run (outputs/diag/p16_work, its run JSON has the command), evaluated on "
                      "the grid only after the patch size was chosen on validation seeds.")),
    "trace_panda_lift_rnd_ai_n8_p16.json": (CURRENT, ("Where the panda_spatial R&D-AI lift-cube gripper goes (8 demos, "
                                            "16-px patches), closed loop on validation seeds 100-119: 17/20; slope of "
                                            "its step-30 displacement on the cube's offset x 0.97, y 0.74 (the demos: "
                                            "1.01, 1.00). With 32-px patches 1/20 (archive/panda_spatial_patch32): "
                                            "the patch size was chosen on this.")),
    "trace_panda_lift_act_n8.json": (CURRENT, ("The panda_spatial ACT lift-cube checkpoint (8 demos) on the same "
                                     "validation seeds: 2/20; slopes x -0.14, y 0.88: it follows the cube's y, not its "
                                     "x.")),
    "chunk_goal_response_panda_lift_rnd_ai_n8_p16_step2000.json": (CURRENT, ("The panda_spatial R&D-AI run (16-px "
                                                                "patches) at step 2,000, on its own 8 demos, open loop "
                                                                "(--delta-actions): first chunk at frame 0 x 0.92, y "
                                                                "0.47, against 0.50, 0.07 with 32-px patches at step "
                                                                "3,000 (archive/panda_spatial_patch32).")),
    "chunk_goal_response_panda_lift_rnd_ai_n8_p16.json": (CURRENT, ("The same run at step 3,000: first chunk at frame 0 "
                                                       "x 0.87, y 0.53.")),
    "train_placements_panda_lift_rnd_ai_n8_p16.json": (CURRENT, ("The same run (step 3,000) on its own 8 demo "
                                                        "placements, measured before the patch size was chosen: 5/8, "
                                                        "against 1/8 with 32-px patches and 7/8 for ACT.")),
    "chunk_goal_response_panda_lift_diffusion_n8.json": (CURRENT, ("The panda_spatial Diffusion Policy checkpoint "
                                                         "(8 lift-cube demos) on its own demos: its executed chunk "
                                                         "follows them by half (slopes x 0.53, y 0.50 at frame 0; "
                                                         "0.56, 0.70 at frame 16): it underfits them.")),
    "trace_panda_lift_diffusion_n8.json": (CURRENT, ("The same Diffusion Policy checkpoint closed loop on validation "
                                         "seeds 100-109: 0/10; its gripper heads for the cube (slopes x 0.84, y 0.71 "
                                         "at step 30) but comes no closer than 3.3 cm and ends 8-21 cm away.")),
    "chunk_goal_response_panda_lift_act_n8.json": (CURRENT, ("The panda_spatial ACT checkpoint on its own demos: slopes "
                                                   "1.05-1.07 at frames 0, 8 and 16 (ACT sees one frame, no history).")),
    "trace_panda_push_random_target_rnd_ai_n8.json": (CURRENT, ("The panda_spatial R&D-AI push-block checkpoint (8 "
                                                      "demos, a random target per episode) on validation seeds "
                                                      "100-119: 0/20; at step 30 its gripper's displacement does not "
                                                      "follow the push start behind the block (slopes x 0.11, y "
                                                      "0.00; the demos 0.82, 0.90).")),
    "chunk_goal_response_panda_push_random_target_rnd_ai_n8.json": (CURRENT, ("The same checkpoint on its own demos, "
                                                                   "open loop: the first chunk ignores the block "
                                                                   "(slopes x -0.04, y -0.00 at frame 0; lift-cube's "
                                                                   "run 0.87, 0.53), and follows the demos halfway "
                                                                   "once the arm has moved (0.47, 0.50 at frame 8). "
                                                                   "On its own 8 demo placements it succeeds at none "
                                                                   "(panda_spatial/train_placements_push-block_n8.json).")),
    "trace_panda_slide_rnd_ai_n8.json": (CURRENT, ("The panda_spatial R&D-AI slide-block checkpoint (8 demos) on "
                                         "validation seeds 100-119: 2/20; at step 30 its gripper follows the push "
                                         "start's y halfway (slope 0.48) and not its x, the front camera's depth "
                                         "(-0.11; the demos 0.85, 1.15).")),
    "trace_panda_slide_rnd_ai_n8_steps4.json": (CURRENT, ("The same checkpoint and seeds sampled with 4 denoising "
                                                "steps instead of 1: 2/20 again, step-30 slopes x -0.05, y 0.41: the "
                                                "number of sampling steps is not why it fails.")),
    "chunk_goal_response_panda_slide_rnd_ai_n8.json": (CURRENT, ("The same checkpoint on its own demos, open loop: "
                                                       "the first chunk follows the demos' x (slope 0.66) but hardly "
                                                       "their y (0.20) or the gripper's turn (0.08); from frame 8 "
                                                       "it follows x and y (0.83, 0.88), the turn less (0.41).")),
    "panda_camera_views_lift-cube.json": (CURRENT, "How large the cube appears in the Panda cameras at the start pose, at "
                                          "the centre and the four (x, y) corners of lift-cube's placement range "
                                          "(benchmarks/camera_views.py): front 10-16 px wide at 128 px; the "
                                          "wrist camera sees it at three of the five, the gripper hides the two "
                                          "corners nearest the robot."),
    "panda_camera_views_push-block.json": (CURRENT, ("The same for push-block's block (its target drawn at random, "
                                           "seeded, as in the benchmark): front 13-18 px wide at 128 px; "
                                           "the gripper hides most of it from the wrist camera at the far "
                                           "corners.")),
    "panda_camera_views_slide-block.json": (CURRENT, ("The same for slide-block's block (its target 10 cm along the "
                                            "block's +y axis, in view at every placement): front 13-17 px wide at "
                                            "128 px; the wrist camera sees most of it except at the two far "
                                            "corners, where the gripper hides it.")),
    "so101_camera_views_reach-target.json": (CURRENT, ("How large the ball appears in the simulated SO-101's cameras "
                                             "at the start pose, at the centre and the four (x, y) corners of "
                                             "reach-target's range (ball at mid height): front 8-10 px wide at 128 "
                                             "px; the wrist camera sees it only at the centre.")),
    "so101_camera_views_pick-cube.json": (CURRENT, ("The same for pick-cube's cube: front 10-15 px wide; the wrist "
                                          "camera sees part of it at the centre and the two near corners, not at "
                                          "the far ones.")),
    # ---- archived: superseded or exploratory ----
    "panda_spatial_push_centre_target": (ARCHIVED, ("Issue 33's first push-block round (8 demos, 3,000 steps, the "
                                         "current set-up otherwise): R&D-AI 0/27, ACT 3/27; own demo placements "
                                         "0/8 and 1/8; R&D-AI's first chunk ignored the block (traces/, also for "
                                         "a second seed, 10 denoising steps and a still history). Superseded: the "
                                         "target sat at the centre of its range where valid, so 6 of 8 demos but "
                                         "only 6 of 27 test cells pushed to the centre (ACT's 3 successes all "
                                         "there); targets are now drawn at random for both. See its NOTE.md.")),
    "panda_spatial_patch32": (ARCHIVED, ("Issue 33's fourth Panda round: lift-cube, 8 demos, 3,000 steps, R&D-AI with "
                              "the MetaWorld CPU tier's 32-px patches: 4/27, ACT 4/27; own demo placements 1/8 "
                              "against ACT's 7/8; validation seeds 1/20, slopes x 0.47, y 0.10; first chunk at frame "
                              "0 x 0.50, y 0.07 (traces/, with 10 denoising steps and a still history too). "
                              "Superseded: with 16-px patches 17/20 on the validation seeds; the Panda config now "
                              "uses them (ACT's run stays current). See its NOTE.md.")),
    "panda_spatial_fast_expert": (ARCHIVED, ("Issue 33's third Panda round: lift-cube, 8 demos, 3,000 steps, re-framed "
                                  "cameras, R&D-AI only: 2/27; 0/20 on validation seeds with slopes x 0.03, y -0.01; on "
                                  "its own demos the first chunk's lateral motion has slope 0.01 (traces/). "
                                  "Superseded: the expert made the whole goal-dependent approach in 5-8 steps, one "
                                  "action chunk planned from the first frame; it now approaches at 0.4 of full speed "
                                  "(10-19 steps). See its NOTE.md.")),
    "panda_spatial_camera_v1": (ARCHIVED, "Issue 33's second Panda spatial round (lift-cube, 8 demos, 3,000 steps): "
                                "R&D-AI 2/27, ACT 3/27, each only at the centre; on their own demo placements 2/8 "
                                "and 1/8; traced on validation seeds neither followed the cube (slopes about 0; "
                                "traces/). Superseded: the front camera showed the cube 8-11 px wide at 128 px and "
                                "the wrist camera lost it away from the centre; the cameras were re-framed. See its "
                                "NOTE.md."),
    "panda_spatial_raw_yaw": (ARCHIVED, "Issue 33's first Panda spatial runs (3,000 steps, 27-cell x/y/yaw grid): "
                              "lift-cube R&D-AI 2/27 with 4 demos and 2/27 with 8, ACT 3/27 with 8; push-block R&D-AI "
                              "0/27 with 2. Superseded: furthest-point sampling compared the cube's yaw without its "
                              "90-degree symmetry, so 3 of the 8 lift-cube demos were near-twins of others (1-2 cm "
                              "apart, yaw +43 against -37 degrees: the same view) that the expert grasped turning "
                              "opposite ways; both methods then failed 7 of their own 8 demo placements "
                              "(train_placements_lift-cube_n8.json). See its NOTE.md; the demos were re-sampled."),
    "so101_reach_wrist_spin": (ARCHIVED, "R&D-AI on SO-101 reach-target (10 demos, measured cameras, 3,000 steps): "
                               "0/50. Superseded: the scripted expert rolled the wrist far in every "
                               "demo, one way or the other by the side of the ball; the policy fitted the demos on "
                               "their own frames (chunk_goal_response.json) but reached no ball. The expert now "
                               "keeps the roll (see its NOTE.md); the demos were re-recorded."),
    "so101_measured_anchor": (ARCHIVED, "SO-101 R&D-AI (the ball on its post; 10 random demos, measured cameras, "
                              "3,000 steps, 50 test episodes from seed 1000): reach-target 1/50, pick-cube 0/50, "
                              "reach-target with 20 demos 1/50, with MuJoCo's exact cameras 2/50; with their "
                              "validation traces and open-loop checks. Superseded: their chunks started from the "
                              "measured joints, which sag below the command under gravity, so holding still sank "
                              "the arm; the SO-101 adapter now starts them from the last command (see its "
                              "NOTE.md)."),
    "so101_reach_floating_ball": (ARCHIVED, "SO-101 reach-target with the ball floating (10 demos, measured cameras, "
                                  "3,000 steps, 50 test episodes from seed 1000): R&D-AI 3/50, ACT 5/50; 20 demos "
                                  "R&D-AI 3/50; with every trace and open-loop diagnostic of those checkpoints and "
                                  "of the variants tried on that task (16-px patches, 16-step chunks, joint-space "
                                  "diffusion, IK weight 0.1). Superseded: from the front camera balls 19 cm apart on "
                                  "one viewing ray fell on the same pixel, only their size (7-13 px) told them "
                                  "apart (so101_reach_ray.json), so no policy could place the goal. The ball now "
                                  "stands on a post; see its NOTE.md."),
    "so101_ik_weight_gripper50": (ARCHIVED, "First SO-101 R&D-AI checkpoints (reach-target, pick-cube; 10 demos, "
                                  "3,000 steps) per IK orientation weight 1 / 0.1 on validation seeds 100-129: 2/30 "
                                  "and 2/30, 0/30 and 0/30. Superseded: they read the demos' gripper with a fixed "
                                  "threshold of 50, so the expert's 40-60 approach counted as closed; the policy "
                                  "shut the jaws at the start and lifted. The gripper range now comes from the demos."),
    "cpu": (ARCHIVED, "The first CPU benchmark: 1,000 steps, the earlier linear patch embedding, 4-step sampling; "
            "superseded by the 3,000-step runs."),
    "cpu_3000_conv": (ARCHIVED, "R&D-AI on reach-v3 (training seed 0) with 4-step sampling; the current reach-v3 "
                      "R&D-AI figure is the seed-1 checkpoint sampled with 1 step (one_step_sampling_test.json); "
                      "both gave 26/50."),
    "cpu_3000_three_tasks": (ARCHIVED, "A collection of the three tasks' 3,000-step runs with 4-step R&D-AI rows; "
                             "superseded by the generated headline of docs/BENCHMARKS.md (R&D-AI from "
                             "one_step_sampling_test.json)."),
    "cpu_3000_reach_demos": (ARCHIVED, "A collection of the 10- and 20-demo reach-v3 runs with 4-step R&D-AI rows; the "
                             "runs are in cpu_3000, cpu_3000_reach_n20 and archive/cpu_3000_conv."),
    "cpu_3000_reach_variants": (ARCHIVED, "Exploratory: R&D-A and R&D-I at the CPU tier's size (no shipped CPU config "
                                "for them), 4-step sampling."),
    "cpu_3000_reach_n20_camera_mismatch": (ARCHIVED, "Evaluated with another corner2 camera pose than the demos show "
                                           "(a harness bug, fixed): see its NOTE.md."),
    "cpu_3000_p16": (ARCHIVED, "Trained only: the 16-px patch ablation (its validation row is in "
                     "ablation_cpu_tcp_3000.json)."),
    "cpu_3000_shift": (ARCHIVED, f"Trained only: image_shift_augment=6, a switch retired at tag {TAG}."),
    "cpu_3000_w384": (ARCHIVED, "Exploratory: twice the width (dim_model=384), not a shipped config; 25/50 against "
                      "the default's 26/50."),
    "cpu_3000_w384_n20": (ARCHIVED, "Exploratory: twice the width at 20 demos, not a shipped config."),
    "cpu_9000": (ARCHIVED, "Trained only: 9,000 steps for validation_curve_cpu_9000.json."),
    "cpu_reach_hand_expert": (ARCHIVED, "reach-v3 on demos of the earlier reach expert (MetaWorld's hand target, "
                              "demos end 3.4-4.9 cm from the goal); superseded by the corrected expert's demos."),
    "smoke": (ARCHIVED, "Smoke-scale harness check of the paper-size configs (a few steps), not a measurement."),
    "ablation_cpu.json": (ARCHIVED, "Validation-seed ablations on the earlier reach-v3 demos (hand-target expert); "
                          f"most rows use switches retired at tag {TAG}."),
    "ablation_cpu_tcp_3000.json": (ARCHIVED, "Validation-seed ablations of the CPU tier on reach-v3 (exploratory; "
                                   f"many rows use switches retired at tag {TAG}); summarised in docs/REACH.md."),
    "ablation_cpu_tcp_3000_3cam.json": (ARCHIVED, "Exploratory: a third camera (topview) on reach-v3, validation seeds."),
    "ablation_cpu_tcp_3000_corner2_topview.json": (ARCHIVED, "Exploratory: corner2 + topview cameras on reach-v3, "
                                                   "validation seeds."),
    "ablation_cpu_tcp_3000_extra40.json": (ARCHIVED, "Exploratory: demos that go on 40 frames after success, "
                                           "validation seeds."),
    "ablation_cpu_tcp_3000_n20.json": (ARCHIVED, "Exploratory: width 384 at 20 demos, validation seeds."),
    "ablation_cpu_tcp_6000_n20.json": (ARCHIVED, "Validation seeds of the 20-demo 6,000-step R&D-AI run; its test-seed "
                                       "result is reach_n20_6000steps_test.json."),
    "episode_overlap_cpu_tcp_3000.json": (ARCHIVED, "Analysis: which episodes the rows of ablation_cpu_tcp_3000.json "
                                          "solve."),
    "one_step_sampling_val.json": (ARCHIVED, "1 vs 4 denoising steps on validation seeds; superseded by the test-seed "
                                   "measurement one_step_sampling_test.json."),
    "quickstart_cpu.json": (ARCHIVED, "reach-v3 quickstart on demos of the earlier reach expert."),
    "quickstart_drawer_4steps_cpu.json": (ARCHIVED, "Quickstart with 4 denoising steps; superseded by "
                                          "quickstart_drawer_cpu.json (1 step)."),
    "quickstart_drawer_linear_cpu.json": (ARCHIVED, "Quickstart with the earlier linear patch embedding; superseded by "
                                          "quickstart_drawer_cpu.json."),
    "inference_cpu.json": (ARCHIVED, "The first inference measurement: the legacy CPU config and the paper size, 4 "
                           "steps, float32, on a loaded machine; superseded by inference_cpu_tier_avx512.json."),
    "inference_cpu_tier.json": (ARCHIVED, "The CPU tier on an AVX2 CPU with 4 denoising steps; the shipped config "
                                "samples with 1 (inference_cpu_tier_avx512.json)."),
    "inference_cpu_tier_avx512_4steps.json": (ARCHIVED, "The CPU tier with 4 denoising steps; superseded by "
                                              "inference_cpu_tier_avx512.json (1 step)."),
    "reach_goal_views.json": (ARCHIVED, "Exploratory (reach-v3 investigation, docs/REACH.md): where the goal marker "
                              "appears in each camera."),
    "trace_reach_conv3x3_stem.json": (ARCHIVED, f"Exploratory trace of the conv3x3-stem ablation (retired at tag {TAG})."),
    "trace_reach_current_defaults.json": (ARCHIVED, "Exploratory trace of the 10-demo validation checkpoint "
                                          "(docs/REACH.md)."),
    "trace_reach_inference_steps_1.json": (ARCHIVED, "Exploratory trace of that checkpoint sampled with 1 step."),
    "trace_reach_n10_act_seed1.json": (ARCHIVED, "Exploratory trace of ACT's second training seed (10 demos)."),
    "trace_reach_n20_act.json": (ARCHIVED, "Exploratory trace of the 20-demo 3,000-step ACT checkpoint."),
    "trace_reach_n20_rnd_ai.json": (ARCHIVED, "Exploratory trace of the 20-demo 3,000-step R&D-AI checkpoint."),
    "trace_reach_width_384.json": (ARCHIVED, "Exploratory trace of the width-384 ablation."),
    "train_placements_reach_n20.json": (ARCHIVED, "Diagnostic: the 20-demo checkpoints replayed on their own demo "
                                        "placements (docs/REACH.md)."),
    "train_placements_reach_n20_act_6000.json": (ARCHIVED, "Diagnostic: ACT's 6,000-step 20-demo checkpoint on its own "
                                                 "demo placements."),
    "validation_curve_cpu_3000_reach_n20.json": (ARCHIVED, "Exploratory: validation-seed success of the 20-demo "
                                                 "3,000-step checkpoint."),
    "validation_curve_cpu_9000.json": (ARCHIVED, "Exploratory: validation-seed success against training step up to "
                                       "9,000 steps."),
}


def find_entries(results: Path = RESULTS) -> dict[str, Path]:
    """Every entry on disk: top-level JSON files and folders of `results` and of `results/archive`, by name.

    A name found in both places is reported under both keys (`name` and `archive/name`), so a duplicate shows.
    """
    found = {}
    for base, prefix in ((results, ""), (results / ARCHIVE, ARCHIVE + "/")):
        if not base.is_dir():
            continue
        for p in sorted(base.iterdir()):
            if p.is_dir() and p.name != ARCHIVE and any(p.rglob("*.json")):
                found[prefix + p.name] = p
            elif p.is_file() and p.suffix == ".json":
                found[prefix + p.name] = p
    return found


def check_placement(found: dict[str, Path], status: dict[str, tuple[str, str]]) -> list[str]:
    """Problems: an entry STATUS does not classify, one it names but is missing, one in the wrong folder."""
    problems = []
    names = {key.removeprefix(ARCHIVE + "/") for key in found}
    for key in found:
        name = key.removeprefix(ARCHIVE + "/")
        if name not in status:
            problems.append(f"{key}: not in STATUS (say whether it is current or archived, and why)")
            continue
        want = ARCHIVE + "/" + name if status[name][0] == ARCHIVED else name
        if key != want:
            problems.append(f"{key}: STATUS says {status[name][0]}, so it belongs at {want}")
    for name, (state, _) in status.items():
        if state not in (CURRENT, ARCHIVED):
            problems.append(f"{name}: unknown status {state!r}")
        if name not in names:
            problems.append(f"{name}: in STATUS but not on disk")
    return problems


def _load(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _python(command: str) -> str:
    """A recorded command with the interpreter's path (a virtual environment's) shortened to `python`."""
    return re.sub(r"^\S*/python[0-9.]*\s", "python ", command.strip())


def _resolve(recorded: str, results: Path) -> Path:
    """A path recorded inside a JSON (relative to the repository), or its archived place when it was moved."""
    path = REPO / recorded
    if not path.exists() and recorded.startswith("benchmarks/results/"):
        moved = results / ARCHIVE / recorded.removeprefix("benchmarks/results/")
        if moved.exists():
            return moved
    return path


def _strings(obj, out: list[str]) -> list[str]:
    if isinstance(obj, str):
        out.append(obj)
    elif isinstance(obj, dict):
        for v in obj.values():
            _strings(v, out)
    elif isinstance(obj, list):
        for v in obj:
            _strings(v, out)
    return out


def _unique(items) -> list[str]:
    return list(dict.fromkeys(i for i in items if i))


def _jsons(path: Path) -> list[tuple[str, dict]]:
    """(relative name, data) of an entry's JSON files: the file itself, or a folder's results JSON and run JSONs."""
    if path.is_file():
        return [(path.name, _load(path))]
    return [(str(p.relative_to(path)), _load(p)) for p in sorted(path.rglob("*.json"))]


def commands_of(path: Path) -> list[str]:
    """The commands that produced an entry, as its JSON records them."""
    commands = []
    for _, data in _jsons(path):
        if not isinstance(data, dict):
            continue
        bench = data.get("benchmark")
        if isinstance(bench, dict):  # a report joined from several calls (run_benchmark.py) lists the earlier ones
            commands += [_python(c) for c in bench.get("earlier_commands") or [] if isinstance(c, str)]
        if isinstance(bench, dict) and bench.get("command"):
            commands.append(_python(bench["command"]))
        if isinstance(data.get("command"), str) and not data.get("method"):  # a run JSON's commands are lerobot's
            commands.append(_python(data["command"]))
        if isinstance(data.get("commands"), list):
            commands += [_python(c) for c in data["commands"] if isinstance(c, str)]
        for row in data.get("rows") or []:
            if isinstance(row, dict) and row.get("ablation_command"):
                commands.append(_python(row["ablation_command"]))
    if not commands:  # a hand-assembled file: the commands of its runs / entries
        for _, data in _jsons(path):
            for key in ("runs", "entries", "rows"):
                for item in (data.get(key) or []) if isinstance(data, dict) else []:
                    if isinstance(item, dict) and isinstance(item.get("command"), str):
                        commands.append(_python(item["command"]))
    return _unique(commands)


def commits_of(path: Path, results: Path) -> list[str]:
    """The code commits an entry records (its own, its runs', or those of the runs a collection reads)."""
    commits = []
    for _, data in _jsons(path):
        if not isinstance(data, dict):
            continue
        commits += [data.get("code_commit"), data.get("commit")]
        for run in data.get("runs") or []:
            if isinstance(run, dict) and run.get("collected_from"):
                commits.append((_load(_resolve(run["collected_from"], results)) or {}).get("code_commit"))
    return _unique(c[:7] + ("+dirty" if c.endswith("+dirty") else "") if isinstance(c, str) else None for c in commits)


def configs_of(path: Path) -> list[str]:
    """The policies_config files (and extra training switches) an entry records."""
    configs = []
    for _, data in _jsons(path):
        if not isinstance(data, dict):
            continue
        settings = data.get("settings")
        if isinstance(settings, dict) and isinstance(settings.get("config_files"), dict):
            configs += settings["config_files"].values()
        bench = data.get("benchmark")
        if isinstance(bench, dict):
            configs += [f"`{a}`" for a in bench.get("train_arg") or []]
        if data.get("benchmark") == "train_step":
            # bench_train_step.py methods: NAME (MetaWorld) or SUITE/NAME
            configs += [f"policies_config/{r['method'] if '/' in r['method'] else 'metaworld/' + r['method']}.json"
                        for r in data.get("results", [])]
        if isinstance(data.get("configs"), dict):  # loss_parity.py: config file -> losses
            configs += [f"policies_config/{name}" for name in data["configs"]]
        if isinstance(data.get("args"), dict) and isinstance(data.get("results"), list):  # bench_inference.py
            configs += [f"`{r['method']}: {r['config']}`" for r in data["results"] if r.get("config")]
        for entry in data.get("entries") or []:  # sampler_steps.py --run-json: the checkpoint's training config
            if isinstance(entry, dict) and isinstance(entry.get("source"), str) and entry["source"].endswith(".json"):
                run = _load(_resolve(entry["source"], RESULTS)) or {}
                configs += [m.group(0) for s in _strings(run.get("commands", {}), [])
                            for m in re.finditer(r"policies_config/[\w/]+\.json", s)]  # fmt: skip
        if not configs:
            configs += [m.group(0) for s in _strings(data, []) for m in re.finditer(r"policies_config/[\w/]+\.json", s)]
    return _unique(c.removeprefix(str(REPO) + "/") for c in configs)


def _code(text: str, limit: int = 400) -> str:
    text = text if len(text) <= limit else text[: limit - 3] + "..."
    return "`" + text.replace("`", "'") + "`"


def build_index(results: Path = RESULTS, status: dict[str, tuple[str, str]] = STATUS) -> str:
    found = find_entries(results)
    problems = check_placement(found, status)
    if problems:
        raise ValueError("benchmarks/results does not match STATUS in benchmarks/write_results_index.py:\n  "
                         + "\n  ".join(problems))  # fmt: skip
    lines = [
        "# Results index",
        "",
        "Generated by `python benchmarks/write_results_index.py` from the JSON; do not edit. Every result under "
        "`benchmarks/results/` is listed once. *Current* results measure configs that ship in `policies_config/` "
        "(the latest measurement of each kind); *archived* ones, under `archive/` with their original names, are "
        "superseded or exploratory. Paths recorded inside the JSON (commands, `collected_from`) are those of the "
        "time of the run, before archived entries moved to `archive/`. The ablation rows of the config switches retired from `RnDConfig` were run with the code "
        f"at git tag `{TAG}`. docs/BENCHMARKS.md shows the current results.",
        "",
    ]
    for state, title in ((CURRENT, "Current"), (ARCHIVED, "Archived (`archive/`)")):
        keys = [k for k in found if status[k.removeprefix(ARCHIVE + "/")][0] == state]
        lines += [f"## {title} ({len(keys)})", ""]
        for key in keys:
            path = found[key]
            name = key.removeprefix(ARCHIVE + "/")
            link = key + ("/" if path.is_dir() else "")
            png = path.with_suffix(".png")
            extra = f" (plot: [`{png.name}`]({key.removesuffix('.json')}.png))" if path.is_file() and png.exists() else ""
            label = "why archived" if state == ARCHIVED else "what"
            lines.append(f"- [`{key}`]({link}) — **{state}**{extra}. {label.capitalize()}: {status[name][1]}")
            commands = commands_of(path)
            if commands:
                more = f" (and {len(commands) - 1} more in the JSON)" if len(commands) > 1 else ""
                lines.append(f"  - command: {_code(commands[0])}{more}")
            else:
                lines.append("  - command: not recorded")
            configs = configs_of(path)
            lines.append("  - config: " + (", ".join(c if c.startswith("`") else f"`{c}`" for c in configs)
                                           if configs else "not recorded"))  # fmt: skip
            commits = commits_of(path, results)
            lines.append("  - code commit: " + (", ".join(f"`{c}`" for c in commits) if commits else "not recorded"))
        lines.append("")
    return "\n".join(lines)


def listed_entries(text: str) -> list[str]:
    """The entries an INDEX.md lists, in order (one per `- [`name`](...)` line)."""
    return re.findall(r"^- \[`([^`]+)`\]", text, flags=re.M)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--check", action="store_true", help="exit 1 when INDEX.md differs from what the JSON gives")
    a = p.parse_args(argv)
    text = build_index(RESULTS, STATUS)  # the module's values at call time (tests point them elsewhere)
    out = RESULTS / INDEX
    if a.check:
        if not out.exists() or out.read_text() != text:
            print(f"{out} is out of date: run python benchmarks/write_results_index.py", file=sys.stderr)
            return 1
        return 0
    out.write_text(text)
    print(f"wrote {out} ({len(listed_entries(text))} entries)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

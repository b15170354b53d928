"""Success-rate benchmark: R&D (A, I, AI) against LeRobot's ACT and Diffusion Policy on MetaWorld (or, with
--suite panda, on the 6-DoF Panda + Robotiq tasks).

One command records (or reuses) scripted demonstrations for every task and demo count, trains every
method on the same demos with matched settings through ``lerobot-train``, evaluates every checkpoint on the
same held-out placements through ``lerobot-eval`` and writes, in ``--out``:

    results.json          every run: method, task, demos, seed, steps, training time, parameters, evaluation
                          episodes and seeds, successes, success rate, Wilson 95% interval, checkpoint and the
                          exact commands; the datasets (placements) and the held-out check
    results.md            success table (rows: methods, columns: task x demos, plus the average), training
                          time / size table, and where R&D loses
    success_vs_demos.png  success rate against the number of demos, per task and averaged, Wilson bars
    heatmap_<task>.png    (--protocol spatial) success over the placement grid, training placements marked

    python benchmarks/run_benchmark.py --scale smoke --out benchmarks/results/smoke           # CPU, minutes
    python benchmarks/run_benchmark.py --scale gpu --tasks reach-v3,push-v3 --demos 10,20 \\
        --out benchmarks/results/gpu --resume --max-minutes 9                                # one GPU slice

Scales (every value can be overridden on the command line; see benchmarks/README.md):
  smoke  CPU, tiny models (R&D 1 x 64, ACT 64-wide, DP [32, 64]), 2 steps of batch 2, 2 evaluation
         episodes of 16 steps: proves the pipeline, says nothing about the methods.
  gpu    CUDA, ~100M parameters each (R&D paper size 8 x 1024: 107M; ACT 768-wide, 6 encoder layers: 92M;
         DP U-Net [640, 1280]: 107M), batch 32 x 25k steps (= the paper's 8 x 100k samples), 50 evaluation
         episodes per task and demo count, 300-step episodes.

Matched settings: every method trains on the same recorded demos (the n-demo set is the first n episodes of
the larger sets: recorded once, then extended with the recorder's --resume), with the same seed, batch size,
number of steps and checkpoint schedule, no pretrained weights (nothing is downloaded: ACT's ImageNet
backbone is switched off), observation history 2 (ACT: 1, the only value LeRobot's ACT accepts) and an
8-step action chunk executed open loop (DP: horizon 12 = 1 past + 8 executed + 3 for the U-Net's 4x
downsampling, of which 8 are executed). Each method keeps its own optimiser preset (learning rate, schedule).
Every policy is evaluated on the observations of its demos: a dataset recorded with other cameras, image size,
corner2 position or state layout than the env's defaults is evaluated with the matching ``--env.*`` flags
(``lerobot_rnd.sim.record.recorded_env_args``).

Held-out placements: demos are recorded with placements drawn from ``numpy.random.default_rng(record_seed)``
(--protocol random) or by furthest point sampling (spatial). ``lerobot-eval --seed=S --eval.n_episodes=N``
resets episode i's env with ``seed=S+i``; the ``rnd_mw`` env then draws its placement from a generator
seeded with S+i (the same PCG64 stream a recorder with ``--seed S+i`` would start with), so the evaluation
seeds must not include the recording seed. The harness computes every evaluation placement and stores its
distance to the nearest training placement in results.json. The spatial protocol evaluates one episode on
every valid point of a grid over two placement coordinates (the others at the centre of their range), with
an in-process copy of lerobot-eval's loop (``rnd_mw`` takes no placement list on the command line).

Panda suite (--suite panda; smoke and cpu scales): records with ``lerobot-rnd-record --suite panda``, trains from
policies_config/panda/*_cpu.json, evaluates with ``--env.type=rnd_panda`` (120-step episodes). Its spatial protocol
records demos by furthest point sampling over the object's x, y and yaw (modulo its 90-degree symmetry) starting from the centre of the range
(``--placements fps-centre``; a target drawn at random, seeded, for demos and grid cells alike) and evaluates on a
G x G x --grid-yaws grid over x, y and yaw (default 3 x 3 x 3 = 27 cell centres), one x-y heat map per yaw.

SO-101 suite (--suite so101; smoke and cpu scales): records with ``lerobot-rnd-record --suite so101``, replaces each
dataset's cameras by those ``lerobot-rnd-calibrate`` measures on a simulated calibration session (``--calibration
measured``; ``exact`` keeps MuJoCo's), trains from policies_config/so101/*_cpu.json, evaluates with
``--env.type=rnd_so101`` (150-step episodes).

Time budget and resumption: with ``--max-minutes M`` the harness stops starting work that would not fit,
stops training cleanly (right after a checkpoint when the next one would not fit, otherwise at the deadline,
losing the steps since the last checkpoint) and exits with code 3; run the same command again with
``--resume`` to continue: training resumes from ``checkpoints/last`` with ``lerobot-train --resume=true``
(same total --steps, so learning-rate schedules are unchanged), evaluation continues chunk by chunk, finished
runs are skipped. Exit codes: 0 complete, 3 work remains, 1 some run failed (its log tail is in
results.json).

Collecting runs: ``--collect-from A,B`` reads a run this benchmark lacks from the first of the results folders
A, B whose ``runs/`` holds it finished, without copying it (the folders' steps, batch, seeds, episode length
and episodes per cell must match; results.md names each run's source). One table over tasks that were run
as separate benchmarks is then a report of those runs, and redoing a source run updates it.
"""

# The harness behind benchmarks/run_benchmark.py, one module per concept (docs/DESIGN.md lists them):
#   scales     what runs: methods, scales, per-method lerobot-train arguments
#   files      JSON files written atomically, repository-relative paths
#   processes  subprocesses: launching, logs, time budget, signals, the lerobot tool wrappers
#   runs       the benchmark: datasets, evaluation placements, train / evaluate / resume per run, results.json
#   reports    pure functions of results.json: Wilson intervals, results.md, plots
#   grid_eval  the spatial protocol: the evaluation grid and lerobot-eval's loop over explicit placements
#   cli        the command line (argparse) and main
# This docstring is the --help text of run_benchmark.py.

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
# the command line; it also runs the wrappers the harness starts as subprocesses (``_lerobot-train`` ...)
ENTRY_POINT = REPO_ROOT / "benchmarks" / "run_benchmark.py"

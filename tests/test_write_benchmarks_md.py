"""benchmarks/write_benchmarks_md.py: the success-by-distance table counts episodes by hand-placed goals."""

from __future__ import annotations

from benchmarks.write_benchmarks_md import generalisation_section


def test_success_by_distance_to_the_nearest_demo_goal():
    def placement(goal_xyz):  # reach-v3: [object xyz, goal xyz]; the object must not count
        return [0.5, 0.5, 0.5, *goal_xyz]

    train = [placement([0.0, 0.8, 0.1]), placement([0.1, 0.8, 0.1])]
    # nearest demo goal at 1 cm, 5 cm (3-4-5 triangle), 7 cm and 30 cm
    evals = [placement([0.01, 0.8, 0.1]), placement([0.13, 0.84, 0.1]), placement([0.0, 0.8, 0.17]),
             placement([0.0, 0.8, 0.4])]  # fmt: skip
    res = {
        "eval_sets": {"reach-v3": {"placements": evals}},
        "datasets": {"reach-v3": {"10": {"placements": train}}},
        "runs": [{"task": "reach-v3", "label": "R&D-AI", "demos": 10, "per_episode_success": [True, True, False, True]},
                 {"task": "drawer-close-v3", "label": "R&D-AI", "demos": 10, "per_episode_success": [True]}],
    }  # fmt: skip
    lines = generalisation_section(res, "cpu")
    assert "| R&D-AI | 10 | 1/1 | 1/1 | 0/1 | 1/1 |" in lines
    assert sum(line.startswith("| R&D-AI") for line in lines) == 1  # drawer-close has no goal to measure

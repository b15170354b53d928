"""The prepared GPU check must be known to work before a GPU is there: its --smoke mode on the CPU."""

import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_device_check_smoke_runs_on_cpu_and_writes_its_json(tmp_path):
    out = tmp_path / "device_check.json"
    env = {**os.environ, "PYTHON": sys.executable, "HF_HUB_OFFLINE": "1"}
    r = subprocess.run(
        ["bash", str(REPO / "benchmarks" / "device_check.sh"), "--smoke", "--device", "cpu", "--out", str(out)],
        capture_output=True, text=True, env=env, timeout=300,
    )
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    res = json.loads(out.read_text())
    lat = res["latency_batch1"]
    assert set(lat) == {"rnd_ai_eager", "act", "diffusion_ddim10"}
    assert all(v["median_ms"] > 0 for v in lat.values())
    assert abs(lat["act"]["ratio_to_act"] - 1.0) < 1e-9
    assert res["train_step"]["batch"] == 2
    assert res["train_step"]["rnd_ai"]["ratio_to_bare_vit"] > 0
    assert res["compiled"].startswith("skipped")
    assert res["wall_s"] < 120

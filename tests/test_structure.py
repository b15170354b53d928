"""The package's structure (docs/DESIGN.md): core modules never import the simulators, imports have no cycle,
modules stay small, and importing the policy has no side effects on the environment.

Reference: the import statements in the source (read with `ast`, including imports inside functions) and a
fresh Python process.
"""

import ast
import json
import subprocess
import sys

from tests.helpers import REPO_ROOT

PACKAGE = REPO_ROOT / "lerobot_rnd"
MAX_MODULE_LINES = 850


def _module_name(path) -> str:
    parts = list(path.relative_to(REPO_ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _imports(path) -> set[str]:
    """The package modules `path` imports anywhere in its code (`from pkg import name` counts as pkg.name when
    that is a module). Implicit imports of parent packages are not edges: Python runs a package's __init__
    before its submodules, so they cannot form a cycle of partially initialised modules by themselves."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                sub = f"{node.module}.{alias.name}"
                out.add(sub if sub in MODULES else node.module)
    return {m for m in out if m in MODULES}


GRAPH = {name: _imports(path) for name, path in MODULES.items()}


def test_core_modules_never_import_the_simulators():
    core = [name for name in MODULES if not name.startswith("lerobot_rnd.sim")]
    assert "lerobot_rnd.embodiment" in core and "lerobot_rnd.modeling_rnd" in core
    offenders = {name: sorted(m for m in GRAPH[name] if m.startswith("lerobot_rnd.sim")) for name in core}
    assert not {k: v for k, v in offenders.items() if v}, offenders


def test_the_package_imports_have_no_cycle():
    state: dict[str, int] = {}  # 1: on the DFS stack, 2: done
    stack: list[str] = []
    cycles = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(GRAPH[node]):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt) :] + [nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for name in sorted(GRAPH):
        if name not in state:
            visit(name)
    assert not cycles, [" -> ".join(c) for c in cycles]
    # the walk does see the imports made inside functions (the former embodiment <-> sim cycle was lazy)
    assert "lerobot_rnd.rendering" in GRAPH["lerobot_rnd.embodiment_binding"]


def test_no_module_is_over_the_size_limit():
    sizes = {name: len(path.read_text().splitlines()) for name, path in MODULES.items()}
    assert max(sizes.values()) <= MAX_MODULE_LINES, {k: v for k, v in sizes.items() if v > MAX_MODULE_LINES}


def test_importing_the_policy_imports_no_simulator_and_sets_no_environment_variable():
    code = (
        "import json, os, sys\n"
        "before = dict(os.environ)\n"
        "import lerobot_rnd, lerobot_rnd.modeling_rnd, lerobot_rnd.processor_rnd, lerobot_rnd.embodiment\n"
        "changed = sorted(k for k in set(before) | set(os.environ) if before.get(k) != os.environ.get(k))\n"
        "loaded = sorted(m for m in ('lerobot_rnd.sim', 'mujoco', 'metaworld', 'gym_hil') if m in sys.modules)\n"
        "print(json.dumps({'changed': changed, 'loaded': loaded}))\n"
    )
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result == {"changed": [], "loaded": []}, result

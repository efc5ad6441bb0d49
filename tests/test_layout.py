"""The layout's rules, checked on the source (docs/architecture.md):

- no import cycle among the project's modules (imports inside functions and under
  `if TYPE_CHECKING:` count too: a type-only circle is still two modules that know each other);
- the packages are layered: a module imports only its own layer and the layers below it
  (`LAYERS`, bottom first);
- only `sim_backend` imports pybullet;
- in `omnisort_hw`, only the device factory, the demos, the CLI's `sim`/`evaluate` commands
  and the evaluation package import `sim_backend`; the core imports nothing of the product
  but the core, its errors and its atomic file writes;
- the CLI imports `sim_backend` only inside its command functions, never at module level or
  in a `register()` (every `omnisort` start builds every parser);
- no code asks whether a device is simulated (`hasattr(x, "cell")` and the like);
- no product module is over 800 lines (the hard limit of the style guide), and one over 600
  says why in its docstring ("Over 600 lines: ...").
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("omnisort_hw", "drivers", "sim_backend")
MAX_LINES = 800
SOFT_LINES = 600
SIM_IMPORTERS = {
    "omnisort_hw.cell.devices",
    "omnisort_hw.cli.demo_cmd",
    "omnisort_hw.cli.sim_cmd",
    "omnisort_hw.cli.evaluate_cmd",
    "omnisort_hw.service.demo",
    "omnisort_hw.service.virtual_cell_demo",
}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
            out[".".join(parts)] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """Every module `name` imports (absolute and relative), resolved to a module or package."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_pkg = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = name.split(".")[: len(name.split(".")) - node.level + (1 if is_pkg else 0)]
                base = ".".join([*parent, base] if base else parent)
            for alias in node.names:
                full = f"{base}.{alias.name}"
                out.add(full if full in MODULES else base)
    return out


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _project_edges(name: str) -> set[str]:
    return {m for m in GRAPH[name] if m in MODULES and m != name}


def test_no_import_cycle() -> None:
    """Tarjan's strongly connected components: every component must be a single module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in _project_edges(v):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in MODULES:
        if v not in index:
            visit(v)
    assert cycles == [], cycles


# Bottom first. The drivers sit below the configuration because the cell file's device
# sections are parsed into each driver's own config dataclass; the simulator sits above it
# (it reads the same sections); the evaluation is an experiment over the pipeline and the
# simulator that the CLI's `evaluate` runs.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("omnisort_hw", "omnisort_hw.errors", "omnisort_hw.fileio", "omnisort_hw.runlog"),
    ("omnisort_hw.core",),
    ("omnisort_hw.sweeps",),  # runs trials it names by string: knows no experiment
    ("drivers",),
    ("omnisort_hw.config",),
    ("sim_backend",),
    ("omnisort_hw.pipeline",),
    ("omnisort_hw.evaluation",),
    ("omnisort_hw.cell",),
    ("omnisort_hw.cli", "omnisort_hw.service", "omnisort_hw.ui"),
)


def _layer(name: str) -> int:
    """The index in LAYERS of the longest prefix of `name`."""
    best, found = -1, -1
    for i, prefixes in enumerate(LAYERS):
        for pre in prefixes:
            if (name == pre or name.startswith(pre + ".")) and len(pre) > best:
                best, found = len(pre), i
    return found


def test_every_module_has_a_layer() -> None:
    assert [n for n in MODULES if _layer(n) < 0] == []


def test_packages_import_only_downwards() -> None:
    up = sorted(f"{n} -> {d}" for n in MODULES for d in _project_edges(n) if _layer(d) > _layer(n))
    assert up == [], up


def test_the_interface_is_only_a_client_of_the_service() -> None:
    """`omnisort ui` reaches the cell through the protocol alone: none of its modules imports
    the cell, the devices, the simulator or the service's own inside."""
    inside = (
        "omnisort_hw.cell",
        "drivers",
        "sim_backend",
        "omnisort_hw.service.server",
        "omnisort_hw.service.handlers",
        "omnisort_hw.service.jobs",
    )
    ui = [n for n in MODULES if n.startswith("omnisort_hw.ui")]
    assert "omnisort_hw.ui.link" in ui
    found = [
        f"{n} -> {d}"
        for n in ui
        for d in _project_edges(n)
        if any(d == p or d.startswith(p + ".") for p in inside)
    ]
    assert found == [], found


def test_the_layer_rule_sees_an_upward_import() -> None:
    """The checker itself: a pipeline module importing the cell is upward, the reverse not."""
    assert _layer("omnisort_hw.pipeline.sort") < _layer("omnisort_hw.cell.cell")
    assert _layer("omnisort_hw.errors") == 0
    assert _layer("omnisort_hw.cli.output") == _layer("omnisort_hw.service.server")


def test_the_rules_see_imports() -> None:
    """The checker itself: it finds known edges, lazy and relative ones included."""
    assert "omnisort_hw.pipeline.sort" in GRAPH["omnisort_hw.cell.cell"]
    assert "sim_backend.sort_harness" in GRAPH["omnisort_hw.cell.devices"]  # inside a function
    assert "pybullet" in GRAPH["sim_backend.world"]
    assert (
        "omnisort_hw.core.extrinsics.system_calibration"
        in GRAPH["omnisort_hw.core.extrinsics.joint"]
    )
    assert "omnisort_hw.cell.devices" in GRAPH["omnisort_hw.cell.jobs"]  # under TYPE_CHECKING


def test_only_sim_backend_imports_pybullet() -> None:
    users = sorted(
        n
        for n, deps in GRAPH.items()
        if "pybullet" in deps or any(d.startswith("pybullet.") for d in deps)
    )
    assert users and all(u.startswith("sim_backend") for u in users), users


@pytest.mark.parametrize("prefix", ["omnisort_hw", "drivers"])
def test_who_imports_the_simulator(prefix: str) -> None:
    bad = sorted(
        n
        for n, deps in GRAPH.items()
        if n.startswith(prefix)
        and any(d == "sim_backend" or d.startswith("sim_backend.") for d in deps)
        and n not in SIM_IMPORTERS
        and not n.startswith("omnisort_hw.evaluation")
    )
    assert bad == [], f"{bad} import sim_backend (allowed: {sorted(SIM_IMPORTERS)}, evaluation)"


def _sim_imports_at_start(tree: ast.Module) -> list[int]:
    """Lines importing sim_backend at module level or in `register()`: what runs at start."""
    starting: list[ast.AST] = [n for n in tree.body if not isinstance(n, ast.FunctionDef)]
    starting += [n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "register"]
    lines = []
    for top in starting:
        for node in ast.walk(top):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            if any(n == "sim_backend" or n.startswith("sim_backend.") for n in names):
                lines.append(node.lineno)
    return lines


def test_the_cli_imports_the_simulator_only_in_its_commands() -> None:
    found = {
        name: lines
        for name, path in MODULES.items()
        if name.startswith("omnisort_hw.cli")
        and (lines := _sim_imports_at_start(ast.parse(path.read_text(encoding="utf-8"))))
    }
    assert found == {}, f"imported when the parser is built: {found}"


def test_the_core_is_pure() -> None:
    """The core imports only the core, the project's errors, its atomic file writes (for
    camera.json) and the replies' codec (for the records it replies with): no devices, no
    configuration, no pipeline, no service."""
    allowed = (
        "omnisort_hw.core",
        "omnisort_hw.errors",
        "omnisort_hw.fileio",
        "omnisort_hw.wire_records",
    )
    bad = {
        n: sorted(d for d in _project_edges(n) if not d.startswith(allowed))
        for n in MODULES
        if n.startswith("omnisort_hw.core")
    }
    assert {n: d for n, d in bad.items() if d} == {}


def test_no_code_asks_whether_a_device_is_simulated() -> None:
    found = []
    for name, path in MODULES.items():
        if name.startswith("sim_backend"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Name)
                and node.func.id in ("hasattr", "getattr")
                and len(node.args) >= 2
                and isinstance(node.args[1], ast.Constant)
                and node.args[1].value in ("cell", "world", "scene")
            ):
                found.append(f"{name}:{node.lineno}")
    assert found == []


def test_no_product_module_over_the_limit() -> None:
    over = {
        str(p.relative_to(ROOT)): len(p.read_text(encoding="utf-8").splitlines())
        for p in MODULES.values()
    }
    over = {k: v for k, v in over.items() if v > MAX_LINES}
    assert over == {}, over


def test_a_module_over_the_soft_limit_says_why() -> None:
    unexplained = []
    for name, path in MODULES.items():
        text = path.read_text(encoding="utf-8")
        if len(text.splitlines()) > SOFT_LINES:
            doc = ast.get_docstring(ast.parse(text)) or ""
            if "Over 600 lines:" not in doc:
                unexplained.append(name)
    assert unexplained == [], unexplained


def test_the_use_cases_are_the_pipeline_modules_with_run() -> None:
    """A pipeline module with a top-level `run(rig, request)` is a use case and is named in
    `pipeline.USE_CASES`; every other pipeline module supports them (docs/architecture.md)."""
    from omnisort_hw.pipeline import USE_CASES

    with_run = set()
    for path in (ROOT / "omnisort_hw" / "pipeline").glob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in tree.body:
            if isinstance(node, ast.FunctionDef) and node.name == "run":
                assert [a.arg for a in node.args.args[:2]] == ["rig", "request"], path.name
                with_run.add(path.stem)
    assert with_run == set(USE_CASES)

"""The layering of the package, read from every module's imports (lazy ones included).

math < mapping < fleet; io beside fleet; eval and cli on top. config, options and errors are
leaves every layer may use. Inside fleet the sub-packages point one way (wire < storage <
sharing < node, security < net < sharing, wire < net), no import circle runs through it, and
nothing in it imports the emulated links (gmmap.eval.links). No package folder holds more than
16 modules.
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "python" / "gmmap"
LAYERS = ("math", "mapping", "fleet", "io", "eval", "cli")
LEAVES = {"config", "options", "errors", "_core", "__init__"}
# What each layer must not import.
FORBIDDEN = {
    "math": {"mapping", "fleet", "io", "eval", "cli", "config"},
    "mapping": {"fleet", "io", "eval", "cli"},
    "fleet": {"io", "eval", "cli"},
    "io": {"fleet", "eval", "cli"},
    "eval": {"cli"},
    "cli": set(),
    "leaf": {"math", "mapping", "fleet", "io", "eval", "cli"},
}
# What each of the fleet's sub-packages may import of the others.
FLEET_USES = {
    "wire": set(),
    "security": set(),
    "storage": {"wire"},
    "net": {"security", "wire"},
    "sharing": {"wire", "storage", "net"},
    "node": {"wire", "storage", "security", "net", "sharing"},
}
EMULATED_LINKS = "gmmap.eval.links"
MAX_MODULES = 16  # per package folder, __init__.py aside


def gmmap_imports(path: Path) -> set[str]:
    """The first component under gmmap of every module ``path`` imports."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            parts = node.module.split(".")
            if parts[0] == "gmmap":
                found |= {parts[1]} if len(parts) > 1 else {a.name for a in node.names}
        elif isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[0] == "gmmap" and len(parts) > 1:
                    found.add(parts[1])
    return found


def layer_of(path: Path) -> str:
    rel = path.relative_to(PACKAGE).parts
    return rel[0] if len(rel) > 1 else "leaf"


MODULES = sorted(p for p in PACKAGE.rglob("*.py") if p.name != "__init__.py" or len(p.parts))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_module_respects_the_layers(path):
    layer = layer_of(path)
    if layer == "leaf" and path.stem == "__init__":
        return  # the package's public API re-exports from the layers
    bad = gmmap_imports(path) & FORBIDDEN[layer]
    assert not bad, f"{path.relative_to(PACKAGE)} ({layer}) imports {sorted(bad)}"


def test_the_rule_catches_the_backend_importing_a_loader(tmp_path):
    """The check itself: a backend that imports the dataset loaders is caught."""
    fake = PACKAGE / "mapping" / "backend.py"
    text = fake.read_text() + "\nfrom gmmap.io.datasets import open as _open\n"
    probe = tmp_path / "backend.py"
    probe.write_text(text)
    assert "io" in gmmap_imports(probe) & FORBIDDEN["mapping"]


def test_the_backend_and_the_core_api_do_not_load_the_loaders_or_eval():
    import subprocess
    import sys

    code = (
        "import sys, gmmap, gmmap.mapping.backend, gmmap.mapping.mapper; "
        "bad = [m for m in sys.modules if m.startswith(('gmmap.io', 'gmmap.eval', 'gmmap.cli',"
        " 'PIL', 'evo', 'rosbags'))]; print(bad); sys.exit(1 if bad else 0)"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_every_module_is_at_most_500_lines():
    long = {
        str(p.relative_to(PACKAGE)): n
        for p in MODULES
        if (n := len(p.read_text().splitlines())) > 500
    }
    assert not long, long


def imported_modules(path: Path, *, types: bool = True) -> set[str]:
    """Every gmmap module ``path`` imports, dotted (``from a import b`` counts as ``a.b`` where
    that is a module, else ``a``), lazy ones included; with ``types`` False, not those under
    ``if TYPE_CHECKING:`` (they load nothing at run time)."""
    tree = ast.parse(path.read_text())
    skip = set()
    if not types:
        for node in ast.walk(tree):
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                skip |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    found = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                full = f"{node.module}.{alias.name}"
                found.add(full if _is_module(full) else node.module)
        elif isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
    return {m for m in found if m.split(".")[0] == "gmmap"}


def _is_module(dotted: str) -> bool:
    base = PACKAGE.parent.joinpath(*dotted.split("."))
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()


def module_name(path: Path, root: Path = PACKAGE.parent) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles in ``graph`` (module -> the modules it imports), each as a path."""
    found, state, stack = [], {}, []

    def visit(u):
        state[u] = "open"
        stack.append(u)
        for v in sorted(graph.get(u, ())):
            if state.get(v) == "open":
                found.append([*stack[stack.index(v) :], v])
            elif v in graph and v not in state:
                visit(v)
        stack.pop()
        state[u] = "done"

    for u in sorted(graph):
        if u not in state:
            visit(u)
    return found


def import_graph(prefix: str) -> dict[str, set[str]]:
    mods = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    return {m: imported_modules(p, types=False) for m, p in mods.items() if m.startswith(prefix)}


FLEET = sorted((PACKAGE / "fleet").rglob("*.py"))


@pytest.mark.parametrize("path", FLEET, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_fleet_sub_packages_point_one_way(path):
    rel = path.relative_to(PACKAGE / "fleet").parts
    if len(rel) == 1:
        return  # gmmap.fleet's own __init__
    mine = rel[0]
    assert mine in FLEET_USES, f"fleet/{mine} is not in the layer rules (FLEET_USES)"
    used = {m.split(".")[2] for m in imported_modules(path) if m.startswith("gmmap.fleet.")}
    bad = used - FLEET_USES[mine] - {mine}
    assert not bad, f"fleet/{'/'.join(rel)} ({mine}) imports fleet {sorted(bad)}"


@pytest.mark.parametrize("path", FLEET, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_the_fleet_never_imports_the_emulated_links(path):
    bad = {m for m in imported_modules(path) if m.startswith(EMULATED_LINKS)}
    assert not bad, f"{path.relative_to(PACKAGE)} imports {sorted(bad)}"


def test_no_package_folder_holds_more_than_16_modules():
    folders = {p.parent for p in PACKAGE.rglob("*.py")}
    counts = {
        str(f.relative_to(PACKAGE.parent)): sum(
            1 for p in f.glob("*.py") if p.name != "__init__.py"
        )
        for f in folders
    }
    crowded = {f: n for f, n in counts.items() if n > MAX_MODULES}
    assert not crowded, crowded


@pytest.mark.parametrize("prefix", ["gmmap.fleet.", EMULATED_LINKS])
def test_no_import_circles(prefix):
    found = circles(import_graph(prefix))
    assert not found, [" -> ".join(c) for c in found]


def test_the_circle_check_catches_a_circle(tmp_path):
    """The check itself: a robot that imports its runner lazily, as it once did, is a circle;
    an import for types only is not."""
    robot, runner = tmp_path / "robot.py", tmp_path / "runner.py"
    robot.write_text("def report(node):\n    from gmmap.fleet.node.runner import node_report\n")
    runner.write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
        "    from gmmap.fleet.node.robot import RobotNode\n"
    )
    graph = {
        "gmmap.fleet.node.robot": imported_modules(robot, types=False),
        "gmmap.fleet.node.runner": imported_modules(runner, types=False),
    }
    assert circles(graph) == []
    runner.write_text("from gmmap.fleet.node.robot import RobotNode\n")
    graph["gmmap.fleet.node.runner"] = imported_modules(runner, types=False)
    assert circles(graph) == [
        ["gmmap.fleet.node.robot", "gmmap.fleet.node.runner", "gmmap.fleet.node.robot"]
    ]

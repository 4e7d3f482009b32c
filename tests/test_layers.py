"""The layering of the package, read from every module's imports (lazy ones included).

math < mapping < fleet; io beside fleet; eval and cli on top. config, options and errors are
leaves every layer may use.
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

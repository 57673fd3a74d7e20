"""The package's imports point one way (../shared/STYLE.md, item 1), in the layers' order that
docs/contributing.md's tree numbers (each folder of the package one layer).

Read from the source with ``ast``: every ``import hcid...`` and ``from hcid... import``,
at module level or inside a function (a function-level import still couples the
layers), must point to the same or a lower layer, and the module graph has no cycle.
"""

import ast
import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "hcid"

DOCS = PACKAGE.parent / "docs" / "contributing.md"


def documented_layers(text: str) -> list[tuple[int, str]]:
    """The numbered entries of docs/contributing.md's tree (the first fenced block under "## The
    code": ``  config/   1 what ...``): each package folder and the public API's module with its
    layer's number, in the tree's order."""
    section = text.split("## The code", 1)[1]
    tree = section.split("```", 2)[1]
    pattern = re.compile(r"^  ([a-z_]+/|api\.py)\s+(\d+) ", flags=re.M)
    return [(int(m[2]), m[1].rstrip("/").removesuffix(".py")) for m in pattern.finditer(tree)]


#: Layers, lowest first (STYLE 1), derived from the package's folders as docs/contributing.md's
#: tree numbers them: each folder is one layer of its own, and a module may import from its own
#: layer and the ones before. ``errors`` and ``tables`` (the column names and schemas every layer
#: shares) come first and import nothing of hcid; ``api`` is the public API's one module.
LAYERS = (
    ("vocabulary", ("hcid.errors", "hcid.tables")),
    *((name, (f"hcid.{name}",)) for _, name in documented_layers(DOCS.read_text())),
    ("entry", ("hcid.__main__",)),
)
#: The only modules outside a layer's folder: the package itself, its entry point, the shared
#: vocabulary, the public API, and what the package sets before numpy loads (hcid/_blas.py).
TOP_LEVEL = {"__init__.py", "__main__.py", "errors.py", "tables.py", "api.py", "_blas.py"}


def module_name(path: Path, root: Path = PACKAGE) -> str:
    parts = path.relative_to(root.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def layer_of(module: str) -> int:
    for i, (_, prefixes) in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return i
    raise AssertionError(f"{module}: in no layer; number its folder in docs/contributing.md's tree")


def imports(path: Path, modules: set[str]) -> list[tuple[str, int]]:
    """The hcid modules ``path`` imports, with the line of each import."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found += [(a.name, node.lineno) for a in node.names if a.name.startswith("hcid.")]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("hcid"):
            for alias in node.names:
                full = f"{node.module}.{alias.name}"
                found.append((full if full in modules else node.module, node.lineno))
    return found


def graph(root: Path = PACKAGE) -> dict[str, list[tuple[str, int]]]:
    files = {module_name(p, root): p for p in root.rglob("*.py")}
    names = set(files)
    return {m: [(t, line) for t, line in imports(p, names) if t != "hcid"] for m, p in files.items()}


def upward_imports(edges: dict[str, list[tuple[str, int]]]) -> list[str]:
    out = []
    for module, targets in edges.items():
        if module == "hcid":  # the package's lazy exports name modules by string only
            continue
        for target, line in targets:
            if layer_of(target) > layer_of(module):
                out.append(
                    f"{module}:{line} imports {target} "
                    f"({LAYERS[layer_of(module)][0]} -> {LAYERS[layer_of(target)][0]})"
                )
    return out


def cycles(edges: dict[str, list[tuple[str, int]]]) -> list[list[str]]:
    """Every cycle's modules (strongly connected components of more than one module, or a self-import)."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w, _ in edges.get(v, []):
            w = w if w in edges else w.rsplit(".", 1)[0]
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1 or any(t == v for t, _ in edges.get(v, [])):
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def _package_imports(edges):
    # A package's __init__ re-exports its own modules: those edges are not cycles.
    return {m: [(t, line) for t, line in ts if not t.startswith(m + ".")] for m, ts in edges.items()}


def test_every_module_sits_in_its_layers_folder():
    # The tree shows the layers: each folder is one layer (none shared, none missing from
    # docs/contributing.md's tree), nothing else lies flat, and the tree numbers them in order.
    assert sorted(p.name for p in PACKAGE.glob("*.py")) == sorted(TOP_LEVEL)
    folders = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()}
    numbered = documented_layers(DOCS.read_text())
    names = [name for _, name in numbered]
    assert sorted(names) == sorted(folders | {"api"}), "docs/contributing.md's tree numbers other layers"
    assert [n for n, _ in numbered] == list(range(1, len(numbered) + 1)), numbered


def test_every_import_points_down_the_layers():
    assert upward_imports(graph()) == []


def test_no_import_cycle():
    assert cycles(_package_imports(graph())) == []


def test_the_checks_catch_a_cycle_and_an_upward_import(tmp_path):
    # A hand-made package: config importing the pipeline is upward, and the two form a cycle.
    root = tmp_path / "hcid"
    (root / "config").mkdir(parents=True)
    (root / "pipeline").mkdir()
    (root / "__init__.py").write_text("")
    (root / "config" / "__init__.py").write_text("def f():\n    from hcid.pipeline import run\n")
    (root / "pipeline" / "__init__.py").write_text("from hcid.config import f\n")
    edges = graph(root)
    assert upward_imports(edges) == ["hcid.config:2 imports hcid.pipeline (config -> pipeline)"]
    assert cycles(_package_imports(edges)) == [["hcid.config", "hcid.pipeline"]]


@pytest.mark.parametrize(
    "module", ["hcid.config.parse", "hcid.config.types", "hcid.loop.signals", "hcid.arx.engine"]
)
def test_the_core_reads_no_files(module):
    # STYLE 2: no file I/O below results: the config layer describes, hcid.assembly.resolve reads.
    path = PACKAGE / (module.replace("hcid.", "").replace(".", "/") + ".py")
    text = path.read_text()
    assert "open(" not in text and "read_signal" not in text and "read_text" not in text


#: What a simulating and identifying command never needs (issue 36's serial part: together
#: about 1 s of imports before any work): python-control and what it pulls in.
HEAVY = ("control", "scipy.signal", "scipy.stats", "matplotlib")


def test_a_study_run_imports_neither_python_control_nor_scipy_signal(tmp_path):
    # Source: the import graph, read from sys.modules after `hcid run configs/ci.yaml --jobs 1`
    # (every stage in this process: simulate, identify both methods, sweep W). hcid.loop._lti
    # does python-control's arithmetic bit for bit (tests/test_hcmodel.py), the loop's filters
    # are compiled (tests/test_simulate.py) and fit-hc is imported on first use.
    import subprocess
    import sys

    code = (
        "import sys\nfrom hcid.cli import main\n"
        f"sys.argv = ['hcid', 'run', 'configs/ci.yaml', '--run', {str(tmp_path / 'run')!r}, "
        "'--jobs', '1', '--quiet']\n"
        "try:\n    main()\nexcept SystemExit as exc:\n    assert not exc.code, exc.code\n"
        f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=PACKAGE.parent, capture_output=True, text=True, check=True
    ).stdout
    assert out.strip().splitlines()[-1] == "[]", out

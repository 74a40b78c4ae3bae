"""The layout rules of DESIGN.md, checked on the source: imports form a DAG, layers point down,
no private JAX modules, no module-global switches, notebooks use public names only."""

import ast
import json
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PKG = ROOT / "jaxnav"


def _module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(PKG.rglob("*.py"))}


def _resolve(module: str, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    is_pkg = MODULES[module].name == "__init__.py"
    base = base if is_pkg else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(module: str) -> set[str]:
    """Every jaxnav module imported anywhere in ``module`` (function-level imports included)."""
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(module, node)
            # "from pkg import sub" imports the module pkg.sub; "from pkg import name" the package pkg
            names = [f"{target}.{a.name}" if f"{target}.{a.name}" in MODULES else target for a in node.names]
        else:
            continue
        for name in names:
            # the deepest jaxnav module the name refers to ("from jaxnav.filters import x" -> jaxnav.filters)
            while name and name not in MODULES:
                name = name.rpartition(".")[0]
            if name.startswith("jaxnav") and name != module:
                out.add(name)
    return out


GRAPH = {m: _imports(m) for m in MODULES}


def _find_cycle(graph):
    state, stack = {}, []

    def visit(u):
        state[u] = 1
        stack.append(u)
        for v in sorted(graph.get(u, ())):
            if state.get(v) == 1:
                return stack[stack.index(v) :] + [v]
            if v not in state:
                cyc = visit(v)
                if cyc:
                    return cyc
        stack.pop()
        state[u] = 2
        return None

    for u in sorted(graph):
        if u not in state:
            cyc = visit(u)
            if cyc:
                return cyc
    return None


def test_module_imports_form_a_dag():
    """No import cycle among jaxnav modules, counting function-level imports."""
    assert _find_cycle(GRAPH) is None, " -> ".join(_find_cycle(GRAPH))


def test_package_imports_form_a_dag():
    """The same between packages (filters, ins, io, ...): the layers of DESIGN.md point one way."""
    top = lambda m: ".".join(m.split(".")[:2])
    pkgs = {}
    for m, deps in GRAPH.items():
        pkgs.setdefault(top(m), set()).update(top(d) for d in deps if top(d) != top(m))
    # the root package re-exports what sits below it; its private helpers (_numerics, _status) are leaves
    pkgs.pop("jaxnav", None)
    for deps in pkgs.values():
        deps.discard("jaxnav")
    assert _find_cycle(pkgs) is None, " -> ".join(_find_cycle(pkgs))


def test_only_the_cli_imports_the_cli_and_nothing_below_imports_experiments():
    library = ("filters", "ins", "sim", "geodesy", "monitoring", "survey", "tune", "io", "plot")
    for m, deps in GRAPH.items():
        if not m.startswith("jaxnav.cli") and m != "jaxnav.__main__":
            assert not [d for d in deps if d.startswith("jaxnav.cli")], m
        if m.split(".")[1:2] and m.split(".")[1] in library:
            assert not [d for d in deps if d.startswith("jaxnav.experiments")], m


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_private_jax_and_no_global_switches(module):
    src = MODULES[module].read_text(encoding="utf-8")
    assert "jax._src" not in src and "jax.interpreters" not in src, module
    tree = ast.parse(src)
    for node in ast.walk(tree):
        assert not isinstance(node, ast.Global), f"{module}: 'global' statement"
        if isinstance(node, ast.Assign):  # no monkey patching of attributes onto functions
            for t in node.targets:
                if (
                    isinstance(t, ast.Attribute)
                    and isinstance(t.value, ast.Name)
                    and t.attr in ("lower", "_cache_size")
                ):
                    raise AssertionError(f"{module}: assigns {t.value.id}.{t.attr}")


def test_cli_commands_are_a_registry():
    """Each command module has register() and run(); main() dispatches."""
    import jaxnav.cli as cli

    for name in cli.COMMANDS:
        mod = __import__(f"jaxnav.cli.{name}", fromlist=["register", "run"])
        assert callable(mod.register) and callable(mod.run), name


@pytest.mark.parametrize("path", sorted((ROOT / "notebooks").glob("*.ipynb")), ids=lambda p: p.name)
def test_notebooks_import_public_names_only(path):
    nb = json.loads(path.read_text(encoding="utf-8"))
    for cell in nb["cells"]:
        if cell["cell_type"] != "code":
            continue
        tree = ast.parse(
            "\n".join(line for line in "".join(cell["source"]).splitlines() if not line.lstrip().startswith(("%", "!")))
        )
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("jaxnav"):
                mods = [node.module] + [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                mods = [a.name for a in node.names if a.name.startswith("jaxnav")]
            else:
                continue
            for name in mods:
                assert not any(part.startswith("_") for part in name.split(".")), f"{path.name}: {name}"
                assert not name.startswith("jaxnav.cli"), f"{path.name}: {name}"


#: the layers, lowest first; a package imports only from its own layer or those below. DESIGN.md's
#: order, except that the simulators sit above the S1/S2/S3 processing (sim builds their records,
#: e.g. the S3 stop list of a simulated survey; no processing module needs a simulator)
LAYERS = [
    ("_numerics", "_status", "units", "_config", "_progress"),
    ("geodesy",),
    ("filters",),
    ("ins",),
    ("monitoring", "survey"),
    ("sim",),
    ("tune",),
    ("plot", "io"),
    ("experiments",),
    ("cli", "__main__"),
]


def test_layers_point_down():
    level = {name: i for i, names in enumerate(LAYERS) for name in names}
    wrong = []
    for m, deps in GRAPH.items():
        parts = m.split(".")
        if len(parts) < 2:
            continue  # the root package re-exports
        for d in deps:
            dp = d.split(".")
            if len(dp) < 2 or dp[1] == parts[1]:
                continue
            if level[dp[1]] > level[parts[1]]:
                wrong.append(f"{m} -> {d}")
    assert not wrong, wrong

"""The package's folders are its layers: each imports only those below it.

Every import of every module (at the top and inside functions) is read
from the source, so that a layer that reaches up fails here, whether or
not the import runs in a test.
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "drake_wbc"

LAYERS = {
    "math": 0,
    "robot": 1,
    "stages": 2,
    "controller": 3,
    "station": 4,
    "hardware": 4,
    "experiments": 5,
    "analysis": 6,
    "deployment": 6,
    "bench": 7,
    "stress": 7,
    "cli": 8,
}
"""The rank of each folder: a folder may import the folders of lower rank
and its own; folders of equal rank are independent of each other."""

FORBIDDEN_THIRD_PARTY = {
    "math": ("pydrake.systems", "pydrake.multibody", "pydrake.geometry",
             "pydrake.lcm", "lcm"),
    "robot": ("pydrake.systems.framework", "pydrake.lcm", "lcm"),
    "stages": ("pydrake.multibody", "pydrake.lcm", "lcm"),
    "controller": ("pydrake.lcm", "lcm"),
}
"""Outside imports a layer must not make: the math is plain functions (no
Drake systems, no plant), the stages need no plant, and nothing below the
hardware speaks LCM."""


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py")
                  if "lcmtypes" not in p.parts)


def _imports(path):
    """Every module name `path` imports, with its line."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom) and node.module:
            yield node.module, node.lineno
            for alias in node.names:
                yield f"{node.module}.{alias.name}", node.lineno


def _layer(path):
    parts = path.relative_to(PACKAGE).parts
    return parts[0] if len(parts) > 1 else None


def test_every_folder_of_the_package_has_a_layer():
    folders = {p.name for p in PACKAGE.iterdir()
               if p.is_dir() and (p / "__init__.py").exists()}
    assert folders == set(LAYERS)
    top = {p.name for p in PACKAGE.glob("*.py")}
    assert top == {"__init__.py"}, "modules belong in a layer's folder"


@pytest.mark.parametrize("path", _modules(),
                         ids=lambda p: str(p.relative_to(PACKAGE)))
def test_a_module_imports_only_the_layers_below_its_own(path):
    layer = _layer(path)
    if layer is None:
        return
    wrong = []
    for name, line in _imports(path):
        parts = name.split(".")
        if parts[0] == "drake_wbc" and len(parts) > 1 and parts[1] in LAYERS:
            other = parts[1]
            if other != layer and LAYERS[other] >= LAYERS[layer]:
                wrong.append(f"line {line}: {name} ({other}, rank "
                             f"{LAYERS[other]} >= {layer}'s {LAYERS[layer]})")
        for prefix in FORBIDDEN_THIRD_PARTY.get(layer, ()):
            if name == prefix or name.startswith(prefix + "."):
                wrong.append(f"line {line}: {name} (not in {layer})")
    assert not wrong, f"{path.relative_to(PACKAGE)}: " + "; ".join(wrong)


def test_every_folder_says_what_it_holds_and_may_import():
    for folder in LAYERS:
        doc = ast.get_docstring(ast.parse(
            (PACKAGE / folder / "__init__.py").read_text()))
        assert doc and len(doc.splitlines()) >= 3, folder


def test_the_check_sees_a_layer_that_reaches_up(tmp_path):
    module = tmp_path / "probe.py"
    module.write_text("def f():\n    from drake_wbc.station import x\n")
    names = [name for name, _ in _imports(module)]
    assert "drake_wbc.station" in names


def _module_name(path):
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_graph(paths):
    """{module: the package's modules it imports}, imports inside
    functions included; `from M import name` counts as an import of
    M.name where that is a module (a package's submodule), else of M."""
    names = {_module_name(p): p for p in paths}
    graph = {}
    for name, path in names.items():
        imported = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                imported.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module:
                for alias in node.names:
                    submodule = f"{node.module}.{alias.name}"
                    imported.add(submodule if submodule in names
                                 else node.module)
        graph[name] = {m for m in imported if m in names and m != name}
    return graph


def _circle(graph):
    """A list of modules that import each other in a loop, or None."""
    state, stack = {}, []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for other in sorted(graph[node]):
            if state.get(other) == "open":
                return stack[stack.index(other):] + [other]
            if other not in state:
                found = visit(other)
                if found:
                    return found
        state[node] = "done"
        stack.pop()
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_no_modules_import_each_other_in_a_loop():
    """Within a layer too: a loop (even through an import inside a
    function, which only hides it) means two modules hold one concept
    between them, or one holds what belongs below both."""
    circle = _circle(_import_graph(_modules()))
    assert circle is None, " -> ".join(circle)


def test_the_check_sees_a_loop():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _circle(graph) == ["a", "b", "c", "a"]
    assert _circle({"a": {"b"}, "b": set()}) is None

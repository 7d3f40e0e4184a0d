"""No import circle in ``tma/`` and ``pipeline/``: no module imports one that imports it back,
directly or through others, at its top or inside a function (a circle there is one all the
same: the two modules know each other). Read from the source (``ast``), every ``import`` and
``from ... import`` naming a module of ``tma`` or ``pipeline`` (a name imported from a package
counts as its submodule when there is one); ``tma.sources.READERS`` and ``tma.families.NAMES``
name modules as text, imported by ``importlib``: the registries, not circles. And the layers:
the library never imports the command line (``pipeline/``), and the stages are independent,
no module of ``tma/stages/`` imports another (they meet through files; what several read, the
run store, lives in ``tma/io/``)."""

import ast
from pathlib import Path

from tests.conftest import REPO


def _modules() -> dict[str, Path]:
    found = {}
    for path in [*(REPO / "tma").rglob("*.py"), *(REPO / "pipeline").rglob("*.py")]:
        parts = list(path.relative_to(REPO).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def _imports(modules: dict[str, Path]) -> dict[str, set[str]]:
    edges = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        out = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                out |= {a.name for a in node.names if a.name in modules}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[:len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([node.module] if node.module else []))
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    out |= {sub} if sub in modules else {base} if base in modules else set()
        edges[name] = out - {name}
    return edges


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges[v]):
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
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def test_the_finder_finds_a_circle():
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": set()}) == []


def test_no_module_of_tma_or_pipeline_imports_itself_back():
    modules = _modules()
    assert len(modules) > 100 and {"tma.stages.estimate", "pipeline.table"} <= set(modules)
    edges = _imports(modules)
    assert "tma.runtime.compile_ahead" in edges["pipeline.table"]  # function-level imports
    assert circles(edges) == []


def test_the_library_never_imports_the_command_line():
    edges = _imports(_modules())
    assert {m: sorted(e for e in out if e.startswith("pipeline"))
            for m, out in edges.items() if m.startswith("tma")
            and any(e.startswith("pipeline") for e in out)} == {}


def test_no_stage_imports_another():
    edges = _imports(_modules())
    stages = {m for m in edges if m.startswith("tma.stages.")}
    assert len(stages) >= 4
    assert {m: sorted(edges[m] & stages) for m in stages if edges[m] & stages} == {}
    assert "tma.io.runs" in edges["tma.stages.aggregate"]  # the finder sees the imports

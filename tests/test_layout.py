"""The folders show the paper's data flow: press data -> model -> responses -> sensitivity / calibration -> planning,
with the plumbing (``press_io``) under everything and the command line (``servo_press``) above everything.

Checked over every import of the packages, including imports inside functions (a lazy import is still a
dependency) and ``if TYPE_CHECKING:`` blocks (an import kept for annotations still ties the two modules: a
circle hidden there is still a circle to whoever reads the code).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import source_trees

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("press_model", "calibration", "monitoring", "planning")
# the floors from the ground up: each imports only floors below it
FLOORS = ("press_io", "press_model", "calibration", "monitoring", "planning", "servo_press")


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg in FLOORS:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
            mods[".".join(parts)] = path
    return mods


def _imports(module: str, path: Path, known: set[str]) -> set[str]:
    """The project modules ``module`` imports at run time (at any depth of its code)."""
    is_pkg = path.name == "__init__.py"
    package = module if is_pkg else module.rpartition(".")[0]
    found: set[str] = set()

    def resolve(name: str) -> None:
        while name and name not in known:  # 'press_model.model.PressModel' -> 'press_model.model'
            name = name.rpartition(".")[0]
        if name and name != module:
            found.add(name)

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.Import):
            for a in node.names:
                resolve(a.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module or ""
            for a in node.names:
                full = f"{stem}.{a.name}"
                resolve(full if full in known else stem)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(source_trees.tree(path))
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods)
    return {m: _imports(m, p, known) for m, p in mods.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


def test_the_check_sees_imports_inside_functions(graph):
    # reproduce imports calibration and planning only inside run_reproduce: the graph must still hold them
    assert "calibration.identification.run" in graph["servo_press.reproduce"]
    assert "planning.compare" in graph["servo_press.reproduce"]


def test_no_import_cycle(graph):
    assert _cycles(graph) == []


def test_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_the_model_imports_neither_calibration_nor_planning(graph):
    bad = {m: sorted(d for d in deps if d.split(".")[0] in ("calibration", "planning", "servo_press"))
           for m, deps in graph.items() if m.startswith("press_model")}
    assert {m: d for m, d in bad.items() if d} == {}


def test_every_floor_imports_only_floors_below(graph):
    rank = {f: i for i, f in enumerate(FLOORS)}
    bad = [(m, d) for m, deps in graph.items() for d in deps if rank[d.split(".")[0]] > rank[m.split(".")[0]]]
    assert bad == []


def test_the_plumbing_imports_nothing_of_the_project(graph):
    bad = {m: sorted(d for d in deps if not d.startswith("press_io")) for m, deps in graph.items() if m.startswith("press_io")}
    assert {m: d for m, d in bad.items() if d} == {}


def test_calibration_does_not_import_planning_or_the_commands(graph):
    bad = {m: sorted(d for d in deps if d.startswith(("planning", "servo_press")))
           for m, deps in graph.items() if m.startswith("calibration")}
    assert {m: d for m, d in bad.items() if d} == {}


def test_planning_does_not_import_the_commands(graph):
    bad = {m: sorted(d for d in deps if d.startswith("servo_press")) for m, deps in graph.items() if m.startswith("planning")}
    assert {m: d for m, d in bad.items() if d} == {}


def test_sensitivity_lives_under_calibration(graph):
    for name in ("responses", "sensitivity.sobol", "sensitivity.report"):
        assert f"calibration.{name}" in graph
        assert f"press_model.{name.split('.')[0]}" not in graph


# calibration's topics in the data flow's order: each imports only topics before it (a drive log knows no
# calibration; identification knows no design; monitoring comes last)
CALIBRATION_TOPICS = ("responses", "traces", "synthetic", "sensitivity", "identification", "design", "fleet")


def test_calibration_is_grouped_by_topic():
    flat = sorted(p.name for p in (ROOT / "calibration").glob("*.py") if p.name not in ("__init__.py", "responses.py"))
    assert flat == [], "calibration/ holds its topics as subpackages; put a new module into one"
    assert {p.name for p in (ROOT / "calibration").iterdir() if (p / "__init__.py").exists()} == set(CALIBRATION_TOPICS) - {"responses"}


def test_calibration_topics_import_only_earlier_topics(graph):
    rank = {t: i for i, t in enumerate(CALIBRATION_TOPICS)}
    bad = []
    for mod, deps in graph.items():
        if mod.startswith("calibration."):
            mine = rank[mod.split(".")[1]]
            bad += [(mod, d) for d in deps if d.startswith("calibration.") and rank[d.split(".")[1]] > mine]
    assert bad == []


def test_a_module_map_in_each_package_readme():
    # every subpackage of calibration and every module of the three packages is named in its package's README
    for pkg in PACKAGES:
        readme = (ROOT / pkg / "README.md").read_text(encoding="utf-8")
        missing = [str(p.relative_to(ROOT / pkg).with_suffix("")) for p in sorted((ROOT / pkg).rglob("*.py"))
                   if p.name != "__init__.py" and f"`{p.stem}`" not in readme and str(p.relative_to(ROOT / pkg)) not in readme]
        assert missing == [], f"{pkg}/README.md's module map misses {missing}"


def test_one_output_writer(graph):
    # atomic files are written by press_io.outputs alone; nobody else calls mkstemp / os.replace
    for mod, path in _modules().items():
        if mod != "press_io.outputs":
            text = path.read_text(encoding="utf-8")
            assert "mkstemp" not in text and "os.replace(" not in text, mod



def _parameter_counts(source: str | ast.Module, prefix: str = "") -> dict[str, int]:
    """Every function in ``source`` (Python text, or its parsed tree) with its number of parameters (self/cls not
    counted, *args and **kwargs one each)."""
    counts = {}
    for node in ast.walk(ast.parse(source) if isinstance(source, str) else source):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
            if names[:1] in (["self"], ["cls"]):
                names = names[1:]
            counts[f"{prefix}{node.lineno}:{node.name}"] = len(names) + bool(a.vararg) + bool(a.kwarg)
    return counts


def test_functions_take_few_parameters():
    # what travels together travels as one object (a settings section, a problem, a log): a long parameter list is a
    # sign of a missing one; at most 10, and more than 8 only by exception
    counts = {}
    for mod, path in _modules().items():
        counts.update(_parameter_counts(source_trees.tree(path), f"{mod}:"))
    assert {f: n for f, n in counts.items() if n > 10} == {}
    over_eight = sorted(f for f, n in counts.items() if n > 8)
    assert len(over_eight) <= 12, over_eight


def test_parameter_count_sees_every_kind_of_parameter():
    src = "class A:\n    def m(self, a, b, /, c, *d, e, f=1, **g): pass\n\n    @classmethod\n    def k(cls, x): pass\n"
    assert _parameter_counts(src) == {"2:m": 7, "5:k": 1}

"""Architecture checks on the source of the `amrvio` package, read with `ast` (nothing is imported).

1. Layers: a module imports only from its own layer or a lower one. Every import counts: module
   level, inside functions, under `if TYPE_CHECKING:`, relative ones (resolved), and
   `importlib.import_module`/`__import__` of a literal name. A part of the package that no layer
   lists fails the check until it is placed.
2. No import cycle between the package's modules (a package's `__init__` is a module).
3. The per-frame path stays small: no module over MAX_MODULE_LINES lines, no class with more than
   MAX_CLASS_ATTRIBUTES attributes (see `class_attributes` for what counts).

The rules are the data below. The checker tests itself on small synthetic sources at the end of
the file, so a checker that stopped seeing imports or attributes would fail, not pass silently.
"""

from __future__ import annotations

import ast
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

# ---------------------------------------------------------------------------------------------
# Rules
# ---------------------------------------------------------------------------------------------

PACKAGE = "amrvio"
PACKAGE_DIR = Path(__file__).resolve().parents[1] / PACKAGE

# Lowest first. A name is the first component below `amrvio` (a subpackage or a top-level module);
# names in one tuple share a layer and may import each other (without cycles).
LAYERS: tuple[tuple[str, ...], ...] = (
    ("errors",),
    ("types",),
    ("io",),
    ("geometry",),
    ("tracking",),
    ("photometric",),
    ("diagnostics",),
    ("frontend", "imu"),
    ("estimator",),
    ("eval",),
    ("pipeline", "config"),
    ("sim",),
    ("report",),
    ("app",),
    ("cli", "demo"),
)

# `amrvio/__init__.py` may import anything; for the same reason it sits above every layer, so no
# module of the package may import the bare `amrvio` package.
ROOT_MODULE_MAY_IMPORT_ANYTHING = True

# The per-frame path: the parts of the package that run on every frame.
PER_FRAME: tuple[str, ...] = ("pipeline", "frontend", "estimator", "diagnostics", "photometric", "tracking", "imu")
MAX_MODULE_LINES = 400
MAX_CLASS_ATTRIBUTES = 12

LAYER_OF: dict[str, int] = {name: i for i, names in enumerate(LAYERS) for name in names}
ROOT_LAYER = len(LAYERS)


# ---------------------------------------------------------------------------------------------
# Reading the package
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Module:
    name: str  # dotted, e.g. "amrvio.io.kitti"; a package's __init__ has the package's name
    path: str  # for messages
    source: str
    is_package: bool


@dataclass(frozen=True)
class Edge:
    importer: str
    imported: str  # dotted name of a module (or of a package, when the import names its contents)
    line: int


def load_package(root: Path = PACKAGE_DIR, package: str = PACKAGE) -> dict[str, Module]:
    modules: dict[str, Module] = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root)
        if "__pycache__" in rel.parts:
            continue
        is_package = rel.name == "__init__.py"
        parts = rel.parent.parts if is_package else (*rel.parent.parts, rel.stem)
        name = ".".join((package, *parts))
        shown = path.relative_to(root.parent) if root.parent in path.parents else path
        modules[name] = Module(name, str(shown), path.read_text(encoding="utf-8"), is_package)
    return modules


def synthetic(sources: Mapping[str, str]) -> dict[str, Module]:
    """Modules from {dotted name: source}; a name ending in ".__init__" is a package."""
    out: dict[str, Module] = {}
    for key, source in sources.items():
        is_package = key.endswith(".__init__")
        name = key.removesuffix(".__init__")
        out[name] = Module(name, key.replace(".", "/") + ".py", source, is_package)
    return out


def part_of(module: str) -> str | None:
    """The first component below the package ("io" for "amrvio.io.kitti"); None for the package itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def layer_of(module: str) -> int | None:
    part = part_of(module)
    return ROOT_LAYER if part is None else LAYER_OF.get(part)


def _in_package(name: str) -> bool:
    return name == PACKAGE or name.startswith(PACKAGE + ".")


def _resolve_relative(module: Module, level: int, target: str | None) -> str:
    base = module.name.split(".") if module.is_package else module.name.split(".")[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join([*base, target] if target else base)


def _dynamic_import_target(call: ast.Call) -> str | None:
    """The module named by `importlib.import_module("...")`, `__import__("...")`, or the package
    for an f-string whose literal part ends at a dot (`import_module(f"amrvio.cli.{n}")`)."""
    func = call.func
    name = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""
    if name not in ("import_module", "__import__") or not call.args:
        return None
    arg = call.args[0]
    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
        return arg.value
    if isinstance(arg, ast.JoinedStr) and arg.values:
        head = arg.values[0]
        if isinstance(head, ast.Constant) and isinstance(head.value, str) and "." in head.value:
            return head.value.rsplit(".", 1)[0]
    return None


def import_edges(module: Module, known: Collection[str]) -> list[Edge]:
    """Every import of a module of the package, anywhere in `module` (any depth, any branch)."""
    edges: list[Edge] = []
    for node in ast.walk(ast.parse(module.source, filename=module.path)):
        if isinstance(node, ast.Import):
            edges += [Edge(module.name, a.name, node.lineno) for a in node.names if _in_package(a.name)]
        elif isinstance(node, ast.ImportFrom):
            base = _resolve_relative(module, node.level, node.module) if node.level else (node.module or "")
            if not _in_package(base):
                continue
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                edges.append(Edge(module.name, sub if sub in known else base, node.lineno))
        elif isinstance(node, ast.Call):
            target = _dynamic_import_target(node)
            if target is not None and _in_package(target):
                edges.append(Edge(module.name, target, node.lineno))
    return sorted(set(edges), key=lambda e: (e.line, e.imported))


def all_edges(modules: Mapping[str, Module]) -> list[Edge]:
    return [e for m in modules.values() for e in import_edges(m, modules)]


# ---------------------------------------------------------------------------------------------
# Checks (each returns the violations as lines of text; empty means the rule holds)
# ---------------------------------------------------------------------------------------------


def unplaced_parts(modules: Mapping[str, Module]) -> list[str]:
    parts = sorted({p for name in modules if (p := part_of(name)) is not None and p not in LAYER_OF})
    return [f"{PACKAGE}.{p} is in no layer: place it in LAYERS in tests/test_architecture.py" for p in parts]


def _layer_name(layer: int | None) -> str:
    if layer is None:
        return "a part in no layer"
    return f"layer {layer}: {', '.join(LAYERS[layer]) if layer < ROOT_LAYER else 'the package root'}"


def layer_violations(modules: Mapping[str, Module]) -> list[str]:
    out: list[str] = []
    for e in all_edges(modules):
        if e.importer == PACKAGE and ROOT_MODULE_MAY_IMPORT_ANYTHING:
            continue
        lo, hi = layer_of(e.importer), layer_of(e.imported)
        if lo is None:
            continue  # reported by unplaced_parts
        if hi is None or hi > lo:
            where = modules[e.importer].path
            out.append(f"{where}:{e.line}: {e.importer} ({_layer_name(lo)}) imports {e.imported} ({_layer_name(hi)})")
    return out


def import_graph(modules: Mapping[str, Module]) -> dict[str, dict[str, int]]:
    """importer -> {imported module: first line}, between modules that exist, without self-loops."""
    graph: dict[str, dict[str, int]] = {name: {} for name in modules}
    for e in all_edges(modules):
        if e.imported in modules and e.imported != e.importer:
            graph[e.importer].setdefault(e.imported, e.line)
    return graph


def strongly_connected(graph: Mapping[str, Mapping[str, int]]) -> list[list[str]]:
    """Tarjan's strongly connected components (iterative), each sorted, in a deterministic order."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    comps: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work: list[tuple[str, Iterator[str]]] = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp: list[str] = []
                while True:
                    top = stack.pop()
                    on_stack.discard(top)
                    comp.append(top)
                    if top == node:
                        break
                comps.append(sorted(comp))
    return sorted(comps)


def one_cycle(graph: Mapping[str, Mapping[str, int]], comp: list[str]) -> list[str]:
    """A shortest cycle through the first module of a strongly connected component, closed (a .. a)."""
    start, inside = comp[0], set(comp)
    parent: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt: list[str] = []
        for node in frontier:
            for child in sorted(graph[node]):
                if child == start:
                    path = [node]
                    while path[-1] != start:
                        path.append(parent[path[-1]])
                    return [*reversed(path), start]
                if child in inside and child not in parent:
                    parent[child] = node
                    nxt.append(child)
        frontier = nxt
    raise ValueError(f"{comp} is not a cycle")


def cycles(modules: Mapping[str, Module]) -> list[str]:
    """One cycle (with the line of each import) per group of modules that import each other."""
    graph = import_graph(modules)
    out: list[str] = []
    for comp in strongly_connected(graph):
        if len(comp) < 2:
            continue
        path = one_cycle(graph, comp)
        steps = " -> ".join(f"{a} (line {graph[a][b]})" for a, b in zip(path, path[1:], strict=False))
        out.append(f"cycle among {len(comp)} modules {comp}: {steps} -> {path[-1]}")
    return out


def _is_classvar(annotation: ast.expr) -> bool:
    node = annotation.value if isinstance(annotation, ast.Subscript) else annotation
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value.startswith(("ClassVar", "typing.ClassVar"))
    return (isinstance(node, ast.Name) and node.id == "ClassVar") or (
        isinstance(node, ast.Attribute) and node.attr == "ClassVar")


def _walk_skipping_classes(node: ast.AST) -> Iterator[ast.AST]:
    """ast.walk below `node` that does not enter nested classes (their `self` is another object)."""
    todo = list(ast.iter_child_nodes(node))
    while todo:
        child = todo.pop()
        if isinstance(child, ast.ClassDef):
            continue
        yield child
        todo.extend(ast.iter_child_nodes(child))


def class_attributes(cls: ast.ClassDef) -> set[str]:
    """Class-level annotated fields (dataclass, NamedTuple; `ClassVar` excluded), `__slots__` names,
    and every `self.X` stored in its methods: assignments (tuple and starred targets too), augmented
    and annotated assignments, for/with targets, `setattr(self, "X", ..)` and
    `object.__setattr__(self, "X", ..)` with a literal name."""
    names: set[str] = set()
    for stmt in cls.body:
        if (isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)
                and stmt.target.id != "__slots__" and not _is_classvar(stmt.annotation)):
            names.add(stmt.target.id)
        elif isinstance(stmt, ast.Assign | ast.AnnAssign) and stmt.value is not None:
            targets = stmt.targets if isinstance(stmt, ast.Assign) else [stmt.target]
            if any(isinstance(t, ast.Name) and t.id == "__slots__" for t in targets):
                value = stmt.value
                items = value.elts if isinstance(value, ast.Tuple | ast.List | ast.Set) else [value]
                names |= {i.value for i in items if isinstance(i, ast.Constant) and isinstance(i.value, str)}
        elif isinstance(stmt, ast.FunctionDef | ast.AsyncFunctionDef):
            decorators = {d.id for d in stmt.decorator_list if isinstance(d, ast.Name)}
            params = [*stmt.args.posonlyargs, *stmt.args.args]
            if not params or decorators & {"staticmethod", "classmethod"}:
                continue
            this = params[0].arg
            for node in _walk_skipping_classes(stmt):
                if (isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store)
                        and isinstance(node.value, ast.Name) and node.value.id == this):
                    names.add(node.attr)
                elif isinstance(node, ast.Call) and len(node.args) >= 2:
                    f = node.func
                    is_setattr = (isinstance(f, ast.Name) and f.id == "setattr") or (
                        isinstance(f, ast.Attribute) and f.attr == "__setattr__"
                        and isinstance(f.value, ast.Name) and f.value.id == "object")
                    obj, key = node.args[0], node.args[1]
                    if (is_setattr and isinstance(obj, ast.Name) and obj.id == this
                            and isinstance(key, ast.Constant) and isinstance(key.value, str)):
                        names.add(key.value)
    return names


def on_per_frame_path(module: str) -> bool:
    return part_of(module) in PER_FRAME


def long_modules(modules: Mapping[str, Module], limit: int = MAX_MODULE_LINES) -> list[str]:
    out: list[str] = []
    for m in modules.values():
        n = len(m.source.splitlines())
        if on_per_frame_path(m.name) and n > limit:
            out.append(f"{m.path}: {n} lines (limit {limit})")
    return out


def big_classes(modules: Mapping[str, Module], limit: int = MAX_CLASS_ATTRIBUTES) -> list[str]:
    out: list[str] = []
    for m in modules.values():
        if not on_per_frame_path(m.name):
            continue
        for node in ast.walk(ast.parse(m.source, filename=m.path)):
            if isinstance(node, ast.ClassDef):
                attrs = class_attributes(node)
                if len(attrs) > limit:
                    out.append(f"{m.path}:{node.lineno}: class {node.name} has {len(attrs)} attributes "
                               f"(limit {limit}): {', '.join(sorted(attrs))}")
    return out


def _report(title: str, lines: list[str]) -> str:
    return f"{title} ({len(lines)}):\n" + "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# The checks on the real package
# ---------------------------------------------------------------------------------------------

REAL = load_package()


def test_the_package_was_read() -> None:
    assert f"{PACKAGE}.errors" in REAL and f"{PACKAGE}.types" in REAL and len(REAL) > 30, sorted(REAL)
    assert sum(len(import_edges(m, REAL)) for m in REAL.values()) > 100


def test_every_part_of_the_package_has_a_layer() -> None:
    problems = unplaced_parts(REAL)
    assert not problems, _report("parts of the package in no layer", problems)


def test_no_upward_import() -> None:
    problems = layer_violations(REAL)
    assert not problems, _report("upward imports (lowest layer first: " + " < ".join(
        ", ".join(names) for names in LAYERS) + ")", problems)


def test_no_import_cycle() -> None:
    problems = cycles(REAL)
    assert not problems, _report("import cycles", problems)


def test_per_frame_modules_are_short() -> None:
    problems = long_modules(REAL)
    assert not problems, _report(f"per-frame modules over {MAX_MODULE_LINES} lines", problems)


def test_per_frame_classes_are_small() -> None:
    problems = big_classes(REAL)
    assert not problems, _report(f"per-frame classes with over {MAX_CLASS_ATTRIBUTES} attributes", problems)


# ---------------------------------------------------------------------------------------------
# The checker on synthetic sources: each rule must see what it is meant to see
# ---------------------------------------------------------------------------------------------


def test_checker_catches_an_upward_import_inside_a_function() -> None:
    mods = synthetic({
        "amrvio.types.lie": "import numpy as np\n\n\ndef f() -> None:\n    from amrvio.io import kitti\n",
        "amrvio.io.__init__": "",
        "amrvio.io.kitti": "from amrvio.types import lie\n",
    })
    problems = layer_violations(mods)
    assert len(problems) == 1, problems
    assert problems == ["amrvio/types/lie.py:5: amrvio.types.lie (layer 1: types) imports amrvio.io.kitti (layer 2: io)"]


def test_checker_catches_a_type_checking_import() -> None:
    src = ("from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n"
           "    from amrvio.pipeline.vo import VoPipeline\n")
    problems = layer_violations(synthetic({"amrvio.geometry.pnp": src, "amrvio.pipeline.vo": ""}))
    assert len(problems) == 1 and ":4: amrvio.geometry.pnp" in problems[0], problems


def test_checker_resolves_relative_and_dynamic_imports() -> None:
    mods = synthetic({
        "amrvio.photometric.__init__": "from . import calibrate\n",
        "amrvio.photometric.calibrate": "def f() -> None:\n    from ..diagnostics import frame\n",
        "amrvio.diagnostics.__init__": "",
        "amrvio.diagnostics.frame": "from ..photometric.calibrate import x\n",
        "amrvio.io.kitti": "import importlib\nmod = importlib.import_module('amrvio.sim.render')\n",
        "amrvio.eval.a": "import importlib\nmods = [importlib.import_module(f'amrvio.report.{n}') for n in 'ab']\n",
    })
    edges = {(e.importer, e.imported, e.line) for e in all_edges(mods)}
    assert ("amrvio.photometric", "amrvio.photometric.calibrate", 1) in edges
    assert ("amrvio.photometric.calibrate", "amrvio.diagnostics.frame", 2) in edges
    assert ("amrvio.diagnostics.frame", "amrvio.photometric.calibrate", 1) in edges
    assert ("amrvio.io.kitti", "amrvio.sim.render", 2) in edges
    assert ("amrvio.eval.a", "amrvio.report", 2) in edges
    problems = layer_violations(mods)
    assert [p.split(":")[0] for p in problems] == [
        "amrvio/photometric/calibrate.py", "amrvio/io/kitti.py", "amrvio/eval/a.py"], problems


def test_checker_allows_own_and_lower_layers_and_the_root_package() -> None:
    mods = synthetic({
        "amrvio.__init__": "from amrvio.cli.main import main\n",
        "amrvio.frontend.klt": "from amrvio.imu import preint\nfrom amrvio.errors import AmrvioError\n",
        "amrvio.imu.preint": "def f() -> None:\n    from amrvio.frontend import klt\n",
        "amrvio.cli.main": "from amrvio.demo import run\nfrom amrvio.types import SE3\n",
        "amrvio.demo": "",
    })
    assert layer_violations(mods) == []
    assert unplaced_parts(mods) == []


def test_checker_flags_an_import_of_the_root_package_and_of_an_unlisted_part() -> None:
    mods = synthetic({"amrvio.cli.main": "from amrvio import __version__\n",
                      "amrvio.io.kitti": "from amrvio.newthing import x\n",
                      "amrvio.newthing.__init__": "x = 1\n"})
    problems = layer_violations(mods)
    assert problems == [
        "amrvio/cli/main.py:1: amrvio.cli.main (layer 14: cli, demo) imports amrvio (layer 15: the package root)",
        "amrvio/io/kitti.py:1: amrvio.io.kitti (layer 2: io) imports amrvio.newthing (a part in no layer)"]
    assert unplaced_parts(mods) == ["amrvio.newthing is in no layer: place it in LAYERS in tests/test_architecture.py"]


def test_checker_finds_a_two_module_cycle_hidden_in_a_function() -> None:
    mods = synthetic({
        "amrvio.io.a": "from amrvio.io import b\n",
        "amrvio.io.b": "def f() -> None:\n    import amrvio.io.a\n",
        "amrvio.io.c": "from amrvio.io import a, b\n",
    })
    assert cycles(mods) == [
        "cycle among 2 modules ['amrvio.io.a', 'amrvio.io.b']: "
        "amrvio.io.a (line 1) -> amrvio.io.b (line 2) -> amrvio.io.a"]


def test_checker_finds_a_cycle_through_a_package_init_and_none_in_a_tree() -> None:
    cyclic = synthetic({
        "amrvio.io.__init__": "from amrvio.io.dataset import open_dataset\n",
        "amrvio.io.dataset": "from amrvio.io import kitti\n",
        "amrvio.io.kitti": "from amrvio.io import read_times\n",  # a name of the package: its __init__
    })
    found = cycles(cyclic)
    assert len(found) == 1 and "amrvio.io (line 1) -> amrvio.io.dataset (line 1) -> amrvio.io.kitti (line 1)" in found[0]
    tree = synthetic({
        "amrvio.io.__init__": "from amrvio.io.dataset import open_dataset\nfrom amrvio.io import kitti\n",
        "amrvio.io.dataset": "from amrvio.io.kitti import read\nfrom amrvio.errors import E\n",
        "amrvio.io.kitti": "from amrvio.errors import E\n",
        "amrvio.errors": "",
    })
    assert cycles(tree) == []


def test_strongly_connected_on_a_longer_cycle() -> None:
    graph = {"a": {"b": 1}, "b": {"c": 1}, "c": {"a": 1, "d": 1}, "d": {}, "e": {"e": 1}}
    assert strongly_connected(graph) == [["a", "b", "c"], ["d"], ["e"]]
    assert one_cycle(graph, ["a", "b", "c"]) == ["a", "b", "c", "a"]


def _class_with_self_attributes(n: int) -> str:
    body = "\n".join(f"        self.a{i} = {i}" for i in range(n))
    return f"class Big:\n    def __init__(self) -> None:\n{body}\n"


def test_checker_counts_13_self_attributes_and_allows_12() -> None:
    thirteen = synthetic({"amrvio.pipeline.vo": _class_with_self_attributes(13)})
    problems = big_classes(thirteen)
    assert len(problems) == 1 and problems[0].startswith("amrvio/pipeline/vo.py:1: class Big has 13 attributes")
    assert big_classes(synthetic({"amrvio.pipeline.vo": _class_with_self_attributes(12)})) == []
    assert big_classes(synthetic({"amrvio.eval.x": _class_with_self_attributes(13)})) == []  # not per-frame


def test_checker_counts_every_kind_of_attribute_once() -> None:
    src = '''
from dataclasses import dataclass
from typing import ClassVar


@dataclass
class Rec:
    a: int
    b: float = 0.0
    LIMIT: ClassVar[int] = 3
    CONST = 4

    def __post_init__(self) -> None:
        object.__setattr__(self, "c", 1)
        self.a = 2


class Slots:
    __slots__ = ("s1", "s2")


class AnnotatedSlots:
    __slots__: tuple[str, ...] = ("t1",)


class Stage:
    def __init__(me, x: int) -> None:
        me.p, (me.q, *me.r) = 1, (2, 3)
        me.n: int = x
        me.n += 1
        setattr(me, "w", 0)
        for me.i in range(3):
            pass
        with open("f") as me.fh:
            pass

        def helper() -> None:
            me.from_closure = 1

        class Inner:
            def __init__(self) -> None:
                self.not_stage = 1

    @staticmethod
    def make(other: Stage) -> None:
        other.not_mine = 1

    def update(self) -> None:
        self.p = 5
        self.z = 6
        other = Stage(1)
        other.not_counted = 1
'''
    classes = {n.name: class_attributes(n) for n in ast.walk(ast.parse(src)) if isinstance(n, ast.ClassDef)}
    assert classes["Rec"] == {"a", "b", "c"}
    assert classes["Slots"] == {"s1", "s2"}
    assert classes["AnnotatedSlots"] == {"t1"}
    assert classes["Stage"] == {"p", "q", "r", "n", "w", "i", "fh", "from_closure", "z"}
    assert classes["Inner"] == {"not_stage"}


def test_checker_measures_per_frame_module_length() -> None:
    src401 = "x = 1\n" * 401
    mods = synthetic({"amrvio.tracking.klt": src401, "amrvio.imu.preint": "x = 1\n" * 400, "amrvio.sim.scene": src401})
    assert long_modules(mods) == ["amrvio/tracking/klt.py: 401 lines (limit 400)"]

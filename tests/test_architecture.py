"""The package's architecture, measured from its source (docs/architecture.md).

The import graph of flexmech_py is read with ``ast`` (every ``import`` and ``from ... import`` of a
package module, at module level or inside a function) and checked against the layer order defined
once here, in :data:`LAYERS`: no circle, no import pointing up a layer, no private name imported
across modules, every function-local import with a comment saying why (start-up time), no model
family compared with a name literal outside the registry, functions within one screen and modules
within 600 lines.  ``python tests/test_architecture.py`` prints the measurements.
"""

from __future__ import annotations

import ast
import re
import sys
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "flexmech_py"

#: the layers, bottom first: a module imports only from its own layer or the layers below it.  A name
#: is a module of the package ("case") or a sub-package with everything in it ("mechanism.*").
LAYERS = [
    ("base", ["base.*"]),
    ("mechanism", ["mechanism.*"]),
    ("case", ["case", "definitions"]),
    ("models", ["models.*"]),
    ("checks", ["checks.*"]),
    ("run", ["run.*"]),
    ("strength", ["strength.*"]),
    ("figures", ["figures.*"]),
    ("studies", ["studies.*"]),
    ("view", ["view", "view.*"]),
    ("cli", ["fmu_slave", "fmu", "cli_args", "cli_accuracy", "cli_design", "cli_fmu", "cli_optimize", "cli_run", "cli",
             "__main__", ""]),
]
MAX_LAYERS = 12

#: the words that justify a function-local import (on its line or the comment line above it)
LOCAL_IMPORT_REASON = re.compile(r"#.*start-?up", re.IGNORECASE)

#: modules still holding function-local imports without a reason, with their number today: the
#: count may only fall (the module moves into its layer's folder with them hoisted or explained)
LOCAL_IMPORTS_LEFT: dict = {}

#: functions over MAX_FUNCTION_LINES and files over MAX_FILE_LINES today, with their length: each
#: may only shrink until it is split (issue 26)
MAX_FUNCTION_LINES, MAX_FILE_LINES = 80, 600
LONG_FUNCTIONS: dict = {}
LONG_FILES: dict = {}


# --------------------------------------------------------------------------------------- the graph

def modules() -> dict[str, Path]:
    """{dotted name relative to the package ('' the package itself): path}."""
    out = {}
    for p in sorted(PACKAGE.rglob("*.py")):
        parts = list(p.relative_to(PACKAGE).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _absolute(mod: str, node: ast.ImportFrom, is_package: bool) -> str | None:
    """The package-relative module a ``from ... import`` names (None: outside the package)."""
    if node.level == 0:
        if node.module is None or not (node.module + ".").startswith("flexmech_py."):
            return None
        return node.module[len("flexmech_py"):].lstrip(".")
    base = mod.split(".") if mod else []
    if not is_package:
        base = base[:-1]
    if node.level > 1:
        base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports() -> list[dict]:
    """Every import of a package module: {src, dst, name (a name imported from dst, or None), local
    (inside a function), line, reason (a start-up comment on the line or the line above)}."""
    mods, out = modules(), []
    for mod, path in mods.items():
        lines = path.read_text(encoding="utf-8").splitlines()
        tree = ast.parse("\n".join(lines))
        local = {id(n) for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                 for n in ast.walk(f) if isinstance(n, (ast.Import, ast.ImportFrom))}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = _absolute(mod, node, path.name == "__init__.py")
                pairs = [] if target is None else [(target, a.name) for a in node.names]
            elif isinstance(node, ast.Import):
                pairs = [(a.name[len("flexmech_py"):].lstrip("."), None) for a in node.names
                         if (a.name + ".").startswith("flexmech_py.")]
            else:
                continue
            text = " ".join(lines[max(0, node.lineno - 2):node.end_lineno])
            for target, name in pairs:
                sub = f"{target}.{name}".lstrip(".") if name else None
                if name == "_flexmech":                  # the compiled kernels: an extension, not a module
                    continue
                dst, imported = (sub, None) if sub in mods else (target, name)
                out.append({"src": mod, "dst": dst, "name": imported, "local": id(node) in local,
                            "line": node.lineno, "reason": bool(LOCAL_IMPORT_REASON.search(text))})
    return out


def layer_of(mod: str) -> int:
    """The index in LAYERS of a module (ValueError: none names it)."""
    for i, (_, names) in enumerate(LAYERS):
        for n in names:
            if mod == n or (n.endswith(".*") and (mod + ".").startswith(n[:-1])):
                return i
    raise ValueError(mod)


def graph(edges=None) -> dict[str, set]:
    g = defaultdict(set)
    for e in imports() if edges is None else edges:
        if e["dst"] != e["src"] and e["dst"] in modules():
            g[e["src"]].add(e["dst"])
    return g


def circles(g: dict) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in g.get(v, ()):
            if w not in index:
                visit(w)
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

    for v in sorted(set(g) | {w for ws in g.values() for w in ws}):
        if v not in index:
            visit(v)
    return out


def longest_chain(g: dict) -> int:
    """Modules in the longest chain of imports (a module one above everything it imports)."""
    depth = {}

    def d(v, path=()):
        if v not in depth:
            depth[v] = 1 + max((d(w, path + (v,)) for w in g.get(v, ()) if w not in path), default=0)
        return depth[v]

    return max(d(v) for v in modules())


def functions():
    """(module, qualified name, lines) of every function."""
    for mod, path in modules().items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield mod, node.name, node.end_lineno - node.lineno + 1


# --------------------------------------------------------------------------------------- the tests

def test_every_module_has_a_layer():
    missing = []
    for mod in modules():
        try:
            layer_of(mod)
        except ValueError:
            missing.append(mod)
    assert not missing, f"modules in no layer of tests/test_architecture.py LAYERS: {missing}"
    assert len(LAYERS) <= MAX_LAYERS


def test_no_import_circle():
    assert circles(graph()) == []


def test_no_import_points_up():
    up = [f"{e['src']}:{e['line']} imports {e['dst']} ({LAYERS[layer_of(e['dst'])][0]} is above "
          f"{LAYERS[layer_of(e['src'])][0]})" for e in imports()
          if e["dst"] in modules() and layer_of(e["dst"]) > layer_of(e["src"])]
    assert up == []


def test_no_private_name_across_modules():
    private = [f"{e['src']}:{e['line']} imports {e['name']} from {e['dst']}" for e in imports()
               if e["name"] and e["name"].startswith("_") and not e["name"].startswith("__")]
    assert private == []


def test_function_local_imports_say_why():
    """A function-local import is for start-up time only, and says so in a comment; the modules of
    LOCAL_IMPORTS_LEFT keep at most their count of older ones without the comment."""
    count = defaultdict(int)
    for e in imports():
        if e["local"] and not e["reason"]:
            count[e["src"]] += 1
    over = {m: (n, LOCAL_IMPORTS_LEFT.get(m, 0)) for m, n in count.items() if n > LOCAL_IMPORTS_LEFT.get(m, 0)}
    assert over == {}, "function-local imports without a '# start-up ...' comment: {module: (now, allowed)}"


def _family_names() -> set:
    sys.path.insert(0, str(PACKAGE / "base"))
    try:
        import families   # the registry is a leaf: importable alone, without the compiled kernels
    finally:
        sys.path.remove(str(PACKAGE / "base"))
    return set(families.MODELS)


def _compared_names(tree, names: set) -> list[int]:
    """Lines where a family name literal is compared (==, !=, in, not in; alone or in a tuple)."""
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            sides = [node.left] + list(node.comparators)
            consts = [c for s in sides for c in ([s] if isinstance(s, ast.Constant) else
                                                 getattr(s, "elts", []) if isinstance(s, (ast.Tuple, ast.List, ast.Set)) else [])]
            if any(isinstance(c, ast.Constant) and c.value in names for c in consts):
                lines.append(node.lineno)
    return lines


def test_no_model_family_compared_by_name():
    """The mechanism, the case, the models, the checks, the run and the plots ask a family
    (flexmech_py.base.families) what it is and what it supports; none compares a model name with a
    literal.  The studies may: a study names the models it studies (the seed report sets case I,
    ``hac``, against case II, ``classic``; a study takes ``nonlinear`` as its reference)."""
    names = _family_names()
    studies = [n for n, _ in LAYERS].index("studies")
    found = {}
    for mod, path in modules().items():
        if mod == "base.families" or layer_of(mod) >= studies:
            continue
        lines = _compared_names(ast.parse(path.read_text(encoding="utf-8")), names)
        if lines:
            found[mod] = lines
    assert found == {}


def test_compared_names_finds_a_literal():
    """The check above finds what it looks for."""
    tree = ast.parse("if model == 'hac' or m in ('coupled', 'x') or k != 'other':\n    pass\n")
    assert _compared_names(tree, {"hac", "coupled"}) == [1, 1]


def test_functions_within_one_screen():
    long = {(m, f): n for m, f, n in functions() if n > MAX_FUNCTION_LINES}
    grown = {k: (n, LONG_FUNCTIONS.get(k)) for k, n in long.items() if n > LONG_FUNCTIONS.get(k, MAX_FUNCTION_LINES)}
    assert grown == {}, "functions over 80 lines (not listed, or longer than listed): {(module, name): (now, listed)}"


def test_modules_within_600_lines():
    long = {m: len(p.read_text(encoding="utf-8").splitlines()) for m, p in modules().items()}
    grown = {m: (n, LONG_FILES.get(m)) for m, n in long.items() if n > LONG_FILES.get(m, MAX_FILE_LINES)}
    assert grown == {}, "modules over 600 lines (not listed, or longer than listed): {module: (now, listed)}"


def test_the_lists_of_what_is_left_are_true():
    """LONG_FUNCTIONS, LONG_FILES and LOCAL_IMPORTS_LEFT name only what is still there: an entry whose
    function was split, or whose module moved or was cleaned, is removed."""
    lengths = {(m, f): n for m, f, n in functions()}
    assert [k for k in LONG_FUNCTIONS if lengths.get(k, 0) <= MAX_FUNCTION_LINES] == []
    mods = modules()
    assert [m for m in LONG_FILES if m not in mods
            or len(mods[m].read_text(encoding="utf-8").splitlines()) <= MAX_FILE_LINES] == []
    assert [m for m in LOCAL_IMPORTS_LEFT if m not in mods] == []


if __name__ == "__main__":
    edges = imports()
    g = graph(edges)
    top = graph([e for e in edges if not e["local"]])
    up = [e for e in edges if e["dst"] in modules() and layer_of(e["dst"]) > layer_of(e["src"])]
    print(f"modules {len(modules())}, import arrows {sum(len(v) for v in g.values())}, layers {len(LAYERS)}")
    print(f"longest chain: {longest_chain(g)} modules (module-level imports only: {longest_chain(top)})")
    print(f"circles: {circles(g)}; upward imports: {len(up)}")
    print(f"function-local imports: {sum(e['local'] for e in edges)}, "
          f"without a start-up comment: {sum(e['local'] and not e['reason'] for e in edges)}")
    print("functions over 80 lines:", sorted((n, m, f) for m, f, n in functions() if n > MAX_FUNCTION_LINES))

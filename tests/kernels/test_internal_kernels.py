"""Kernels compiled without numba's entry wrappers (``njit(internal=True)``, demcli/jit.py) crash
the interpreter when Python calls them, so none may be called from plain Python: this test reads
every module of demcli (and the tests and benchmarks) and fails on a call to an internal kernel
from a function that is not itself a kernel (njit-decorated), an overload, or the plain-Python
fallback an overload implements (run only with NUMBA_DISABLE_JIT=1)."""

import ast
from pathlib import Path

import numba
import pytest

from demcli.jit import INTERNAL

ROOT = Path(__file__).resolve().parents[2]


def _internal_kernels():
    """{(module, name)} of every internal dispatcher in demcli.kernels."""
    import importlib
    import pkgutil

    import demcli.kernels as pkg

    found = set()
    for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
        mod = importlib.import_module(info.name)
        for name, obj in vars(mod).items():
            if isinstance(obj, numba.core.registry.CPUDispatcher) and obj.__module__ == info.name and all(
                    obj.targetoptions.get(k) == v for k, v in INTERNAL.items()):
                found.add((info.name, name))
    return found


def _module_name(path):
    rel = path.relative_to(ROOT).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _imports(tree, module):
    """{local name: (module, name)} for ``from M import a as b``, {alias: (M, None)} for
    ``import M as m``; relative imports resolved against ``module``."""
    names = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(module.split(".")[:-node.level] + ([base] if base else []))
            for al in node.names:
                names[al.asname or al.name] = (base, al.name)
        elif isinstance(node, ast.Import):
            for al in node.names:
                names[al.asname or al.name.split(".")[0]] = (al.name if al.asname else al.name.split(".")[0], None)
    return names


def _is_kernel(fn):
    """A function decorated with njit (compiled) or registered as an overload."""
    for d in fn.decorator_list:
        target = d.func if isinstance(d, ast.Call) else d
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name in ("njit", "jit", "overload", "register_jitable"):
            return True
    return False


def _python_calls(tree, module):
    """((module, name) called, line) of the calls made by plain-Python functions (not kernels)."""
    imports = _imports(tree, module)
    # a plain function that an overload implements is the kernels' fallback without the JIT
    # (NUMBA_DISABLE_JIT=1, where every kernel is plain Python): it counts as a kernel
    overloaded = {d.args[0].id for node in ast.walk(tree) if isinstance(node, ast.FunctionDef)
                  for d in node.decorator_list if isinstance(d, ast.Call) and getattr(d.func, "id", "") == "overload"
                  and d.args and isinstance(d.args[0], ast.Name)}
    out = []

    def target(f):
        if isinstance(f, ast.Name):
            return imports.get(f.id, (module, f.id))
        if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id in imports:
            mod, name = imports[f.value.id]
            return (mod if name is None else f"{mod}.{name}", f.attr)
        return None

    def visit(node, in_kernel):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                visit(child, in_kernel or _is_kernel(child) or child.name in overloaded)
                continue
            if isinstance(child, ast.Call) and not in_kernel:
                t = target(child.func)
                if t is not None:
                    out.append((t, child.lineno))
            visit(child, in_kernel)

    visit(tree, False)
    return out


def test_internal_kernels_exist():
    # the marking is in force (a refactor that drops it would make the next test vacuous)
    names = {name for _, name in _internal_kernels()}
    assert {"gather", "kick_drift", "rebuild_lists"} <= names, names


@pytest.mark.parametrize("folder", ["demcli", "tests", "bench"])
def test_no_plain_python_function_calls_an_internal_kernel(folder):
    kernels = _internal_kernels()
    bad = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        for (mod, name), line in _python_calls(ast.parse(path.read_text(), str(path)), _module_name(path)):
            if (mod, name) in kernels:
                bad.append(f"{path.relative_to(ROOT)}:{line}: {mod}.{name}")
    assert not bad, "internal kernels called from Python (a crash, not an error):\n" + "\n".join(bad)

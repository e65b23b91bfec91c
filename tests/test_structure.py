"""The codebase's structure rules, checked on the source text (nothing is imported).

Layers as sub-packages (geometry -> coordinates -> basis -> parallel -> evolution -> models ->
apps); a lower layer never imports a higher one; no module imports or reads another module's
private names (a class offers a public method instead); `__init__` files only re-export; modules
stay under 800 lines and Python functions under 80 (numba kernels may be longer where they say why).
"""
import ast
import pathlib

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "skfem_nem"
LAYERS = ["geometry", "coordinates", "basis", "parallel", "evolution", "models", "apps"]
MAX_MODULE_LINES = 800
MAX_FUNCTION_LINES = 80
# scikit-fem's own private names that the assembly hook must use (and only it): the
# version range in pyproject.toml and the hook's tests guard them
SCIKIT_FEM_PRIVATE = {"_assemble", "_kernel", "_normalize_asm_kwargs"}


def modules():
    return sorted(PACKAGE.rglob("*.py"))


def name_of(path):
    return ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)


def parsed(path):
    return ast.parse(path.read_text(), filename=str(path))


def layer(module):
    parts = module.split(".")
    return LAYERS.index(parts[1]) if len(parts) > 1 and parts[1] in LAYERS else None


def imported(path, tree):
    """(module imported, names) for every import of the package from ``path``."""
    package = name_of(path).split(".")[:-1]  # for __init__.py: the package itself
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] == "skfem_nem":
                yield target, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "skfem_nem":
                    yield a.name, []


def private(name):
    return name.startswith("_") and not name.startswith("__")


def is_kernel(fn):
    return any("jit" in ast.unparse(d) for d in fn.decorator_list)


def test_the_package_has_the_layers():
    assert [p.name for p in sorted(PACKAGE.iterdir()) if (p / "__init__.py").exists()] == \
        sorted(LAYERS)


@pytest.mark.parametrize("path", modules(), ids=name_of)
def test_module_size(path):
    n = len(path.read_text().splitlines())
    assert n <= MAX_MODULE_LINES, f"{name_of(path)} has {n} lines"


def test_python_functions_are_short():
    long = []
    for path in modules():
        for fn in ast.walk(parsed(path)):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)) and not is_kernel(fn):
                n = fn.end_lineno - fn.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    long.append(f"{name_of(path)}.{fn.name}: {n} lines")
    assert not long, long


def test_long_kernels_say_why():
    """A numba kernel above the limit says why in a "# Long kernel: ..." comment."""
    silent = []
    for path in modules():
        text = path.read_text().splitlines()
        for fn in ast.walk(parsed(path)):
            if isinstance(fn, ast.FunctionDef) and is_kernel(fn) and \
                    fn.end_lineno - fn.lineno + 1 > MAX_FUNCTION_LINES:
                body = text[fn.lineno - 1:fn.end_lineno]
                if not any(line.strip().startswith("# Long kernel:") for line in body):
                    silent.append(f"{name_of(path)}.{fn.name}")
    assert not silent, silent


def test_lower_layers_never_import_higher_ones():
    wrong = []
    for path in modules():
        here = layer(name_of(path))
        if here is None:
            continue
        for target, _ in imported(path, parsed(path)):
            there = layer(target)
            if there is not None and there > here:
                wrong.append(f"{name_of(path)} imports {target}")
    assert not wrong, wrong


def test_no_private_name_imported_across_modules():
    wrong = []
    for path in modules():
        for target, names in imported(path, parsed(path)):
            wrong += [f"{name_of(path)} imports {target}.{n}" for n in names if private(n)]
            wrong += [f"{name_of(path)} imports {target}" for part in target.split(".")
                      if private(part)]
    assert not wrong, wrong


def defined_private_names(tree):
    """Private names a module defines: functions, classes, variables and the
    attributes it assigns on ``self`` / ``cls`` (writing another object's private
    attribute defines nothing: it reaches into that object's module)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and private(node.name):
            out.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store) and private(node.id):
            out.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store) and \
                private(node.attr) and isinstance(node.value, ast.Name) and \
                node.value.id in ("self", "cls"):
            out.add(node.attr)
    return out


def test_no_private_attribute_of_another_module_is_read_or_written():
    trees = {path: parsed(path) for path in modules()}
    own = {path: defined_private_names(tree) for path, tree in trees.items()}
    wrong = []
    for path, tree in trees.items():
        others = set().union(*(v for p, v in own.items() if p != path))
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Attribute) and private(node.attr)):
                continue
            if isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"):
                continue
            if node.attr in SCIKIT_FEM_PRIVATE and path.name == "assembly.py":
                continue
            if node.attr in others and node.attr not in own[path]:
                wrong.append(f"{name_of(path)}:{node.lineno} uses .{node.attr}")
    assert not wrong, wrong


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("__init__.py")), ids=name_of)
def test_init_files_only_re_export(path):
    for node in parsed(path).body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            continue
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
            continue  # the docstring
        if isinstance(node, ast.Assign) and \
                all(isinstance(t, ast.Name) and t.id in ("__all__", "__version__")
                    for t in node.targets):
            continue
        pytest.fail(f"{name_of(path)} line {node.lineno}: {ast.unparse(node)[:60]}")

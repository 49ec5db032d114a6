"""The type stubs of rokeby_native (python/rokeby_native/*.pyi: one file per submodule, shipped in
the wheel with py.typed) match the built module: the submodules are the core's areas, every public
name of the module and of each submodule has a stub and no stub names something the module lacks;
every function's and method's parameters (names, positional or keyword-only, defaults) equal its
`__text_signature__`; properties are properties; NumericalError is a RuntimeError. Adding a
function to the binding without its stub fails here."""

import ast
import builtins
import importlib
import inspect
import types
from pathlib import Path

import pytest
import rokeby_native as rn

ROOT = Path(__file__).resolve().parents[2]
STUBS = ROOT / "python" / "rokeby_native"
# The areas of the core (folders of rust/rokeby-core/src, files of rust/rokeby-py/src).
AREAS = ("reflection", "geometry", "envmaps", "shadows", "compositing", "exr_io")


def _stub_tree(module: str) -> ast.Module:
    path = STUBS / ("__init__.pyi" if module == "" else f"{module}.pyi")
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _public_stub_names(tree: ast.Module) -> dict[str, ast.AST]:
    out: dict[str, ast.AST] = {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            out[node.name] = node
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            out[node.target.id] = node
        elif isinstance(node, ast.Assign):
            for t in node.targets:
                if isinstance(t, ast.Name):
                    out[t.id] = node
        elif isinstance(node, ast.ImportFrom) and node.module is None and node.level == 1:
            for alias in node.names:  # `from . import reflection as reflection`: a submodule
                out[alias.asname or alias.name] = node
    return {k: v for k, v in out.items() if not k.startswith("_") or k == "__version__"}


def _module_public_names(module: str) -> set[str]:
    mod = getattr(rn, module) if module else rn
    names = {n for n in dir(mod) if not n.startswith("_")}
    if module:
        return names
    # maturin's package __init__ (python/rokeby_native/__init__.py) re-exports the extension
    # module's names and keeps the extension module itself as the attribute `rokeby_native`.
    names.discard("rokeby_native")
    return names | {"__version__"}


def _stubbed_modules() -> list[str]:
    return ["", *AREAS]


def test_the_submodules_are_the_core_areas():
    core = ROOT / "rust" / "rokeby-core" / "src"
    binding = ROOT / "rust" / "rokeby-py" / "src"
    for area in AREAS:
        assert (core / area).is_dir() or (core / f"{area}.rs").is_file(), f"{area}: no such area in the core"
        assert (binding / f"{area}.rs").is_file(), f"{area}: no binding file rust/rokeby-py/src/{area}.rs"
        assert isinstance(getattr(rn, area), types.ModuleType), area
        assert importlib.import_module(f"rokeby_native.{area}") is getattr(rn, area)
    submodules = {n for n in dir(rn) if isinstance(getattr(rn, n), types.ModuleType)} - {"rokeby_native"}
    assert submodules == set(AREAS)
    # The top level holds only what spans the areas.
    assert _module_public_names("") - set(AREAS) == {"__version__", "NumericalError", "cancel"}
    stubs = {p.stem for p in STUBS.glob("*.pyi")} - {"__init__", "_types"}
    assert stubs == set(AREAS), f"stub files {sorted(stubs)} != areas {sorted(AREAS)}"


_NO_DEFAULT = object()


def _stub_params(fn: ast.FunctionDef, drop_first: bool) -> list[tuple[str, str, object]]:
    a = fn.args
    assert not a.vararg and not a.kwarg, f"{fn.name}: *args/**kwargs in the stub"
    positional = a.posonlyargs + a.args
    defaults = [_NO_DEFAULT] * (len(positional) - len(a.defaults)) + list(a.defaults)
    out = [(p.arg, "positional", d) for p, d in zip(positional, defaults)]
    out += [(p.arg, "keyword", d if d is not None else _NO_DEFAULT)
            for p, d in zip(a.kwonlyargs, a.kw_defaults)]
    if drop_first:
        out = out[1:]
    return out


def _runtime_params(obj, what: str) -> list[tuple[str, str, object]]:
    text = getattr(obj, "__text_signature__", None)
    assert text, f"{what}: no __text_signature__"
    sig = inspect.signature(obj)
    out = []
    for p in sig.parameters.values():
        if p.name in ("self", "cls", "$self", "$cls"):
            continue
        assert p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY, p.POSITIONAL_ONLY), (what, p)
        kind = "keyword" if p.kind is p.KEYWORD_ONLY else "positional"
        out.append((p.name, kind, _NO_DEFAULT if p.default is p.empty else p.default))
    return out


def _compare(stub: list, runtime: list, what: str) -> None:
    assert [(n, k) for n, k, _ in stub] == [(n, k) for n, k, _ in runtime], (
        f"{what}: stub parameters {[(n, k) for n, k, _ in stub]} "
        f"!= module {[(n, k) for n, k, _ in runtime]}")
    for (name, _, sd), (_, _, rd) in zip(stub, runtime):
        if rd is _NO_DEFAULT:
            assert sd is _NO_DEFAULT, f"{what}: {name} has a default in the stub, none in the module"
            continue
        assert sd is not _NO_DEFAULT, f"{what}: {name} has a default in the module, none in the stub"
        stub_default = ast.literal_eval(sd)
        if stub_default is Ellipsis or rd is Ellipsis:
            continue  # a default the text signature cannot spell (a Rust constant)
        assert stub_default == rd, f"{what}: {name} defaults to {stub_default!r} in the stub, {rd!r} in the module"


def _is_property(fn: ast.FunctionDef) -> bool:
    return any(isinstance(d, ast.Name) and d.id == "property" for d in fn.decorator_list)


def test_every_public_name_has_a_stub_and_every_stub_a_name():
    for module in _stubbed_modules():
        stubs = set(_public_stub_names(_stub_tree(module)))
        names = _module_public_names(module)
        what = f"rokeby_native.{module}" if module else "rokeby_native"
        assert names - stubs == set(), f"in {what} without a stub: {sorted(names - stubs)}"
        assert stubs - names == set(), f"stubbed but not in {what}: {sorted(stubs - names)}"


def test_function_signatures_match_the_module():
    checked = 0
    for module in _stubbed_modules():
        mod = getattr(rn, module) if module else rn
        for name, node in _public_stub_names(_stub_tree(module)).items():
            if not isinstance(node, ast.FunctionDef):
                continue
            what = f"{module}.{name}" if module else name
            _compare(_stub_params(node, drop_first=False), _runtime_params(getattr(mod, name), what), what)
            checked += 1
    assert checked >= 25


def test_class_members_match_the_module():
    for module in _stubbed_modules():
        mod = getattr(rn, module) if module else rn
        classes = [n for n in _public_stub_names(_stub_tree(module)).values() if isinstance(n, ast.ClassDef)]
        for cls_node in classes:
            cls = getattr(mod, cls_node.name)
            if issubclass(cls, BaseException):
                bases = [getattr(builtins, b.id) for b in cls_node.bases if isinstance(b, ast.Name)]
                assert bases and all(issubclass(cls, b) for b in bases), cls_node.name
                continue
            assert cls.__module__ == f"rokeby_native.{module}", (cls_node.name, cls.__module__)
            members = {n.name: n for n in cls_node.body if isinstance(n, ast.FunctionDef)}
            runtime = {n for n in vars(cls) if not n.startswith("_")}
            stubbed = {n for n in members if not n.startswith("_")}
            assert runtime == stubbed, (f"{cls_node.name}: module members {sorted(runtime)} "
                                        f"!= stub members {sorted(stubbed)}")
            assert "__new__" in members, f"{cls_node.name}: the constructor has no stub"
            _compare(_stub_params(members["__new__"], drop_first=True),
                     _runtime_params(cls, f"{cls_node.name}()"), f"{cls_node.name}()")
            for name in stubbed:
                attr = vars(cls)[name]
                what = f"{cls_node.name}.{name}"
                if _is_property(members[name]):
                    assert inspect.isdatadescriptor(attr), f"{what}: a property in the stub, not in the module"
                else:
                    assert callable(attr), f"{what}: a method in the stub, not callable in the module"
                    _compare(_stub_params(members[name], drop_first=True), _runtime_params(attr, what), what)


def test_numerical_error_is_stubbed_as_a_runtime_error():
    node = _public_stub_names(_stub_tree(""))["NumericalError"]
    assert isinstance(node, ast.ClassDef)
    assert [b.id for b in node.bases if isinstance(b, ast.Name)] == ["RuntimeError"]
    assert issubclass(rn.NumericalError, RuntimeError)


def test_the_wheel_ships_the_stubs_and_py_typed():
    pkg = Path(rn.__file__).parent
    if not (pkg / "__init__.py").exists():
        pytest.skip("rokeby_native is not installed as a package (an in-place build)")
    assert (pkg / "py.typed").exists(), f"no py.typed in {pkg}"
    for stub in sorted(STUBS.glob("*.pyi")):
        shipped = pkg / stub.name
        assert shipped.exists(), f"no {stub.name} in {pkg}: {sorted(p.name for p in pkg.iterdir())}"
        assert shipped.read_text(encoding="utf-8") == stub.read_text(encoding="utf-8"), (
            f"the installed wheel's {stub.name} differs from python/rokeby_native/{stub.name}: rebuild the wheel")

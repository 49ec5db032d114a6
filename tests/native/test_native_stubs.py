"""The type stubs of rokeby_native (rokeby_native.pyi at the repository root, shipped in the wheel
with py.typed) match the built module: every public name has a stub and no stub names something
the module lacks; every function's and method's parameters (names, positional or keyword-only,
defaults) equal its `__text_signature__`; properties are properties; NumericalError is a
RuntimeError. Adding a function to the binding without its stub fails here."""

import ast
import builtins
import inspect
from pathlib import Path

import pytest
import rokeby_native as rn

ROOT = Path(__file__).resolve().parents[2]
STUB = ROOT / "rokeby_native.pyi"


def _stub_tree() -> ast.Module:
    return ast.parse(STUB.read_text(encoding="utf-8"), filename=str(STUB))


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
    return {k: v for k, v in out.items() if not k.startswith("_") or k == "__version__"}


def _module_public_names() -> set[str]:
    names = {n for n in dir(rn) if not n.startswith("_")}
    # maturin's generated package __init__ re-exports the extension module's names and keeps the
    # extension module itself as the attribute `rokeby_native`.
    names.discard("rokeby_native")
    return names | {"__version__"}


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
    stubs = set(_public_stub_names(_stub_tree()))
    module = _module_public_names()
    assert module - stubs == set(), f"in rokeby_native without a stub: {sorted(module - stubs)}"
    assert stubs - module == set(), f"stubbed but not in rokeby_native: {sorted(stubs - module)}"


def test_function_signatures_match_the_module():
    checked = 0
    for name, node in _public_stub_names(_stub_tree()).items():
        if not isinstance(node, ast.FunctionDef):
            continue
        _compare(_stub_params(node, drop_first=False), _runtime_params(getattr(rn, name), name), name)
        checked += 1
    assert checked >= 25


def test_class_members_match_the_module():
    classes = [n for n in _public_stub_names(_stub_tree()).values() if isinstance(n, ast.ClassDef)]
    for cls_node in classes:
        cls = getattr(rn, cls_node.name)
        if issubclass(cls, BaseException):
            bases = [getattr(builtins, b.id) for b in cls_node.bases if isinstance(b, ast.Name)]
            assert bases and all(issubclass(cls, b) for b in bases), cls_node.name
            continue
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
    node = _public_stub_names(_stub_tree())["NumericalError"]
    assert isinstance(node, ast.ClassDef)
    assert [b.id for b in node.bases if isinstance(b, ast.Name)] == ["RuntimeError"]
    assert issubclass(rn.NumericalError, RuntimeError)


def test_the_wheel_ships_the_stubs_and_py_typed():
    pkg = Path(rn.__file__).parent
    if not (pkg / "__init__.py").exists():
        pytest.skip("rokeby_native is not installed as a package (an in-place build)")
    assert (pkg / "py.typed").exists(), f"no py.typed in {pkg}"
    shipped = pkg / "rokeby_native.pyi"
    if not shipped.exists():
        shipped = pkg / "__init__.pyi"
    assert shipped.exists(), f"no stubs in {pkg}: {sorted(p.name for p in pkg.iterdir())}"
    assert shipped.read_text(encoding="utf-8") == STUB.read_text(encoding="utf-8"), (
        "the installed wheel's stubs differ from rokeby_native.pyi: rebuild the wheel")

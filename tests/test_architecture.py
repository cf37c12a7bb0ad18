"""The house rules of docs/architecture.md, checked on the source.

* the import-linter contracts in pyproject.toml (layers, no sibling cycles, a light core);
* every package with modules of its own in the no-cycles contract;
* no private name imported from another module;
* no function-local flexreg import outside the command line (``cli/``, ``picker/``);
* no module over 800 lines and no function over 100 lines (docstrings not counted), except the
  ones named in docs/architecture.md with their reasons.

The source is parsed, not imported, so these tests cost a few seconds.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "flexreg"
ADAPTERS = ("flexreg.cli", "flexreg.picker")  # may import lazily: keeps `flexreg --help` fast
MAX_MODULE_LINES = 800
MAX_FUNCTION_LINES = 100
#: Longer than the limits on purpose; docs/architecture.md says why for each.
EXCEPTIONS: dict[str, str] = {}


def _modules() -> list[tuple[str, Path]]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(REPO).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.append((".".join(parts), path))
    return out


def _package(module: str, path: Path) -> str:
    return module if path.name == "__init__.py" else module.rpartition(".")[0]


def _absolute(module: str, path: Path, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    base = _package(module, path).split(".")
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _lint_imports(cwd: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("lint-imports")
    if not exe.exists():
        pytest.skip("import-linter is not installed (pip install -e '.[dev]')")
    return subprocess.run(
        [str(exe), str(REPO / "pyproject.toml"), "--no-cache"],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
    )


def test_import_contracts_hold():
    r = _lint_imports(REPO, {**os.environ, "PYTHONPATH": str(REPO)})
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]


def test_every_package_is_in_the_no_cycles_contract():
    """A new package (or one forgotten, as the survey once was) may not grow a cycle unseen."""
    import tomllib

    contracts = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"]
    (acyclic,) = [c for c in contracts["contracts"] if c["id"] == "acyclic"]
    packages = {
        module
        for module, path in _modules()
        if path.name == "__init__.py" and len(list(path.parent.glob("*.py"))) > 2
    }
    assert packages - set(acyclic["ancestors"]) == set()


def test_import_contracts_catch_an_upward_import(tmp_path):
    """The contract is not vacuous: a copy of the package where a core module imports the
    command line must be refused."""
    shutil.copytree(PACKAGE, tmp_path / "flexreg", ignore=shutil.ignore_patterns("__pycache__"))
    scan = tmp_path / "flexreg" / "core" / "scan.py"
    scan.write_text(scan.read_text() + "\nimport flexreg.cli.app  # noqa\n")
    r = _lint_imports(tmp_path, {**os.environ, "PYTHONPATH": str(tmp_path)})
    assert r.returncode != 0
    assert "flexreg.core is not allowed to import flexreg.cli" in r.stdout


def test_no_private_names_across_modules():
    """``from flexreg.a.b import _x`` nowhere: a name another module needs is public in the
    module that owns it. A private module (``flexreg.a._b``) is imported only inside its
    package."""
    bad = []
    for module, path in _modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom):
                continue
            source = _absolute(module, path, node)
            if not source.startswith("flexreg"):
                continue
            owner = (
                source if (REPO / source.replace(".", "/")).is_dir() else source.rpartition(".")[0]
            )
            here = _package(module, path)
            private = [
                a.name for a in node.names if a.name.startswith("_") and a.name != "__version__"
            ]
            private_module = any(p.startswith("_") for p in source.split(".")[1:])
            same = here == owner and here != "flexreg"
            if private or (private_module and not same and source != "flexreg._version"):
                bad.append(f"{path.relative_to(REPO)}:{node.lineno} {source} {private}")
    assert not bad, "\n".join(bad)


def test_flexreg_imports_at_module_level_outside_the_cli():
    bad = []
    for module, path in _modules():
        if module.startswith(ADAPTERS):
            continue
        tree = ast.parse(path.read_text())
        for fn in ast.walk(tree):
            if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.ImportFrom):
                    source = _absolute(module, path, node)
                elif isinstance(node, ast.Import):
                    source = node.names[0].name
                else:
                    continue
                if (
                    source == "flexreg"
                    or source.startswith("flexreg.")
                    or (isinstance(node, ast.ImportFrom) and node.level)
                ):
                    bad.append(f"{path.relative_to(REPO)}:{node.lineno} {fn.name} -> {source}")
    assert not bad, "\n".join(bad)


def _body_lines(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    n = fn.end_lineno - fn.lineno + 1
    first = fn.body[0]
    if isinstance(first, ast.Expr) and isinstance(getattr(first, "value", None), ast.Constant):
        if isinstance(first.value.value, str):
            n -= first.end_lineno - first.lineno + 1
    return n


def test_modules_and_functions_stay_readable():
    too_long = []
    scripts = [p for d in ("benchmarks", "scripts") for p in sorted((REPO / d).glob("*.py"))]
    for path in [p for _, p in _modules()] + scripts:
        rel = path.relative_to(REPO).as_posix()
        text = path.read_text()
        if len(text.splitlines()) > MAX_MODULE_LINES and rel not in EXCEPTIONS:
            too_long.append(f"{rel}: {len(text.splitlines())} lines")
        for fn in ast.walk(ast.parse(text)):
            if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
                key = f"{rel}:{fn.name}"
                if _body_lines(fn) > MAX_FUNCTION_LINES and key not in EXCEPTIONS:
                    too_long.append(f"{key}: {_body_lines(fn)} lines")
    assert not too_long, "\n".join(too_long)


def test_every_exception_is_explained_in_the_architecture_page():
    doc = (REPO / "docs" / "architecture.md").read_text()
    missing = [key for key in EXCEPTIONS if key not in doc]
    assert not missing, missing


#: The dense check's entry points (flexreg.registration.check, fullres): their tolerances come
#: from its one Tolerance model, never from a number typed at the call.
CHECK_CALLS = frozenset(
    {"classify", "judge", "score", "check_masks", "duel_masks", "pose_masks", "full_masks"}
)


def test_no_bare_numbers_in_calls_to_the_dense_check():
    """A call to the dense check in registration/ or survey/ passes no number literal (a
    tolerance written at the call drifts from the one model: check.TOLERANCE)."""
    found = []
    for folder in ("registration", "survey"):
        for path in sorted((PACKAGE / folder).glob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if not isinstance(node, ast.Call):
                    continue
                f = node.func
                name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
                if name not in CHECK_CALLS:
                    continue
                args = [*node.args, *(k.value for k in node.keywords)]
                for a in args:
                    inner = a.operand if isinstance(a, ast.UnaryOp) else a
                    if isinstance(inner, ast.Constant) and isinstance(inner.value, float):
                        found.append(f"{path.relative_to(REPO)}:{node.lineno} {name}")
                    if isinstance(a, ast.BinOp) and any(
                        isinstance(x, ast.Constant) and isinstance(x.value, float)
                        for x in (a.left, a.right)
                    ):
                        found.append(f"{path.relative_to(REPO)}:{node.lineno} {name}")
    assert not found, "\n".join(found)

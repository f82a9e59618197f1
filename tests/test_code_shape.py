"""The code's shape limits: no function in core/ or kd_addon/ takes more than 12 parameters (kernels take
named tuples of arrays instead), and no module of the project, tests included, is over 600 lines."""
import ast
from pathlib import Path


ROOT = Path(__file__).resolve().parent.parent
MAX_PARAMETERS = 12
MAX_LINES = 600


def _modules(folders=("core", "kd_addon")):
    return sorted(p for folder in folders for p in (ROOT / folder).rglob("*.py"))


def _parameter_count(function) -> int:
    """Every parameter, self and *args / **kwargs included."""
    a = function.args
    return (len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None)
            + (a.kwarg is not None))


def test_no_function_takes_more_than_12_parameters():
    long = [f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({_parameter_count(node)})"
            for path in _modules() for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and _parameter_count(node) > MAX_PARAMETERS]
    assert not long, "functions over 12 parameters:\n" + "\n".join(long)


def test_no_module_is_over_600_lines():
    counts = {path.relative_to(ROOT).as_posix(): len(path.read_text(encoding="utf-8").splitlines())
              for path in _modules(("core", "kd_addon", "tests", "benchmarks", "tools"))}
    long = {name: n for name, n in counts.items() if n > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"


def test_the_checker_counts_every_kind_of_parameter():
    function = ast.parse("def f(a, /, b, *c, d, **e): pass").body[0]
    assert _parameter_count(function) == 5

"""Numba's inliner with core's memo of callee IR (core/jit/inline_memo.py) compiles to the same machine code
as without it, translating each inline="always" callee once per compile instead of once per call site."""
import json
import re

import pytest

from tests.addon_support import run_python
from tests.test_inline_copy import KERNEL, PREAMBLE, TYPED_TWICE, _python_reference

# Inserted into a kernel script of test_inline_copy.py (with core's scope-sharing copy and without the memo):
# with the memo installed again or not, it prints the machine code, the number of untyped-pipeline runs for callees
# and the memo's state after the compile.
MEMO_SWITCH = """
import core.jit.inline_memo as inline_memo
if {memo}:
    inline_memo.install()  # the kernel script's preamble took it out
runs = [0]
numba_run = inline_closurecall.InlineWorker.run_untyped_passes
def counting_run(self, *args, **kwargs):
    runs[0] += 1
    return numba_run(self, *args, **kwargs)
inline_closurecall.InlineWorker.run_untyped_passes = counting_run
"""
REPORT = """
asm = "\\n".join(kernel.inspect_asm().values()) + "\\n".join(g.inspect_asm().values() if "g" in globals() else ())
print(json.dumps({{"asm": asm, "runs": runs[0], "result": result, "open": inline_memo._MEMO["current"] is not None}}))
"""


def _compile(memo: bool, script: str) -> dict:
    head, _, tail = script.partition("copies = [0]")
    source = head + MEMO_SWITCH.format(memo=memo) + "copies = [0]" + tail + REPORT
    proc = run_python(source.format(patched=True), env={"NUMBA_DISABLE_JIT": None})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _machine_code(asm: str) -> str:
    """The assembly without what differs between compiles of the same code: the version numbers Numba
    gives compiled functions (one count per process), addresses in names, and block label numbers."""
    asm = re.sub(r"B\d+v\d+B", "BvB", asm)
    asm = re.sub(r"0x[0-9a-f]{6,}", "0xADDR", asm)
    labels = {}
    return re.sub(r"(?<![\w.])B\d+\b", lambda m: labels.setdefault(m.group(0), f"L{len(labels)}"), asm)


@pytest.mark.slow
def test_the_memo_compiles_the_same_machine_code_translating_each_callee_once():
    numba_own, memo = _compile(False, KERNEL), _compile(True, KERNEL)
    assert _machine_code(memo["asm"]) == _machine_code(numba_own["asm"])
    a = [-2.0 + 4.0 * k / 6 for k in range(7)]
    assert memo["result"] == numba_own["result"] == pytest.approx(_python_reference(a, 5), rel=1e-12)
    # kernel inlines sweep twice and step once; each sweep inlines step twice and clamp once, each step
    # clamp three times: Numba translates callees at every site, the memo once a function (3)
    assert numba_own["runs"] > 10 and memo["runs"] == 3, (numba_own["runs"], memo["runs"])
    assert not memo["open"]


def test_an_overload_inlined_during_an_inlining_compiles_the_same_with_the_memo():
    numba_own, memo = _compile(False, TYPED_TWICE), _compile(True, TYPED_TWICE)
    assert memo["result"] == numba_own["result"] == (4 + 70) + (4 + 70)
    assert _machine_code(memo["asm"]) == _machine_code(numba_own["asm"])
    assert not memo["open"]


# A function inlined twice into a kernel and twice into a parallel function (prange, whose parfor analyses
# read variable versions: each reuse of the kept IR takes a fresh unique name, so two inlined copies never
# share their variables' names), compiled in one process.
NESTED_FLAGS = PREAMBLE + """
from numba import prange

@njit(inline="always")
def h(x):
    return x * 2 + 1

@njit(parallel=True)
def g(x):
    s = 0
    for i in prange(3):
        s += h(x + i) - h(x - i)
    return s

@njit(inline="always")
def f(x):
    if isinstance(x, int):
        return g(x) + h(x) + h(x + 1)
    return g(x) + h(x)

@njit
def kernel(x):
    return f(x)

result = kernel(5)
print(json.dumps({{"llvm": "", "copies": copies[0], "result": result}}))
"""


def test_a_callee_inlined_twice_into_a_parallel_function_compiles_the_same():
    numba_own, memo = _compile(False, NESTED_FLAGS), _compile(True, NESTED_FLAGS)
    assert memo["result"] == numba_own["result"] == (0 + 4 + 8) + 11 + 13  # g(5) + h(5) + h(6)
    assert _machine_code(memo["asm"]) == _machine_code(numba_own["asm"])
    # f once; h once in f's compile and once in g's, where Numba translates it at each of the four sites
    assert memo["runs"] == 3 < numba_own["runs"], (memo["runs"], numba_own["runs"])
    assert not memo["open"]

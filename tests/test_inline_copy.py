"""Numba's inliner with core's scope-sharing copy (core/jit/inline_copy.py) compiles to the same LLVM IR as
Numba's own: a kernel of nested inline="always" functions (copying far fewer variables, and each block
once), and an @overload(inline="always") inlined twice in a function compiled during another inlining."""
import json

import pytest

from tests.addon_support import run_python

# Compiled without a cache in a fresh process, with or without the patch; each kernel script ends by
# printing its LLVM IR, the number of Var deep copies and a result.
PREAMBLE = """
import json
import numpy as np
from numba import njit
from numba.core import inline_closurecall, ir
if {patched}:
    import core.jit.inline_copy  # installs itself
    assert inline_closurecall.InlineWorker.inline_ir.kd_preview_scope_sharing
    # core's import also installs the memo of callee IR (tests/test_inline_memo.py): the copy alone here
    from numba.core import untyped_passes
    inline_closurecall.InlineWorker.inline_function = inline_closurecall.InlineWorker.inline_function.__wrapped__
    untyped_passes.InlineInlinables.run_pass = untyped_passes.InlineInlinables.run_pass.__wrapped__
copies = [0]
numba_var_copy = ir.Var.__deepcopy__
def counting_var_copy(self, memo):
    copies[0] += 1
    return numba_var_copy(self, memo)
ir.Var.__deepcopy__ = counting_var_copy
# Blocks inlined (each callee's, at each inlining) and blocks deep-copied
import copy as copy_module
callee_blocks, block_copies = [0], [0]
numba_inline_ir = inline_closurecall.InlineWorker.inline_ir
def counting_inline_ir(self, caller_ir, block, i, callee_ir, *args, **kwargs):
    callee_blocks[0] += len(callee_ir.blocks)
    return numba_inline_ir(self, caller_ir, block, i, callee_ir, *args, **kwargs)
inline_closurecall.InlineWorker.inline_ir = counting_inline_ir
python_deepcopy = copy_module.deepcopy
def counting_deepcopy(x, memo=None, _nil=[]):
    if isinstance(x, ir.Block) and (memo is None or id(x) not in memo):
        block_copies[0] += 1
    return python_deepcopy(x, memo, _nil)
copy_module.deepcopy = counting_deepcopy
"""

# Three levels of inlined functions with loops and branches (many blocks, many variables).
KERNEL = PREAMBLE + """
@njit(inline="always")
def clamp(x, lo, hi):
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x

@njit(inline="always")
def step(a, i):
    s = 0.0
    for k in range(a.shape[0]):
        v = clamp(a[k] * i - k, -3.0, 3.0)
        if v > 1.0:
            s += v
        elif v < -1.0:
            s -= clamp(v * v, 0.0, 2.0)
        else:
            s += clamp(v, 0.5, 0.75)
    return s

@njit(inline="always")
def sweep(a, n):
    total = 0.0
    for i in range(n):
        total += step(a, i) if i % 3 else -step(a, i + 1)
        total = clamp(total, -1e6, 1e6)
    return total

@njit
def kernel(a, n):
    return sweep(a, n) + sweep(a, n + 1) + step(a, n)

result = kernel(np.linspace(-2.0, 2.0, 7), 5)
llvm = "\\n".join(kernel.inspect_llvm().values())
print(json.dumps({{"llvm": llvm, "copies": copies[0], "result": result,
                  "callee_blocks": callee_blocks[0], "block_copies": block_copies[0]}}))
"""


# A failing case: the typed pass inlines a cached @overload IR twice into g, which compiles
# while f is being inlined (isinstance makes the untyped inliner type f's body). Memos kept across that
# whole inlining handed the second inlining the first one's renamed blocks: the compile failed.
TYPED_TWICE = PREAMBLE + """
from numba.extending import overload

def distance(a, b):
    pass

@overload(distance, inline="always")
def distance_impl(a, b):
    def impl(a, b):
        if a > b:
            return a - b
        return b - a + 1
    return impl

@njit
def g(x):
    return distance(x, x + 3) + distance(x + 7, x) * 10

@njit(inline="always")
def f(x):
    if isinstance(x, int):
        return g(x) + g(4)
    return g(x) + g(4) + 1

@njit
def kernel(x):
    return f(x)

result = kernel(5)
llvm = "\\n".join(kernel.inspect_llvm().values()) + "\\n".join(g.inspect_llvm().values())
print(json.dumps({{"llvm": llvm, "copies": copies[0], "result": result,
                  "callee_blocks": callee_blocks[0], "block_copies": block_copies[0]}}))
"""


def _compile(patched: bool, script: str = KERNEL) -> dict:
    proc = run_python(script.format(patched=patched), env={"NUMBA_DISABLE_JIT": None})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _python_reference(a, n):
    clamp = lambda x, lo, hi: lo if x < lo else hi if x > hi else x  # noqa: E731

    def step(i):
        s = 0.0
        for k, ak in enumerate(a):
            v = clamp(ak * i - k, -3.0, 3.0)
            s += v if v > 1.0 else -clamp(v * v, 0.0, 2.0) if v < -1.0 else clamp(v, 0.5, 0.75)
        return s

    def sweep(n):
        total = 0.0
        for i in range(n):
            total = clamp(total + (step(i) if i % 3 else -step(i + 1)), -1e6, 1e6)
        return total

    return sweep(n) + sweep(n + 1) + step(n)


@pytest.mark.slow
def test_scope_sharing_copy_compiles_the_same_code_with_fewer_copies():
    numba_own, shared = _compile(False), _compile(True)
    assert shared["llvm"] == numba_own["llvm"]
    a = [-2.0 + 4.0 * k / 6 for k in range(7)]
    assert shared["result"] == pytest.approx(_python_reference(a, 5), rel=1e-12)
    assert shared["result"] == numba_own["result"]
    # Numba's own copies each block's scope: at least one Var copy per block and variable
    assert shared["copies"] * 3 < numba_own["copies"], (shared["copies"], numba_own["copies"])


@pytest.mark.parametrize("script", [KERNEL, TYPED_TWICE], ids=["nested", "typed-twice"])
def test_each_inlined_block_is_copied_once(script):
    """Numba's inline_ir copies a callee twice (the second copy: an unmutated original that its callers
    discard); with the shim each block of each inlining is copied once, and the code is the same."""
    numba_own, shared = _compile(False, script), _compile(True, script)
    assert numba_own["callee_blocks"] == shared["callee_blocks"] > 0
    assert numba_own["block_copies"] == 2 * numba_own["callee_blocks"]
    assert shared["block_copies"] == shared["callee_blocks"]
    assert shared["llvm"] == numba_own["llvm"] and shared["result"] == numba_own["result"]


def test_overload_inlined_twice_during_another_inlining_compiles_the_same():
    numba_own, shared = _compile(False, TYPED_TWICE), _compile(True, TYPED_TWICE)
    assert numba_own["result"] == shared["result"] == (4 + 70) + (4 + 70)  # g(5) + g(4)
    assert shared["llvm"] == numba_own["llvm"]

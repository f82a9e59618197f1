"""Numba's inliner copies a callee's IR one block at a time, and so its whole variable scope once per
block; `install` makes it copy the scope once per callee. Same machine code, half the compile time.

Core inlines its hot paths (inline="always": the traversal into the sampling kernel and the camera
rays' kernel, traversal.trace_ray). For every call site of such a function, Numba's InlineInlinables
pass compiles the callee to IR (inlining its own callees first) and copies that IR twice
(`InlineWorker.inline_ir`'s `copy_ir`: `copy.deepcopy` of each block with its own memo). Every block
holds the function's Scope and each Var its Scope, so each block's copy copies the whole scope: a
callee of B blocks and V variables costs B x V copies, and the nesting (sampling kernel <- pixel <- ray
visibility <- scene traversal <- tree traversal) grows B and V at every level. Numba's issue #8989
("Spurious deep copies in inlining", open) reports the same. Profiled (cProfile, an empty cache, the
first render of a small scene): 215 of 433 s in deepcopy, 11.6 million Var copies.

`install` gives `copy_ir` one memo per callee scope for the length of one `inline_ir` (both of
Numba's inlinings: the untyped pass's of inline="always" functions and the typed pass's of
@overload(inline="always") implementations), so a callee's blocks share one copied scope, as the
callee's own blocks share one. `inline_ir` then gives every
copied block the caller's scope and renames the callee's variables into it, so nothing downstream can
tell the copies apart. Checked: the sampling kernel's LLVM IR is byte-identical with and without
(tests/test_inline_copy.py checks a nested kernel the same way). Measured (benchmarks/bench_compile.py's
demo, one process, an empty cache, 2026-11-27): the first frame 255 -> 135 s; the sampling kernel's
inline pass 64 -> 11 s (docs/choices.md).

The shim replaces the `copy` module in numba.core.inline_closurecall only, whose one use of it is
that deepcopy (numba 0.68.1, pinned); anything else it is asked for is the `copy` module's own. The
memos live for one `inline_ir` only: an outside review found that memos kept for a whole
`inline_function` (which may compile other functions while it runs) handed the typed pass's second
inlining of a cached @overload IR the first one's already-renamed blocks, and the compile failed
(tests/test_inline_copy.py keeps that case). The patch is process-wide: other Numba code in the
process (another add-on in the same Blender) gets the same IR faster. It relies on Numba's global
compiler lock: one inlining at a time.
"""
import copy
import functools

from numba.core import inline_closurecall


class _ScopeSharingCopy:
    """Stands in for the `copy` module inside numba.core.inline_closurecall."""

    def __init__(self):
        self.memos = None  # scope id -> deepcopy memo, while an inline_ir runs

    def deepcopy(self, value, memo=None):
        scope = getattr(value, "scope", None)
        if memo is not None or self.memos is None or scope is None:
            return copy.deepcopy(value, memo)
        # The memo keeps the scope alive (deepcopy's keep-alive list), so its id is not reused meanwhile.
        return copy.deepcopy(value, self.memos.setdefault(id(scope), {}))

    def __getattr__(self, name):
        return getattr(copy, name)


_SHIM = _ScopeSharingCopy()


def _sharing_scope_copies(inline_ir):
    """Fresh memos for each inlining; an inlining that compiles other functions (the typed pass
    types the inlined body) nests, and they get theirs."""
    @functools.wraps(inline_ir)
    def wrapped(self, *args, **kwargs):
        outer, _SHIM.memos = _SHIM.memos, {}
        try:
            return inline_ir(self, *args, **kwargs)
        finally:
            _SHIM.memos = outer

    wrapped.kd_preview_scope_sharing = True
    return wrapped


def install() -> None:
    """Idempotent; must run before core's kernels compile (their first call), not before decoration."""
    inline_closurecall.copy = _SHIM
    worker = inline_closurecall.InlineWorker
    if not getattr(worker.inline_ir, "kd_preview_scope_sharing", False):
        worker.inline_ir = _sharing_scope_copies(worker.inline_ir)


install()

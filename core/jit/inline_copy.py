"""Numba's inliner copies a callee's IR one block at a time, and so its whole variable scope once per
block, and then copies the copy; `install` makes it copy the scope once per callee and the callee once.
Same machine code, a fraction of the compile time.

`InlineWorker.inline_ir`'s `copy_ir` deep-copies each block with the function's Scope: blocks x
variables copies at every nesting level of core's inline="always" hot paths (Numba issue #8989;
docs/choices.md#numbas-inliner-copies-a-callees-scope-once). The shim (replacing `copy` in
numba.core.inline_closurecall only; numba 0.68.1 pinned) gives `copy_ir` one memo per callee scope for
one `inline_ir`, never longer, since an inlining may compile other functions. inline_ir's second
`copy_ir`, of its own fresh copy, makes the unmutated original it returns first, which every caller in
Numba discards (`_, _, _, new_blocks = ...`): the shim hands those blocks back uncopied
(docs/choices.md#numbas-inliner-copies-each-callee-twice). The LLVM IR is byte-identical
(tests/test_inline_copy.py). Process-wide; relies on Numba's global compiler lock.
"""
import copy
import functools

from numba.core import inline_closurecall


class _ScopeSharingCopy:
    """Stands in for the `copy` module inside numba.core.inline_closurecall."""

    def __init__(self):
        self.memos = None  # scope id -> deepcopy memo, while an inline_ir runs
        self.made = None  # the blocks this inline_ir's copies made (kept alive by its callee copy)

    def deepcopy(self, value, memo=None):
        scope = getattr(value, "scope", None)
        if memo is not None or self.memos is None or scope is None:
            return copy.deepcopy(value, memo)
        if id(value) in self.made:
            return value  # copy_ir of the fresh copy: the discarded "original"
        # The memo keeps the scope alive (deepcopy's keep-alive list), so its id is not reused meanwhile.
        made = copy.deepcopy(value, self.memos.setdefault(id(scope), {}))
        self.made[id(made)] = made
        return made

    def __getattr__(self, name):
        return getattr(copy, name)


_SHIM = _ScopeSharingCopy()


def _sharing_scope_copies(inline_ir):
    """Fresh memos for each inlining; an inlining that compiles other functions (the typed pass
    types the inlined body) nests, and they get theirs."""
    @functools.wraps(inline_ir)
    def wrapped(self, *args, **kwargs):
        outer = _SHIM.memos, _SHIM.made
        _SHIM.memos, _SHIM.made = {}, {}
        try:
            return inline_ir(self, *args, **kwargs)
        finally:
            _SHIM.memos, _SHIM.made = outer

    wrapped.kd_preview_scope_sharing = True
    return wrapped


def install() -> None:
    """Idempotent; must run before core's kernels compile (their first call), not before decoration."""
    inline_closurecall.copy = _SHIM
    worker = inline_closurecall.InlineWorker
    if not getattr(worker.inline_ir, "kd_preview_scope_sharing", False):
        worker.inline_ir = _sharing_scope_copies(worker.inline_ir)


install()

"""Numba's inliner rebuilds an inline="always" callee's IR at every call site; `install` makes it build
each callee's IR once per compile.

`InlineWorker.inline_function` (the InlineInlinables pass's only route) runs the untyped pipeline over
the callee's bytecode each time it inlines it, and that pipeline inlines the callee's own inline="always"
callees the same way, so a function inlined k times whose callees are inlined m times each is translated
k * m times. The IR it returns is only read: `inline_ir` deep-copies it before changing anything. The
shim keeps it for the rest of the outermost InlineInlinables pass (one function's untyped pipeline,
with everything inlined into it), keyed by the function and the objects the pipeline reads (flags,
locals, typing and target contexts, pipeline), which the memo holds so their ids stay theirs. Same
machine code (tests/test_inline_memo.py); docs/choices.md#numbas-inliner-translates-a-callee-once-per-compile.
Process-wide; relies on Numba's global compiler lock (numba 0.68.1 pinned).
"""
import copy
import functools

from numba.core import inline_closurecall, untyped_passes

_MEMO = {"current": None}  # (function, ids...) -> (FunctionIR, the keyed objects), during a pass


def _memoized(inline_function):
    """InlineWorker.inline_function (its body: the callee's untyped IR, then inline_ir) taking that IR
    from the memo while one is open."""
    @functools.wraps(inline_function)
    def wrapped(self, caller_ir, block, i, function, arg_typs=None):
        memo = _MEMO["current"]
        if memo is None:
            return inline_function(self, caller_ir, block, i, function, arg_typs)
        keyed = (function, self.flags, self.locals, self.typingctx, self.targetctx, self.pipeline)
        key = tuple(id(x) for x in keyed)
        if key not in memo:
            memo[key] = (self.run_untyped_passes(function), keyed)
            callee = memo[key][0]
        else:
            self.flags.enable_ssa = False  # what the pipeline's run leaves behind
            callee = copy.copy(memo[key][0])  # inline_ir copies the blocks it changes
            # A fresh unique name, as a fresh translation has: the inlined variables are named after it,
            # and two inlinings sharing one would make their variables versions of one another.
            callee.func_id = callee.func_id.derive()
        return self.inline_ir(caller_ir, block, i, callee, function.__code__.co_freevars, arg_typs=arg_typs)

    wrapped.kd_preview_memo = True
    return wrapped


def _memo_for_outermost_pass(run_pass):
    """The outermost InlineInlinables pass opens the memo and closes it when it ends; passes that run
    inside it (the callees' pipelines) use it."""
    @functools.wraps(run_pass)
    def wrapped(self, state):
        if _MEMO["current"] is not None:
            return run_pass(self, state)
        _MEMO["current"] = {}
        try:
            return run_pass(self, state)
        finally:
            _MEMO["current"] = None

    wrapped.kd_preview_memo = True
    return wrapped


def install() -> None:
    """Idempotent; must run before core's kernels compile (their first call)."""
    worker = inline_closurecall.InlineWorker
    if not getattr(worker.inline_function, "kd_preview_memo", False):
        worker.inline_function = _memoized(worker.inline_function)
    inliner = untyped_passes.InlineInlinables
    if not getattr(inliner.run_pass, "kd_preview_memo", False):
        inliner.run_pass = _memo_for_outermost_pass(inliner.run_pass)


install()

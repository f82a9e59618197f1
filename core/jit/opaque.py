"""A value the optimiser cannot see through: keeps work inside the branch that needs it.

LLVM hoists arithmetic that does not change inside a loop out of it, and may do so from a branch the
loop rarely or never takes, since integer arithmetic is safe to run speculatively. The sampling loop's
AO branch is such a case: the first scramble of an AO sample depends on the sample number only, so it
left the per-use loop and ran for every sample of a shadow-only render
(docs/choices.md#the-ao-sample-kept-in-its-branch). `opaque(x)` returns x through an empty inline
assembly statement marked as having side effects: no instruction is emitted, but nothing computed from
its result can move above it (nor can a load or store cross it: LLVM treats it as a call that may
touch memory).
"""
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic


@intrinsic
def opaque(typingctx, x):
    """x itself (an integer), as a value LLVM cannot compute ahead of this point."""
    if not isinstance(x, types.Integer):
        return None
    x = types.unliteral(x)  # a literal's callers would use the constant, not the result

    def codegen(context, builder, signature, args):
        llvm_type = context.get_value_type(signature.args[0])
        return builder.asm(ir.FunctionType(llvm_type, [llvm_type]), "", "=r,0", [args[0]], True)

    return x(x), codegen

"""A value the optimiser cannot see through: keeps work inside the branch that needs it.

LLVM hoists arithmetic that does not change inside a loop out of it, and may do so from a branch the
loop rarely or never takes, since integer arithmetic is safe to run speculatively. The sampling loop's
AO branch is such a case: the first scramble of an AO sample depends on the sample number only, so it
left the per-use loop and ran for every sample of a shadow-only render
(docs/choices.md#the-ao-sample-kept-in-its-branch). `opaque(x)` returns x through an empty inline
assembly statement: no instruction is emitted, and LLVM never runs an inline assembly call
speculatively (it has no callee to call speculatable), so nothing computed from its result moves ahead
of the branch it sits in. It reads and writes no memory, so loads and stores around it move freely.
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
        value = builder.asm(ir.FunctionType(llvm_type, [llvm_type]), "", "=r,0", [args[0]], False)
        value.attributes.add("readnone")  # touches no memory: loads and stores may still move across it
        value.attributes.add("nounwind")
        return value

    return x(x), codegen

"""The one way a named SX function of the contract is built: named inputs and outputs, dense
outputs (the C buffers are plain column-major arrays), common subexpressions eliminated as
the Function is built (measured: it pays there, not at codegen; docs/explanation/codegen.md)."""

from __future__ import annotations

import casadi as ca

__all__ = ["sx_function"]


def sx_function(
    name: str, ins: list[tuple[str, ca.SX]], outs: list[tuple[str, ca.SX]]
) -> ca.Function:
    """``name(ins) -> outs`` as a CasADi Function with dense outputs and CSE."""
    return ca.Function(
        name,
        [s for _, s in ins],
        [ca.densify(e) for _, e in outs],
        [n for n, _ in ins],
        [n for n, _ in outs],
        {"cse": True},
    )

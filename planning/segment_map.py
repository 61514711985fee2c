"""A segment function mapped over the stroke's segments, differentiated through one segment's own Jacobian.

Why. The jerk-limited stage writes its rows as small CasADi SX functions of one segment (its two knots' states and its
duration, :mod:`planning.optimal`) mapped over every segment. CasADi differentiates a mapped call by mapping the
segment's forward derivative in as many directions as the call has seeded inputs, and evaluates it with every input's
seeds, the parameters' zero seeds too (the torque rows' nine friction and drive terms per segment): on the door panel
the constraint Jacobian took ~9 ms an evaluation, a third of an IPOPT solve. :func:`segment_map` gives the mapped
function its Jacobian instead: one segment's Jacobian block with respect to the inputs the NLP differentiates (the
unknowns), evaluated once per segment and laid out block-diagonally, which CasADi multiplies by its seeds.

The block is the segment function's forward derivative with each direction seeding one entry of one input, so the
terms of the other entries' and inputs' seeds never enter; its entries are the same products in the same order as
CasADi's forward derivative evaluated with those seeds, so the Jacobian is the same bits (tests/test_segment_map.py).
"""
from __future__ import annotations

import casadi as ca


def segment_map(fn: ca.Function, n: int, wrt: tuple[int, ...] = (0,)) -> ca.Function:
    """``fn`` (an SX function of one segment: column-vector inputs, one output) mapped serially over ``n`` segments,
    like ``fn.map(n, "serial")``, with a Jacobian (CasADi's ``custom_jacobian``) made of ``fn``'s own Jacobian block
    per segment with respect to the inputs ``wrt``; the other inputs are declared not differentiable (parameters,
    constants). Returns the mapped CasADi function: inputs as ``fn``'s with ``n`` columns, output ``fn``'s with ``n``."""
    if fn.n_out() != 1 or any(fn.size2_in(i) != 1 for i in range(fn.n_in())):
        raise ValueError(f"segment_map: {fn.name()} must have column-vector inputs and one output")
    ins = [ca.SX.sym(f"in{i}", fn.sparsity_in(i)) for i in range(fn.n_in())]
    out = fn(*ins)
    blocks, units = [], []
    for i in wrt:
        r = fn.nnz_in(i)
        # direction c seeds input entry c alone, through a symbol (1 at evaluation): a constant 1 would be folded into
        # the products at the build and change their order; no other input is seeded
        unit = ca.SX.sym(f"unit{i}", r)
        seeds = [ca.diag(unit) if j == i else ca.SX(fn.nnz_in(j), r) for j in range(fn.n_in())]
        sens = fn.forward(r)(*ins, out, *seeds)  # column c: d out / d in_i[c]
        blocks.append(ca.project(sens, fn.sparsity_jac(i, 0)))
        units.append(unit)
    jac_segment = ca.Function(f"{fn.name()}_jacobian", [*ins, *units], [ca.cse(b) for b in blocks])
    mapped, jac_mapped = fn.map(n, "serial"), jac_segment.map(n, "serial")
    name = f"map{n}_{fn.name()}_own_jacobian"
    X = [ca.MX.sym(f"in{i}", fn.size1_in(i), n) for i in range(fn.n_in())]
    jacs = jac_mapped(*X, *(ca.DM.ones(fn.nnz_in(i), n) for i in wrt))
    jacs = [jacs] if isinstance(jacs, ca.MX) else list(jacs)
    outs = []
    for i in range(fn.n_in()):
        if i in wrt:
            k = wrt.index(i)
            # the mapped blocks side by side hold their nonzeros in the block diagonal's order (column by column)
            outs.append(ca.sparsity_cast(jacs[k], ca.diagcat(*[blocks[k].sparsity()] * n)))
        else:
            outs.append(ca.MX(mapped.nnz_out(0), mapped.nnz_in(i)))
    jac = ca.Function("jac_" + name, [*X, ca.MX.sym("out", mapped.sparsity_out(0))], outs)
    return ca.Function(name, X, [mapped(*X)],
                       {"custom_jacobian": jac, "jac_penalty": 0, "enable_forward": False, "enable_reverse": False,
                        "enable_fd": False, "is_diff_in": [i in wrt for i in range(fn.n_in())]})

"""The friction kernel's per-lane bodies (:mod:`batch_kernel`), emitted as LLVM IR by numba intrinsics.

The generated kernel keeps its loops (crank angles, blocks of sets, passes, the lanes of a block) as Python for numba;
the bodies of those loops are written here straight into numba's IR builder. As Python statements they were
~1,500 floating-point operations for the reference press (mostly the fixed-point pass, twice: one copy per half of
the block), and numba typed and lowered each on its own: ~70 % of the kernel's compile (type inference alone ~30 %,
template matching per operation), against ~15 % for LLVM's optimisation. Here the same operations, in the same order
and on the same operands, cost numba one typed call per loop body. Its fastmath pass then puts the kernel's
``contract`` flag on them as on the rest of the kernel, so LLVM fuses the same multiply-adds and every result is the
same bytes as the statements' kernel (compared when it was replaced: docs/benchmarks.md, "The friction kernel's first
compile"); tests/test_batch.py holds the kernel to the numpy fixed point and each set to the same bytes for any lanes.

:func:`kernel_intrinsics` makes the intrinsics for one loop structure (G, r reactions, n_feat features) and block
size. Their arguments: ``w`` the work array (``w[row * lanes + lane]``, rows :func:`work_rows`), ``l`` the lane,
``consts`` the crank angle's constants (:func:`constant_layout`), ``it`` the pass number, ``tol`` the fixed point's
tolerance.
"""
from __future__ import annotations

import itertools


def work_rows(n_rows: int, r: int, n_feat: int) -> dict[str, int]:
    """Rows of the kernel's work array (``w[row * lanes + lane]``): C (output columns without Coulomb friction), NR
    (reaction magnitudes, the fixed point's state), DN (converged flag), IT (pass count), IN (the block's inputs: c_r,
    c_s, mu_r, mu_s, the features), MR and MS (mu_r and mu_s within IN), FP and GP (the previous pass's residual and
    F(x), for the Anderson step); ``rows``: how many."""
    K = n_rows + 2  # output columns: tau_d, the 2r - 1 reaction columns, the zero column
    IN = K + r + 2
    FP = IN + 4 + n_feat
    return {"C": 0, "NR": K, "DN": K + r, "IT": K + r + 1, "IN": IN, "MR": IN + 2, "MS": IN + 3, "FP": FP, "GP": FP + r,
            "rows": FP + 2 * r}


def constant_layout(n_rows: int, r: int, n_lam: int) -> dict[str, int]:
    """Offsets in a crank angle's constants (the tuple ``point_constants`` returns): v0 and v1 (the viscous columns,
    K - 1 each), q (the loop-force coefficients ``coul_lam[p, c, i]`` at ``c * r + i``), t (``coul_tau[p]``, r);
    ``size``: how many."""
    K1 = n_rows + 1  # the output columns that are read (the last, zero, is not)
    return {"v0": 0, "v1": K1, "q": 2 * K1, "t": 2 * K1 + n_lam * r, "size": 2 * K1 + n_lam * r + r}


def kernel_intrinsics(G, r: int, n_feat: int, lanes: int, gamma_max: float) -> dict:
    """The numba intrinsics of the kernel's loop bodies for the constant matrix ``G`` (a tuple of rows of floats,
    (2 r - 1, n_lam)), r reactions (the last with one component), n_feat features and blocks of ``lanes`` sets;
    ``gamma_max``: the bound of the Anderson weight. Returns them by name:

    * ``point_constants(visc_pt, coul_lam, coul_tau, p)``: the crank angle's constants, a tuple;
    * ``setup_lane(w, l, max_it, consts)``: a lane's flag and count, and its viscous output columns;
    * ``base_row(base_pt, p, k)``: the features' coefficients of output column k, a tuple;
    * ``column_lane(w, l, k, row)``: adds the features times ``row`` to output column k of a lane;
    * ``start_lane(w, l, consts)``: a lane's reactions without friction, the Anderson history zeroed;
    * ``one_pass(w, l, it, tol, consts)``: one fixed-point pass of lane ``l`` of each half of the block;
    * ``finish_lane(w, l, consts, (tau, iters, done), row, p)``: a lane's torque (N m), pass count and flag, into
      row ``row + l`` of each.

    Each does what the Python statements it replaces did, operation for operation (a pass, per lane)::

        h_j = mu_j N_j;  l_c = sum_i q_ci h_i;  z_k = C_k + sum_c G_kc l_c;  m_j = |(z_xj, z_yj)|;  f_j = m_j - N_j
        converged: max |f_j| <= tol max(1, m_j);  gamma = clip(f.d / d.d, -gamma_max, gamma_max), d = f - f_prev
        N_j <- m_j - gamma (m_j - m_prev_j)   (a lane converged earlier keeps its state; one converging now takes m)
    """
    import numba
    from llvmlite import ir
    from numba.core import cgutils, types

    G = [[float(c) for c in row] for row in G]
    n_rows, n_lam = len(G), len(G[0])
    rows = work_rows(n_rows, r, n_feat)
    cl = constant_layout(n_rows, r, n_lam)
    K1 = n_rows + 1
    comp = [(1 + j, 1 + r + j if 1 + r + j <= n_rows else None) for j in range(r)]
    mu_rows = [rows["MR"]] * (r - 1) + [rows["MS"]]
    half_lanes = lanes // 2
    f64, i64 = ir.DoubleType(), ir.IntType(64)
    zero, one = ir.Constant(f64, 0.0), ir.Constant(f64, 1.0)

    class Lane:
        """Loads and stores of one lane's rows of the work array, and the operations numba's lowering would emit."""

        def __init__(self, context, builder, aryty, w, lane, offset=0):
            self.b = builder
            self.data = cgutils.create_struct_proxy(aryty)(context, builder, value=w).data
            self.lane, self.offset = lane, offset

        def at(self, row, col=None):  # row: a constant, or with col (an i64 value) the row col + row
            base = ir.Constant(i64, row * lanes + self.offset)
            idx = self.b.add(self.lane, base) if col is None else self.b.add(
                self.b.mul(self.b.add(col, ir.Constant(i64, row)), ir.Constant(i64, lanes)), self.lane)
            return self.b.gep(self.data, [idx], inbounds=True)

        def ld(self, row, col=None):
            return self.b.load(self.at(row, col))

        def st(self, value, row, col=None):
            self.b.store(value, self.at(row, col))

        def call(self, name, x):
            return self.b.call(self.b.module.declare_intrinsic(name, [f64]), [x])

        def gt(self, a, b):  # Python's and numba's max(b, a): a if a > b else b
            return self.b.select(self.b.fcmp_ordered(">", a, b), a, b)

    def item(context, builder, aryty, ary, *inds):
        arr = context.make_array(aryty)(context, builder, value=ary)
        return builder.load(cgutils.get_item_pointer(context, builder, aryty, arr, list(inds)))

    def unpack(builder, consts, key, count):
        return [builder.extract_value(consts, cl[key] + i) for i in range(count)]

    def point_constants_ir(context, builder, sig, args):
        (vt, qt, tt, _), (visc, qarr, tarr, p) = sig.args, args
        c = [ir.Constant(i64, v) for v in range(max(K1, n_lam, r, 2))]
        vals = [item(context, builder, vt, visc, p, c[i], c[k]) for i in range(2) for k in range(K1)]
        vals += [item(context, builder, qt, qarr, p, c[ci], c[i]) for ci in range(n_lam) for i in range(r)]
        vals += [item(context, builder, tt, tarr, p, c[j]) for j in range(r)]
        return context.make_tuple(builder, sig.return_type, vals)

    def setup_lane_ir(context, builder, sig, args):
        w, lane, max_it, consts = args
        L = Lane(context, builder, sig.args[0], w, lane)
        v0, v1 = unpack(builder, consts, "v0", K1), unpack(builder, consts, "v1", K1)
        L.st(zero, rows["DN"])
        L.st(builder.fadd(builder.sitofp(max_it, f64), one), rows["IT"])
        for k in range(K1):
            L.st(builder.fadd(builder.fmul(L.ld(rows["IN"]), v0[k]), builder.fmul(L.ld(rows["IN"] + 1), v1[k])), rows["C"] + k)
        return context.get_dummy_value()

    def base_row_ir(context, builder, sig, args):
        bt, (base, p, k) = sig.args[0], args
        vals = [item(context, builder, bt, base, p, ir.Constant(i64, f), k) for f in range(n_feat)]
        return context.make_tuple(builder, sig.return_type, vals)

    def column_lane_ir(context, builder, sig, args):
        w, lane, k, row = args
        L = Lane(context, builder, sig.args[0], w, lane)
        acc = L.ld(rows["C"], k)
        for f in range(n_feat):
            acc = builder.fadd(acc, builder.fmul(L.ld(rows["IN"] + 4 + f), builder.extract_value(row, f)))
        L.st(acc, rows["C"], k)
        return context.get_dummy_value()

    def start_lane_ir(context, builder, sig, args):
        w, lane, consts = args
        L = Lane(context, builder, sig.args[0], w, lane)
        v0, v1 = unpack(builder, consts, "v0", K1), unpack(builder, consts, "v1", K1)

        def friction_free(k):  # no friction at all to start with, as inverse_dynamics: the viscous part taken out
            return builder.fsub(builder.fsub(L.ld(rows["C"] + k), builder.fmul(L.ld(rows["IN"]), v0[k])),
                                builder.fmul(L.ld(rows["IN"] + 1), v1[k]))

        for j, (x, y) in enumerate(comp):
            zx = friction_free(x)
            if y:
                zy = friction_free(y)
                L.st(L.call("llvm.sqrt", builder.fadd(builder.fmul(zx, zx), builder.fmul(zy, zy))), rows["NR"] + j)
            else:
                L.st(L.call("llvm.fabs", zx), rows["NR"] + j)
        for j in range(r):
            L.st(zero, rows["FP"] + j)
        for j in range(r):
            L.st(zero, rows["GP"] + j)
        return context.get_dummy_value()

    def one_pass_ir(context, builder, sig, args):
        w, lane, it, tol, consts = args
        qv = unpack(builder, consts, "q", n_lam * r)
        q = [qv[c * r : (c + 1) * r] for c in range(n_lam)]
        it_f = builder.sitofp(it, f64)
        second = builder.icmp_signed(">", it, ir.Constant(i64, 2))
        lo, hi = ir.Constant(f64, -gamma_max), ir.Constant(f64, gamma_max)

        def half_pass(half):
            # a generator, one group of statements per step, so that the two halves' statements alternate (two
            # independent dependency chains in one loop body, as the statements' kernel had them)
            L = Lane(context, builder, sig.args[0], w, lane, half * half_lanes)
            h = [builder.fmul(L.ld(mu_rows[j]), L.ld(rows["NR"] + j)) for j in range(r)]
            yield
            lam = []
            for c in range(n_lam):
                acc = builder.fmul(q[c][0], h[0])
                for i in range(1, r):
                    acc = builder.fadd(acc, builder.fmul(q[c][i], h[i]))
                lam.append(acc)
                yield
            z = {}
            for k in range(1, n_rows + 1):
                acc = L.ld(rows["C"] + k)
                for c, coef in enumerate(G[k - 1]):
                    if coef == 0.0:
                        continue
                    acc = (builder.fadd(acc, lam[c]) if coef == 1.0 else builder.fsub(acc, lam[c]) if coef == -1.0
                           else builder.fadd(acc, builder.fmul(ir.Constant(f64, coef), lam[c])))
                z[k] = acc
                yield
            m = [L.call("llvm.sqrt", builder.fadd(builder.fmul(z[x], z[x]), builder.fmul(z[y], z[y]))) if y
                 else L.call("llvm.fabs", z[x]) for x, y in comp]
            f = [builder.fsub(m[j], L.ld(rows["NR"] + j)) for j in range(r)]
            yield
            change = L.call("llvm.fabs", f[0])
            for j in range(1, r):
                change = L.gt(L.call("llvm.fabs", f[j]), change)
            scale = one
            for j in range(r):
                scale = L.gt(m[j], scale)
            old = builder.fcmp_unordered("!=", L.ld(rows["DN"]), zero)
            conv = builder.fcmp_ordered("<=", change, builder.fmul(tol, scale))
            yield
            d = [builder.fsub(f[j], L.ld(rows["FP"] + j)) for j in range(r)]
            den, num = builder.fmul(d[0], d[0]), builder.fmul(f[0], d[0])
            for j in range(1, r):
                den = builder.fadd(den, builder.fmul(d[j], d[j]))
            for j in range(1, r):
                num = builder.fadd(num, builder.fmul(f[j], d[j]))
            low = L.gt(lo, builder.fdiv(num, den))  # max(num / den, -gamma_max), then min(.., gamma_max)
            clipped = builder.select(builder.fcmp_ordered("<", hi, low), hi, low)
            gam = builder.select(builder.and_(builder.fcmp_ordered(">", den, zero), second), clipped, zero)
            yield
            for j in range(r):
                L.st(f[j], rows["FP"] + j)
            x = [builder.fsub(m[j], builder.fmul(gam, builder.fsub(m[j], L.ld(rows["GP"] + j)))) for j in range(r)]
            for j in range(r):
                L.st(m[j], rows["GP"] + j)
            yield
            for j in range(r):
                L.st(builder.select(old, L.ld(rows["NR"] + j), builder.select(conv, m[j], x[j])), rows["NR"] + j)
            L.st(builder.select(builder.or_(old, builder.not_(conv)), L.ld(rows["IT"]), it_f), rows["IT"])
            L.st(builder.select(builder.or_(old, conv), one, zero), rows["DN"])
            yield

        for _ in itertools.zip_longest(half_pass(0), half_pass(1)):
            pass
        return context.get_dummy_value()

    def finish_lane_ir(context, builder, sig, args):
        w, lane, consts, outputs, row, p = args
        L = Lane(context, builder, sig.args[0], w, lane)
        (tau_t, iters_t, done_t), (tau, iters, done) = sig.args[3], cgutils.unpack_tuple(builder, outputs, 3)
        t = unpack(builder, consts, "t", r)
        acc = L.ld(rows["C"])
        for j in range(r):
            acc = builder.fadd(acc, builder.fmul(builder.fmul(L.ld(mu_rows[j]), L.ld(rows["NR"] + j)), t[j]))
        at = builder.add(row, lane)
        for aty, arr, value in ((tau_t, tau, acc), (iters_t, iters, builder.fptosi(L.ld(rows["IT"]), i64)),
                                (done_t, done, builder.fcmp_unordered("!=", L.ld(rows["DN"]), zero))):
            ptr = cgutils.get_item_pointer(context, builder, aty, context.make_array(aty)(context, builder, value=arr), [at, p])
            builder.store(context.get_value_as_data(builder, aty.dtype, value) if aty.dtype == types.boolean else value, ptr)
        return context.get_dummy_value()

    consts_t = types.UniTuple(types.float64, cl["size"])
    row_t = types.UniTuple(types.float64, n_feat)

    # numba's intrinsics take their arguments by name (no *args): one typer each
    intrinsic = numba.extending.intrinsic

    @intrinsic
    def point_constants(typingctx, visc_pt, coul_lam, coul_tau, p):
        return consts_t(visc_pt, coul_lam, coul_tau, p), point_constants_ir

    @intrinsic
    def setup_lane(typingctx, w, lane, max_it, consts):
        return types.void(w, lane, max_it, consts), setup_lane_ir

    @intrinsic
    def base_row(typingctx, base_pt, p, k):
        return row_t(base_pt, p, k), base_row_ir

    @intrinsic
    def column_lane(typingctx, w, lane, k, row):
        return types.void(w, lane, k, row), column_lane_ir

    @intrinsic
    def start_lane(typingctx, w, lane, consts):
        return types.void(w, lane, consts), start_lane_ir

    @intrinsic
    def one_pass(typingctx, w, lane, it, tol, consts):
        return types.void(w, lane, it, tol, consts), one_pass_ir

    @intrinsic
    def finish_lane(typingctx, w, lane, consts, outputs, row, p):
        return types.void(w, lane, consts, outputs, row, p), finish_lane_ir

    return {"point_constants": point_constants, "setup_lane": setup_lane, "base_row": base_row,
            "column_lane": column_lane, "start_lane": start_lane, "one_pass": one_pass, "finish_lane": finish_lane}

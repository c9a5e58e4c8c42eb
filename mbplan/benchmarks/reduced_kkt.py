"""Study: the RIPM's KKT matrix of a maximal-coordinate multibody problem with the joints
eliminated knot by knot (a reduced, generalized-coordinate-sized KKT), and its cost.

Unknowns of the KKT ``K`` (:mod:`mbplan.solvers.kkt.system`): primal tangent coordinates
``x``, equality multipliers ``y``, inequality multipliers ``z``. Per knot ``k`` and body ``b``
the state ``s = (R, F, p, v)`` (12), the joint force ``λ`` (5) and torque ``τ`` (1); per step
the kinematics rows ``g(X_{k+1}, (R, p)_{k+1})`` with ``X_{k+1} = (R_k F_k, p_k + v_k Δt)``
(6 per body), the LGVI rows (6 per body, holding ``J(x_{k+1})ᵀλ_{k+1}``) and the joint
constraints ``h(X_{k+1})`` (5 per joint, on ``s_k`` only). Three exact congruences:

1. dual, per step: ``h`` and ``g`` read ``X_{k+1}`` the same way, so ``∂h/∂s_k = M ∂g/∂s_k`` with
   ``M = ∂h/∂X (∂g/∂X)⁻¹`` (per joint, on its two bodies' kinematics rows); five of the child's
   kinematics rows are replaced by ``M g - h``, rows on ``(R, p)_{k+1}`` alone (the joint
   constraint on the next configuration);
2. primal, per knot: those rows and ``h`` at knot ``k`` (10 per joint, on ``s_k`` alone) split
   ``s_k`` into 10 dependent coordinates per body and 2 free ones (knot 1: step 0's six
   kinematics rows and ``h``, 11 and 1), a tree-ordered variable reduction
   ``x_dep = u - E x_free``; the pair (dependent coordinates, local rows) is a
   nonsingular saddle block whose multipliers touch nothing else, so the Schur complement of
   the rest is the rest itself;
3. optional (``forces=True``), the pair (``λ_k``, five of each child's LGVI rows of step ``k-1``): their coupling block is
   block-triangular over the tree and nonsingular, ``K_YY = 0``; its Schur complement is
   ``K_rr - K_rλ X - Xᵀ K_λr + Xᵀ G X`` with ``X = B⁻¹ K_Yr``.

Each eliminated pair ``[[G, Bᵀ], [B, 0]]`` with ``B`` square nonsingular has inertia ``(m, m, 0)``
whatever ``G`` is, so ``inertia(K) = inertia(K_reduced) + (m, m, 0)`` with ``m`` the number of
eliminated primal coordinates. The eliminated multiplier rows must carry no ``-δ_c`` (the
default; a ``δ_c > 0`` step is left to the full factorization). The reduced matrix is
factorized by :class:`~mbplan.solvers.kkt.system.KKTSystem` (AMD, static regularization
``1e-8``: with ``1e-9`` its zero-diagonal ``λ``/``τ`` pivots broke the unpivoted LDLᵀ down on a
nonsingular matrix), and every solve is refined against the full ``K``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mbplan.errors import InputError
from mbplan.formulations.maximal_layout import MaximalLayout
from mbplan.solvers.kkt.system import Inertia, KKTSystem


class _Entries:
    """Dense values ``a[rows[..., :, None], cols[..., None, :]]`` of a sparse matrix ``a`` (a
    canonical CSR copy and its sorted entry keys, computed once)."""

    def __init__(self, a: sp.spmatrix) -> None:
        a = sp.csr_matrix(a, copy=True)
        a.sum_duplicates()
        self.a, self.n = a, a.shape[1]
        self.keys = np.repeat(np.arange(a.shape[0], dtype=np.int64), np.diff(a.indptr)) * self.n
        self.keys += a.indices

    def __call__(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        want = rows[..., :, None].astype(np.int64) * self.n + cols[..., None, :]
        pos = np.minimum(np.searchsorted(self.keys, want), len(self.keys) - 1)
        return np.where(self.keys[pos] == want, self.a.data[pos], 0.0)


def product_flops(a: sp.spmatrix, b: sp.spmatrix) -> float:
    """Multiply-adds of the sparse product ``a @ b``: ``Σ_j nnz(a[:, j]) nnz(b[j, :])``."""
    ca = np.diff(sp.csc_matrix(a).indptr).astype(float)
    rb = np.diff(sp.csr_matrix(b).indptr).astype(float)
    return float(ca @ rb)


def _pivots(m: np.ndarray) -> np.ndarray:
    """Column order of a QR with column pivoting (the first ``rank`` are well conditioned)."""
    return sla.qr(m, pivoting=True, mode="r")[1]


@dataclass
class ReducedKKT:
    """The joint-eliminated KKT of one full KKT matrix (module docstring), its factorization
    and solves. ``forces``: also eliminate the joint forces (stage 3; otherwise ``λ`` and the
    LGVI rows stay in the reduced matrix for the sparse LDLᵀ). ``flops`` holds the
    multiply-adds counted per part."""

    layout: MaximalLayout
    K: sp.csr_matrix
    forces: bool = False
    static_reg: float = 1e-8
    flops: dict[str, float] = field(default_factory=dict)
    dropped: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        lay, K = self.layout, sp.csr_matrix(self.K)
        K.sum_duplicates()
        K.sort_indices()
        self.K = K
        n, me = lay.n, lay.n_eq
        self.n_dim = K.shape[0]
        dual_eq = K[n : n + me, n : n + me]
        if dual_eq.nnz and np.max(np.abs(dual_eq.data)) > 0.0:
            raise InputError("ReducedKKT: needs δ_c = 0 on the equality rows")
        H, AE, AI = K[:n, :n], K[n : n + me, :n].tocsr(), K[n + me :, :n]
        S, replaced = self._dual_transform(AE)
        AE2 = sp.csr_matrix(S @ AE)
        self.flops["dual transform"] = product_flops(S, AE)
        AE2 = self._drop_outside(AE2, replaced, "M g - h outside (R, p)_{k+1}")
        T, local_rows, dep = self._primal_transform(AE2, replaced)
        Dsub = K[n:, n:]
        self.flops["T^T H T, A T"] = (
            product_flops(H, T) + product_flops(T.T, H @ T) + product_flops(AE2, T)
            + product_flops(AI, T)
        )  # fmt: skip
        H1 = sp.csr_matrix(T.T @ (H @ T))
        AE3 = sp.csr_matrix(AE2 @ T)
        AE3 = self._drop_rows_outside(AE3, local_rows, dep, "local rows outside x_dep")
        A1 = sp.vstack([AE3, sp.csr_matrix(AI @ T)]).tocsr()
        K1 = sp.bmat([[H1, A1.T], [A1, Dsub]], format="csr")
        self.S, self.T = S, T
        # stage 1: (x_dep, local rows) -> the rest as it is
        U1, Y1 = dep, n + local_rows
        self.B1 = sp.csc_matrix(K1[Y1][:, U1])
        self.U1, self.Y1 = U1, Y1
        keep1 = np.setdiff1d(np.arange(self.n_dim), np.concatenate([U1, Y1]))
        self.R1 = keep1
        self._K1_R1U1 = sp.csr_matrix(K1[keep1][:, U1])
        self._K1_U1U1 = sp.csr_matrix(K1[U1][:, U1])
        self._K1_U1R1 = sp.csr_matrix(K1[U1][:, keep1])
        Kr = sp.csr_matrix(K1[keep1][:, keep1])
        self.Kr = Kr
        self._lu1 = spla.splu(self.B1)
        self.m_eliminated = len(U1)
        if self.forces:
            P, keep2 = self._eliminate_forces(K1, Kr, keep1)
            self.R2 = keep2
            orig = keep1[keep2]
        else:
            P, orig = Kr, keep1
        self.reduced = P
        self._factor_setup(P, orig < n)

    def _eliminate_forces(self, K1, Kr, keep1) -> tuple[sp.csr_matrix, np.ndarray]:
        """Stage 3: the pairs (``λ_k``, five LGVI rows of step k-1 per body) out of ``Kr``."""
        lay, n = self.layout, self.layout.n
        K1_at = _Entries(K1)
        pos1 = np.full(self.n_dim, -1, np.int64)
        pos1[keep1] = np.arange(len(keep1))
        lam = lay.lam_cols[1:]
        sel_rows = np.empty(lam.shape, np.int64)
        for k in range(lay.N):
            Bk = K1_at(n + lay.dyn_rows[k], lay.lam_cols[k + 1])  # (nb, 6, 5)
            for c in range(lay.nb):
                sel_rows[k, c] = lay.dyn_rows[k, c][np.sort(_pivots(Bk[c].T)[:5])]
        U2 = pos1[lam.reshape(-1)]
        Y2 = pos1[n + sel_rows.reshape(-1)]
        if np.any(U2 < 0) or np.any(Y2 < 0):
            raise InputError("ReducedKKT: λ or LGVI rows eliminated in stage 1")
        keep2 = np.setdiff1d(np.arange(Kr.shape[0]), np.concatenate([U2, Y2]))
        B2 = sp.csc_matrix(Kr[Y2][:, U2])
        G2 = sp.csr_matrix(Kr[U2][:, U2])
        KYr = sp.csr_matrix(Kr[Y2][:, keep2])
        KUr = sp.csr_matrix(Kr[U2][:, keep2])
        X = self._block_solve(B2, KYr, 5 * lay.nb)
        Krr = sp.csr_matrix(Kr[keep2][:, keep2])
        self.flops["X = B^-1 K_Yr"] = self._solve_flops
        self.flops["Schur of (λ, LGVI rows)"] = (
            2 * product_flops(KUr.T, X) + product_flops(G2, X) + product_flops(X.T, G2 @ X)
        )
        red = sp.csr_matrix(Krr - KUr.T @ X - X.T @ KUr + X.T @ (G2 @ X))
        red.sum_duplicates()
        self.U2, self.Y2 = U2, Y2
        self.G2, self.X, self.KUr = G2, X, KUr
        self._lu2 = spla.splu(B2)
        self.m_eliminated += len(U2)
        return sp.csr_matrix((red + red.T) * 0.5), keep2

    def _factor_setup(self, P: sp.csr_matrix, primal: np.ndarray) -> None:
        """A :class:`KKTSystem` for ``P`` (primal unknowns first, then the multipliers, whose
        block must be diagonal)."""
        self.red_primal = np.flatnonzero(primal)
        self.red_dual = np.flatnonzero(~primal)
        dd = P[self.red_dual][:, self.red_dual]
        off = dd - sp.diags(dd.diagonal())
        if off.nnz and np.max(np.abs(off.data)) > 0.0:
            raise InputError("ReducedKKT: the reduced multiplier block is not diagonal")
        self.kkt = KKTSystem(len(self.red_primal), len(self.red_dual), 0)
        Hr = sp.csr_matrix(P[self.red_primal][:, self.red_primal])
        self.kkt.set_matrices(
            sp.tril(Hr, k=-1, format="csr") + sp.diags(np.zeros(Hr.shape[0]), format="csr"),
            sp.csr_matrix(P[self.red_dual][:, self.red_primal]),
            None,
        )
        self._diag = np.concatenate([Hr.diagonal(), dd.diagonal()])
        self.red_perm = np.concatenate([self.red_primal, self.red_dual])
        self.flops["reduced LDLT (AMD)"] = self.kkt.analysis.flops

    @property
    def elimination_flops(self) -> float:
        """Multiply-adds of the reduction as implemented (every part but the reduced LDLᵀ)."""
        return sum(v for k, v in self.flops.items() if k != "reduced LDLT (AMD)")

    @property
    def elimination_flops_tree(self) -> float:
        """The same with ``B⁻¹ K_Yr`` by back substitution over the tree."""
        if not self.forces:
            return self.elimination_flops
        return self.elimination_flops - self.flops["X = B^-1 K_Yr"] + self.flops_tree_solve

    # -------------------------------------------------------------- construction
    def _dual_transform(self, AE: sp.csr_matrix) -> tuple[sp.csr_matrix, np.ndarray]:
        """``S`` on the equality rows: five kinematics rows of each child, steps 1…N-1,
        replaced by ``M g - h``; returns ``S`` and the replaced rows ``(N, nb, 5)`` (step 0:
        all six kinematics rows stay, ``-1``)."""
        lay = self.layout
        me, nb, N = lay.n_eq, lay.nb, lay.N
        AE_at = _Entries(AE)
        replaced = -np.ones((N, nb, 5), np.int64)
        r_i, r_j, r_v = [], [], []
        flops = 0.0
        for k in range(1, N):
            s = lay.s_cols[k]
            Kb = AE_at(lay.kin_rows[k], s)  # (nb, 6, 12)
            pinv = np.linalg.pinv(Kb)  # (nb, 12, 6)
            flops += nb * (6 * 6 * 12 * 2 + 6**3)
            for c in range(nb):
                p = lay.parent[c]
                Cc = AE_at(lay.con_rows[k, c], s[c])
                Mc = Cc @ pinv[c]
                parts = [(lay.kin_rows[k, c], Mc)]
                res = np.abs(Mc @ Kb[c] - Cc).max() / max(np.abs(Cc).max(), 1e-300)
                if p >= 0:
                    Cp = AE_at(lay.con_rows[k, c], s[p])
                    Mp = Cp @ pinv[p]
                    parts.append((lay.kin_rows[k, p], Mp))
                    res = max(res, np.abs(Mp @ Kb[p] - Cp).max() / max(np.abs(Cp).max(), 1e-300))
                self.dropped["chain rule ∂h = M ∂g"] = max(
                    self.dropped.get("chain rule ∂h = M ∂g", 0.0), float(res)
                )
                flops += len(parts) * 5 * 12 * 6
                sel = np.sort(_pivots(Mc)[:5])
                slots = lay.kin_rows[k, c][sel]
                replaced[k, c] = slots
                for i, slot in enumerate(slots):
                    for rows, Mx in parts:
                        r_i += [slot] * 6
                        r_j += list(rows)
                        r_v += list(Mx[i])
                    r_i.append(slot)
                    r_j.append(lay.con_rows[k, c][i])
                    r_v.append(-1.0)
        self.flops["M = ∂h (∂g)^+"] = flops
        keep = np.setdiff1d(np.arange(me), replaced[replaced >= 0])
        S = sp.csr_matrix(
            (
                np.concatenate([np.ones(len(keep)), r_v]),
                (np.concatenate([keep, r_i]), np.concatenate([keep, r_j])),
            ),
            shape=(me, me),
        )
        return S, replaced

    def _drop_outside(self, AE2, replaced, what: str) -> sp.csr_matrix:
        """Zero the (round-off) entries of the replaced rows off ``(R, p)_{k+1}``."""
        lay = self.layout
        AE2 = AE2.tolil()
        worst, scale = 0.0, 0.0
        for k in range(1, lay.N):
            ok = set(
                np.concatenate(
                    [lay.s_cols[k + 1][:, :3], lay.s_cols[k + 1][:, 6:9]], axis=1
                ).ravel()
            )
            for slot in replaced[k].ravel():
                row_cols, row_vals = AE2.rows[slot], AE2.data[slot]
                new_c, new_v = [], []
                for c, val in zip(row_cols, row_vals, strict=True):
                    if c in ok:
                        new_c.append(c)
                        new_v.append(val)
                        scale = max(scale, abs(val))
                    else:
                        worst = max(worst, abs(val))
                AE2.rows[slot], AE2.data[slot] = new_c, new_v
        self.dropped[what] = worst / max(scale, 1e-300)
        return sp.csr_matrix(AE2)

    def _local(self, replaced) -> list[list[tuple[int, np.ndarray]]]:
        """Per knot 1…N and body, the local rows on ``s_k``: step 0's kinematics rows (knot 1)
        or the replaced rows of step k-1, then ``h`` at knot k."""
        lay = self.layout
        out = []
        for k in range(1, lay.N + 1):
            first = lay.kin_rows[0] if k == 1 else replaced[k - 1]
            out.append([np.concatenate([first[c], lay.con_rows[k, c]]) for c in range(lay.nb)])
        return out

    def _primal_transform(self, AE2, replaced):
        """``T`` (``x_dep = u - E x_free``, identity elsewhere), the local rows and ``x_dep``."""
        lay = self.layout
        n = lay.n
        AE2_at = _Entries(AE2)
        t_i, t_j, t_v = [], [], []
        local_all, dep_all = [], []
        flops = 0.0
        for k, groups in enumerate(self._local(replaced), start=1):
            s = lay.s_cols[k]
            dep, free, E = [], [], []
            for c, rows in enumerate(groups):
                Lc = AE2_at(rows, s[c])
                piv = _pivots(Lc)
                r = len(rows)
                dep.append(s[c][np.sort(piv[:r])])
                free.append(s[c][np.sort(piv[r:])])
            free_all = np.concatenate(free)
            fpos = {int(col): i for i, col in enumerate(free_all)}
            for c, rows in enumerate(groups):
                p = lay.parent[c]
                Ld = AE2_at(rows, dep[c])
                rhs = np.zeros((len(rows), len(free_all)))
                for b in (c, p) if p >= 0 else (c,):
                    Lf = AE2_at(rows, free[b])
                    rhs[:, [fpos[int(x)] for x in free[b]]] += Lf
                if p >= 0:
                    Lp = AE2_at(rows, dep[p])
                    rhs -= Lp @ E[p]
                    nz = np.count_nonzero(np.any(E[p] != 0, axis=0))
                    flops += len(rows) * len(dep[p]) * nz
                Ec = np.linalg.solve(Ld, rhs)
                nzc = np.count_nonzero(np.any(Ec != 0, axis=0))
                flops += len(rows) ** 3 / 3 + len(rows) ** 2 * nzc
                E.append(Ec)
            Ek = np.concatenate(E)
            depk = np.concatenate(dep)
            ii, jj = np.nonzero(Ek)
            t_i.append(depk[ii])
            t_j.append(free_all[jj])
            t_v.append(-Ek[ii, jj])
            local_all.append(np.concatenate(groups))
            dep_all.append(depk)
        self.flops["E = L_dep^-1 L_free"] = flops
        T = sp.csr_matrix(
            (
                np.concatenate([np.ones(n), *t_v]),
                (np.concatenate([np.arange(n), *t_i]), np.concatenate([np.arange(n), *t_j])),
            ),
            shape=(n, n),
        )
        return T, np.concatenate(local_all), np.concatenate(dep_all)

    def _drop_rows_outside(self, A, rows, cols, what: str) -> sp.csr_matrix:
        """Zero the round-off entries of ``rows`` outside ``cols``."""
        A = sp.csr_matrix(A)
        mark_r = np.zeros(A.shape[0], bool)
        mark_r[rows] = True
        mark_c = np.zeros(A.shape[1], bool)
        mark_c[cols] = True
        r = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
        bad = mark_r[r] & ~mark_c[A.indices]
        good = mark_r[r] & mark_c[A.indices]
        scale = np.max(np.abs(A.data[good]), initial=1e-300)
        self.dropped[what] = float(np.max(np.abs(A.data[bad]), initial=0.0) / scale)
        A.data[bad] = 0.0
        A.eliminate_zeros()
        return A

    def _block_solve(self, B: sp.csc_matrix, rhs: sp.csr_matrix, block: int) -> sp.csr_matrix:
        """``B⁻¹ rhs`` for block-diagonal ``B`` (blocks of ``block`` rows, one per knot);
        ``self._solve_flops``: LU of each block plus its triangular solves on the block's
        nonzero right-hand-side columns (dense); ``self.flops_tree_solve``: the same solve by
        back substitution over the tree (``B`` is block-triangular with 5 × 5 blocks), one
        multiply-add per nonzero of ``B`` and right-hand-side column."""
        out = []
        flops = tree = 0.0
        Bd = B.tocsr()
        for start in range(0, B.shape[0], block):
            sl = slice(start, start + block)
            Bk = Bd[sl][:, sl].toarray()
            R = rhs[sl]
            cols = np.unique(R.indices)
            Xk = np.linalg.solve(Bk, R[:, cols].toarray())
            flops += block**3 / 3 + block**2 * len(cols)
            tree += np.count_nonzero(Bk) * len(cols) + block * 5**2 / 3
            ii, jj = np.nonzero(Xk)
            out.append(sp.csr_matrix((Xk[ii, jj], (ii, cols[jj])), shape=(block, rhs.shape[1])))
        self._solve_flops = flops
        self.flops_tree_solve = tree
        return sp.vstack(out).tocsr()

    # -------------------------------------------------------------- numeric
    def factorize(self) -> Inertia | None:
        """Factorize the reduced KKT; the inertia of the full ``K``."""
        inertia = self.kkt.factorize(self._diag, self.static_reg)
        if inertia is None:
            return None
        m = self.m_eliminated
        return Inertia(inertia.positive + m, inertia.negative + m, inertia.zero)

    def solve(self, rhs: np.ndarray, refine: int = 2) -> np.ndarray:
        """``K⁻¹ rhs`` through the reduction, then ``refine`` refinement steps against ``K``."""
        sol = self._solve_once(rhs)
        for _ in range(refine):
            sol = sol + self._solve_once(rhs - self.K @ sol)
        return sol

    def _solve_once(self, rhs: np.ndarray) -> np.ndarray:
        n, me = self.layout.n, self.layout.n_eq
        b = np.concatenate([self.T.T @ rhs[:n], self.S @ rhs[n : n + me], rhs[n + me :]])
        # stage 1
        xU1 = self._lu1.solve(b[self.Y1])
        c = b[self.R1] - self._K1_R1U1 @ xU1
        x1 = self._forces_solve(c) if self.forces else self._reduced_solve(c)
        xY1 = self._lu1.solve(b[self.U1] - self._K1_U1U1 @ xU1 - self._K1_U1R1 @ x1, trans="T")
        xp = np.empty(self.n_dim)
        xp[self.R1], xp[self.U1], xp[self.Y1] = x1, xU1, xY1
        return np.concatenate([self.T @ xp[:n], self.S.T @ xp[n : n + me], xp[n + me :]])

    def _forces_solve(self, c: np.ndarray) -> np.ndarray:
        """Stage 3's pairs around the reduced solve."""
        z = self._lu2.solve(c[self.Y2])
        cU = c[self.U2] - self.G2 @ z
        sol_r = self._reduced_solve(c[self.R2] - self.KUr.T @ z - self.X.T @ cU)
        xU2 = z - self.X @ sol_r
        xY2 = self._lu2.solve(c[self.U2] - self.G2 @ xU2 - self.KUr @ sol_r, trans="T")
        x1 = np.empty(len(c))
        x1[self.R2], x1[self.U2], x1[self.Y2] = sol_r, xU2, xY2
        return x1

    def _reduced_solve(self, r: np.ndarray) -> np.ndarray:
        out = np.empty_like(r)
        out[self.red_perm] = self.kkt.solve(r[self.red_perm])[0]
        return out

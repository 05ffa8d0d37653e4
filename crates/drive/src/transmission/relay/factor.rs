//! Factorisation: the local block of a pair with relay friction, eliminated along its
//! structure ([`LocalFactor`]), and the joint matrix's LU with threshold pivoting
//! ([`lu_in_place`], [`lu_solve`]).

use super::iz_psi;

/// Smallest pivot of a relay chain relative to its row's diagonal ([`LocalFactor`]).
const PIVOT_FLOOR: f64 = 1e-12;

/// The factor of a pair's local block `K_zz`, kept for the chord iterations. The block
/// is a chain per rope (each relay row couples to its neighbours along the rope) whose
/// first relay also couples to the two border unknowns, motor angle and tensioner
/// stretch; each chain is eliminated from its far end towards the motor (the Thomas
/// algorithm), the first relays into the border, and the `2 x 2` border solved. No
/// pivoting: a relay row's diagonal is its inertia and friction slope plus the sum of
/// the magnitudes of its neighbour entries (both spans' stiffness times `r^2`; with
/// the friction's hub-load term when the radii are equal), so the chain is diagonally
/// dominant and elimination keeps it so. A zero or non-finite pivot reports the block
/// singular.
#[derive(Debug, Clone)]
pub(crate) struct LocalFactor {
    /// Diagonal of relay row `side * m + l`, then its pivot after elimination.
    pub(crate) dia: Vec<f64>,
    /// Entry of relay row `l` at relay `l - 1` of the same rope (towards the motor).
    pub(crate) sub: Vec<f64>,
    /// Entry of relay row `l` at relay `l + 1` of the same rope (towards the joint).
    pub(crate) sup: Vec<f64>,
    /// Elimination multiplier of relay row `l` into row `l - 1`.
    pub(crate) mult: Vec<f64>,
    /// `1 / pivot` of every relay row.
    pub(crate) inv: Vec<f64>,
    /// Entries of the first relay row of each rope at `[theta, x]`.
    pub(crate) edge: [[f64; 2]; 2],
    /// Entries of the border rows `[theta, x]` at the first relay of each rope.
    pub(crate) couple: [[f64; 2]; 2],
    /// Elimination multipliers of the first relay rows into the border rows.
    pub(crate) gmul: [[f64; 2]; 2],
    /// The border block `[theta, x] x [theta, x]`, then its Schur complement.
    pub(crate) border: [[f64; 2]; 2],
    /// Inverse of the border's Schur complement.
    pub(crate) binv: [[f64; 2]; 2],
}

impl LocalFactor {
    pub(crate) fn new(m: usize) -> Self {
        Self {
            dia: vec![1.0; 2 * m],
            sub: vec![0.0; 2 * m],
            sup: vec![0.0; 2 * m],
            mult: vec![0.0; 2 * m],
            inv: vec![1.0; 2 * m],
            edge: [[0.0; 2]; 2],
            couple: [[0.0; 2]; 2],
            gmul: [[0.0; 2]; 2],
            border: [[1.0, 0.0], [0.0, 1.0]],
            binv: [[1.0, 0.0], [0.0, 1.0]],
        }
    }

    /// Factors the block set up in `dia`, `sub`, `sup`, `edge`, `couple` and `border`
    /// (`m` relays per rope); false when a pivot is zero or not finite.
    pub(crate) fn factor(&mut self, m: usize) -> bool {
        let regular = |p: f64| p != 0.0 && p.is_finite();
        for side in 0..2 {
            let base = side * m;
            for l in (1..m).rev() {
                let piv = self.dia[base + l];
                if !regular(piv) {
                    return false;
                }
                self.inv[base + l] = 1.0 / piv;
                let f = self.sup[base + l - 1] / piv;
                self.mult[base + l] = f;
                let before = self.dia[base + l - 1];
                let after = before - f * self.sub[base + l];
                // A run of relays between two slack spans, with neither inertia nor
                // friction, floats: its rows cancel to round-off. Such a pivot is held
                // at a millionth of a millionth of the row's own diagonal (the rope
                // segment then stays where the predictor put it); a regular chain's
                // pivots stay within a few orders of its diagonal and never meet it.
                self.dia[base + l - 1] = if after.abs() < PIVOT_FLOOR * before.abs() {
                    PIVOT_FLOOR * before.abs()
                } else {
                    after
                };
            }
            if m > 0 {
                let piv = self.dia[base];
                if !regular(piv) {
                    return false;
                }
                self.inv[base] = 1.0 / piv;
                for beta in 0..2 {
                    let g = self.couple[beta][side] / piv;
                    self.gmul[beta][side] = g;
                    self.border[beta][0] -= g * self.edge[side][0];
                    self.border[beta][1] -= g * self.edge[side][1];
                }
            }
        }
        let [[a, b], [c, d]] = self.border;
        let det = a * d - b * c;
        if !regular(det) {
            return false;
        }
        self.binv = [[d / det, -b / det], [-c / det, a / det]];
        true
    }

    /// Solves `K_zz X = B` in place for the `w` columns of `b` (unknowns x `w`,
    /// row-major, rows in the order of [`CompiledRelays::iz_theta`]).
    pub(crate) fn solve(&self, m: usize, b: &mut [f64], w: usize) {
        let (it, ix) = (m, m + 1);
        for side in 0..2 {
            let base = side * m;
            for l in (1..m).rev() {
                let f = self.mult[base + l];
                let (dst, src) = two_rows(b, w, iz_psi(m, side, l - 1), iz_psi(m, side, l));
                for (x, y) in dst.iter_mut().zip(src) {
                    *x -= f * y;
                }
            }
            if m > 0 {
                let first = iz_psi(m, side, 0);
                for (border, row) in [it, ix].into_iter().enumerate() {
                    let f = self.gmul[border][side];
                    let (dst, src) = two_rows(b, w, row, first);
                    for (x, y) in dst.iter_mut().zip(src) {
                        *x -= f * y;
                    }
                }
            }
        }
        let [[p, q], [r, s]] = self.binv;
        {
            let (bt, bx) = b[it * w..(ix + 1) * w].split_at_mut(w);
            for (u, v) in bt.iter_mut().zip(bx.iter_mut()) {
                (*u, *v) = (p * *u + q * *v, r * *u + s * *v);
            }
        }
        if m == 0 {
            return;
        }
        for side in 0..2 {
            let base = side * m;
            let [et, ex] = self.edge[side];
            let inv = self.inv[base];
            let first = iz_psi(m, side, 0);
            // The border rows follow each other (`it`, `ix`), next to both first relays.
            let (row, border) = two_rows(b, w, first, it);
            let (bt, bx) = (&border[..w], &border[w..2 * w]);
            for ((v, t), x) in row.iter_mut().zip(bt).zip(bx) {
                *v = (*v - et * t - ex * x) * inv;
            }
            for l in 1..m {
                let (sub, inv) = (self.sub[base + l], self.inv[base + l]);
                let (row, prev) = two_rows(b, w, iz_psi(m, side, l), iz_psi(m, side, l - 1));
                for (x, y) in row.iter_mut().zip(prev) {
                    *x = (*x - sub * y) * inv;
                }
            }
        }
    }

    /// [`Self::solve`] for one right side (the chord iterations), same arithmetic.
    pub(crate) fn solve_one(&self, m: usize, b: &mut [f64]) {
        let (it, ix) = (m, m + 1);
        for side in 0..2 {
            let base = side * m;
            for l in (1..m).rev() {
                b[iz_psi(m, side, l - 1)] -= self.mult[base + l] * b[iz_psi(m, side, l)];
            }
            if m > 0 {
                let first = b[iz_psi(m, side, 0)];
                b[it] -= self.gmul[0][side] * first;
                b[ix] -= self.gmul[1][side] * first;
            }
        }
        let [[p, q], [r, s]] = self.binv;
        let (u, v) = (b[it], b[ix]);
        (b[it], b[ix]) = (p * u + q * v, r * u + s * v);
        if m == 0 {
            return;
        }
        for side in 0..2 {
            let base = side * m;
            let [et, ex] = self.edge[side];
            let first = iz_psi(m, side, 0);
            b[first] = (b[first] - et * b[it] - ex * b[ix]) * self.inv[base];
            for l in 1..m {
                let prev = b[iz_psi(m, side, l - 1)];
                let row = iz_psi(m, side, l);
                b[row] = (b[row] - self.sub[base + l] * prev) * self.inv[base + l];
            }
        }
    }
}

/// Row `dst` (mutable) and the rows from `src` on (`w` entries each, row-major `b`),
/// `dst != src`.
fn two_rows(b: &mut [f64], w: usize, dst: usize, src: usize) -> (&mut [f64], &[f64]) {
    if dst < src {
        let (lo, hi) = b.split_at_mut(src * w);
        (&mut lo[dst * w..(dst + 1) * w], hi)
    } else {
        let (lo, hi) = b.split_at_mut(dst * w);
        (&mut hi[..w], &lo[src * w..])
    }
}

/// A pivot candidate replaces the diagonal in [`lu_in_place`] only when the diagonal is
/// below this fraction of it (threshold partial pivoting, as sparse LU codes do, e.g.
/// UMFPACK's default 0.1: the factor entries grow at most tenfold per step, and an arm's
/// Newton matrix, mass matrix plus rope stiffness, keeps its order).
const PIVOT_THRESHOLD: f64 = 0.1;

/// LU factorisation with threshold partial pivoting of the row-major `n x n` matrix `a`
/// in place (unit lower factor below the diagonal, the reciprocals of the pivots on it:
/// the solves multiply); false when singular or not finite.
#[inline(never)]
pub(crate) fn lu_in_place(a: &mut [f64], n: usize, perm: &mut [usize]) -> bool {
    for k in 0..n {
        let mut piv = k;
        let mut best = a[k * n + k].abs();
        for i in k + 1..n {
            let v = a[i * n + k].abs();
            if v > best {
                best = v;
                piv = i;
            }
        }
        if best <= 0.0 || !best.is_finite() {
            return false;
        }
        if a[k * n + k].abs() >= PIVOT_THRESHOLD * best {
            piv = k;
        }
        perm[k] = piv;
        if piv != k {
            // Columns `k..` only (LAPACK `gbtrf` style): the multipliers already stored
            // stay with the elimination step that made them, as `lu_solve` replays them.
            for j in k..n {
                a.swap(k * n + j, piv * n + j);
            }
        }
        let inv = 1.0 / a[k * n + k];
        a[k * n + k] = inv;
        for i in k + 1..n {
            let f = a[i * n + k] * inv;
            a[i * n + k] = f;
            if f != 0.0 {
                let (top, bottom) = a.split_at_mut(i * n);
                let pivot_row = &top[k * n + k + 1..(k + 1) * n];
                for (x, u) in bottom[k + 1..n].iter_mut().zip(pivot_row) {
                    *x -= f * u;
                }
            }
        }
    }
    true
}

/// Solves `A x = b` in place with the factor of [`lu_in_place`].
#[inline(never)]
pub(crate) fn lu_solve(a: &[f64], n: usize, perm: &[usize], b: &mut [f64]) {
    for k in 0..n {
        if perm[k] != k {
            b.swap(k, perm[k]);
        }
        let bk = b[k];
        if bk != 0.0 {
            for i in k + 1..n {
                b[i] -= a[i * n + k] * bk;
            }
        }
    }
    for i in (0..n).rev() {
        let s: f64 = a[i * n + i + 1..(i + 1) * n]
            .iter()
            .zip(&b[i + 1..n])
            .map(|(u, x)| u * x)
            .sum();
        b[i] = (b[i] - s) * a[i * n + i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lu_solves_a_non_symmetric_system_that_needs_pivoting() {
        // [0 2 1; 1 1 0; 3 0 1] x = b for x = [1, -2, 3].
        let a0 = [0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let x = [1.0, -2.0, 3.0];
        let mut b: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| a0[i * 3 + j] * x[j]).sum())
            .collect();
        let mut a = a0;
        let mut perm = [0; 3];
        assert!(lu_in_place(&mut a, 3, &mut perm));
        lu_solve(&a, 3, &perm, &mut b);
        for i in 0..3 {
            assert!((b[i] - x[i]).abs() < 1e-14, "{b:?}");
        }
        let mut singular = [1.0, 2.0, 2.0, 4.0];
        assert!(!lu_in_place(&mut singular, 2, &mut [0; 2]));
    }

    /// `A x = b` solved by [`lu_in_place`] and by nalgebra's dense LU: the pivot rows
    /// and the largest difference of the solutions.
    fn against_nalgebra(a0: &[f64], n: usize) -> (Vec<usize>, f64) {
        let b0: Vec<f64> = (0..n).map(|k| ((k * 7 % 11) as f64) - 5.0).collect();
        let mut a = a0.to_vec();
        let mut perm = vec![0; n];
        assert!(lu_in_place(&mut a, n, &mut perm));
        let mut b = b0.clone();
        lu_solve(&a, n, &perm, &mut b);
        let x = nalgebra::DMatrix::from_row_slice(n, n, a0)
            .lu()
            .solve(&nalgebra::DVector::from_vec(b0))
            .expect("regular");
        let worst = (0..n).map(|i| (b[i] - x[i]).abs()).fold(0.0, f64::max);
        (perm, worst)
    }

    /// Test matrix: diagonal `d(i)`, every other entry `1 / (1 + |i - j|)`, negative
    /// below the diagonal.
    fn test_matrix(n: usize, d: &dyn Fn(usize) -> f64) -> Vec<f64> {
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let v = 1.0 / (1.0 + i.abs_diff(j) as f64);
                a[i * n + j] = if i == j {
                    d(i)
                } else if i > j {
                    -v
                } else {
                    v
                };
            }
        }
        a
    }

    #[test]
    fn local_factor_solves_the_chains_and_border_as_a_dense_lu_does() {
        // Three relays per rope, both border unknowns free: fill the factor's entries,
        // build the same dense block in the order of `iz_psi`, and compare the solves
        // of two right sides.
        let m = 3;
        let l = 2 * m + 2;
        let mut fa = LocalFactor::new(m);
        let mut dense = vec![0.0; l * l];
        for side in 0..2 {
            for rl in 0..m {
                let k = side * m + rl;
                let row = iz_psi(m, side, rl);
                fa.dia[k] = 5.0 + k as f64;
                dense[row * l + row] = fa.dia[k];
                if rl > 0 {
                    fa.sub[k] = -1.0 - 0.1 * k as f64;
                    dense[row * l + iz_psi(m, side, rl - 1)] = fa.sub[k];
                }
                if rl + 1 < m {
                    fa.sup[k] = 1.5 - 0.2 * k as f64;
                    dense[row * l + iz_psi(m, side, rl + 1)] = fa.sup[k];
                }
            }
            let first = iz_psi(m, side, 0);
            fa.edge[side] = [0.7 - side as f64, 0.3];
            fa.couple[0][side] = -0.4 + side as f64;
            fa.couple[1][side] = 0.9;
            for border in 0..2 {
                dense[first * l + m + border] = fa.edge[side][border];
                dense[(m + border) * l + first] = fa.couple[border][side];
            }
        }
        fa.border = [[6.0, 0.5], [-0.8, 4.0]];
        for (i, row) in fa.border.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                dense[(m + i) * l + m + j] = *v;
            }
        }
        assert!(fa.factor(m));
        let w = 2;
        let b0: Vec<f64> = (0..l * w).map(|k| ((k * 5 % 7) as f64) - 3.0).collect();
        let mut b = b0.clone();
        fa.solve(m, &mut b, w);
        let x = nalgebra::DMatrix::from_row_slice(l, l, &dense)
            .lu()
            .solve(&nalgebra::DMatrix::from_row_slice(l, w, &b0))
            .expect("regular");
        for i in 0..l {
            for c in 0..w {
                assert!((b[i * w + c] - x[(i, c)]).abs() < 1e-13, "row {i}: {b:?}");
            }
        }
        // One right side: the chord iterations' solve gives the first column bitwise.
        let mut one: Vec<f64> = (0..l).map(|i| b0[i * w]).collect();
        fa.solve_one(m, &mut one);
        for i in 0..l {
            assert_eq!(one[i].to_bits(), b[i * w].to_bits(), "row {i}");
        }
        // A zero pivot is reported, not divided by.
        let mut zero = LocalFactor::new(m);
        zero.dia[m + 1] = 0.0;
        assert!(!zero.factor(m));
    }

    #[test]
    fn lu_keeps_the_diagonal_above_the_pivot_threshold_and_solves_exactly() {
        // Diagonal 0.4 against entries up to 0.5 below it: above a tenth of the largest
        // candidate, so no row is interchanged.
        let (perm, err) = against_nalgebra(&test_matrix(7, &|_| 0.4), 7);
        assert_eq!(perm, (0..7).collect::<Vec<_>>());
        assert!(err < 1e-12, "{err}");
        // Zero diagonal (a skew-symmetric matrix of even order, regular): every column
        // needs an interchange, and the solve must replay them in order.
        let (perm, err) = against_nalgebra(&test_matrix(6, &|_| 0.0), 6);
        let interchanges = perm.iter().enumerate().filter(|(k, &p)| p != *k).count();
        assert!(interchanges >= 2, "{perm:?}");
        assert!(err < 1e-12, "{err}");
    }
}

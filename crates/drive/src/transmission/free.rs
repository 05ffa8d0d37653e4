//! Coordinates of the joint side that no pair and no joint load touches (the bending
//! modes of flexible links: the ropes see the joint angles only), eliminated from the
//! Newton system of the step.
//!
//! With the joints `j` first and the free coordinates `m` last, the Newton matrix is
//!
//! ```text
//! [ A_jj + P   A_jm ]      A = the joint side's base, 4 M / h^2 + 2 D / h (+ K of the modes)
//! [ A_mj       A_mm ]      P = what the pairs and the joint loads add (joints only)
//! ```
//!
//! and only `P` changes between the iterations of a step (the base is made once, at
//! the step's first assembly). So the free block is factored once per base,
//! `A_mm = L L^T`, with `W = L^-1 A_mj` and the Schur complement on the joints
//! `S = A_jj - W^T W`; an iteration then solves `(S + P) dq_j = r_j - W^T y` with
//! `y = L^-1 r_m`, an `nj x nj` system, and `dq_m = L^-T (y - W dq_j)`. The same update
//! as the full solve, to round-off.

/// The factor of the free block of a Newton matrix base, its Schur complement on the
/// joints, and the scratch of the solves.
#[derive(Debug, Clone)]
pub(crate) struct FreeFactor {
    /// Joints (coordinates the pairs and loads may touch).
    nj: usize,
    /// Free coordinates, after the joints.
    nf: usize,
    /// Cholesky factor of `A_mm` (lower triangle, row-major `nf x nf`), and the
    /// reciprocals of its diagonal (the solves multiply: a division's latency in
    /// their dependent chains cost more than the rest of them).
    l: Vec<f64>,
    inv_d: Vec<f64>,
    /// `W^T`, row-major `nj x nf`: row `c` is `L^-1 A_m,c`.
    wt: Vec<f64>,
    /// The Schur complement `A_jj - W^T W`, row-major `nj x nj`.
    pub schur: Vec<f64>,
    /// `L^-1 r_m` of the last [`Self::reduce`].
    y: Vec<f64>,
    /// The last [`Self::factor`] succeeded.
    pub ok: bool,
    /// Steps begun since the last [`Self::factor`].
    pub age: u32,
}

#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |s, (x, y)| s + x * y)
}

impl FreeFactor {
    /// Buffers for `nj` joints and `nf` free coordinates.
    pub(crate) fn new(nj: usize, nf: usize) -> Self {
        Self {
            nj,
            nf,
            l: vec![0.0; nf * nf],
            inv_d: vec![0.0; nf],
            wt: vec![0.0; nj * nf],
            schur: vec![0.0; nj * nj],
            y: vec![0.0; nf],
            ok: false,
            age: 0,
        }
    }

    /// Factors the free block of the base `a` (row-major `n x n`, `n = nj + nf`) and
    /// makes the Schur complement; false when the free block is not positive definite.
    pub(crate) fn factor(&mut self, a: &[f64]) -> bool {
        let (nj, nf) = (self.nj, self.nf);
        let n = nj + nf;
        self.age = 0;
        // Cholesky-Banachiewicz, row by row.
        for i in 0..nf {
            let (prev, rest) = self.l.split_at_mut(i * nf);
            let ri = &mut rest[..nf];
            ri.copy_from_slice(&a[(nj + i) * n + nj..(nj + i + 1) * n]);
            for j in 0..i {
                let rj = &prev[j * nf..j * nf + j];
                ri[j] = (ri[j] - dot(&ri[..j], rj)) * self.inv_d[j];
            }
            let d = ri[i] - dot(&ri[..i], &ri[..i]);
            if !(d > 0.0 && d.is_finite()) {
                return false;
            }
            ri[i] = d.sqrt();
            self.inv_d[i] = 1.0 / ri[i];
        }
        // W^T: forward substitution of every joint column of A_mj.
        for c in 0..nj {
            let w = &mut self.wt[c * nf..(c + 1) * nf];
            for i in 0..nf {
                let li = &self.l[i * nf..i * nf + i];
                w[i] = (a[(nj + i) * n + c] - dot(li, &w[..i])) * self.inv_d[i];
            }
        }
        for r in 0..nj {
            for c in 0..=r {
                let v = a[r * n + c]
                    - dot(
                        &self.wt[r * nf..(r + 1) * nf],
                        &self.wt[c * nf..(c + 1) * nf],
                    );
                self.schur[r * nj + c] = v;
                self.schur[c * nj + r] = v;
            }
        }
        true
    }

    /// The joints' right side of the reduced system: `r_j - W^T L^-1 r_m` into
    /// `rhs[..nj]` (`rhs` = `[r_j; r_m]`, the free part kept for [`Self::expand`]).
    pub(crate) fn reduce(&mut self, rhs: &mut [f64]) {
        let (nj, nf) = (self.nj, self.nf);
        let (rj, rm) = rhs.split_at_mut(nj);
        for i in 0..nf {
            let li = &self.l[i * nf..i * nf + i];
            self.y[i] = (rm[i] - dot(li, &self.y[..i])) * self.inv_d[i];
        }
        for (c, r) in rj.iter_mut().enumerate() {
            *r -= dot(&self.wt[c * nf..(c + 1) * nf], &self.y);
        }
    }

    /// The free coordinates' update from the joints' (`rhs[..nj]`, solved):
    /// `L^-T (y - W dq_j)` into `rhs[nj..]`.
    pub(crate) fn expand(&self, rhs: &mut [f64]) {
        let (nj, nf) = (self.nj, self.nf);
        let (dq, z) = rhs.split_at_mut(nj);
        let z = &mut z[..nf];
        z.copy_from_slice(&self.y);
        for (c, &d) in dq.iter().enumerate() {
            for (zi, w) in z.iter_mut().zip(&self.wt[c * nf..(c + 1) * nf]) {
                *zi -= w * d;
            }
        }
        // Back substitution with L^T, column by column (rows of L).
        for i in (0..nf).rev() {
            let li = &self.l[i * nf..i * nf + i];
            let x = z[i] * self.inv_d[i];
            z[i] = x;
            for (zk, l) in z[..i].iter_mut().zip(li) {
                *zk -= l * x;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transmission::step::{cholesky_in_place, cholesky_solve};

    #[test]
    fn the_reduced_solve_is_the_full_solve() {
        // A symmetric positive definite 7 x 7 matrix, 3 joints and 4 free coordinates.
        let n = 7;
        let nj = 3;
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let x = ((i * 7 + j * 3) % 11) as f64 / 11.0 + ((i + j) % 3) as f64 * 0.1;
                a[i * n + j] += x;
                a[j * n + i] += x;
            }
            a[i * n + i] += 10.0 + i as f64;
        }
        let b: Vec<f64> = (0..n).map(|i| (i as f64 * 0.7).sin()).collect();
        let mut full = a.clone();
        assert!(cholesky_in_place(&mut full, n));
        let mut x = b.clone();
        cholesky_solve(&full, n, &mut x);
        let mut ff = FreeFactor::new(nj, n - nj);
        assert!(ff.factor(&a));
        let mut s = ff.schur.clone();
        assert!(cholesky_in_place(&mut s, nj));
        let mut y = b.clone();
        ff.reduce(&mut y);
        cholesky_solve(&s, nj, &mut y[..nj]);
        ff.expand(&mut y);
        for i in 0..n {
            assert!((x[i] - y[i]).abs() < 1e-14, "{i}: {} vs {}", x[i], y[i]);
        }
        // Not positive definite: refused.
        let mut bad = a.clone();
        bad[(n - 1) * n + n - 1] = -1.0;
        assert!(!ff.factor(&bad));
    }
}

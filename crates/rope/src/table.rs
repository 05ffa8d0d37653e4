//! A function of one variable given by its values at knots: the shape-free form of an
//! effect's law (stiffness against tension, creep rate against tension, friction against
//! load or speed). Linear between the knots, constant beyond the last one (no runaway
//! outside the measured range), and defined from the first knot at 0.
//!
//! The table is `Copy` (at most [`MAX_KNOTS`] knots, no heap), so that laws holding one
//! stay cheap to copy, and it keeps, for the rope laws, the integrals of `1/y` and `x/y`
//! from 0 to every knot (`y > 0`): the strain and the energy of a spring whose tangent
//! stiffness the table scales ([`Table::integral_inv`], [`Table::integral_x_over`]).

use std::cell::Cell;

use serde::{Deserialize, Serialize};

use crate::error::RopeError;

thread_local! {
    /// The knot that opens the highest segment in which a table was evaluated on this
    /// thread since the innermost [`reached_during`] began (`-inf`: none).
    static REACHED: Cell<f64> = const { Cell::new(f64::NEG_INFINITY) };
}

/// Notes an evaluation of a table in the segment that knot `x` opens
/// ([`reached_during`]).
#[inline]
fn reach(x: f64) {
    REACHED.with(|r| {
        if x > r.get() {
            r.set(x);
        }
    });
}

/// Runs `f`, and returns with its result the knot that opens the highest segment of
/// any table it evaluated on this thread (`None`: it evaluated none). Every evaluation
/// counts, a Newton iterate's as a converged state's. The value at knot `k` moves the
/// law above knot `k - 1` only (the segment from `k - 1` to `k` and beyond), so a
/// table changed only at knots whose knot before lies above the returned one leaves
/// what `f` computed the same to the bit (a simulation runs on one thread). Segments,
/// not arguments, are noted: a knot changes rarely, so the note seldom stores.
/// [`Table::max_abs_slope`] is not an evaluation: a rope law reads it once, for the
/// stopping test of its spring's solve, whose result it does not change beyond
/// rounding. Scopes nest: the enclosing one counts what the inner one reached.
pub fn reached_during<R>(f: impl FnOnce() -> R) -> (R, Option<f64>) {
    let outer = REACHED.with(|r| r.replace(f64::NEG_INFINITY));
    let out = f();
    let inner = REACHED.with(|r| {
        let inner = r.get();
        r.set(outer.max(inner));
        inner
    });
    (out, (inner > f64::NEG_INFINITY).then_some(inner))
}

/// Most knots a table holds.
pub const MAX_KNOTS: usize = 12;

/// A piecewise-linear function (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Table {
    n: usize,
    x: [f64; MAX_KNOTS],
    y: [f64; MAX_KNOTS],
    /// `int_0^x_i dx / y` and `int_0^x_i x dx / y` at every knot (0 when some `y <= 0`).
    inv: [f64; MAX_KNOTS],
    xinv: [f64; MAX_KNOTS],
}

/// How a table is written in files: its knots and values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableFile {
    /// Knots, increasing from 0.
    pub x: Vec<f64>,
    /// Values at the knots.
    pub y: Vec<f64>,
}

impl Serialize for Table {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        TableFile {
            x: self.x().to_vec(),
            y: self.y().to_vec(),
        }
        .serialize(s)
    }
}

impl<'de> Deserialize<'de> for Table {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let f = TableFile::deserialize(d)?;
        Table::new(&f.x, &f.y).map_err(serde::de::Error::custom)
    }
}

impl Table {
    /// The table through `(x[i], y[i])`: at least 2 and at most [`MAX_KNOTS`] knots,
    /// `x[0] = 0`, `x` strictly increasing, every value finite.
    pub fn new(x: &[f64], y: &[f64]) -> Result<Self, RopeError> {
        let bad = |reason: String| RopeError::BadParameter {
            field: "table".into(),
            value: x.len() as f64,
            reason,
        };
        if x.len() != y.len() || x.len() < 2 || x.len() > MAX_KNOTS {
            return Err(bad(format!(
                "needs 2 to {MAX_KNOTS} knots and one value per knot ({} knots, {} values)",
                x.len(),
                y.len()
            )));
        }
        if x[0] != 0.0 {
            return Err(bad(format!("the first knot must be 0, not {}", x[0])));
        }
        if x.windows(2)
            .any(|w| w[1] <= w[0] || !w[1].is_finite() || w[0].is_nan())
        {
            return Err(bad(format!("knots must increase strictly: {x:?}")));
        }
        if y.iter().any(|v| !v.is_finite()) {
            return Err(bad(format!("values must be finite: {y:?}")));
        }
        let n = x.len();
        let mut t = Self {
            n,
            x: [0.0; MAX_KNOTS],
            y: [0.0; MAX_KNOTS],
            inv: [0.0; MAX_KNOTS],
            xinv: [0.0; MAX_KNOTS],
        };
        t.x[..n].copy_from_slice(x);
        t.y[..n].copy_from_slice(y);
        if y.iter().all(|v| *v > 0.0) {
            for i in 1..n {
                t.inv[i] = t.inv[i - 1] + t.seg_inv(i - 1, x[i]);
                t.xinv[i] = t.xinv[i - 1] + t.seg_xinv(i - 1, x[i]);
            }
        }
        Ok(t)
    }

    /// The knots.
    pub fn x(&self) -> &[f64] {
        &self.x[..self.n]
    }

    /// The values.
    pub fn y(&self) -> &[f64] {
        &self.y[..self.n]
    }

    /// True when every value is > 0.
    pub fn positive(&self) -> bool {
        self.y().iter().all(|v| *v > 0.0)
    }

    /// True when the values never fall (never rise) from knot to knot.
    pub fn non_decreasing(&self) -> bool {
        self.y().windows(2).all(|w| w[1] >= w[0])
    }

    /// Index of the segment holding `x >= 0` (the last knot's for `x` beyond it).
    #[inline]
    fn segment(&self, x: f64) -> usize {
        let mut i = 0;
        while i + 1 < self.n && x >= self.x[i + 1] {
            i += 1;
        }
        reach(self.x[i]);
        i
    }

    /// Slope of segment `i` (0 beyond the last knot).
    #[inline]
    fn slope_of(&self, i: usize) -> f64 {
        if i + 1 < self.n {
            (self.y[i + 1] - self.y[i]) / (self.x[i + 1] - self.x[i])
        } else {
            0.0
        }
    }

    /// The value at `x` (the first value for `x < 0`).
    #[inline]
    pub fn eval(&self, x: f64) -> f64 {
        let x = x.max(0.0);
        let i = self.segment(x);
        self.y[i] + self.slope_of(i) * (x - self.x[i])
    }

    /// The value and the slope at `x` (the slope is 0 for `x < 0` and beyond the last
    /// knot; at a knot, the segment to its right).
    #[inline]
    pub fn eval_slope(&self, x: f64) -> (f64, f64) {
        if x < 0.0 {
            reach(0.0);
            return (self.y[0], 0.0);
        }
        let i = self.segment(x);
        let m = self.slope_of(i);
        (self.y[i] + m * (x - self.x[i]), m)
    }

    /// `int_x_i^x dt / y(t)` within segment `i`.
    #[inline]
    fn seg_inv(&self, i: usize, x: f64) -> f64 {
        let (y0, m) = (self.y[i], self.slope_of(i));
        let d = x - self.x[i];
        if (m * d).abs() <= 1e-9 * y0 {
            // ln(1 + u)/m with u = m d / y0 small: d / y0 (1 - u/2 + u^2/3).
            let u = m * d / y0;
            d / y0 * (1.0 - u / 2.0 + u * u / 3.0)
        } else {
            ((y0 + m * d) / y0).ln() / m
        }
    }

    /// `int_x_i^x t dt / y(t)` within segment `i`.
    fn seg_xinv(&self, i: usize, x: f64) -> f64 {
        let (xi, y0, m) = (self.x[i], self.y[i], self.slope_of(i));
        let d = x - xi;
        if (m * d).abs() <= 1e-9 * y0 {
            (x * x - xi * xi) / (2.0 * y0)
        } else {
            // y = a + m t with a = y0 - m xi: int t/(a + m t) = t/m - a/m^2 ln(a + m t).
            let a = y0 - m * xi;
            d / m - a / (m * m) * ((y0 + m * d) / y0).ln()
        }
    }

    /// `int_0^x dt / y(t)` for `x >= 0` (the strain of a spring of unit base stiffness
    /// whose tangent stiffness the table scales, at tension `x`); needs every value > 0.
    #[inline]
    pub fn integral_inv(&self, x: f64) -> f64 {
        let x = x.max(0.0);
        let i = self.segment(x);
        self.inv[i] + self.seg_inv(i, x)
    }

    /// `int_0^x t dt / y(t)` for `x >= 0` (that spring's stored energy at tension `x`);
    /// needs every value > 0.
    pub fn integral_x_over(&self, x: f64) -> f64 {
        let x = x.max(0.0);
        let i = self.segment(x);
        self.xinv[i] + self.seg_xinv(i, x)
    }

    /// The `x >= 0` at which [`Self::integral_inv`] reaches `v >= 0` (its inverse: the
    /// tension of that spring at strain `v`).
    pub fn inverse_integral_inv(&self, v: f64) -> f64 {
        self.inverse_integral_inv_value(v).0
    }

    /// [`Self::inverse_integral_inv`] and the value of the table there, from one search
    /// and one exponential: within segment `i` the inverse is
    /// `x = x_i + y_i (exp(m r) - 1) / m` and the value `y_i exp(m r)`, `r` the part of
    /// `v` beyond the knot (the tension and the tangent stiffness of the spring).
    #[inline]
    pub fn inverse_integral_inv_value(&self, v: f64) -> (f64, f64) {
        if v <= 0.0 {
            reach(0.0);
            return (0.0, self.y[0]);
        }
        let mut i = 0;
        while i + 1 < self.n && v >= self.inv[i + 1] {
            i += 1;
        }
        let (xi, y0, m) = (self.x[i], self.y[i], self.slope_of(i));
        let r = v - self.inv[i];
        let out = if (m * r).abs() <= 1e-12 {
            (xi + r * y0, y0 + m * r * y0)
        } else {
            // ln(1 + m d / y0) / m = r  =>  d = y0 (exp(m r) - 1) / m
            let e = (m * r).exp_m1();
            (xi + y0 * e / m, y0 + y0 * e)
        };
        // (segment `i` was read: its knot's value and the next one's)
        reach(xi);
        out
    }

    /// The largest `|slope|` of any segment (0 for a constant table).
    pub fn max_abs_slope(&self) -> f64 {
        (0..self.n)
            .map(|i| self.slope_of(i).abs())
            .fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integrals_match_quadrature_and_invert() {
        let t = Table::new(&[0.0, 50.0, 200.0, 400.0], &[1.0, 1.4, 2.2, 2.3]).unwrap();
        for x in [0.0, 10.0, 50.0, 120.0, 400.0, 700.0] {
            // Simpson on a fine grid.
            let n = 20_000;
            let h = x / n as f64;
            let (mut s1, mut s2) = (0.0, 0.0);
            for k in 0..=n {
                let t_k = k as f64 * h;
                let w = if k == 0 || k == n {
                    1.0
                } else if k % 2 == 1 {
                    4.0
                } else {
                    2.0
                };
                s1 += w / t.eval(t_k);
                s2 += w * t_k / t.eval(t_k);
            }
            let (q1, q2) = (s1 * h / 3.0, s2 * h / 3.0);
            assert!((t.integral_inv(x) - q1).abs() < 1e-9 * (1.0 + q1), "{x}");
            assert!((t.integral_x_over(x) - q2).abs() < 1e-7 * (1.0 + q2), "{x}");
            let back = t.inverse_integral_inv(t.integral_inv(x));
            assert!((back - x).abs() < 1e-9 * (1.0 + x), "{x}: {back}");
        }
        assert!((t.eval_slope(100.0).1 - (2.2 - 1.4) / 150.0).abs() < 1e-15);
        assert!((t.eval(1e6) - 2.3).abs() < 1e-15);
        assert!(t.non_decreasing() && t.positive());
    }

    #[test]
    fn bad_tables_are_refused_with_the_reason() {
        assert!(Table::new(&[1.0, 2.0], &[1.0, 1.0]).is_err());
        assert!(Table::new(&[0.0, 2.0, 2.0], &[1.0, 1.0, 1.0]).is_err());
        assert!(Table::new(&[0.0], &[1.0]).is_err());
        let e = Table::new(&[0.0, 1.0], &[1.0, f64::NAN]).unwrap_err();
        assert!(e.to_string().contains("finite"), "{e}");
    }

    /// The knot opening the highest segment evaluated in a scope: an inverse counts the
    /// segment it finds, a negative argument counts as the first segment, scopes nest
    /// (the outer one counts the inner one's), and a scope that evaluates nothing
    /// reaches nothing.
    #[test]
    fn a_scope_reaches_the_highest_segment_it_evaluated() {
        let t = Table::new(&[0.0, 100.0, 400.0], &[1.0, 2.0, 3.0]).unwrap();
        let ((), none) = reached_during(|| ());
        assert_eq!(none, None);
        let (_, neg) = reached_during(|| t.eval_slope(-5.0));
        assert_eq!(neg, Some(0.0));
        let (x, inv) = reached_during(|| t.inverse_integral_inv(t.integral_inv(250.0)));
        assert!((x - 250.0).abs() < 1e-9, "{x}");
        assert_eq!(inv, Some(100.0));
        let (_, top) = reached_during(|| t.eval(400.0));
        assert_eq!(top, Some(400.0));
        let ((_, inner), outer) = reached_during(|| {
            t.eval(30.0);
            let r = reached_during(|| t.eval(120.0));
            t.eval(60.0);
            r
        });
        assert_eq!(inner, Some(100.0));
        assert_eq!(outer, Some(100.0));
    }
}

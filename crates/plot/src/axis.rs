//! One plot axis (linear or base-10 logarithmic) as a plotters coordinate.
//!
//! plotters' own log coordinate labels ticks with raw `Debug` floats; this type
//! picks 1-2-5 ticks itself (per decade on a log axis, `{1, 2, 5} * 10^k`
//! steps on a linear one), draws 1..9 minor grid lines per decade, and formats
//! labels with as few digits as the tick spacing needs.

use plotters::coord::ranged1d::{KeyPointHint, NoDefaultFormatting, Ranged, ValueFormatter};
use std::ops::Range;

/// A finite, non-empty data range on a linear or log10 axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
}

/// What kind of major ticks an axis uses; the minor ticks and label format follow from it.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Ticks {
    /// Linear ticks at integer multiples of `step` (`step` = 1, 2 or 5 times a power of ten).
    Linear { step: f64 },
    /// Log ticks at `m * 10^k` for each mantissa `m` in the set.
    Decades {
        mantissas: &'static [f64],
        stride: i32,
    },
}

const ONE_TWO_FIVE: &[f64] = &[1.0, 2.0, 5.0];
const ONE_TO_NINE: &[f64] = &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
const ONE: &[f64] = &[1.0];

impl Axis {
    /// Axis over `lo..hi` (data units). Callers guarantee `lo < hi`, both finite,
    /// and both positive when `log` is set.
    pub(crate) fn new(lo: f64, hi: f64, log: bool) -> Self {
        Self { lo, hi, log }
    }

    /// Lower end of the axis in data units.
    pub(crate) fn lo(&self) -> f64 {
        self.lo
    }

    /// Upper end of the axis in data units.
    pub(crate) fn hi(&self) -> f64 {
        self.hi
    }

    /// Data value to the axis' linear parameter (log10 on a log axis).
    pub(crate) fn param(&self, v: f64) -> f64 {
        if self.log {
            v.log10()
        } else {
            v
        }
    }

    /// Inverse of [`Axis::param`].
    pub(crate) fn value_at(&self, t: f64) -> f64 {
        if self.log {
            10f64.powf(t)
        } else {
            t
        }
    }

    /// Automatic axis around the finite data extent `min..=max` with a margin of
    /// `margin` (fraction of the span, in log10 units on a log axis). A zero span
    /// is widened to +-10 % (or +-1 around zero; a factor 2 on a log axis).
    pub(crate) fn auto(min: f64, max: f64, log: bool, margin: f64) -> Self {
        if log {
            let (tl, th) = (min.log10(), max.log10());
            let span = th - tl;
            if span <= 0.0 {
                return Self::new(min / 2.0, max * 2.0, true);
            }
            Self::new(
                10f64.powf(tl - margin * span),
                10f64.powf(th + margin * span),
                true,
            )
        } else {
            let span = max - min;
            if span <= 0.0 {
                let half = if min == 0.0 { 1.0 } else { 0.1 * min.abs() };
                return Self::new(min - half, max + half, false);
            }
            Self::new(min - margin * span, max + margin * span, false)
        }
    }

    /// Chooses the major tick scheme for at most `max_n` labelled ticks.
    fn ticks(&self, max_n: usize) -> Ticks {
        let max_n = max_n.max(2);
        if self.log {
            let count = |m: &[f64]| self.decade_ticks(m, 1).len();
            let n125 = count(ONE_TWO_FIVE);
            if (3..=max_n).contains(&n125) {
                return Ticks::Decades {
                    mantissas: ONE_TWO_FIVE,
                    stride: 1,
                };
            }
            if n125 < 3 {
                if (2..=max_n).contains(&count(ONE_TO_NINE)) {
                    return Ticks::Decades {
                        mantissas: ONE_TO_NINE,
                        stride: 1,
                    };
                }
                // Less than about one decade: plain linear ticks read best.
                return Ticks::Linear {
                    step: nice_step(self.hi - self.lo, max_n),
                };
            }
            let decades = count(ONE).max(1);
            let stride = decades.div_ceil(max_n).max(1) as i32;
            Ticks::Decades {
                mantissas: ONE,
                stride,
            }
        } else {
            Ticks::Linear {
                step: nice_step(self.hi - self.lo, max_n),
            }
        }
    }

    /// `m * 10^k` inside the axis for every mantissa `m` and every `stride`-th decade `k`.
    fn decade_ticks(&self, mantissas: &[f64], stride: i32) -> Vec<f64> {
        let k_lo = self.lo.log10().floor() as i32 - 1;
        let k_hi = self.hi.log10().ceil() as i32 + 1;
        let mut out = Vec::new();
        for k in k_lo..=k_hi {
            if k.rem_euclid(stride) != 0 {
                continue;
            }
            let decade = 10f64.powi(k);
            for &m in mantissas {
                let v = m * decade;
                if self.contains(v) {
                    out.push(v);
                }
            }
        }
        out
    }

    /// Integer multiples of `step` inside the axis.
    fn linear_ticks(&self, step: f64) -> Vec<f64> {
        let first = (self.lo / step).ceil() as i64;
        let last = (self.hi / step).floor() as i64;
        if last.saturating_sub(first) > 10_000 {
            return Vec::new(); // cannot happen for steps from `nice_step`; guards the loop
        }
        (first..=last)
            .map(|i| i as f64 * step)
            .map(|v| if v == 0.0 { 0.0 } else { v }) // no "-0"
            .filter(|&v| self.contains(v))
            .collect()
    }

    /// Whether `v` lies on the axis (with a relative tolerance for rounding).
    fn contains(&self, v: f64) -> bool {
        let tol = 1e-9 * (self.param(self.hi) - self.param(self.lo));
        let t = self.param(v);
        t >= self.param(self.lo) - tol && t <= self.param(self.hi) + tol
    }

    /// Major tick positions (data units) for at most `max_n` labels.
    pub(crate) fn major_ticks(&self, max_n: usize) -> Vec<f64> {
        match self.ticks(max_n) {
            Ticks::Linear { step } => self.linear_ticks(step),
            Ticks::Decades { mantissas, stride } => self.decade_ticks(mantissas, stride),
        }
    }

    /// Minor grid positions (data units) belonging to the majors for `max_n` labels.
    fn minor_ticks(&self, max_n: usize) -> Vec<f64> {
        match self.ticks(max_n) {
            Ticks::Linear { step } => {
                let mantissa = (step / 10f64.powf(step.log10().floor())).round() as i64;
                let divisions = if mantissa == 2 { 4.0 } else { 5.0 };
                self.linear_ticks(step / divisions)
            }
            Ticks::Decades { mantissas, stride } => {
                if stride == 1 && mantissas.len() < ONE_TO_NINE.len() {
                    self.decade_ticks(ONE_TO_NINE, 1)
                } else {
                    self.decade_ticks(ONE, 1)
                }
            }
        }
    }

    /// Tick label for `v` when at most `max_n` labels are shown.
    pub(crate) fn label(&self, v: f64, max_n: usize) -> String {
        match self.ticks(max_n) {
            Ticks::Linear { step } => {
                let biggest = self.lo.abs().max(self.hi.abs());
                if biggest >= 1e6 || (biggest < 1e-3 && biggest > 0.0) {
                    format_significant(v)
                } else {
                    let decimals = (-(step.log10() + 1e-9).floor()).max(0.0) as usize;
                    format!("{v:.decimals$}")
                }
            }
            Ticks::Decades { .. } => format_significant(v),
        }
    }
}

/// Smallest step `{1, 2, 5} * 10^k` that puts at most `max_n` ticks on a span.
fn nice_step(span: f64, max_n: usize) -> f64 {
    let raw = span / max_n.saturating_sub(1).max(1) as f64;
    let decade = 10f64.powf(raw.log10().floor());
    for m in [1.0, 2.0, 5.0, 10.0] {
        if m * decade >= raw * (1.0 - 1e-9) {
            return m * decade;
        }
    }
    10.0 * decade
}

/// Short label: plain decimal for 1e-3 <= |v| < 1e5, else `2e-4` / `1.5e6`,
/// at most 6 significant digits and no trailing zeros.
fn format_significant(v: f64) -> String {
    if v == 0.0 {
        return "0".to_string();
    }
    let a = v.abs();
    if (1e-3..1e5).contains(&a) {
        let decimals = (5 - a.log10().floor() as i32).clamp(0, 12) as usize;
        trim_zeros(&format!("{v:.decimals$}"))
    } else {
        let s = format!("{v:.5e}");
        match s.split_once('e') {
            Some((mantissa, exponent)) => format!("{}e{exponent}", trim_zeros(mantissa)),
            None => s,
        }
    }
}

fn trim_zeros(s: &str) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s.to_string()
    }
}

impl Ranged for Axis {
    type FormatOption = NoDefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let (t0, t1) = (self.param(self.lo), self.param(self.hi));
        let fraction = (self.param(*value) - t0) / (t1 - t0);
        let pixel = f64::from(limit.0) + fraction * f64::from(limit.1 - limit.0);
        // Callers clip data to the axis first; the clamp only guards the cast.
        pixel.round().clamp(-1e7, 1e7) as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            let minor = self.minor_ticks(hint.bold_points());
            if minor.len() <= hint.max_num_points() {
                minor
            } else {
                Vec::new()
            }
        } else {
            self.major_ticks(hint.max_num_points())
        }
    }

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }
}

/// Plotters asks the coordinate for tick labels; it must use the same tick
/// scheme as `key_points`, which depends on the label count. [`LabelledAxis`]
/// carries that count.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LabelledAxis {
    pub(crate) axis: Axis,
    pub(crate) max_labels: usize,
}

impl Ranged for LabelledAxis {
    type FormatOption = NoDefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.axis.map(value, limit)
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        self.axis.key_points(hint)
    }

    fn range(&self) -> Range<f64> {
        self.axis.range()
    }
}

impl ValueFormatter<f64> for LabelledAxis {
    fn format(value: &f64) -> String {
        format_significant(*value)
    }

    fn format_ext(&self, value: &f64) -> String {
        self.axis.label(*value, self.max_labels)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels(axis: &Axis, n: usize) -> Vec<String> {
        axis.major_ticks(n)
            .iter()
            .map(|&v| axis.label(v, n))
            .collect()
    }

    #[test]
    fn log_axis_over_three_decades_gets_one_two_five_ticks() {
        let axis = Axis::new(0.08, 120.0, true);
        assert_eq!(
            labels(&axis, 12),
            ["0.1", "0.2", "0.5", "1", "2", "5", "10", "20", "50", "100"]
        );
        // Minor grid: 1..9 per decade, 0.08 is the first inside 0.08..120.
        let minor = axis.minor_ticks(12);
        assert!((minor[0] - 0.08).abs() < 1e-12, "{minor:?}");
        assert_eq!(minor.len(), 2 + 9 + 9 + 9 + 1); // 0.08, 0.09, 0.1..0.9, 1..9, 10..90, 100
    }

    #[test]
    fn log_axis_over_many_decades_keeps_decades_only() {
        let axis = Axis::new(1e-3, 1e6, true);
        assert_eq!(
            labels(&axis, 10),
            ["0.001", "0.01", "0.1", "1", "10", "100", "1000", "10000", "1e5", "1e6"]
        );
        assert_eq!(labels(&axis, 5), ["0.01", "1", "100", "10000", "1e6"]);
    }

    #[test]
    fn narrow_log_axis_falls_back_to_finer_ticks() {
        assert_eq!(
            labels(&Axis::new(2.5, 9.5, true), 10),
            ["3", "4", "5", "6", "7", "8", "9"]
        );
        assert_eq!(
            labels(&Axis::new(2.1, 2.9, true), 6),
            ["2.2", "2.4", "2.6", "2.8"]
        );
    }

    #[test]
    fn linear_ticks_are_one_two_five_multiples() {
        assert_eq!(
            labels(&Axis::new(-190.0, 10.0, false), 8),
            ["-150", "-100", "-50", "0"]
        );
        assert_eq!(
            labels(&Axis::new(-0.05, 1.05, false), 8),
            ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]
        );
        assert!((nice_step(7.0, 8) - 1.0).abs() < 1e-12);
        assert!((nice_step(7.1, 8) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn auto_range_adds_margin_and_widens_flat_data() {
        let a = Axis::auto(0.0, 10.0, false, 0.05);
        assert_eq!((a.lo(), a.hi()), (-0.5, 10.5));
        let b = Axis::auto(1.0, 100.0, true, 0.05);
        assert!((b.lo().log10() + 0.1).abs() < 1e-12 && (b.hi().log10() - 2.1).abs() < 1e-12);
        let c = Axis::auto(49.0, 49.0, false, 0.05);
        assert!((c.lo() - 44.1).abs() < 1e-12 && (c.hi() - 53.9).abs() < 1e-12);
        let d = Axis::auto(0.0, 0.0, false, 0.05);
        assert_eq!((d.lo(), d.hi()), (-1.0, 1.0));
    }

    #[test]
    fn map_is_linear_in_log10_on_log_axes() {
        let axis = Axis::new(1.0, 1000.0, true);
        assert_eq!(axis.map(&10.0, (0, 300)), 100);
        assert_eq!(axis.map(&1000.0, (0, 300)), 300);
        let lin = Axis::new(-1.0, 1.0, false);
        assert_eq!(lin.map(&0.0, (400, 0)), 200);
    }

    #[test]
    fn significant_formatting() {
        assert_eq!(format_significant(2.0 * 10f64.powi(-4)), "2e-4");
        assert_eq!(format_significant(1.5e6), "1.5e6");
        assert_eq!(format_significant(0.05), "0.05");
        assert_eq!(format_significant(-20000.0), "-20000");
    }
}

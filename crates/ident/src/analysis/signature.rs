//! The residual's signatures, quantified: for every pattern `diagnose` finds in a
//! baseline's residual (phase error growing with frequency, residual following the sign
//! of the velocity, harmonics, error depending on the mean tension or on the amplitude,
//! drift), the simplest term that would produce it, its size in physical units, and the
//! share of the baseline's excess squared error (`SSR - SSR_floor`) that adding the term
//! removes. Each share is measured: the term is applied to the model's simulated channel
//! (or the model re-simulated with it) and the SSR recomputed over the analysed samples.
//!
//! | signature | term | size |
//! |---|---|---|
//! | phase error grows with frequency | a pure delay of the output (the registry's `sensor_delay`, [`Delay`]) | `tau` [s] |
//! | residual follows the velocity's sign | a dry torque at the output shaft, `-F sign(w)`, through the rig's small-signal dynamics (sweeps); `-a sign(rate)` on the channel otherwise | `F` [N*m] (sweeps), `a` [channel unit] |
//! | harmonics at 2f / 3f | a non-linear term: the residual's 2f and 3f components of every frequency step | largest amplitude [rad] |
//! | error depends on the mean tension | a stiffness per run (`k1` scaled), its log-slope against the tension | `d ln k1 / dT` [1/N] |
//! | error depends on the amplitude | a damping per run; dry friction by the describing function `C_eq = C_v + 4 F / (pi V)` | `F` [N*m] |
//! | drift over time | a term linear in time (common slope, each run's offset) | slope [channel unit / s] |
//! | a periodic component the test does not drive (residual not white) | a sinusoid at the residual's dominant frequency (each run its amplitude and phase) | amplitude [channel unit], its frequency in `equivalent` |
//! | a channel's residual follows the channel itself | a calibration of every measured channel, `measured = g model + c` (per channel, common to the runs: a sensor's gain and zero) | the largest gain error `g - 1` [1], its channel's offset `c` in `equivalent` |
//!
//! Every share is of the excess over every stacked channel (a sweep's tensions with its
//! angle, each weighted by its noise as in the fits): a term on the output angle is
//! measured against all the error there is to explain (a load cell's gain error leaves
//! the angle at its floor, where a share of the angle's own excess, a few percent of
//! the floor's SSR, was 70% of nothing).
//!
//! See `docs/models.md`, "Residual signatures".

use longreach_drive::effects::{DataKind, Delay, SensorModel};
use num_complex::Complex64;
use rayon::prelude::*;
use serde::Serialize;
use std::f64::consts::{PI, TAU};

use super::compare::dft;
use super::{Comparison, Prepared, RunData, RunError, FLOOR_MARGIN};
use crate::dataset::DatasetKind;
use crate::error::IdentError;
use crate::fitting::{fit, FitOptions, ParamSpec, ResidualError, Residuals};
use crate::metrics;
use crate::model::{Model, PlantParams};

/// The patterns a residual can show.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SignatureKind {
    /// The phase error (model minus measured) grows with the test frequency.
    PhaseGrowsWithFrequency,
    /// The residual follows the sign of the velocity.
    VelocitySign,
    /// The residual has components at 2f and 3f of the test frequency.
    Harmonics,
    /// The per-run error correlates with the mean tension.
    TensionDependence,
    /// The per-run error depends on the input amplitude.
    AmplitudeDependence,
    /// The residual correlates with time.
    Drift,
    /// The residual holds a periodic component at a frequency the test does not drive
    /// (a disturbance, a mode the model lacks).
    Periodic,
    /// The residual of a measured channel follows the channel itself: the measurement
    /// is the model's scaled and offset (a sensor's gain or zero, a radius ratio).
    Calibration,
    /// The residual at the test frequencies is what a second mode at the output leaves:
    /// part of the output's inertia sits behind a compliant shaft (a load, a coupling,
    /// a flexible link) that the model holds rigid.
    SecondMode,
    /// The residual at the test frequencies is what another viscous damping of the
    /// output leaves (or, the ropes' stiffness scaled alike, another inertia: a rig
    /// constant misstated).
    OutputDamping,
}

/// The same term's size in another quantity (e.g. a dry torque as the angle offset it
/// leaves at low frequency).
#[derive(Debug, Clone, Serialize)]
pub struct Equivalent {
    /// What the value is.
    pub what: &'static str,
    /// Its value.
    pub value: f64,
    /// Its unit.
    pub unit: &'static str,
}

/// One signature of a residual, with the simplest term that produces it.
#[derive(Debug, Clone, Serialize)]
pub struct Signature {
    /// The pattern.
    pub kind: SignatureKind,
    /// What was seen in the residual, in words (with the statistic that detected it).
    pub evidence: String,
    /// The simplest term that would produce it, in words, ending with its symbol.
    pub term: String,
    /// What else the reader should know of the term (how it was fitted, per-run values).
    pub note: String,
    /// The term's fitted size, in `unit` (NaN, i.e. null in JSON, when it could not be
    /// fitted).
    pub size: f64,
    /// Unit of `size`.
    pub unit: &'static str,
    /// The size in another quantity, when one helps.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub equivalent: Option<Equivalent>,
    /// Share of the baseline's excess squared error above the noise floor,
    /// `(SSR - SSR_with_term) / (SSR - SSR_floor)`, that the term removes (0 when the
    /// baseline has no excess); over every stacked channel (module docs).
    pub share_removed: f64,
    /// The same reduction of the SSR over the floor's SSR (meaningful at the floor too).
    pub removed_over_floor: f64,
}

impl Signature {
    /// One clause for the explanation: evidence, term, size and share.
    pub fn sentence(&self) -> String {
        if !self.share_removed.is_finite() {
            return format!("{} ({})", self.evidence, self.note);
        }
        let eq = self
            .equivalent
            .as_ref()
            .map(|e| format!(", {} = {}", e.what, quantity(e.value, e.unit)))
            .unwrap_or_default();
        let note = if self.note.is_empty() {
            String::new()
        } else {
            format!(" ({})", self.note)
        };
        format!(
            "{}: {} = {}{eq} would remove {:.0}% of the excess error{note}",
            self.evidence,
            self.term,
            quantity(self.size, self.unit),
            100.0 * self.share_removed
        )
    }
}

/// The explanation's "Residual signature: ..." sentence.
pub fn describe(signatures: &[Signature]) -> String {
    if signatures.is_empty() {
        "Residual signature: none of the known patterns (phase error growing with frequency, the velocity's sign, harmonics, tension or amplitude dependence, drift, a periodic component, a second mode or the output's damping, a channel's calibration).".into()
    } else {
        let parts: Vec<String> = signatures.iter().map(Signature::sentence).collect();
        format!("Residual signature: {}.", parts.join("; "))
    }
}

/// A value with its unit, delays in ms.
fn quantity(v: f64, unit: &str) -> String {
    if unit == "s" && v.abs() < 1.0 {
        return format!("{:.1} ms", v * 1e3);
    }
    let a = v.abs();
    let num = if a != 0.0 && !(1e-2..1e4).contains(&a) {
        format!("{v:.2e}")
    } else {
        format!("{v:.3}")
    };
    if unit == "1" {
        num
    } else {
        format!("{num} {unit}")
    }
}

/// The baseline's residual and what a term is measured against.
struct Base<'p, 'a> {
    prep: &'p Prepared<'a>,
    model: &'p Model,
    sims: &'p [Vec<f64>],
    /// SSR of the baseline over the analysed samples.
    ssr: f64,
    /// The noise floor's SSR.
    ssr_floor: f64,
    /// The excess the shares are of: over every stacked channel when the simulation
    /// holds them (a sweep's tensions with its angle: a term on the angle is measured
    /// against all the error there is to explain, and a share of an angle already at
    /// its floor is not a share of anything), else the primary channel's.
    excess: f64,
}

impl Base<'_, '_> {
    /// SSR of run `r`'s channel `y` over its analysed samples.
    fn ssr_run(&self, r: usize, y: &[f64]) -> f64 {
        let run = &self.prep.runs[r];
        run.idx
            .iter()
            .map(|&i| (y[i] - run.measured[i]).powi(2))
            .sum()
    }

    /// `(share_removed, removed_over_floor)` of a term that leaves `ssr_after`.
    fn shares(&self, ssr_after: f64) -> (f64, f64) {
        let removed = self.ssr - ssr_after;
        let excess = self.excess;
        (
            if excess > 0.0 { removed / excess } else { 0.0 },
            removed / self.ssr_floor.max(f64::MIN_POSITIVE),
        )
    }

    fn signature(
        &self,
        kind: SignatureKind,
        evidence: String,
        term: Result<Term, IdentError>,
    ) -> Signature {
        match term {
            Ok(t) => {
                let (share_removed, removed_over_floor) = self.shares(t.ssr_after);
                Signature {
                    kind,
                    evidence,
                    term: t.term,
                    note: t.note,
                    size: t.size,
                    unit: t.unit,
                    equivalent: t.equivalent,
                    share_removed,
                    removed_over_floor,
                }
            }
            Err(e) => Signature {
                kind,
                evidence,
                term: String::new(),
                note: format!("not quantified: {e}"),
                size: f64::NAN,
                unit: "",
                equivalent: None,
                share_removed: f64::NAN,
                removed_over_floor: f64::NAN,
            },
        }
    }

    /// The plant parameters of run `r`.
    fn params(&self, r: usize) -> Result<PlantParams, IdentError> {
        Ok(self.model.plant_params(r)?)
    }

    /// The measured frequency response of run `r` at its test frequencies (from the
    /// comparison), `(frequency_hz, H)`.
    fn measured_frf(&self, cmp: &Comparison, r: usize) -> Vec<(f64, Complex64)> {
        let name = &self.prep.runs[r].name;
        cmp.frequency
            .iter()
            .filter(|p| &p.run == name)
            .map(|p| {
                (
                    p.frequency_hz,
                    Complex64::from_polar(
                        10f64.powf(p.gain_measured_db / 20.0),
                        p.phase_measured_deg.to_radians(),
                    ),
                )
            })
            .collect()
    }
}

/// What a term leaves and how large it is.
struct Term {
    term: String,
    note: String,
    size: f64,
    unit: &'static str,
    equivalent: Option<Equivalent>,
    ssr_after: f64,
}

/// A term added to a sweep model: its parameters act on a run's plant numbers (a
/// stiffness, a damping), on the analytic response and on the simulated output (a
/// sensor's delay). Its size and share come from [`fit_sweep_term`].
struct SweepTerm<'t> {
    /// The term's parameters (their starting values estimated from the data).
    specs: Vec<ParamSpec>,
    /// The values at which the term does nothing.
    neutral: Vec<f64>,
    /// Further values the simulation's fit may start from (with the model's own
    /// values), when closer to the data than the analytic fit's and the neutral ones.
    start: Option<Vec<f64>>,
    /// Refit the baseline's free parameters with it.
    refit_base: bool,
    /// Puts the term's values into run `r`'s plant numbers.
    on_plant: &'t (dyn Fn(&[f64], usize, &mut PlantParams) + Sync),
    /// What a sensor term does: the factor on the analytic response at `f`, and the
    /// transform of a simulated output sampled at `time_s`.
    sensor: Option<SensorTerm<'t>>,
}

/// The sensor part of a [`SweepTerm`].
struct SensorTerm<'t> {
    response: &'t (dyn Fn(&[f64], f64) -> Complex64 + Sync),
    output: &'t (dyn Fn(&[f64], &[f64], &[f64]) -> Vec<f64> + Sync),
}

/// The baseline's free parameters and a term's, fitted together: on the analytic
/// response (squared log ratios of the measured one) for a start, then on the
/// simulation (least squares over the analysed samples).
struct TermFit<'p, 'a, 't> {
    b: &'p Base<'p, 'a>,
    term: &'p SweepTerm<'t>,
    n_base: usize,
    frf: Vec<Vec<(f64, Complex64)>>,
}

impl TermFit<'_, '_, '_> {
    /// The plant numbers of run `r` at `x` (baseline's free values, then the term's).
    fn plant(&self, x: &[f64], r: usize) -> Result<PlantParams, IdentError> {
        let (xb, xt) = x.split_at(self.n_base);
        let mut p = if self.n_base > 0 {
            self.b
                .model
                .with_values(xb, self.b.prep.runs.len())
                .plant_params(r)?
        } else {
            self.b.params(r)?
        };
        (self.term.on_plant)(xt, r, &mut p);
        Ok(p)
    }

    /// Log-ratio residuals of the analytic response.
    fn frf_residuals(&self, x: &[f64], out: &mut Vec<f64>) -> Result<(), IdentError> {
        out.clear();
        let prep = self.b.prep;
        for (r, points) in self.frf.iter().enumerate() {
            let p = self.plant(x, r)?;
            for &(f, h) in points {
                let mut m =
                    prep.plant
                        .small_signal_response(&p, r, f)
                        .ok_or(IdentError::NotASweep {
                            kind: prep.ds.kind.name(),
                        })?;
                if let Some(s) = &self.term.sensor {
                    m *= (s.response)(&x[self.n_base..], f);
                }
                let d = (m / h).ln();
                out.push(d.re);
                out.push(d.im);
            }
        }
        Ok(())
    }

    /// The simulated output of every run at `x`.
    fn simulate(&self, x: &[f64]) -> Result<Vec<Vec<f64>>, IdentError> {
        let prep = self.b.prep;
        (0..prep.runs.len())
            .into_par_iter()
            .map(|r| {
                let y = prep.simulate_params(&self.plant(x, r)?, r)?.into_primary();
                Ok(match &self.term.sensor {
                    Some(s) => (s.output)(&x[self.n_base..], &prep.runs[r].time_s, &y),
                    None => y,
                })
            })
            .collect()
    }

    fn ssr(&self, x: &[f64]) -> f64 {
        self.simulate(x).map_or(f64::INFINITY, |sims| {
            (0..sims.len()).map(|r| self.b.ssr_run(r, &sims[r])).sum()
        })
    }
}

/// The analytic-response problem of a [`TermFit`].
struct FrfOf<'f, 'p, 'a, 't>(&'f TermFit<'p, 'a, 't>);

impl Residuals for FrfOf<'_, '_, '_, '_> {
    fn residuals(&self, x: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
        Ok(self.0.frf_residuals(x, out)?)
    }
}

/// The time-domain problem of a [`TermFit`].
struct SimOf<'f, 'p, 'a, 't>(&'f TermFit<'p, 'a, 't>);

impl Residuals for SimOf<'_, '_, '_, '_> {
    fn residuals(&self, x: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
        *out = self.0.b.prep.primary_residuals_of(&self.0.simulate(x)?);
        Ok(())
    }
}

/// Adds `term` to the baseline and fits it (with the baseline's free parameters when
/// `term.refit_base`): least squares on the analytic response from the term's
/// starting values, then on the simulation from the better of that point and the
/// baseline with the term neutral (so the term never leaves more than the baseline).
/// Returns the term's values and the SSR it leaves.
fn fit_sweep_term(
    b: &Base<'_, '_>,
    cmp: &Comparison,
    term: &SweepTerm<'_>,
) -> Result<(Vec<f64>, f64), IdentError> {
    let n_runs = b.prep.runs.len();
    let base_specs = if term.refit_base {
        b.model.fit_specs(n_runs)
    } else {
        Vec::new()
    };
    let tf = TermFit {
        b,
        term,
        n_base: base_specs.len(),
        frf: (0..n_runs).map(|r| b.measured_frf(cmp, r)).collect(),
    };
    let mut specs = base_specs;
    specs.extend(term.specs.iter().cloned());
    let initial: Vec<f64> = specs.iter().map(|s| s.initial).collect();
    let analytic = fit(
        &FrfOf(&tf),
        &specs,
        &FitOptions {
            tolerance: 1e-8,
            gtol: 1e-10,
            patience: 40,
            diff_step: 1e-6,
            max_evaluations: usize::MAX,
            probation_jacobians: None,
            intervals: true,
        },
    )
    .map_or(initial.clone(), |r| r.values);
    let mut neutral: Vec<f64> = initial[..tf.n_base].to_vec();
    neutral.extend(&term.neutral);
    let mut start = if tf.ssr(&analytic) <= tf.ssr(&neutral) {
        analytic
    } else {
        neutral
    };
    if let Some(given) = &term.start {
        let mut v: Vec<f64> = initial[..tf.n_base].to_vec();
        v.extend(given);
        if tf.ssr(&v) < tf.ssr(&start) {
            start = v;
        }
    }
    for (s, &v) in specs.iter_mut().zip(&start) {
        s.initial = crate::fitting::strictly_inside(v, s.lower, s.upper);
    }
    let r = fit(
        &SimOf(&tf),
        &specs,
        &FitOptions {
            tolerance: 1e-6,
            gtol: 1e-8,
            patience: 8,
            diff_step: 1e-5,
            max_evaluations: usize::MAX,
            probation_jacobians: None,
            intervals: true,
        },
    )?;
    Ok((r.values[tf.n_base..].to_vec(), r.ssr))
}

/// Every signature the baseline's residual shows, each with its term, size and share.
/// `model` is the (fitted) baseline, `sims` its simulated channel of every run and `cmp`
/// its comparison with the data ([`super::compare`]).
pub fn signatures(
    prep: &Prepared<'_>,
    model: &Model,
    sims: &[Vec<f64>],
    cmp: &Comparison,
) -> Vec<Signature> {
    // the primary channel's: the signatures are the output angle's
    let ssr_floor = prep.primary_floor_ssr();
    let mut base = Base {
        prep,
        model,
        sims,
        ssr: 0.0,
        ssr_floor,
        excess: 0.0,
    };
    base.ssr = (0..prep.runs.len())
        .map(|r| base.ssr_run(r, &sims[r]))
        .sum();
    let stacked = prep
        .runs
        .iter()
        .zip(sims)
        .all(|(run, y)| y.len() >= run.n_channels() * run.measured.len());
    base.excess = if stacked {
        prep.ssr(sims) - prep.floor_ssr()
    } else {
        base.ssr - ssr_floor
    };
    let b = &base;
    let r = &cmp.residual;
    let mut out = Vec::new();
    if cmp.frequency.len() >= 4 {
        let (f, p): (Vec<f64>, Vec<f64>) = cmp
            .frequency
            .iter()
            .map(|x| (x.frequency_hz, x.phase_error_deg))
            .unzip();
        if let Ok(c) = metrics::pearson(&f, &p) {
            if c.abs() > 0.8 {
                out.push(b.signature(
                    SignatureKind::PhaseGrowsWithFrequency,
                    format!("phase error grows with frequency (correlation {c:.2})"),
                    delay(b, cmp),
                ));
            }
        }
    }
    let moved = resonance_shift(cmp);
    let corr_tension = r.corr_mean_tension.filter(|c| c.abs() > 0.7);
    if corr_tension.is_some() || moved.is_some() {
        let mut ev = Vec::new();
        if let Some(c) = corr_tension {
            ev.push(format!(
                "error {} with mean tension (correlation {c:.2})",
                if c > 0.0 { "grows" } else { "falls" }
            ));
        }
        if let Some((t0, t1, d)) = moved {
            ev.push(format!(
                "the measured resonance moves {:.1}% {} than the model's between {t0:.0} and {t1:.0} N",
                100.0 * d.abs(),
                if d > 0.0 { "further up" } else { "less far up" }
            ));
        }
        out.push(b.signature(
            SignatureKind::TensionDependence,
            ev.join(", "),
            tension_stiffness(b, cmp),
        ));
    }
    // The residual follows the velocity's sign itself, or (sweeps) the output's
    // response to a torque of that sign (a dry torque's effect near the resonance is
    // in phase with the angle, not with the velocity: there the first test misses it).
    let friction = dry_friction(b);
    let corr_response = friction.as_ref().map_or(0.0, |f| f.1);
    let follows_response = prep.kind == DataKind::SineSweep && corr_response.abs() > 0.3;
    if r.corr_velocity_sign.abs() > 0.2 || follows_response {
        out.push(b.signature(
            SignatureKind::VelocitySign,
            format!(
                "residual follows the sign of the velocity ({:.2}{})",
                r.corr_velocity_sign,
                if prep.kind == DataKind::SineSweep {
                    format!(
                        "; {corr_response:.2} with the output's response to a torque of that sign"
                    )
                } else {
                    String::new()
                }
            ),
            friction.map(|f| f.0),
        ));
    }
    if r.harmonic_2f > 0.02 || r.harmonic_3f > 0.02 {
        out.push(b.signature(
            SignatureKind::Harmonics,
            format!(
                "harmonics in the residual (2f: {:.1}%, 3f: {:.1}%)",
                100.0 * r.harmonic_2f,
                100.0 * r.harmonic_3f
            ),
            Ok(harmonics(b)),
        ));
    }
    if r.corr_time.abs() > 0.3 {
        out.push(b.signature(
            SignatureKind::Drift,
            format!("drift over time (correlation {:.2})", r.corr_time),
            Ok(drift(b)),
        ));
    }
    if r.ljung_box_p < 0.05 && prep.kind != DataKind::ArmMoves {
        if let Some((t, f_hz)) = periodic(b) {
            let (share, _) = b.shares(t.ssr_after);
            if share >= PERIODIC_MIN_SHARE {
                out.push(b.signature(
                    SignatureKind::Periodic,
                    format!(
                        "the residual is not white (Ljung-Box p = {:.1e}) and holds a periodic component at {f_hz:.4} Hz (period {:.2} s) that the input does not drive",
                        r.ljung_box_p,
                        1.0 / f_hz
                    ),
                    Ok(t),
                ));
            }
        }
    }
    if let Some(sig) = calibration(b) {
        out.push(sig);
    }
    if let Some((lo, hi)) = amplitude_contrast(cmp) {
        out.push(b.signature(
            SignatureKind::AmplitudeDependence,
            format!(
                "the error depends on the amplitude (NRMSE {:.3} at {:.3} rad vs {:.3} at {:.3} rad, {:.0} N; noise floors {:.3} and {:.3})",
                lo.nrmse,
                lo.amplitude_rad.unwrap_or(0.0),
                hi.nrmse,
                hi.amplitude_rad.unwrap_or(0.0),
                lo.mean_tension_n.unwrap_or(0.0),
                lo.noise_floor_nrmse,
                hi.noise_floor_nrmse
            ),
            amplitude_damping(b, cmp),
        ));
    }
    // The shaft's linear terms have no statistic of their own, only their share: each
    // is reported where no term above explains more, and a mode only where its load
    // and frequency are determined apart (a mode's tail alone, an inertia growing with
    // the frequency, was "found" on a rig whose stated inertia was 12% low, on the
    // relay lead's model). A mode that does little more than
    // the output's damping off says nothing of a mode (on a hidden dry friction a
    // "mode" at 0.5 Hz removes 64% and a damping 62%): the damping is reported instead
    // where it removes as much, its share measured on the simulation (tried there from
    // half the bar on the small-signal picture).
    if prep.kind == DataKind::SineSweep {
        if let Ok(ShaftTerms {
            mode,
            determined,
            damping_dc,
            damping_after,
        }) = second_mode(b)
        {
            let best = out
                .iter()
                .map(|s| s.share_removed)
                .filter(|s| s.is_finite())
                .fold(0.0, f64::max);
            let (share, _) = b.shares(mode.ssr_after);
            let (simple, _) = b.shares(damping_after);
            if determined && share >= MODE_MIN_SHARE.max(best) && share - simple >= MODE_MARGIN {
                out.push(b.signature(
                    SignatureKind::SecondMode,
                    "the residual at the test frequencies is what a second mode at the output leaves".into(),
                    Ok(mode),
                ));
            } else if simple >= 0.5 * MODE_MIN_SHARE {
                if let Ok(t) = output_damping(b, cmp, damping_dc) {
                    if b.shares(t.ssr_after).0 >= MODE_MIN_SHARE.max(best) {
                        out.push(b.signature(
                            SignatureKind::OutputDamping,
                            format!(
                                "the residual at the test frequencies is what {} damping of the output leaves",
                                if t.size < 0.0 { "a lower" } else { "a higher" }
                            ),
                            Ok(t),
                        ));
                    }
                }
            }
        }
    }
    out
}

/// The measured resonance's move between the lowest and highest mean tension against
/// the model's, `ln(measured ratio) - ln(model ratio)`, when larger than 3%: a stiffness
/// that depends on the tension (the per-run error need not follow the tension: a fitted
/// global stiffness misses both ends).
fn resonance_shift(cmp: &Comparison) -> Option<(f64, f64, f64)> {
    let mut res: Vec<(f64, f64, f64)> = cmp
        .resonance
        .iter()
        .filter_map(|r| Some((r.mean_tension_n, r.measured_hz?, r.model_hz?)))
        .collect();
    res.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (lo, hi) = (res.first()?, res.last()?);
    let moved = (hi.1 / lo.1).ln() - (hi.2 / lo.2).ln();
    (hi.0 > lo.0 && moved.abs() > 0.03).then_some((lo.0, hi.0, moved))
}

/// Two runs at one mean tension (within 1%) and different amplitudes whose excess
/// errors above their noise floors, `sqrt(NRMSE^2 - floor^2)`, differ by more than a
/// factor 2 (`|ln ratio| > 0.7`), the one with the larger excess beyond the floor
/// margin: the pair of the largest contrast, smaller amplitude first. (The NRMSE itself
/// is no measure here: the noise alone makes it grow as the amplitude falls.)
fn amplitude_contrast(cmp: &Comparison) -> Option<(&RunError, &RunError)> {
    let excess = |x: &RunError| {
        (x.nrmse.powi(2) - x.noise_floor_nrmse.powi(2))
            .max(0.0)
            .sqrt()
    };
    let mut best: Option<(f64, &RunError, &RunError)> = None;
    for lo in &cmp.runs {
        for hi in &cmp.runs {
            let (Some(al), Some(ah), Some(tl), Some(th)) = (
                lo.amplitude_rad,
                hi.amplitude_rad,
                lo.mean_tension_n,
                hi.mean_tension_n,
            ) else {
                continue;
            };
            if ah <= al || (th - tl).abs() > 0.01 * tl.abs().max(th.abs()) {
                continue;
            }
            let worse = if excess(lo) >= excess(hi) { lo } else { hi };
            let contrast = (excess(hi).max(1e-12) / excess(lo).max(1e-12)).ln().abs();
            if contrast > 0.7
                && worse.nrmse > FLOOR_MARGIN * worse.noise_floor_nrmse
                && best.is_none_or(|b| contrast > b.0)
            {
                best = Some((contrast, lo, hi));
            }
        }
    }
    best.map(|(_, lo, hi)| (lo, hi))
}

/// `y` shifted later by `tau` (earlier for `tau < 0`) with the registry's sensor delay.
fn shifted(time_s: &[f64], y: &[f64], tau: f64) -> Vec<f64> {
    let mut v = y.to_vec();
    let d = Delay {
        channel: "output_angle_rad",
        delay_s: tau.abs(),
    };
    if tau >= 0.0 {
        d.apply(time_s, &mut v);
    } else {
        // An advance is a delay of the time-reversed series.
        let t: Vec<f64> = time_s.iter().rev().map(|t| -t).collect();
        v.reverse();
        d.apply(&t, &mut v);
        v.reverse();
    }
    v
}

/// A pure delay of the output (the registry's `sensor_delay`, [`Delay`]): started from
/// least squares on the per-frequency phase errors (`360 f tau` degrees: the model
/// leads the data by it), fitted with the baseline's free parameters (a delay the
/// baseline could not have pulled its stiffness down to mimic part of), the model's
/// output shifted by `tau` for the share.
fn delay(b: &Base<'_, '_>, cmp: &Comparison) -> Result<Term, IdentError> {
    let (sfp, sff) = cmp.frequency.iter().fold((0.0, 0.0), |(a, c), x| {
        (
            a + x.frequency_hz * x.phase_error_deg,
            c + x.frequency_hz.powi(2),
        )
    });
    let tau0 = sfp / (360.0 * sff.max(f64::MIN_POSITIVE));
    let response = |x: &[f64], f: f64| Complex64::from_polar(1.0, -TAU * f * x[0]);
    let output = |x: &[f64], t: &[f64], y: &[f64]| shifted(t, y, x[0]);
    let term = SweepTerm {
        specs: vec![ParamSpec {
            name: "delay_s".into(),
            unit: "s".into(),
            initial: tau0.clamp(-0.1, 0.1),
            lower: -0.2,
            upper: 0.2,
            log_scale: false,
        }],
        neutral: vec![0.0],
        start: None,
        refit_base: true,
        on_plant: &|_, _, _| {},
        sensor: Some(SensorTerm {
            response: &response,
            output: &output,
        }),
    };
    let (x, ssr_after) = fit_sweep_term(b, cmp, &term)?;
    Ok(Term {
        term: "a delay of the output tau".into(),
        note: format!(
            "{}the phase errors alone give {}; the baseline's parameters refitted with it",
            if x[0] < 0.0 {
                "negative: an advance, the model lags the data; "
            } else {
                ""
            },
            quantity(tau0, "s")
        ),
        size: x[0],
        unit: "s",
        equivalent: None,
        ssr_after,
    })
}

/// The rig's dimensions from a sweep dataset: `(r1, r2, L, I, C)`.
fn rig_of(b: &Base<'_, '_>, p: &PlantParams) -> Option<(f64, f64, f64, f64, f64)> {
    let DatasetKind::SineSweep(sw) = &b.prep.ds.kind else {
        return None;
    };
    let rig = &sw.rig;
    Some((
        rig.input_radius_m,
        rig.output_radius_m,
        rig.rope_length_m,
        rig.output_inertia_kg_m2,
        p.output_damping_n_m_s.unwrap_or(rig.output_damping_n_m_s),
    ))
}

/// Dry friction. On a sweep: a torque `-F sign(w)` at the output shaft, passed through
/// the rig's small-signal dynamics from a torque at the shaft to its angle,
/// `G = (1 - (r2/r1) H) / (-I w^2 + i C w)` (eq. 9 with the ropes' complex stiffness
/// eliminated through the small-signal response `H`), at every odd harmonic of each
/// step's square wave `sign(w)` (its phase: the model's velocity); `F` by least squares
/// on the residual. The angle offset it leaves at low frequency is `F / k_t`, with the
/// ropes' torsional stiffness `k_t = 2 r2^2 k1 / L` (the model's `k1`). Other kinds:
/// `-a sign(rate)` of the channel. Also returns the correlation of the residual with
/// the term's regressor.
fn dry_friction(b: &Base<'_, '_>) -> Result<(Term, f64), IdentError> {
    let prep = b.prep;
    if prep.kind != DataKind::SineSweep {
        // regression on the sign of the model's rate
        let mut srs = 0.0;
        let mut sss = 0.0;
        for (run, y) in prep.runs.iter().zip(b.sims) {
            for &i in &run.idx {
                let (lo, hi) = (i.saturating_sub(1), (i + 1).min(y.len() - 1));
                let s = metrics::signum_series(&[y[hi] - y[lo]])[0];
                srs += (y[i] - run.measured[i]) * s;
                sss += s * s;
            }
        }
        let a = srs / sss.max(f64::MIN_POSITIVE);
        let corr = srs / (b.ssr * sss).sqrt().max(f64::MIN_POSITIVE);
        return Ok((
            Term {
                term: "a dry-friction term -a sign(rate), a".into(),
                note: "the sign of the model's rate".into(),
                size: a,
                unit: "N",
                equivalent: None,
                ssr_after: b.ssr - a * srs,
            },
            corr,
        ));
    }
    let responses: Vec<Vec<Vec<f64>>> = (0..prep.runs.len())
        .into_par_iter()
        .map(|r| friction_response(b, r))
        .collect::<Result<_, _>>()?;
    let mut srg = 0.0;
    let mut sgg = 0.0;
    for (r, steps) in responses.iter().enumerate() {
        let run = &prep.runs[r];
        for (&(_, a, _), g) in run.segments.iter().zip(steps) {
            for (k, gk) in g.iter().enumerate() {
                srg += (b.sims[r][a + k] - run.measured[a + k]) * gk;
                sgg += gk * gk;
            }
        }
    }
    let torque = srg / sgg.max(f64::MIN_POSITIVE);
    let p = b.params(0)?;
    let (_, r2, l, _, _) = rig_of(b, &p).unwrap_or((1.0, 1.0, 1.0, 1.0, 0.0));
    let k_t = 2.0 * r2 * r2 * p.law.k1_n / l;
    let corr = srg / (b.ssr * sgg).sqrt().max(f64::MIN_POSITIVE);
    Ok((Term {
        term: "a dry torque at the output shaft F".into(),
        note: format!(
            "{}an estimate: the torque's first-order effect through the rig's small-signal dynamics",
            if torque < 0.0 {
                "negative, so not friction; "
            } else {
                ""
            }
        ),
        size: torque,
        unit: "N*m",
        equivalent: Some(Equivalent {
            what: "its angle offset at low frequency F / k_t",
            value: torque / k_t,
            unit: "rad",
        }),
        ssr_after: b.ssr - torque * srg,
    }, corr))
}

/// The shaft's torque-to-angle response at `w` from the small-signal response `h`
/// (eq. 9 with the ropes eliminated): `G = (1 - (r2/r1) H) / (-I w^2 + i C w)`.
fn shaft_response(h: Complex64, r1: f64, r2: f64, inertia: f64, c: f64, w: f64) -> Complex64 {
    (1.0 - (r2 / r1) * h) / Complex64::new(-inertia * w * w, c * w)
}

/// The output angle's response to a unit dry torque `-sign(w)` at the shaft over every
/// analysis window of run `r` (the velocity's phase from the model's fundamental).
fn friction_response(b: &Base<'_, '_>, r: usize) -> Result<Vec<Vec<f64>>, IdentError> {
    let prep = b.prep;
    let run = &prep.runs[r];
    let p = b.params(r)?;
    let (r1, r2, _, inertia, c) = rig_of(b, &p).unwrap_or((1.0, 1.0, 1.0, 1.0, 0.0));
    let nyquist = 0.5 / run.dt_s;
    let y = &b.sims[r];
    run.segments
        .iter()
        .map(|&(f, a, e)| {
            let psi = dft(&y[a..e], run.dt_s, f).arg() + 0.5 * PI;
            // odd harmonics of the square wave: (4/pi) sum sin(k x) / k
            let mut harm = Vec::new();
            let mut k = 1;
            while (k as f64) * f < nyquist && k <= 25 {
                let fk = k as f64 * f;
                let w = TAU * fk;
                let h =
                    prep.plant
                        .small_signal_response(&p, r, fk)
                        .ok_or(IdentError::NotASweep {
                            kind: prep.ds.kind.name(),
                        })?;
                harm.push((k as f64, shaft_response(h, r1, r2, inertia, c, w)));
                k += 2;
            }
            Ok((0..e - a)
                .map(|i| {
                    let x = TAU * f * i as f64 * run.dt_s + psi;
                    4.0 / PI
                        * harm
                            .iter()
                            .map(|(k, g)| g.norm() / k * (k * x + g.arg()).sin())
                            .sum::<f64>()
                })
                .collect())
        })
        .collect()
}

/// Least share of the excess error a second mode must remove to be reported.
const MODE_MIN_SHARE: f64 = 0.2;

/// Least share of the excess error a second mode must remove beyond the output's
/// damping off ([`second_mode`]; its inertia off is the same term) to be reported.
const MODE_MARGIN: f64 = 0.1;

/// One test frequency's step as [`second_mode`] sees it.
struct ShaftStep {
    /// Run.
    run: usize,
    /// Test frequency, Hz.
    f_hz: f64,
    /// The input's fundamental.
    x: Complex64,
    /// The residual's fundamental.
    r: Complex64,
    /// The model's small-signal response at its own values.
    h0: Complex64,
    /// Half the step's analysed samples.
    half_n: f64,
}

/// The least-squares problem of a [`ShaftTerm`]: the model's free values (`n_base`)
/// then the term's; per step, `sqrt(N/2) (R + Z)`.
struct ShaftProblem<'b, 'p, 'a> {
    b: &'b Base<'p, 'a>,
    steps: &'b [ShaftStep],
    n_base: usize,
    term: ShaftTerm,
}

/// A linear term at the output shaft: the dynamic stiffness it adds to the pulley's.
#[derive(Debug, Clone, Copy, PartialEq)]
enum ShaftTerm {
    /// Nothing: the model's free values alone refitted on the small-signal picture.
    Rigid,
    /// A load behind a torsional shaft, `(phi, f2, zeta)` ([`second_mode`]).
    Mode,
    /// A viscous torque `i dc w`, `(dc)` in N*m*s.
    Damping,
}

impl ShaftTerm {
    /// The dynamic stiffness the term adds at `w` to an output of inertia `inertia`.
    fn added(self, v: &[f64], w: f64, inertia: f64) -> Complex64 {
        match self {
            Self::Rigid => Complex64::new(0.0, 0.0),
            Self::Mode => {
                let j2 = v[0] * inertia;
                let k2 = j2 * (TAU * v[1]).powi(2);
                let c2 = 2.0 * v[2] * (k2 * j2).sqrt();
                -(j2 * j2 * w.powi(4)) / Complex64::new(k2 - j2 * w * w, c2 * w)
            }
            Self::Damping => Complex64::new(0.0, v[0] * w),
        }
    }
}

impl ShaftProblem<'_, '_, '_> {
    /// Every step's `R + Z` (unscaled) at `v`.
    fn corrected(&self, v: &[f64]) -> Result<Vec<Complex64>, IdentError> {
        let prep = self.b.prep;
        let not_sweep = || IdentError::NotASweep {
            kind: prep.ds.kind.name(),
        };
        let (xb, load) = v.split_at(self.n_base);
        let model = if self.n_base > 0 {
            Some(self.b.model.with_values(xb, prep.runs.len()))
        } else {
            None
        };
        let params = (0..prep.runs.len())
            .map(|r| model.as_ref().unwrap_or(self.b.model).plant_params(r))
            .collect::<Result<Vec<_>, _>>()?;
        let rigs = params
            .iter()
            .map(|p| rig_of(self.b, p).ok_or_else(not_sweep))
            .collect::<Result<Vec<_>, _>>()?;
        self.steps
            .iter()
            .map(|s| {
                let (r1, r2, _, inertia, c) = rigs[s.run];
                let w = TAU * s.f_hz;
                let h = prep
                    .plant
                    .small_signal_response(&params[s.run], s.run, s.f_hz)
                    .ok_or_else(not_sweep)?;
                let g = shaft_response(h, r1, r2, inertia, c, w);
                let dd = self.term.added(load, w, inertia);
                Ok(s.r + (h / (1.0 + g * dd) - s.h0) * s.x)
            })
            .collect()
    }

    /// The steps' squared error at their fundamental at `v` (infinite where the model
    /// fails).
    fn ssr(&self, v: &[f64]) -> f64 {
        self.corrected(v).map_or(f64::INFINITY, |c| {
            c.iter()
                .zip(self.steps)
                .map(|(d, s)| s.half_n * d.norm_sqr())
                .sum()
        })
    }
}

impl Residuals for ShaftProblem<'_, '_, '_> {
    fn residuals(&self, v: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
        out.clear();
        for (d, s) in self.corrected(v)?.iter().zip(self.steps) {
            let d = d * s.half_n.sqrt();
            out.push(d.re);
            out.push(d.im);
        }
        Ok(())
    }
}

/// A part `J2 = phi I` of the output's inertia `I` behind a torsional shaft of
/// stiffness `k2 = J2 (2 pi f2)^2` and damping `c2 = 2 zeta sqrt(k2 J2)`, the pulley
/// (and its encoder) keeping `I - J2`. On the output's small-signal dynamics the load
/// adds the dynamic stiffness `dD = -J2^2 w^4 / (k2 + i c2 w - J2 w^2)` to the pulley's
/// `D = -I w^2 + i C w` (rigid at low frequency, the pulley alone far above the load's
/// mode), so the response becomes `H / (1 + G dD)` with `G = (1 - (r2/r1) H) / D` the
/// shaft's torque-to-angle response ([`dry_friction`]). A step's correction is the
/// change of its fundamental, `Z = (H_c - H_0) X`, with `H_0` the model's response, `H_c`
/// the load's with the model's free values refitted (a load lowers the first resonance,
/// which the baseline's stiffness had matched) and `X` the input's fundamental
/// (single-bin DFT over the step's whole cycles); it changes the step's squared error by
/// exactly `N/2 (|R + Z|^2 - |R|^2)` (`R` the residual's fundamental, `N` samples).
/// Least squares on that from a grid of starts over `phi` and `f2`. The SSR after is
/// the baseline's less what the term removes beyond the model's free values refitted
/// alone on the same picture ([`ShaftTerm::Rigid`]: the simulation's fit has spent what
/// they gain, the picture's optimum not being the simulation's). Also returns the
/// simpler term a mode must beat, fitted alike: the output's damping off, `i dc w`
/// (its inertia off, `-di I w^2`, is the same term once the ropes' stiffness is
/// refitted: only `C / I` is left), whose share [`output_damping`] then measures on the
/// simulation.
fn second_mode(b: &Base<'_, '_>) -> Result<ShaftTerms, IdentError> {
    let prep = b.prep;
    let not_sweep = || IdentError::NotASweep {
        kind: prep.ds.kind.name(),
    };
    let DatasetKind::SineSweep(sw) = &prep.ds.kind else {
        return Err(not_sweep());
    };
    let mut steps: Vec<ShaftStep> = Vec::new();
    let (mut inertia, mut damping) = (0.0, 0.0);
    let (mut f_lo, mut f_hi) = (f64::INFINITY, 0.0f64);
    for (r, run) in prep.runs.iter().enumerate() {
        let p = b.params(r)?;
        (inertia, damping) = rig_of(b, &p).map(|x| (x.3, x.4)).ok_or_else(not_sweep)?;
        let input = crate::sim::drive_input(&sw.runs[r]);
        let y = &b.sims[r];
        for &(f, a, e) in &run.segments {
            let res: Vec<f64> = (a..e).map(|i| y[i] - run.measured[i]).collect();
            steps.push(ShaftStep {
                run: r,
                f_hz: f,
                x: dft(&input[a..e], run.dt_s, f),
                r: dft(&res, run.dt_s, f),
                h0: prep
                    .plant
                    .small_signal_response(&p, r, f)
                    .ok_or_else(not_sweep)?,
                half_n: 0.5 * (e - a) as f64,
            });
            f_lo = f_lo.min(f);
            f_hi = f_hi.max(f);
        }
    }
    if steps.is_empty() || inertia <= 0.0 {
        return Err(not_sweep());
    }
    // What the model's free values alone gain on the small-signal picture, which the
    // simulation's own fit has already spent (its optimum is the simulation's, not the
    // picture's): a term is credited with what it removes beyond that.
    let rigid = fit_shaft_term(b, &steps, ShaftTerm::Rigid, &[], &[Vec::new()])?.0;
    let after = |ssr: f64| b.ssr - (rigid - ssr).max(0.0);
    let spec = |name: &str, unit: &str, bounds: (f64, f64), log_scale: bool| ParamSpec {
        name: name.into(),
        unit: unit.into(),
        initial: 0.0,
        lower: bounds.0,
        upper: bounds.1,
        log_scale,
    };
    let (f2_lo, f2_hi) = (0.5 * f_lo, 10.0 * f_hi);
    let mut starts = Vec::new();
    for phi in [0.2, 0.5, 0.8] {
        for k in 0..6 {
            let f2 = f_hi * 0.5 * 20f64.powf(f64::from(k) / 5.0);
            starts.push(vec![phi, f2.clamp(1.01 * f2_lo, 0.99 * f2_hi), 0.02]);
        }
    }
    let (mode_ssr, v) = fit_shaft_term(
        b,
        &steps,
        ShaftTerm::Mode,
        &[
            spec("load_share", "1", (1e-3, 1.0 - 1e-3), false),
            spec("f2_hz", "Hz", (f2_lo, f2_hi), true),
            spec("zeta", "1", (1e-4, 2.0), true),
        ],
        &starts,
    )?;
    // The simpler term a mode must beat: the output's damping off. (Its inertia off is
    // the same term: the ropes' stiffness refitted with it, only C / I is left.)
    let (dc_ssr, dc) = fit_shaft_term(
        b,
        &steps,
        ShaftTerm::Damping,
        &[spec("dc", "N*m*s", (-0.999 * damping, 1e3), false)],
        &[vec![0.0]],
    )?;
    let dc = dc[0];
    let j2 = v[0] * inertia;
    let k2 = j2 * (TAU * v[1]).powi(2);
    // A mode far above the sweep shows only through its tail, -J2 w^4 / (2 pi f2)^2 to
    // first order: the fit then runs the load's share to a bound.
    let determined = v[0] > 2e-3 && v[0] < 1.0 - 2e-3;
    Ok(ShaftTerms {
        determined,
        mode: Term {
            term: "a load behind a torsional shaft at the output (a second mode), its frequency with the pulley held f2".into(),
            note: format!(
                "J2 = {} of the output's {}, k2 = {}, damping ratio {:.3}, the model's own values refitted with it; an estimate from each test frequency's fundamental through the rig's small-signal dynamics",
                quantity(j2, "kg*m^2"),
                quantity(inertia, "kg*m^2"),
                quantity(k2, "N*m/rad"),
                v[2]
            ),
            size: v[1],
            unit: "Hz",
            equivalent: Some(Equivalent {
                what: "the load's share of the output's inertia J2 / I",
                value: v[0],
                unit: "1",
            }),
            ssr_after: after(mode_ssr),
        },
        damping_dc: dc,
        damping_after: after(dc_ssr),
    })
}

/// What [`second_mode`] finds.
struct ShaftTerms {
    /// The second mode.
    mode: Term,
    /// Whether the mode's load and frequency are determined apart (its share of the
    /// inertia off its bounds): a mode above the sweep shows only its tail, an inertia
    /// growing with the frequency, which other failures leave as well.
    determined: bool,
    /// The output's damping off on the small-signal picture, `dc` (N*m*s): the start
    /// of [`output_damping`].
    damping_dc: f64,
    /// The SSR after it there.
    damping_after: f64,
}

/// The shaft term `term` (its parameters `term_specs`) fitted with the model's free
/// values on the steps' fundamentals ([`second_mode`]) from each of `starts` (the
/// term's values; the model's own values with each): the least squared error there and
/// the term's values.
fn fit_shaft_term(
    b: &Base<'_, '_>,
    steps: &[ShaftStep],
    term: ShaftTerm,
    term_specs: &[ParamSpec],
    starts: &[Vec<f64>],
) -> Result<(f64, Vec<f64>), IdentError> {
    let mut specs = b.model.fit_specs(b.prep.runs.len());
    let n_base = specs.len();
    let problem = ShaftProblem {
        b,
        steps,
        n_base,
        term,
    };
    specs.extend(term_specs.iter().cloned());
    let own: Vec<f64> = specs[..n_base].iter().map(|s| s.initial).collect();
    let opts = FitOptions {
        intervals: false,
        ..FitOptions::default()
    };
    let mut best: (f64, Vec<f64>) = (f64::INFINITY, Vec::new());
    for start in starts {
        let mut v = own.clone();
        v.extend(start);
        for (s, &x) in specs.iter_mut().zip(&v) {
            s.initial = crate::fitting::strictly_inside(x, s.lower, s.upper);
        }
        let v = fit(&problem, &specs, &opts).map_or(v, |r| r.values);
        let s = problem.ssr(&v);
        if s < best.0 {
            best = (s, v);
        }
    }
    if !best.0.is_finite() {
        return Err(IdentError::NotASweep {
            kind: b.prep.ds.kind.name(),
        });
    }
    Ok((best.0, best.1[n_base..].to_vec()))
}

/// The residual's 2f and 3f components of every frequency step (single-bin DFT over
/// the step's whole cycles), removed from it.
fn harmonics(b: &Base<'_, '_>) -> Term {
    let prep = b.prep;
    let mut ssr_after = 0.0;
    let mut largest = (0.0, 0usize, 0.0, 2usize);
    let mut energy = [0.0; 2];
    for (r, (run, y)) in prep.runs.iter().zip(b.sims).enumerate() {
        let mut covered = vec![false; run.measured.len()];
        for &(f, a, e) in &run.segments {
            let mut res: Vec<f64> = (a..e).map(|i| y[i] - run.measured[i]).collect();
            for (j, m) in [2usize, 3].into_iter().enumerate() {
                let fm = m as f64 * f;
                if fm >= 0.5 / run.dt_s {
                    continue;
                }
                let c = dft(&res, run.dt_s, fm);
                let before: f64 = res.iter().map(|v| v * v).sum();
                for (i, v) in res.iter_mut().enumerate() {
                    let t = i as f64 * run.dt_s;
                    *v -= c.norm() * (TAU * fm * t + c.arg()).sin();
                }
                energy[j] += before - res.iter().map(|v| v * v).sum::<f64>();
                if c.norm() > largest.0 {
                    largest = (c.norm(), r, f, m);
                }
            }
            ssr_after += res.iter().map(|v| v * v).sum::<f64>();
            covered[a..e].iter_mut().for_each(|c| *c = true);
        }
        // analysed samples outside the frequency steps (none for a sweep) stay as they are
        ssr_after += run
            .idx
            .iter()
            .filter(|&&i| !covered[i])
            .map(|&i| (y[i] - run.measured[i]).powi(2))
            .sum::<f64>();
    }
    let (amp, r, f, m) = largest;
    let odd = energy[1] >= energy[0];
    Term {
        term: format!(
            "{}: the residual's 2f and 3f components of every step, the largest",
            if odd {
                "a symmetric non-linear stiffness (odd harmonics: stiffening, slack)"
            } else {
                "an asymmetric non-linearity (even harmonics)"
            }
        ),
        note: format!(
            "at {m}f of {:.2} Hz in {}",
            f,
            prep.runs.get(r).map_or("-", |x| x.name.as_str())
        ),
        size: amp,
        unit: "rad",
        equivalent: None,
        ssr_after,
    }
}

/// A term linear in time: each run's offset and a common slope, by least squares.
fn drift(b: &Base<'_, '_>) -> Term {
    let prep = b.prep;
    let stats: Vec<(f64, f64)> = prep
        .runs
        .iter()
        .zip(b.sims)
        .map(|(run, y)| {
            let n = run.idx.len().max(1) as f64;
            let t = run.idx.iter().map(|&i| run.time_s[i]).sum::<f64>() / n;
            let e = run.idx.iter().map(|&i| y[i] - run.measured[i]).sum::<f64>() / n;
            (t, e)
        })
        .collect();
    let (mut ste, mut stt) = (0.0, 0.0);
    for ((run, y), (tm, em)) in prep.runs.iter().zip(b.sims).zip(&stats) {
        for &i in &run.idx {
            let dt = run.time_s[i] - tm;
            ste += dt * (y[i] - run.measured[i] - em);
            stt += dt * dt;
        }
    }
    let slope = ste / stt.max(f64::MIN_POSITIVE);
    let ssr_after = prep
        .runs
        .iter()
        .zip(b.sims)
        .zip(&stats)
        .map(|((run, y), (tm, em))| {
            run.idx
                .iter()
                .map(|&i| (y[i] - run.measured[i] - em - slope * (run.time_s[i] - tm)).powi(2))
                .sum::<f64>()
        })
        .sum();
    Term {
        term: "a term linear in time, slope".into(),
        note: "with each run's offset".into(),
        size: slope,
        unit: if prep.kind == DataKind::SineSweep {
            "rad/s"
        } else {
            "N/s"
        },
        equivalent: None,
        ssr_after,
    }
}

/// Least share of the stacked excess error a calibration of the channels must remove to
/// be reported ([`calibration`]).
const CALIBRATION_MIN_SHARE: f64 = 0.2;

/// [`CALIBRATION_MIN_SHARE`] on an arm, whose calibration has a gain and an offset for
/// each of its sensors (46 on `example_arm_joint_friction`'s 23): there they absorb a
/// share of any failure. With `joint_friction` hidden (`diagnose --without
/// joint_friction`) they removed 21%, a 4.7% gain on `joint_j5_rad` reading as the
/// missing friction; j2's two load cells 5% high, 100%.
const ARM_CALIBRATION_MIN_SHARE: f64 = 0.5;

/// A calibration of every measured channel: the model's channel `y` mapped to
/// `g y + c`, with `g` and `c` per channel and common to the runs (one sensor, one
/// calibration), by linear least squares over the analysed samples (separable: a
/// channel's correction changes only its own residuals). Its share is of the stacked
/// excess, every channel weighted as in the fits (its noise over the primary's);
/// reported when it removes at least [`CALIBRATION_MIN_SHARE`] of it. A miscalibrated
/// load cell (a 5% gain on a sweep's tensions: 13.8x the floor, no other signature
/// removing any of it) or encoder (3% on the output angle) is otherwise a failure no
/// term accounts for, and the baseline's fitted stiffness may lean on it. The term is
/// the largest gain error, of the channel whose calibration removes most.
fn calibration(b: &Base<'_, '_>) -> Option<Signature> {
    let (prep, sims) = (b.prep, b.sims);
    // every channel's (an arm's: every sensor's) calibration
    let per: Vec<Calibrated> = match &prep.ds.kind {
        DatasetKind::ArmMoves(am) => arm_sensors(b, am),
        _ => {
            let n_channels = prep.runs.iter().map(RunData::n_channels).max()?;
            let primary = super::prepare::primary_name(&prep.ds.kind);
            (0..n_channels)
                .filter_map(|k| {
                    // the channel's samples over the runs that stack it: (model,
                    // measured, analysed indices, weight^2)
                    let name = prep
                        .runs
                        .iter()
                        .rev()
                        .find(|run| k < run.n_channels())
                        .map_or(primary, |run| run.channel_name(k, primary));
                    let samples = || {
                        prep.runs.iter().zip(sims).filter_map(move |(run, y)| {
                            let len = run.measured.len();
                            (k < run.n_channels() && y.len() >= (k + 1) * len).then(|| {
                                (
                                    &y[k * len..(k + 1) * len],
                                    run.channel_values(k),
                                    &run.idx[..],
                                    run.weight(k).powi(2),
                                )
                            })
                        })
                    };
                    regressed(name, samples)
                })
                .collect()
        }
    };
    let excess = b.excess;
    let removed: f64 = per.iter().map(Calibrated::removed).sum();
    let min_share = if prep.kind == DataKind::ArmMoves {
        ARM_CALIBRATION_MIN_SHARE
    } else {
        CALIBRATION_MIN_SHARE
    };
    if !(excess > 0.0 && removed >= min_share * excess) {
        return None;
    }
    let best = per
        .iter()
        .max_by(|a, b| a.removed().total_cmp(&b.removed()))?;
    let unit = super::compare::unit_of(&best.name);
    let listed: Vec<String> = per
        .iter()
        .filter(|p| p.removed() >= 0.01 * removed)
        .map(|p| {
            format!(
                "{}: g {:.4}, c {}, {:.0}%",
                p.name,
                p.g,
                quantity(p.c, super::compare::unit_of(&p.name)),
                100.0 * p.removed() / excess
            )
        })
        .collect();
    Some(Signature {
        kind: SignatureKind::Calibration,
        evidence: format!(
            "the residual of {} follows that channel itself (correlation {:.2} with the model's channel)",
            best.name, best.corr
        ),
        term: format!(
            "a calibration of every measured channel, measured = g model + c (per channel, common to the runs); the gain error of {}, g - 1",
            best.name
        ),
        note: format!(
            "a sensor's gain or zero, or a radius ratio; of the excess over every channel, by channel: {}",
            listed.join("; ")
        ),
        size: best.g - 1.0,
        unit: "1",
        equivalent: Some(Equivalent {
            what: "its offset c",
            value: best.c,
            unit,
        }),
        share_removed: removed / excess,
        removed_over_floor: removed / prep.floor_ssr().max(f64::MIN_POSITIVE),
    })
}

/// A channel's calibration ([`calibration`], [`regressed`]): `measured = g model + c`.
struct Calibrated {
    name: String,
    /// The channel's weighted SSR before and after the calibration.
    before: f64,
    after: f64,
    g: f64,
    c: f64,
    /// The correlation of the residual with the model's channel.
    corr: f64,
}

impl Calibrated {
    /// What the calibration removes of the channel's weighted SSR.
    fn removed(&self) -> f64 {
        self.before - self.after
    }
}

/// The calibration of the channel `name` by the linear least squares `measured = g
/// model + c` over `samples`' slices (model, measured, the analysed indices, the weight
/// squared); `None` with fewer than 3 samples.
fn regressed<'s, I>(name: &str, samples: impl Fn() -> I) -> Option<Calibrated>
where
    I: Iterator<Item = (&'s [f64], &'s [f64], &'s [usize], f64)>,
{
    let (mut n, mut sy, mut sm) = (0.0, 0.0, 0.0);
    for (y, m, idx, _) in samples() {
        for &i in idx {
            n += 1.0;
            sy += y[i];
            sm += m[i];
        }
    }
    if n < 3.0 {
        return None;
    }
    let (ym, mm) = (sy / n, sm / n);
    let (mut syy, mut sym, mut see, mut sey) = (0.0, 0.0, 0.0, 0.0);
    for (y, m, idx, _) in samples() {
        for &i in idx {
            let (dy, dm) = (y[i] - ym, m[i] - mm);
            syy += dy * dy;
            sym += dy * dm;
            let de = y[i] - m[i] - (ym - mm);
            see += de * de;
            sey += de * dy;
        }
    }
    let g = if syy > 0.0 { sym / syy } else { 1.0 };
    let c = mm - g * ym;
    // (weighted as the fits weigh the channel in each run)
    let (mut before, mut after) = (0.0, 0.0);
    for (y, m, idx, w2) in samples() {
        for &i in idx {
            before += w2 * (y[i] - m[i]).powi(2);
            after += w2 * (g * y[i] + c - m[i]).powi(2);
        }
    }
    let corr = if see > 0.0 && syy > 0.0 {
        sey / (see * syy).sqrt()
    } else {
        0.0
    };
    Some(Calibrated {
        name: name.to_string(),
        before,
        after: after.min(before),
        g,
        c,
        corr,
    })
}

/// [`calibration`]'s channels on an arm: every sensor of the stacked channel
/// ([`crate::plant::stack`]: each sensor's values minus their mean over their noise,
/// one slice per sensor), by its name over the runs, in the sensor's unit (the model's
/// slice times its noise plus its mean, against the sensor's own values, weighted by
/// the noise's inverse square: the stacked SSR). In the sensor's unit a gain reads on the level as well as on the
/// motion; in the stacked units each run's own mean would leave it to the motion
/// alone (j2's load cells 5% high on `example_arm_control`: g 1.003 and c 42 N there).
fn arm_sensors(b: &Base<'_, '_>, am: &crate::dataset::ArmMovesDataset) -> Vec<Calibrated> {
    let (prep, sims) = (b.prep, b.sims);
    let mut names: Vec<&str> = Vec::new();
    for run in &am.runs {
        for c in &run.channels {
            if !names.contains(&c.name.as_str()) {
                names.push(&c.name);
            }
        }
    }
    // each run's sensors: (name, model, measured, analysed indices, weight^2), in the
    // sensor's unit
    type Slice<'n> = (&'n str, Vec<f64>, &'n [f64], Vec<usize>, f64);
    let slices: Vec<Slice<'_>> = am
        .runs
        .iter()
        .zip(&prep.runs)
        .zip(sims)
        .flat_map(|((ar, run), y)| {
            let n = ar.time_s.len();
            let stacking = crate::plant::stacking(ar);
            let w2 = run.weight(0).powi(2);
            ar.channels
                .iter()
                .enumerate()
                .filter(move |(k, c)| {
                    y.len() >= (k + 1) * n
                        && run.measured.len() >= (k + 1) * n
                        && c.values.len() >= n
                })
                .map(move |(k, c)| {
                    let (mean, sigma) = stacking[k];
                    let model = y[k * n..(k + 1) * n]
                        .iter()
                        .map(|x| x * sigma + mean)
                        .collect();
                    let idx = run
                        .idx
                        .iter()
                        .filter(|&&i| i >= k * n && i < (k + 1) * n)
                        .map(|&i| i - k * n)
                        .collect();
                    (
                        c.name.as_str(),
                        model,
                        &c.values[..],
                        idx,
                        w2 / (sigma * sigma),
                    )
                })
        })
        .collect();
    names
        .iter()
        .filter_map(|&name| {
            let samples = || {
                slices
                    .iter()
                    .filter(move |s| s.0 == name)
                    .map(|s| (&s.1[..], s.2, &s.3[..], s.4))
            };
            regressed(name, samples)
        })
        .collect()
}

/// Least share of the excess error a periodic component must remove to be reported.
const PERIODIC_MIN_SHARE: f64 = 0.2;

/// Frequencies tried for a periodic component, log-spaced from two cycles over the
/// longest run to a fifth of the sampling rate.
const PERIODIC_GRID: usize = 600;

/// A periodic component of the residual at a frequency the test does not drive: the
/// frequency where the residual's power (a periodogram over the analysed samples of
/// every run, decimated to at most 4000 samples per run) is largest, away from a
/// sweep's test frequencies and their 2nd and 3rd harmonics (within 10%); the term is a
/// sinusoid there with each run's own amplitude and phase (linear least squares), its
/// size the RMS-weighted amplitude over the runs. Returns the term and the frequency.
fn periodic(b: &Base<'_, '_>) -> Option<(Term, f64)> {
    let prep = b.prep;
    let res: Vec<Vec<(f64, f64)>> = prep
        .runs
        .iter()
        .zip(b.sims)
        .map(|(run, y)| {
            let step = run.idx.len().div_ceil(4000).max(1);
            run.idx
                .iter()
                .step_by(step)
                .map(|&i| (run.time_s[i], y[i] - run.measured[i]))
                .collect()
        })
        .collect();
    let span = prep
        .runs
        .iter()
        .filter_map(|r| Some(r.time_s[*r.idx.last()?] - r.time_s[*r.idx.first()?]))
        .fold(0.0f64, f64::max);
    let dt = prep
        .runs
        .iter()
        .map(|r| r.dt_s)
        .fold(f64::INFINITY, f64::min);
    if !(span > 0.0 && dt.is_finite() && dt > 0.0) {
        return None;
    }
    let (f_lo, f_hi) = (2.0 / span, 0.2 / dt);
    if f_hi <= f_lo {
        return None;
    }
    let driven = |f: f64| {
        prep.runs.iter().any(|r| {
            r.segments
                .iter()
                .any(|s| (1..=3).any(|h| (f / (h as f64 * s.0) - 1.0).abs() < 0.1))
        })
    };
    let power = |f: f64| -> f64 {
        let w = TAU * f;
        res.iter()
            .map(|e| {
                let n = e.len().max(1) as f64;
                let mean = e.iter().map(|x| x.1).sum::<f64>() / n;
                let (c, s) = e.iter().fold((0.0, 0.0), |(c, s), &(t, x)| {
                    let (sn, cs) = (w * t).sin_cos();
                    (c + (x - mean) * cs, s + (x - mean) * sn)
                });
                (c * c + s * s) / n
            })
            .sum()
    };
    let grid: Vec<f64> = (0..PERIODIC_GRID)
        .map(|k| f_lo * (f_hi / f_lo).powf(k as f64 / (PERIODIC_GRID - 1) as f64))
        .filter(|&f| !driven(f))
        .collect();
    let powers: Vec<f64> = grid.par_iter().map(|&f| power(f)).collect();
    let k = (0..grid.len()).max_by(|&a, &c| powers[a].total_cmp(&powers[c]))?;
    // Power that keeps rising towards two cycles over the longest run is a trend, not a
    // periodic component (the drift signature reports it): a two-strain relaxation whose
    // creep grows with tension was told "a sinusoid of period 268 s would remove 83% of
    // the excess error" on runs of 550 s.
    if grid[k] <= grid[0] {
        return None;
    }
    // golden-section refinement between the neighbouring grid points
    let f = longreach_drive::golden_section_max(
        power,
        grid[k.saturating_sub(1)],
        grid[(k + 1).min(grid.len() - 1)],
        30,
        0.0,
    );
    let w = TAU * f;
    // each run: offset, cos and sin by least squares (3x3 normal equations)
    let mut ssr_after = 0.0;
    let (mut amp2, mut n_all) = (0.0, 0.0);
    for (run, y) in prep.runs.iter().zip(b.sims) {
        let mut ata = [[0.0f64; 3]; 3];
        let mut atb = [0.0f64; 3];
        for &i in &run.idx {
            let (sn, cs) = (w * run.time_s[i]).sin_cos();
            let row = [1.0, cs, sn];
            let e = y[i] - run.measured[i];
            for p in 0..3 {
                atb[p] += row[p] * e;
                for q in 0..3 {
                    ata[p][q] += row[p] * row[q];
                }
            }
        }
        let m = solve3(ata, atb)?;
        amp2 += (m[1] * m[1] + m[2] * m[2]) * run.idx.len() as f64;
        n_all += run.idx.len() as f64;
        ssr_after += run
            .idx
            .iter()
            .map(|&i| {
                let (sn, cs) = (w * run.time_s[i]).sin_cos();
                (y[i] - run.measured[i] - m[0] - m[1] * cs - m[2] * sn).powi(2)
            })
            .sum::<f64>();
    }
    let amplitude = (amp2 / n_all.max(1.0)).sqrt();
    let unit = if prep.kind == DataKind::SineSweep {
        "rad"
    } else {
        "N"
    };
    Some((
        Term {
            term: "a sinusoid at that frequency (each run its amplitude and phase), amplitude"
                .into(),
            note:
                "a disturbance or a mode the model lacks: look for what oscillates at this period"
                    .into(),
            size: amplitude,
            unit,
            equivalent: Some(Equivalent {
                what: "its frequency",
                value: f,
                unit: "Hz",
            }),
            ssr_after,
        },
        f,
    ))
}

/// Solves the 3x3 system `a x = b` by Cramer's rule (`None` when singular).
fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    if !d.is_finite() || d.abs() < 1e-300 {
        return None;
    }
    let mut x = [0.0; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut m = a;
        for r in 0..3 {
            m[r][k] = b[r];
        }
        *xk = det(m) / d;
    }
    Some(x)
}

/// A stiffness per run: `k1` scaled per run (fitted on the analytic response, then on
/// the simulation); size: the slope of `ln k1` against the mean tension
/// (`nonlinear_stiffness`'s `b` to first order: its tangent is `k1 (1 + b f)`).
fn tension_stiffness(b: &Base<'_, '_>, cmp: &Comparison) -> Result<Term, IdentError> {
    let runs = &b.prep.runs;
    let term = SweepTerm {
        specs: per_run_specs(runs.len(), "k1_per_run", "1", 1.0, (0.3, 3.0)),
        neutral: vec![1.0; runs.len()],
        start: None,
        refit_base: false,
        on_plant: &|x, r, p| p.law.k1_n *= x[r],
        sensor: None,
    };
    let (scales, ssr_after) = fit_sweep_term(b, cmp, &term)?;
    let pts: Vec<(f64, f64)> = runs
        .iter()
        .zip(&scales)
        .map(|(r, s)| (r.mean_tension_n.unwrap_or(0.0), s.ln()))
        .collect();
    Ok(Term {
        term: "a stiffness per run, k1 rising with the mean tension by d ln k1 / dT".into(),
        note: per_run_note(b, "k1 per run", &scales, |r, s| {
            format!("x{s:.3} at {:.0} N", r.mean_tension_n.unwrap_or(0.0))
        }),
        size: slope(&pts),
        unit: "1/N",
        equivalent: None,
        ssr_after,
    })
}

/// `"{what}: v0, v1, ..."`, each run's value written by `one`.
fn per_run_note(
    b: &Base<'_, '_>,
    what: &str,
    values: &[f64],
    one: impl Fn(&RunData, f64) -> String,
) -> String {
    let listed: Vec<String> = b
        .prep
        .runs
        .iter()
        .zip(values)
        .map(|(r, &v)| one(r, v))
        .collect();
    format!("{what}: {}", listed.join(", "))
}

/// One fitted parameter per run, on a log scale.
fn per_run_specs(
    n: usize,
    name: &str,
    unit: &str,
    initial: f64,
    (lower, upper): (f64, f64),
) -> Vec<ParamSpec> {
    (0..n)
        .map(|r| ParamSpec {
            name: format!("{name}[{r}]"),
            unit: unit.into(),
            initial,
            lower,
            upper,
            log_scale: true,
        })
        .collect()
}

/// Least-squares slope of `y` on `x` (0 without spread in `x`).
fn slope(pts: &[(f64, f64)]) -> f64 {
    let n = pts.len().max(1) as f64;
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    if sxx > 0.0 {
        sxy / sxx
    } else {
        0.0
    }
}

/// The output's viscous damping off by `dc` (a rig constant misstated, or, the ropes'
/// stiffness scaled alike, its inertia): the rig's `C + dc` in the plant, fitted with
/// the baseline's free parameters from `C + dc0` (the small-signal estimate of
/// [`second_mode`]), on the analytic response, then on the simulation.
fn output_damping(b: &Base<'_, '_>, cmp: &Comparison, dc0: f64) -> Result<Term, IdentError> {
    let c0 = rig_of(b, &b.params(0)?).map_or(0.05, |x| x.4).max(1e-4);
    let term = SweepTerm {
        specs: vec![ParamSpec {
            name: "output_damping".into(),
            unit: "N*m*s".into(),
            initial: crate::fitting::strictly_inside(c0 + dc0, 1e-4 * c0, 1e3 * c0),
            lower: 1e-4 * c0,
            upper: 1e3 * c0,
            log_scale: true,
        }],
        neutral: vec![c0],
        start: Some(vec![c0 + dc0]),
        refit_base: true,
        on_plant: &|x, _, p| p.output_damping_n_m_s = Some(x[0]),
        sensor: None,
    };
    let (c, ssr_after) = fit_sweep_term(b, cmp, &term)?;
    let dc = c[0] - c0;
    Ok(Term {
        term: "the output's viscous damping off by dc".into(),
        note: format!(
            "C = {} against the rig's {}, the model's own values refitted with it",
            quantity(c[0], "N*m*s"),
            quantity(c0, "N*m*s")
        ),
        size: dc,
        unit: "N*m*s",
        equivalent: Some(Equivalent {
            what: "or, the ropes' stiffness scaled alike, the output's inertia times C / (C + dc)",
            value: c0 / c[0],
            unit: "1",
        }),
        ssr_after,
    })
}

/// Amplitude-dependent damping: an output damping per run, fitted with the baseline's
/// free parameters (on the analytic response, then on the simulation); size: the dry
/// torque `F` that the describing function gives, `C_r = C_v + 4 F / (pi V_r)` by least
/// squares over the runs, `V_r` the largest measured output velocity amplitude of run
/// `r` (at its resonance, where the damping acts).
fn amplitude_damping(b: &Base<'_, '_>, cmp: &Comparison) -> Result<Term, IdentError> {
    let prep = b.prep;
    let c0 = rig_of(b, &b.params(0)?).map_or(0.05, |x| x.4).max(1e-4);
    let term = SweepTerm {
        specs: per_run_specs(
            prep.runs.len(),
            "damping_per_run",
            "N*m*s",
            c0,
            (0.2 * c0, 50.0 * c0),
        ),
        neutral: vec![c0; prep.runs.len()],
        start: None,
        refit_base: true,
        on_plant: &|x, r, p| p.output_damping_n_m_s = Some(x[r]),
        sensor: None,
    };
    let (damping, ssr_after) = fit_sweep_term(b, cmp, &term)?;
    let pts: Vec<(f64, f64)> = prep
        .runs
        .iter()
        .zip(&damping)
        .filter_map(|(run, &c)| {
            let v = run
                .segments
                .iter()
                .map(|&(f, a, e)| TAU * f * dft(&run.measured[a..e], run.dt_s, f).norm())
                .fold(0.0, f64::max);
            (v > 0.0).then_some((4.0 / (PI * v), c))
        })
        .collect();
    Ok(Term {
        term: "amplitude-dependent damping, a damping per run read as dry friction by the describing function C = C_v + 4 F / (pi V), F".into(),
        note: per_run_note(b, "output damping per run, N*m*s", &damping, |r, c| {
            format!("{c:.4} in {}", r.name)
        }),
        size: slope(&pts),
        unit: "N*m",
        equivalent: None,
        ssr_after,
    })
}

//! A model compared with an arm dataset (`arm_moves`): every measured channel of every
//! run, its NRMSE and its noise floor, where the error concentrates (run x channel x
//! time window, move phase against settling phase), and per move the vibration
//! figures of the measurement against the model's.
//!
//! Noise floors, per channel (the standard deviation of the error a perfect model would
//! leave, on the NRMSE scale of the channel):
//!
//! - encoder channels (`motor_J_rad`, `joint_J_rad`): the RMS of the encoder's
//!   quantisation error on the model's own signal, `rms(quantise(model) - model)` at
//!   [`crate::dataset::ARM_ENCODER_RESOLUTION_RAD`] (about `q / sqrt(12)` for a signal
//!   that moves over many counts; exact for a perfect model);
//! - tensions, tip positions and accelerations: the measured channel's noise from its
//!   second differences ([`super::noise_sigma_second_difference`]).
//!
//! Vibration figures of a move (each joint whose command changes in the run), from the
//! joint angle when the run measured it, else from the motor angle:
//!
//! - 2% settling time: from the start of the commanded move until the angle stays
//!   within 2% of the move of the final command;
//! - overshoot: the largest excursion past the final command, % of the move;
//! - residual vibration: in the settling phase (after the command stops moving) the
//!   angle minus its mean over the last fifth of the run, cut into half-cycles by
//!   hysteresis at three noise floors; the frequency from the spacing of the
//!   half-cycles' extremes, the damping ratio from the logarithmic decrement of their
//!   sizes (`zeta = delta / sqrt(4 pi^2 + delta^2)`, `delta` per cycle from a
//!   least-squares line through `ln |a_k|`); `None` with fewer than three half-cycles;
//! - peak and minimum rope tension of the joint's pair (both sides), when measured.

use serde::Serialize;

mod evidence;
pub use evidence::{arm_findings, describe_findings, ArmFinding, FINDINGS_TOLD, OFFSET_COUNTS};

use super::prepare::noise_sigma_second_difference;
use crate::dataset::{
    ArmMovesDataset, ArmQuantity, ArmRun, Dataset, DatasetKind, ARM_ENCODER_RESOLUTION_RAD,
};
use crate::error::IdentError;
use crate::model::Model;
use crate::plant::{ArmPlant, ArmPoses, Channels, Plant};
use crate::sensors::Encoder;

use super::SimulationStep;

/// Length of the windows the error is cut into, s.
pub const ARM_WINDOW_S: f64 = 0.5;

/// The error of one channel of one run.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelError {
    /// Run name.
    pub run: String,
    /// Column name.
    pub channel: String,
    /// Driven joint (`None` for the tip).
    pub joint: Option<String>,
    /// Unit of the channel.
    pub unit: &'static str,
    /// RMS error, in the channel's unit.
    pub rms_error: f64,
    /// Noise standard deviation (the floor), in the channel's unit.
    pub noise_sigma: f64,
    /// NRMSE (RMS error over the measurement's standard deviation).
    pub nrmse: f64,
    /// The floor on the NRMSE scale.
    pub noise_floor_nrmse: f64,
    /// `rms_error / noise_sigma`: 1 at the floor.
    pub ratio: f64,
    /// The same ratio over the move phase (command moving), if the run has one.
    pub ratio_move: Option<f64>,
    /// The same ratio over the settling phase (after the last command change).
    pub ratio_settling: Option<f64>,
}

/// A place where the error concentrates: one window of one channel of one run.
#[derive(Debug, Clone, Serialize)]
pub struct ArmWhere {
    /// Run name.
    pub run: String,
    /// Column name.
    pub channel: String,
    /// `"rest"` (before the move), `"move"` or `"settling"`.
    pub phase: &'static str,
    /// Start of the window, s.
    pub start_s: f64,
    /// End of the window, s.
    pub end_s: f64,
    /// RMS error over the floor in the window.
    pub ratio: f64,
    /// Share of the dataset's floor-normalised squared error.
    pub share: f64,
}

/// The vibration figures of one move of one joint.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct Figures {
    /// 2% settling time from the start of the move, s (`None`: never settles).
    pub settling_time_s: Option<f64>,
    /// Overshoot, % of the move.
    pub overshoot_pct: Option<f64>,
    /// Dominant residual vibration frequency, Hz.
    pub vibration_hz: Option<f64>,
    /// Damping ratio of the residual vibration.
    pub damping_ratio: Option<f64>,
    /// Peak tension of either rope of the joint's pair, N.
    pub peak_tension_n: Option<f64>,
    /// Minimum tension of either rope of the joint's pair, N.
    pub min_tension_n: Option<f64>,
}

/// Measured and model figures of one move.
#[derive(Debug, Clone, Serialize)]
pub struct MoveFigures {
    /// Run name.
    pub run: String,
    /// The moved joint.
    pub joint: String,
    /// The channel the angle figures come from.
    pub channel: String,
    /// Commanded move, rad.
    pub move_rad: f64,
    /// From the measurement.
    pub measured: Figures,
    /// From the model.
    pub model: Figures,
}

/// Everything `compare` reports on an arm dataset.
#[derive(Debug, Clone, Serialize)]
pub struct ArmComparison {
    /// Dataset title.
    pub dataset: String,
    /// Every channel of every run.
    pub channels: Vec<ChannelError>,
    /// The largest `ratio` of any channel.
    pub worst_ratio: f64,
    /// The windows with the largest share of the floor-normalised squared error.
    pub worst_windows: Vec<ArmWhere>,
    /// The figures of every move.
    pub figures: Vec<MoveFigures>,
    /// What the sensors show against the model in the arm's terms, largest first
    /// ([`arm_findings`]).
    pub findings: Vec<ArmFinding>,
    /// The simulation step the model ran at, when it was chosen from the data
    /// ([`super::choose_arm_step`]; `None`: steps of at most [`crate::plant::ARM_MAX_STEP_S`]).
    pub step: Option<SimulationStep>,
}

/// The phases of a run from its commands: first and last sample where any command
/// changes (`None`: the commands never change).
fn move_span(r: &ArmRun) -> Option<(usize, usize)> {
    let n = r.time_s.len();
    let moving = |i: usize| {
        r.command_rad
            .iter()
            .any(|c| (c[i] - c[i - 1]).abs() > 1e-12 * (1.0 + c[i].abs()))
    };
    let first = (1..n).find(|&i| moving(i))?;
    let last = (1..n).rev().find(|&i| moving(i))?;
    Some((first - 1, last))
}

fn rms(x: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = x.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    if n == 0 {
        0.0
    } else {
        (s / n as f64).sqrt()
    }
}

fn std_dev(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let m = x.iter().sum::<f64>() / x.len() as f64;
    rms(x.iter().map(|v| v - m))
}

/// The noise standard deviation of a channel (see the module docs).
fn noise_sigma(q: ArmQuantity, measured: &[f64], model: &[f64]) -> f64 {
    match q {
        ArmQuantity::Motor | ArmQuantity::Joint => match Encoder::new(ARM_ENCODER_RESOLUTION_RAD) {
            Ok(e) => rms(model.iter().map(|&m| e.quantise(m) - m)),
            Err(_) => ARM_ENCODER_RESOLUTION_RAD / 12f64.sqrt(),
        }
        .max(ARM_ENCODER_RESOLUTION_RAD * 1e-3),
        _ => noise_sigma_second_difference(measured).max(1e-12),
    }
}

/// The angle figures of a move of size `move_rad` starting at sample `start` toward
/// `target`, settling after sample `end` (the last command change), on signal `x`
/// sampled at `time_s`; `floor` is the channel's noise.
fn angle_figures(
    time_s: &[f64],
    x: &[f64],
    start: usize,
    end: usize,
    target: f64,
    move_rad: f64,
    floor: f64,
) -> Figures {
    let n = x.len();
    let band = 0.02 * move_rad.abs();
    let settled_from = (start..n)
        .rev()
        .find(|&i| (x[i] - target).abs() > band)
        .map_or(start, |i| i + 1);
    let settling_time_s =
        (settled_from < n).then(|| time_s[settled_from.max(start)] - time_s[start]);
    let sign = move_rad.signum();
    let over = x[start..]
        .iter()
        .map(|v| sign * (v - target))
        .fold(0.0_f64, f64::max);
    let overshoot_pct = (move_rad.abs() > 0.0).then(|| 100.0 * over / move_rad.abs());
    let (vibration_hz, damping_ratio) = residual_vibration(&time_s[end..], &x[end..], floor);
    Figures {
        settling_time_s,
        overshoot_pct,
        vibration_hz,
        damping_ratio,
        peak_tension_n: None,
        min_tension_n: None,
    }
}

/// Frequency and damping ratio of the residual oscillation of `x` (see the module
/// docs).
pub fn residual_vibration(time_s: &[f64], x: &[f64], floor: f64) -> (Option<f64>, Option<f64>) {
    let n = x.len();
    if n < 8 {
        return (None, None);
    }
    let tail = &x[n - n / 5..];
    let base = tail.iter().sum::<f64>() / tail.len() as f64;
    let r: Vec<f64> = x.iter().map(|v| v - base).collect();
    let thr = 3.0 * floor;
    // Half-cycles: lobes beyond +thr or -thr, alternating.
    let mut lobes: Vec<(f64, f64)> = Vec::new(); // (time of extreme, |extreme|)
    let mut sign = 0i8;
    let mut best = (0usize, 0.0f64);
    for (i, &v) in r.iter().enumerate() {
        let s: i8 = if v > thr {
            1
        } else if v < -thr {
            -1
        } else {
            0
        };
        if s != 0 && s != sign {
            if sign != 0 {
                lobes.push(extreme_at(time_s, &r, best.0));
            }
            sign = s;
            best = (i, v.abs());
        } else if s == sign && sign != 0 && v.abs() > best.1 {
            best = (i, v.abs());
        }
    }
    // The last lobe only counts if the signal left it (a complete half-cycle).
    if lobes.len() < 3 {
        return (None, None);
    }
    let k = lobes.len();
    let half_period = (lobes[k - 1].0 - lobes[0].0) / (k - 1) as f64;
    let hz = (half_period > 0.0).then(|| 0.5 / half_period);
    // ln|a| against the half-cycle index: slope per half-cycle.
    let xs: Vec<f64> = (0..k).map(|i| i as f64).collect();
    let ys: Vec<f64> = lobes.iter().map(|l| l.1.ln()).collect();
    let mx = xs.iter().sum::<f64>() / k as f64;
    let my = ys.iter().sum::<f64>() / k as f64;
    let sxy: f64 = xs.iter().zip(&ys).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = xs.iter().map(|a| (a - mx).powi(2)).sum();
    let delta = -2.0 * sxy / sxx;
    let zeta = delta / (4.0 * std::f64::consts::PI.powi(2) + delta * delta).sqrt();
    (hz, Some(zeta))
}

/// Time and size of the extreme at sample `i`, refined by a parabola through its
/// neighbours.
fn extreme_at(time_s: &[f64], r: &[f64], i: usize) -> (f64, f64) {
    if i == 0 || i + 1 >= r.len() {
        return (time_s[i], r[i].abs());
    }
    let (a, b, c) = (r[i - 1], r[i], r[i + 1]);
    let den = a - 2.0 * b + c;
    if den.abs() < 1e-300 {
        return (time_s[i], b.abs());
    }
    let p = (0.5 * (a - c) / den).clamp(-0.5, 0.5);
    let dt = time_s[i + 1] - time_s[i];
    (time_s[i] + p * dt, (b - 0.25 * (a - c) * p).abs())
}

/// The simulated channels of every run of `ds` with `model` (in parallel, run order),
/// every step of at most [`crate::plant::ARM_MAX_STEP_S`] divided into `refinement`
/// ([`super::choose_arm_step`]).
pub fn simulate_arm(
    ds: &Dataset,
    model: &Model,
    refinement: usize,
) -> Result<Vec<Channels>, IdentError> {
    per_run(ds, model, refinement, |plant, params, r| {
        plant.simulate(params, r)
    })
}

/// [`simulate_arm`], and the model arm of every run with its coordinates at every
/// sample (to draw it).
pub fn simulate_arm_poses(
    ds: &Dataset,
    model: &Model,
    refinement: usize,
) -> Result<Vec<(Channels, ArmPoses)>, IdentError> {
    per_run(ds, model, refinement, |plant, params, r| {
        plant.simulate_with_poses(params, r)
    })
}

/// `f` on every run of the arm dataset `ds` with `model`'s numbers for that run (in
/// parallel, results in run order).
fn per_run<T: Send>(
    ds: &Dataset,
    model: &Model,
    refinement: usize,
    f: impl Fn(&ArmPlant, &crate::model::PlantParams, usize) -> Result<T, IdentError> + Sync,
) -> Result<Vec<T>, IdentError> {
    use rayon::prelude::*;
    let DatasetKind::ArmMoves(am) = &ds.kind else {
        return Err(IdentError::NotAnArm {
            kind: ds.kind.name(),
        });
    };
    let plant = ArmPlant::with_refinement(am, refinement);
    (0..am.runs.len())
        .into_par_iter()
        .map(|r| f(&plant, &model.plant_params(r)?, r))
        .collect()
}

/// Compares the simulated channels `sims` (from [`simulate_arm`]) with the arm dataset
/// `ds`.
pub fn compare_arm(ds: &Dataset, sims: &[Channels]) -> Result<ArmComparison, IdentError> {
    let DatasetKind::ArmMoves(am) = &ds.kind else {
        return Err(IdentError::NotAnArm {
            kind: ds.kind.name(),
        });
    };
    let mut channels = Vec::new();
    let mut windows: Vec<ArmWhere> = Vec::new();
    let mut figures = Vec::new();
    for (r, sim) in am.runs.iter().zip(sims) {
        let span = move_span(r);
        let phase_of = |i: usize| match span {
            Some((a, _)) if i < a => "rest",
            Some((_, b)) if i <= b => "move",
            Some(_) => "settling",
            None => "rest",
        };
        let mut sigma_of = Vec::new();
        for c in &r.channels {
            let model = sim.get(&c.name).unwrap_or(&[]);
            if model.len() != c.values.len() {
                return Err(IdentError::ArmBuild {
                    run: r.name.clone(),
                    message: format!("the model gave no channel {}", c.name),
                });
            }
            let err: Vec<f64> = model.iter().zip(&c.values).map(|(m, x)| m - x).collect();
            let sigma = noise_sigma(c.quantity, &c.values, model);
            sigma_of.push(sigma);
            let sd = std_dev(&c.values).max(1e-300);
            let rms_error = rms(err.iter().copied());
            let phase_ratio =
                |lo: usize, hi: usize| (hi > lo).then(|| rms(err[lo..hi].iter().copied()) / sigma);
            let (ratio_move, ratio_settling) = match span {
                Some((a, b)) => (phase_ratio(a, b + 1), phase_ratio(b + 1, err.len())),
                None => (None, None),
            };
            channels.push(ChannelError {
                run: r.name.clone(),
                channel: c.name.clone(),
                joint: c.joint.map(|j| am.joints[j].clone()),
                unit: c.quantity.unit(),
                rms_error,
                noise_sigma: sigma,
                nrmse: rms_error / sd,
                noise_floor_nrmse: sigma / sd,
                ratio: rms_error / sigma,
                ratio_move,
                ratio_settling,
            });
            // Windows of this channel.
            let w = ((ARM_WINDOW_S / r.dt_s()).round() as usize).max(1);
            let mut i = 0;
            while i < err.len() {
                let j = (i + w).min(err.len());
                let ss: f64 = err[i..j].iter().map(|e| (e / sigma).powi(2)).sum();
                windows.push(ArmWhere {
                    run: r.name.clone(),
                    channel: c.name.clone(),
                    phase: phase_of((i + j) / 2),
                    start_s: r.time_s[i],
                    end_s: r.time_s[j - 1],
                    ratio: (ss / (j - i) as f64).sqrt(),
                    share: ss,
                });
                i = j;
            }
        }
        if let Some((a, b)) = span {
            for (k, joint) in am.joints.iter().enumerate() {
                let cmd = &r.command_rad[k];
                let move_rad = cmd[cmd.len() - 1] - cmd[a];
                if move_rad.abs() < 1e-9 {
                    continue;
                }
                let Some(ci) = r.angle_channel(k) else {
                    continue;
                };
                let c = &r.channels[ci];
                let model = sim.get(&c.name).unwrap_or(&[]);
                // A motor angle follows the joint through the transmission ratio.
                let (target, mv) = if c.quantity == ArmQuantity::Joint {
                    (cmd[cmd.len() - 1], move_rad)
                } else {
                    let m = &c.values;
                    (m[m.len() - 1], m[m.len() - 1] - m[a])
                };
                let mut fm = angle_figures(&r.time_s, &c.values, a, b, target, mv, sigma_of[ci]);
                let mut fs = angle_figures(&r.time_s, model, a, b, target, mv, sigma_of[ci]);
                for (f, src) in [(&mut fm, None), (&mut fs, Some(sim))] {
                    let tens: Vec<&[f64]> = r
                        .channels
                        .iter()
                        .filter(|c| {
                            c.joint == Some(k)
                                && matches!(
                                    c.quantity,
                                    ArmQuantity::Tension1 | ArmQuantity::Tension2
                                )
                        })
                        .filter_map(|c| match src {
                            None => Some(c.values.as_slice()),
                            Some(s) => s.get(&c.name),
                        })
                        .collect();
                    if !tens.is_empty() {
                        f.peak_tension_n = Some(
                            tens.iter()
                                .flat_map(|t| t.iter())
                                .copied()
                                .fold(f64::MIN, f64::max),
                        );
                        f.min_tension_n = Some(
                            tens.iter()
                                .flat_map(|t| t.iter())
                                .copied()
                                .fold(f64::MAX, f64::min),
                        );
                    }
                }
                figures.push(MoveFigures {
                    run: r.name.clone(),
                    joint: joint.clone(),
                    channel: c.name.clone(),
                    move_rad,
                    measured: fm,
                    model: fs,
                });
            }
        }
    }
    let total: f64 = windows.iter().map(|w| w.share).sum();
    if total > 0.0 {
        for w in &mut windows {
            w.share /= total;
        }
    }
    windows.sort_by(|a, b| b.share.total_cmp(&a.share));
    windows.truncate(8);
    let worst_ratio = channels.iter().map(|c| c.ratio).fold(0.0, f64::max);
    let mut c = ArmComparison {
        dataset: ds.title.clone(),
        channels,
        worst_ratio,
        worst_windows: windows,
        figures,
        findings: Vec::new(),
        step: None,
    };
    c.findings = evidence::arm_findings(am, &c, sims);
    Ok(c)
}

/// The arm dataset of `ds`, if it is one.
pub fn arm_dataset(ds: &Dataset) -> Option<&ArmMovesDataset> {
    match &ds.kind {
        DatasetKind::ArmMoves(a) => Some(a),
        _ => None,
    }
}

//! Synthetic datasets in the measurement format (stepped-sine sweeps, relaxation and
//! cyclic tests, arm moves) from any model, with any effects hidden and realistic
//! sensors (0.18 deg encoders on the rig, 1e-4 rad on the arm, Gaussian tension and
//! tip noise), seeded.

use longreach_drive::{InputSignal, SteppedSine};

use crate::dataset::{
    CyclicDataset, CyclicRun, CyclicSpecimen, Frf, RelaxationDataset, RelaxationRun,
    RelaxationSpecimen, RigSpec, SweepDataset, SweepRun, Tensioner,
};
use crate::error::IdentError;
use crate::model::Model;
use crate::plant::{apply_sensors, Channel, Channels};
use crate::sensors::{Encoder, GaussianNoise};
use crate::sim;

/// Options of a synthetic stepped-sine dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepOptions {
    /// The rig (`rope` is the catalog name written into `dataset.toml`).
    pub rig: RigSpec,
    /// One run per `(mean tension [N], amplitude [rad])`.
    pub runs: Vec<(f64, f64)>,
    /// Test frequencies [Hz].
    pub frequencies_hz: Vec<f64>,
    /// Settle time per step [s].
    pub settle_s: f64,
    /// Least analysed time per step [s].
    pub min_hold_s: f64,
    /// Sample interval [s].
    pub dt_s: f64,
    /// Simulation sub-steps per sample (finer than the analysis' to act as "truth").
    pub substeps: usize,
    /// Write the four tension channels.
    pub tension_channels: bool,
    /// Tension noise standard deviation [N].
    pub tension_noise_n: f64,
    /// Seed of the noise.
    pub seed: u64,
}

impl SweepOptions {
    /// The paper's rig and the example datasets' schedule: 49, 147, 294, 392 N at
    /// 4.5 deg, 17 frequencies 0.1-6 Hz, 3 s settle, 200 Hz, 0.8 N tension noise.
    pub fn paper(rope: &str, seed: u64) -> Self {
        Self {
            rig: RigSpec {
                rope: rope.to_string(),
                rope_length_m: 15.2,
                input_radius_m: 0.025,
                output_radius_m: 0.025,
                output_inertia_kg_m2: 0.0284,
                output_damping_n_m_s: 0.05,
                relay_pulleys: 3,
                relay_radius_m: 0.025,
                tensioner: Tensioner::ConstantForce,
            },
            runs: [49.0, 147.0, 294.0, 392.0]
                .iter()
                .map(|&t| (t, 4.5f64.to_radians()))
                .collect(),
            frequencies_hz: vec![
                0.1, 0.2, 0.4, 0.7, 1.0, 1.4, 1.8, 2.1, 2.4, 2.7, 3.0, 3.3, 3.6, 4.0, 4.5, 5.0, 6.0,
            ],
            settle_s: 3.0,
            min_hold_s: 2.0,
            dt_s: 0.005,
            substeps: 5,
            tension_channels: true,
            tension_noise_n: 0.8,
            seed,
        }
    }
}

/// A short synthetic sweep (tests): the baseline `base` (the paper's dyneema2 rig)
/// with `relay_friction` hidden at coefficient 0.02 and inertia 1e-4 kg*m^2, tension
/// channels recorded, `runs` as `(mean tension N, amplitude rad)`, each frequency held
/// `hold_s`.
#[cfg(test)]
pub(crate) fn short_relay_sweep(
    base: &Model,
    seed: u64,
    runs: Vec<(f64, f64)>,
    frequencies_hz: Vec<f64>,
    hold_s: f64,
) -> crate::Dataset {
    let effect = longreach_drive::effects::find("relay_friction").expect("registered");
    let mut truth = base.with_effect(effect);
    truth.effects[0].params[0].value = 0.02;
    truth.effects[0].params[1].value = 1e-4;
    let mut opt = SweepOptions::paper("dyneema2", seed);
    opt.runs = runs;
    opt.frequencies_hz = frequencies_hz;
    opt.settle_s = hold_s;
    opt.min_hold_s = hold_s;
    opt.tension_channels = true;
    crate::Dataset {
        dir: Default::default(),
        title: String::new(),
        kind: crate::DatasetKind::SineSweep(sweep(&truth, &opt).expect("a valid sweep")),
    }
}

/// Simulates `model` (its values for run `r` apply to run `r`) on the options' schedule
/// and writes nothing: returns the dataset (write it with [`SweepDataset::write`]).
pub fn sweep(model: &Model, opt: &SweepOptions) -> Result<SweepDataset, IdentError> {
    let enc = Encoder::rig();
    let mut runs = Vec::new();
    for (r, &(tension, amp)) in opt.runs.iter().enumerate() {
        let sine = SteppedSine {
            amplitude_rad: amp,
            frequencies_hz: opt.frequencies_hz.clone(),
            settle_s: opt.settle_s,
            min_cycles: 2,
            min_hold_s: opt.min_hold_s,
        };
        let signal = InputSignal::stepped_sine(sine.clone()).map_err(IdentError::Drive)?;
        let steps = sine.steps();
        let total = steps.last().map_or(0.0, |s| s.end_s);
        let n = (total / opt.dt_s).floor() as usize;
        let time_s: Vec<f64> = (0..n).map(|i| i as f64 * opt.dt_s).collect();
        let command: Vec<f64> = time_s.iter().map(|&t| signal.angle_rad(t)).collect();
        let mut k = 0;
        let freq: Vec<f64> = time_s
            .iter()
            .map(|&t| {
                while k + 1 < steps.len() && t >= steps[k].end_s - 1e-9 {
                    k += 1;
                }
                steps[k].frequency_hz
            })
            .collect();
        let params = model.plant_params(r)?;
        let mut spec = sim::drive_rig(&opt.rig, params.law.clone(), tension);
        if let Some(c) = params.output_damping_n_m_s {
            spec.output_damping_n_m_s = c;
        }
        let mut s = sim::simulate_sweep(spec, &params.effects, &command, opt.dt_s, opt.substeps)
            .map_err(IdentError::Drive)?;
        // What the sensors report of it (sensor-site effects hidden in the data).
        let mut reported = Channels(vec![Channel {
            name: "output_angle_rad".into(),
            values: std::mem::take(&mut s.output_rad),
        }]);
        apply_sensors(&params, &time_s, &mut reported)?;
        s.output_rad = reported.into_primary();
        let noise = |ch: u64, x: &[f64]| -> Result<Vec<f64>, IdentError> {
            let mut g = GaussianNoise::new(
                opt.tension_noise_n,
                opt.seed.wrapping_mul(1000) + r as u64 * 10 + ch,
            )?;
            Ok(g.noisy(x))
        };
        let (t1, t2, t3, t4) = if opt.tension_channels {
            (
                Some(noise(1, &s.tension_in_1_n)?),
                Some(noise(2, &s.tension_in_2_n)?),
                Some(noise(3, &s.tension_1_n)?),
                Some(noise(4, &s.tension_2_n)?),
            )
        } else {
            (None, None, None, None)
        };
        runs.push(SweepRun {
            name: format!("run_{:02}", r + 1),
            file: format!("run_{:02}.csv", r + 1),
            frf: None::<Frf>,
            mean_tension_n: tension,
            amplitude_rad: amp,
            settle_s: opt.settle_s,
            time_s,
            frequency_hz: freq,
            input_angle_rad: enc.quantise_all(&command),
            command_rad: command,
            output_angle_rad: enc.quantise_all(&s.output_rad),
            tension_in_1_n: t1,
            tension_in_2_n: t2,
            tension_out_1_n: t3,
            tension_out_2_n: t4,
        });
    }
    Ok(SweepDataset {
        rig: opt.rig.clone(),
        runs,
    })
}

/// Options of a synthetic relaxation test.
#[derive(Debug, Clone, PartialEq)]
pub struct RelaxationOptions {
    /// Rope catalog name.
    pub rope: String,
    /// Specimen length [m].
    pub length_m: f64,
    /// Held strain (the specimen's, the first run's).
    pub strain: f64,
    /// Further runs, one per strain held (`[[run]] strain`; empty: one run).
    pub more_strains: Vec<f64>,
    /// Duration [s].
    pub duration_s: f64,
    /// Sample interval [s].
    pub dt_s: f64,
    /// Tension noise [N].
    pub tension_noise_n: f64,
    /// Seed.
    pub seed: u64,
}

impl RelaxationOptions {
    /// The example test: 1.5% strain, 550 s at 10 Hz, 2 N noise.
    pub fn paper(rope: &str, seed: u64) -> Self {
        Self {
            rope: rope.into(),
            length_m: 0.1,
            strain: 0.015,
            more_strains: Vec::new(),
            duration_s: 550.0,
            dt_s: 0.1,
            tension_noise_n: 2.0,
            seed,
        }
    }
}

/// A synthetic relaxation test of `model`.
pub fn relaxation(model: &Model, opt: &RelaxationOptions) -> Result<RelaxationDataset, IdentError> {
    let n = (opt.duration_s / opt.dt_s).round() as usize + 1;
    let time_s: Vec<f64> = (0..n).map(|i| i as f64 * opt.dt_s).collect();
    let mut g = GaussianNoise::new(opt.tension_noise_n, opt.seed)?;
    let (law, _) = model.law_for_run(0)?;
    let runs = std::iter::once(opt.strain)
        .chain(opt.more_strains.iter().copied())
        .enumerate()
        .map(|(i, strain)| {
            if !(strain.is_finite() && strain > 0.0) {
                return Err(IdentError::RelaxationStrain { run: i + 1, strain });
            }
            let f = sim::simulate_relaxation(&law, strain, &time_s).map_err(IdentError::Drive)?;
            let name = if i == 0 {
                "relax".to_string()
            } else {
                format!("relax_{}", i + 1)
            };
            Ok(RelaxationRun {
                file: format!("{name}.csv"),
                name,
                time_s: time_s.clone(),
                tension_n: g.noisy(&f),
                strain: (i > 0).then_some(strain),
            })
        })
        .collect::<Result<Vec<_>, IdentError>>()?;
    Ok(RelaxationDataset {
        specimen: RelaxationSpecimen {
            rope: opt.rope.clone(),
            length_m: opt.length_m,
            strain: opt.strain,
        },
        runs,
    })
}

/// Options of a synthetic cyclic load-strain test (paper Sec. II): the strain rises
/// from 0 to the run's upper strain at a constant rate, then cycles between its lower
/// and upper strains at the same rate.
#[derive(Debug, Clone, PartialEq)]
pub struct CyclicOptions {
    /// Rope catalog name.
    pub rope: String,
    /// Specimen length [m].
    pub length_m: f64,
    /// One run per `(lower strain, upper strain)`.
    pub runs: Vec<(f64, f64)>,
    /// Strain rate of the ramps [1/s].
    pub strain_rate_per_s: f64,
    /// Full cycles after the first loading.
    pub cycles: usize,
    /// Sample interval [s].
    pub dt_s: f64,
    /// Tension noise [N].
    pub tension_noise_n: f64,
    /// Seed.
    pub seed: u64,
}

impl CyclicOptions {
    /// Two runs (0.5-1.0% and 1.0-1.5% strain) at 0.2%/s, 8 cycles, 20 Hz, 2 N noise.
    pub fn paper(rope: &str, seed: u64) -> Self {
        Self {
            rope: rope.into(),
            length_m: 0.1,
            runs: vec![(0.005, 0.010), (0.010, 0.015)],
            strain_rate_per_s: 0.002,
            cycles: 8,
            dt_s: 0.05,
            tension_noise_n: 2.0,
            seed,
        }
    }
}

/// Strain of the cyclic history at time `t`: up from 0 to `hi`, then triangles
/// between `lo` and `hi` at `rate`.
fn cyclic_strain(t: f64, lo: f64, hi: f64, rate: f64) -> f64 {
    let t_up = hi / rate;
    if t <= t_up {
        return rate * t;
    }
    let half = (hi - lo) / rate;
    let u = (t - t_up) % (2.0 * half);
    if u <= half {
        hi - rate * u
    } else {
        lo + rate * (u - half)
    }
}

/// A synthetic cyclic test of `model` (its values for run `r` apply to run `r`).
pub fn cyclic(model: &Model, opt: &CyclicOptions) -> Result<CyclicDataset, IdentError> {
    if !(opt.strain_rate_per_s > 0.0 && opt.dt_s > 0.0) {
        return Err(IdentError::CyclicRates {
            strain_rate_per_s: opt.strain_rate_per_s,
            dt_s: opt.dt_s,
        });
    }
    let mut runs = Vec::new();
    for (r, &(lo, hi)) in opt.runs.iter().enumerate() {
        if !(0.0 <= lo && lo < hi) {
            return Err(IdentError::CyclicStrains {
                run: r + 1,
                lower: lo,
                upper: hi,
            });
        }
        let duration = hi / opt.strain_rate_per_s
            + 2.0 * opt.cycles as f64 * (hi - lo) / opt.strain_rate_per_s;
        let n = (duration / opt.dt_s).round() as usize + 1;
        let time_s: Vec<f64> = (0..n).map(|i| i as f64 * opt.dt_s).collect();
        let strain: Vec<f64> = time_s
            .iter()
            .map(|&t| cyclic_strain(t, lo, hi, opt.strain_rate_per_s))
            .collect();
        let (law, _) = model.law_for_run(r)?;
        let f = sim::simulate_cyclic(&law, &time_s, &strain).map_err(IdentError::Drive)?;
        let mut g =
            GaussianNoise::new(opt.tension_noise_n, opt.seed.wrapping_mul(1000) + r as u64)?;
        runs.push(CyclicRun {
            name: format!("cyclic_{:02}", r + 1),
            file: format!("cyclic_{:02}.csv", r + 1),
            time_s,
            strain,
            tension_n: g.noisy(&f),
        });
    }
    Ok(CyclicDataset {
        specimen: CyclicSpecimen {
            rope: opt.rope.clone(),
            length_m: opt.length_m,
        },
        runs,
    })
}

// ---------------------------------------------------------------------------------------
// Arm moves

/// One synthetic move: a trapezoidal move of one joint (its run holds every other
/// joint).
#[derive(Debug, Clone, PartialEq)]
pub struct ArmMove {
    /// The moved joint (a joint the scenario drives).
    pub joint: String,
    /// The move from the initial angle, rad.
    pub move_rad: f64,
    /// Start of the move, s.
    pub start_s: f64,
    /// Payload of the run (overrides the scenario's), kg.
    pub payload_kg: Option<f64>,
}

/// Options of a synthetic arm dataset (`arm_moves`).
#[derive(Debug, Clone, PartialEq)]
pub struct ArmMovesOptions {
    /// The arm scenario (the `longreach run` format); the dataset carries a copy.
    pub scenario: std::path::PathBuf,
    /// One run per move.
    pub moves: Vec<ArmMove>,
    /// Speed limit of the trapezoidal moves, rad/s.
    pub max_velocity_rad_s: f64,
    /// Acceleration limit, rad/s^2.
    pub max_accel_rad_s2: f64,
    /// Length of each run, s.
    pub duration_s: f64,
    /// Sample rate, Hz.
    pub sample_hz: f64,
    /// Encoder resolution (motor and joint angles), rad.
    pub encoder_resolution_rad: f64,
    /// Write the joint angles.
    pub joint_channels: bool,
    /// Write the rope tensions at the motor pulleys.
    pub tension_channels: bool,
    /// Write the tip position.
    pub tip_channels: bool,
    /// Tension noise standard deviation, N.
    pub tension_noise_n: f64,
    /// Tip position noise standard deviation (a tracker), m.
    pub tip_noise_m: f64,
    /// Seed of the noise.
    pub seed: u64,
}

impl ArmMovesOptions {
    /// The example datasets' sensors and schedule: 50 Hz, 8 s per move starting at
    /// 0.5 s, 0.2 rad/s and 0.5 rad/s^2, 1e-4 rad encoders on motors and joints, 0.5 N
    /// tension noise, 0.2 mm tip noise; no moves yet.
    pub fn new(scenario: impl Into<std::path::PathBuf>, seed: u64) -> Self {
        Self {
            scenario: scenario.into(),
            moves: Vec::new(),
            max_velocity_rad_s: 0.2,
            max_accel_rad_s2: 0.5,
            duration_s: 8.0,
            sample_hz: 50.0,
            encoder_resolution_rad: crate::dataset::ARM_ENCODER_RESOLUTION_RAD,
            joint_channels: true,
            tension_channels: true,
            tip_channels: true,
            tension_noise_n: 0.5,
            tip_noise_m: 2e-4,
            seed,
        }
    }
}

/// `x` rounded to `decimals` decimals, as the nearest double to that decimal (so that
/// it prints short).
fn decimal(x: f64, decimals: i32) -> f64 {
    let s = 10f64.powi(decimals);
    // `+ 0.0` turns a negative zero into 0 (files write "0", not "-0").
    (x * s).round() / s + 0.0
}

/// The dataset the options describe with its commands and every channel it will
/// measure, the channels still zero: the skeleton [`arm_moves`] fills (and the dataset
/// a model file for it is read against).
pub fn arm_plan(opt: &ArmMovesOptions) -> Result<crate::Dataset, IdentError> {
    use crate::dataset::{ArmChannel, ArmMovesDataset, ArmQuantity, ArmRun, DatasetKind};
    let sc = longreach_arm::scenario::load(&opt.scenario).map_err(|e| IdentError::ArmScenario {
        message: e.to_string(),
    })?;
    let arm = &sc.arm;
    let joints: Vec<String> = arm
        .pairs()
        .iter()
        .map(|p| arm.spec().joints[p.spec.joint].name.clone())
        .collect();
    let bad = |what: String| IdentError::ArmScenario { message: what };
    if !(opt.sample_hz.is_finite() && opt.sample_hz > 0.0 && opt.duration_s > 0.0) {
        return Err(bad(format!(
            "sample rate {} Hz and duration {} s must be > 0",
            opt.sample_hz, opt.duration_s
        )));
    }
    if !(opt.max_velocity_rad_s > 0.0 && opt.max_accel_rad_s2 > 0.0) {
        return Err(bad(
            "the move's speed and acceleration limits must be > 0".into()
        ));
    }
    if opt.moves.is_empty() {
        return Err(bad("no moves: give at least one (joint, move)".into()));
    }
    let n = (opt.duration_s * opt.sample_hz).round() as usize + 1;
    let time_s: Vec<f64> = (0..n).map(|i| i as f64 / opt.sample_hz).collect();
    let mut runs = Vec::new();
    for (r, mv) in opt.moves.iter().enumerate() {
        let k = joints.iter().position(|j| *j == mv.joint).ok_or_else(|| {
            bad(format!(
                "move {}: joint `{}` is not driven by the scenario (driven: {})",
                r + 1,
                mv.joint,
                joints.join(", ")
            ))
        })?;
        let command_rad: Vec<Vec<f64>> = arm
            .pairs()
            .iter()
            .enumerate()
            .map(|(p, pair)| {
                let q0 = arm.initial_q_rad()[pair.spec.joint];
                let c = if p == k {
                    longreach_arm::Command::Trapezoid {
                        to_rad: q0 + mv.move_rad,
                        start_s: mv.start_s,
                        max_velocity_rad_s: opt.max_velocity_rad_s,
                        max_accel_rad_s2: opt.max_accel_rad_s2,
                    }
                } else {
                    longreach_arm::Command::Hold
                };
                time_s
                    .iter()
                    .map(|&t| decimal(c.angle_rad(q0, t), 7))
                    .collect()
            })
            .collect();
        let mut channels = Vec::new();
        let mut add = |q: ArmQuantity, joint: Option<usize>| {
            channels.push(ArmChannel {
                name: q.column(joint.map_or("", |j| joints[j].as_str())),
                quantity: q,
                joint,
                values: vec![0.0; n],
            })
        };
        for j in 0..joints.len() {
            add(ArmQuantity::Motor, Some(j));
        }
        for j in 0..joints.len() {
            if opt.joint_channels {
                add(ArmQuantity::Joint, Some(j));
            }
            if opt.tension_channels {
                add(ArmQuantity::Tension1, Some(j));
                add(ArmQuantity::Tension2, Some(j));
            }
        }
        if opt.tip_channels {
            for a in 0..3 {
                add(ArmQuantity::Tip(a), None);
            }
        }
        let file = format!("move_{:02}.csv", r + 1);
        runs.push(ArmRun {
            name: format!("move_{:02}", r + 1),
            file,
            title: Some(format!("{} {:+} rad", mv.joint, mv.move_rad)),
            payload_kg: mv.payload_kg,
            time_s: time_s.clone(),
            command_rad,
            channels,
        });
    }
    let rope = arm
        .pairs()
        .first()
        .map(|p| p.spec.rope_name.clone())
        .unwrap_or_default();
    Ok(crate::Dataset {
        dir: std::path::PathBuf::new(),
        title: String::new(),
        kind: DatasetKind::ArmMoves(ArmMovesDataset {
            scenario: "arm.toml".into(),
            scenario_path: opt.scenario.clone(),
            joints,
            flex_links: sc.flex_link_names(),
            rope,
            runs,
        }),
    })
}

/// Simulates `model` on the moves of `plan` (from [`arm_plan`]), at steps of 1/8 ms
/// ([`crate::plant::SYNTH_ARM_REFINEMENT`]), and reports what the sensors of `opt` would: encoders quantise the motor and joint angles, tensions and
/// the tip get Gaussian noise (seeded, one stream per run and channel). Write the
/// result with [`crate::dataset::ArmMovesDataset::write`].
pub fn arm_moves(
    model: &Model,
    plan: &crate::Dataset,
    opt: &ArmMovesOptions,
) -> Result<crate::dataset::ArmMovesDataset, IdentError> {
    use crate::dataset::{ArmQuantity, DatasetKind};
    use crate::plant::{ArmPlant, Plant};
    let DatasetKind::ArmMoves(am) = &plan.kind else {
        return Err(IdentError::NotAnArm {
            kind: plan.kind.name(),
        });
    };
    let enc = Encoder::new(opt.encoder_resolution_rad)?;
    // The encoder's decimals, for short numbers in the files.
    let enc_decimals = (-opt.encoder_resolution_rad.log10()).ceil() as i32;
    // The truth at the finest step `compare` tries: the data carry (almost) no step
    // error of their own, as a measurement carries none.
    let plant = ArmPlant::with_refinement(am, crate::plant::SYNTH_ARM_REFINEMENT);
    let mut out = am.clone();
    for (r, run) in out.runs.iter_mut().enumerate() {
        let sim = plant.simulate(&model.plant_params(r)?, r)?;
        for (ci, c) in run.channels.iter_mut().enumerate() {
            let truth = sim.get(&c.name).unwrap_or(&[]);
            let seed = opt.seed.wrapping_mul(1_000_003) + (r as u64) * 1000 + ci as u64;
            c.values = match c.quantity {
                ArmQuantity::Motor | ArmQuantity::Joint => truth
                    .iter()
                    .map(|&x| decimal(enc.quantise(x), enc_decimals))
                    .collect(),
                ArmQuantity::Tension1 | ArmQuantity::Tension2 => {
                    GaussianNoise::new(opt.tension_noise_n, seed)?
                        .noisy(truth)
                        .into_iter()
                        .map(|x| decimal(x, 3))
                        .collect()
                }
                ArmQuantity::Tip(_) | ArmQuantity::TipAcc(_) => {
                    GaussianNoise::new(opt.tip_noise_m, seed)?
                        .noisy(truth)
                        .into_iter()
                        .map(|x| decimal(x, 6))
                        .collect()
                }
            };
        }
    }
    Ok(out)
}

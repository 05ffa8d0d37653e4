//! The plants the measurement loop drives: `fit`, `compare` and `diagnose` see a
//! dataset through a [`Plant`], which simulates a run's recorded inputs with a model's
//! numbers ([`PlantParams`]) and returns the channels the run measured. A fit changes
//! numbers; the plant's structure (the rig of the dataset, the specimen) is built once.
//!
//! - [`RigPlant`]: the paper's rig (sine sweeps), driven by the recorded input angle;
//!   channels `output_angle_rad` and, when the run recorded them, the four rope
//!   tensions;
//! - [`SpecimenPlant`]: a rope specimen (relaxation at constant strain, cyclic
//!   load-strain), channel `tension_n`.
//!
//! - [`ArmPlant`] (`arm.rs`): a long-reach arm (`arm_moves`), built once from its
//!   scenario per payload, driven by each run's recorded commands from the static
//!   equilibrium at the first commanded pose; every channel the run measured (motor and
//!   joint angles, rope tensions at the motor, the tip).
//!
//! [`plant_for`] picks the plant of a dataset.

use std::borrow::Cow;

use longreach_drive::effects::{Argument, DataKind};
use longreach_drive::{rig_transfer, RigSpec as DriveRig};
use num_complex::Complex64;

use crate::dataset::{CyclicDataset, Dataset, DatasetKind, RelaxationDataset, SweepDataset};
use crate::error::IdentError;
use crate::model::PlantParams;
use crate::sim;

mod arm;

pub use arm::{
    bends_links, longest_step_s, stack, stacking, substeps_for, ArmPlant, ArmPoses,
    ARM_MAX_REFINEMENT, ARM_MAX_STEP_S, ARM_STACKED, SYNTH_ARM_REFINEMENT,
};

/// One simulated channel of a run, named as the dataset's column.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// Column name (`output_angle_rad`, `tension_in_1_n`, `motor_j1_rad`, ...).
    pub name: Cow<'static, str>,
    /// One value per sample of the run.
    pub values: Vec<f64>,
}

/// The channels of one simulated run, the compared one ([`Self::primary`]) first.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Channels(pub Vec<Channel>);

impl Channels {
    /// The compared channel (output angle of a sweep, tension of a specimen).
    pub fn primary(&self) -> &[f64] {
        self.0.first().map_or(&[], |c| c.values.as_slice())
    }

    /// Takes the compared channel.
    pub fn into_primary(self) -> Vec<f64> {
        self.0
            .into_iter()
            .next()
            .map_or_else(Vec::new, |c| c.values)
    }

    /// The channel called `name`.
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        self.0
            .iter()
            .find(|c| c.name == name)
            .map(|c| c.values.as_slice())
    }
}

/// A plant the loop can drive: built once from a dataset, simulated with a model's
/// numbers on each run's recorded inputs.
pub trait Plant: Send + Sync + std::fmt::Debug {
    /// The kind of data the plant reproduces.
    fn kind(&self) -> DataKind;

    /// Number of runs.
    fn runs(&self) -> usize;

    /// Why `effect`, applicable to the plant's kind of data, has nothing to act on in
    /// this plant (`diagnose` leaves it out of the candidates and says why); `None`:
    /// it has.
    fn excludes(&self, _effect: &dyn longreach_drive::effects::Effect) -> Option<String> {
        None
    }

    /// Simulates run `run` with the numbers `params` (the model's for that run,
    /// [`crate::model::Model::plant_params`]): every channel the run measured, one
    /// value per sample, the compared channel first.
    fn simulate(&self, params: &PlantParams, run: usize) -> Result<Channels, IdentError>;

    /// [`Self::simulate`] (the same channels, to the bit), and the knot opening the
    /// highest segment in which that simulation evaluated a shape-free law's table,
    /// every evaluation counted (a Newton iterate's too,
    /// [`longreach_rope::reached_during`]); `None` when it evaluated none. A table value
    /// whose knot before lies above it leaves the run's simulation the same to the bit,
    /// so a forward difference in that value need not simulate the run again
    /// (`SimCache` in `analysis::fit`). Every table of the model counts: one of another
    /// argument can only raise the bound, never hide a run.
    fn simulate_bounded(
        &self,
        params: &PlantParams,
        run: usize,
    ) -> Result<(Channels, Option<f64>), IdentError> {
        let (channels, reached) = longreach_rope::reached_during(|| self.simulate(params, run));
        Ok((channels?, reached))
    }

    /// The plant's small-signal response (compared channel over input) of run `run`
    /// at `frequency_hz`, when it has a closed form (eqs. 12-13 for the rig): fits use
    /// it to start. `None`: no closed form.
    fn small_signal_response(
        &self,
        _params: &PlantParams,
        _run: usize,
        _frequency_hz: f64,
    ) -> Option<Complex64> {
        None
    }

    /// The values the argument `arg` of an effect's shape ([`longreach_drive::effects::Shape`])
    /// takes over run `run` simulated with `params`: where the data can inform a
    /// shape-free law (its knots are placed over them). `at`: only at these joints (an
    /// arm's effect restricted to some, [`crate::model::EffectUse::at`]; the rig's
    /// plants have one joint and ignore it). Empty when the plant has no such quantity.
    fn argument_samples(
        &self,
        _params: &PlantParams,
        _run: usize,
        _arg: Argument,
        _at: Option<&[String]>,
    ) -> Result<Vec<f64>, IdentError> {
        Ok(Vec::new())
    }
}

/// The plant of a dataset, its sweeps simulated at the sample period over `substeps`
/// (an arm's at [`ARM_MAX_STEP_S`]; [`arm_plant_for`] for finer).
pub fn plant_for(ds: &Dataset, substeps: usize) -> Box<dyn Plant + '_> {
    arm_plant_for(ds, substeps, 1)
}

/// [`plant_for`], an arm's steps of at most [`ARM_MAX_STEP_S`] divided into
/// `arm_refinement` ([`ArmPlant::with_refinement`]).
pub fn arm_plant_for(ds: &Dataset, substeps: usize, arm_refinement: usize) -> Box<dyn Plant + '_> {
    match &ds.kind {
        DatasetKind::SineSweep(sw) => Box::new(RigPlant {
            sweep: sw,
            substeps,
        }),
        DatasetKind::Relaxation(rx) => Box::new(SpecimenPlant::Relaxation(rx)),
        DatasetKind::Cyclic(cy) => Box::new(SpecimenPlant::Cyclic(cy)),
        DatasetKind::ArmMoves(am) => Box::new(ArmPlant::with_refinement(am, arm_refinement)),
    }
}

/// The paper's rig of a sweep dataset ([`crate::sim::simulate_sweep`]).
#[derive(Debug)]
pub struct RigPlant<'a> {
    sweep: &'a SweepDataset,
    substeps: usize,
}

impl RigPlant<'_> {
    fn sweep_sim(&self, params: &PlantParams, run: usize) -> Result<sim::SimSweep, IdentError> {
        let r = &self.sweep.runs[run];
        sim::simulate_sweep(
            self.rig(params, run),
            &params.effects,
            sim::drive_input(r),
            r.dt_s(),
            self.substeps,
        )
        .map_err(|source| IdentError::Simulation {
            run: r.name.clone(),
            source,
        })
    }

    /// The channels the run measured, from the rig's simulation `s` of it.
    fn channels(
        &self,
        params: &PlantParams,
        run: usize,
        s: sim::SimSweep,
    ) -> Result<Channels, IdentError> {
        let r = &self.sweep.runs[run];
        let mut out = vec![Channel {
            name: "output_angle_rad".into(),
            values: s.output_rad,
        }];
        for (name, measured, values) in [
            ("tension_in_1_n", &r.tension_in_1_n, s.tension_in_1_n),
            ("tension_in_2_n", &r.tension_in_2_n, s.tension_in_2_n),
            ("tension_out_1_n", &r.tension_out_1_n, s.tension_1_n),
            ("tension_out_2_n", &r.tension_out_2_n, s.tension_2_n),
        ] {
            if measured.is_some() {
                out.push(Channel {
                    name: name.into(),
                    values,
                });
            }
        }
        let mut channels = Channels(out);
        apply_sensors(params, &r.time_s, &mut channels)?;
        Ok(channels)
    }

    fn rig(&self, params: &PlantParams, run: usize) -> DriveRig {
        let mut spec = sim::drive_rig(
            &self.sweep.rig,
            params.law.clone(),
            self.sweep.runs[run].mean_tension_n,
        );
        if let Some(c) = params.output_damping_n_m_s {
            spec.output_damping_n_m_s = c;
        }
        spec
    }
}

impl Plant for RigPlant<'_> {
    fn kind(&self) -> DataKind {
        DataKind::SineSweep
    }

    fn runs(&self) -> usize {
        self.sweep.runs.len()
    }

    fn simulate(&self, params: &PlantParams, run: usize) -> Result<Channels, IdentError> {
        self.channels(params, run, self.sweep_sim(params, run)?)
    }

    fn small_signal_response(
        &self,
        params: &PlantParams,
        run: usize,
        frequency_hz: f64,
    ) -> Option<Complex64> {
        let mut h = rig_transfer(&self.rig(params, run), frequency_hz);
        // Linear sensors on the output multiply it (a delay: its phase).
        for a in &params.effects {
            if let Ok(Some(sensor)) = a.sensor() {
                if sensor.acts_on("output_angle_rad") {
                    h *= sensor.response(frequency_hz)?;
                }
            }
        }
        Some(h)
    }

    /// Tension: every span's, at every sample; hub load: a relay's two sides (input and
    /// output span of a rope); joint rate: the output shaft's, by central differences.
    fn argument_samples(
        &self,
        params: &PlantParams,
        run: usize,
        arg: Argument,
        _at: Option<&[String]>,
    ) -> Result<Vec<f64>, IdentError> {
        let s = self.sweep_sim(params, run)?;
        Ok(match arg {
            Argument::TensionN => [
                s.tension_in_1_n,
                s.tension_in_2_n,
                s.tension_1_n,
                s.tension_2_n,
            ]
            .concat(),
            Argument::HubLoadN => (s.tension_in_1_n.iter().zip(&s.tension_1_n))
                .chain(s.tension_in_2_n.iter().zip(&s.tension_2_n))
                .map(|(a, b)| a + b)
                .collect(),
            Argument::JointRateRadS => {
                let dt = self.sweep.runs[run].dt_s();
                s.output_rad
                    .windows(3)
                    .map(|w| ((w[2] - w[0]) / (2.0 * dt)).abs())
                    .collect()
            }
        })
    }
}

/// Applies the sensor-site effects of `params` to the channels they act on (what the
/// sensors report of the simulated quantities), sampled at `time_s`.
pub fn apply_sensors(
    params: &PlantParams,
    time_s: &[f64],
    channels: &mut Channels,
) -> Result<(), IdentError> {
    for a in &params.effects {
        let Some(sensor) = a.sensor().map_err(|source| {
            IdentError::Model(crate::model::ModelError::Effect {
                effect: a.effect.name(),
                source,
            })
        })?
        else {
            continue;
        };
        for c in channels.0.iter_mut().filter(|c| sensor.acts_on(&c.name)) {
            sensor.apply(time_s, &mut c.values);
        }
    }
    Ok(())
}

/// A rope specimen: relaxation at constant strain (eq. 6) or a cyclic load-strain test.
#[derive(Debug)]
pub enum SpecimenPlant<'a> {
    /// Tension relaxation ([`crate::sim::simulate_relaxation`]).
    Relaxation(&'a RelaxationDataset),
    /// Cyclic test ([`crate::sim::simulate_cyclic`]).
    Cyclic(&'a CyclicDataset),
}

impl SpecimenPlant<'_> {
    /// The specimen's simulated tension over run `run`.
    fn tension(&self, params: &PlantParams, run: usize) -> Result<Vec<f64>, IdentError> {
        let (name, out) = match self {
            Self::Relaxation(rx) => (
                &rx.runs[run].name,
                sim::simulate_relaxation(&params.law, rx.strain_of(run), &rx.runs[run].time_s),
            ),
            Self::Cyclic(cy) => (
                &cy.runs[run].name,
                sim::simulate_cyclic(&params.law, &cy.runs[run].time_s, &cy.runs[run].strain),
            ),
        };
        out.map_err(|source| IdentError::Simulation {
            run: name.clone(),
            source,
        })
    }

    /// The measured channel from the simulated tension `values`.
    fn channels(
        &self,
        params: &PlantParams,
        run: usize,
        values: Vec<f64>,
    ) -> Result<Channels, IdentError> {
        let mut channels = Channels(vec![Channel {
            name: "tension_n".into(),
            values,
        }]);
        let time_s = match self {
            Self::Relaxation(rx) => &rx.runs[run].time_s,
            Self::Cyclic(cy) => &cy.runs[run].time_s,
        };
        apply_sensors(params, time_s, &mut channels)?;
        Ok(channels)
    }
}

impl Plant for SpecimenPlant<'_> {
    fn kind(&self) -> DataKind {
        match self {
            Self::Relaxation(_) => DataKind::Relaxation,
            Self::Cyclic(_) => DataKind::Cyclic,
        }
    }

    fn runs(&self) -> usize {
        match self {
            Self::Relaxation(rx) => rx.runs.len(),
            Self::Cyclic(cy) => cy.runs.len(),
        }
    }

    fn simulate(&self, params: &PlantParams, run: usize) -> Result<Channels, IdentError> {
        self.channels(params, run, self.tension(params, run)?)
    }

    /// The specimen's tension (the only argument it has).
    fn argument_samples(
        &self,
        params: &PlantParams,
        run: usize,
        arg: Argument,
        _at: Option<&[String]>,
    ) -> Result<Vec<f64>, IdentError> {
        Ok(match arg {
            Argument::TensionN => self.simulate(params, run)?.into_primary(),
            _ => Vec::new(),
        })
    }
}

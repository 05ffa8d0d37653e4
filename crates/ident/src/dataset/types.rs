//! What a loaded dataset holds: the kinds, the rig and specimens, the runs and the
//! frequency steps of a stepped-sine run.

use std::path::PathBuf;

use super::{DatasetError, KINDS};

/// A loaded dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// The dataset folder.
    pub dir: PathBuf,
    /// `title` from `dataset.toml` (the folder name if absent).
    pub title: String,
    /// The kind-specific content.
    pub kind: DatasetKind,
}

/// The kind-specific content of a dataset.
#[derive(Debug, Clone, PartialEq)]
pub enum DatasetKind {
    /// `kind = "sine_sweep"`.
    SineSweep(SweepDataset),
    /// `kind = "relaxation"`.
    Relaxation(RelaxationDataset),
    /// `kind = "cyclic"`.
    Cyclic(CyclicDataset),
    /// `kind = "arm_moves"`.
    ArmMoves(ArmMovesDataset),
}

impl DatasetKind {
    /// The kind as spelled in `dataset.toml`.
    pub fn name(&self) -> &'static str {
        match self {
            DatasetKind::SineSweep(_) => KINDS[0],
            DatasetKind::Relaxation(_) => KINDS[1],
            DatasetKind::Cyclic(_) => KINDS[2],
            DatasetKind::ArmMoves(_) => KINDS[3],
        }
    }
}

/// How the rig keeps its ropes tensioned (`tensioner = ...`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tensioner {
    /// `"constant_force"`: the input pulley rides a carriage pulled with a constant force,
    /// so `tension_in_1 + tension_in_2 = 2 * mean_tension_n` at all times.
    ConstantForce,
}

impl Tensioner {
    /// Valid spellings in `dataset.toml`.
    pub const NAMES: [&'static str; 1] = ["constant_force"];

    /// The spelling in `dataset.toml`.
    pub fn name(self) -> &'static str {
        match self {
            Tensioner::ConstantForce => "constant_force",
        }
    }

    pub(super) fn parse(s: &str) -> Option<Self> {
        match s {
            "constant_force" => Some(Tensioner::ConstantForce),
            _ => None,
        }
    }
}

/// The `[rig]` table of a sine-sweep dataset: the paper's cable-pulley rig (Sec. IV,
/// Fig. 8, Table VII).
#[derive(Debug, Clone, PartialEq)]
pub struct RigSpec {
    /// Rope name in the rope catalog.
    pub rope: String,
    /// L: length of each rope from input to output pulley (m).
    pub rope_length_m: f64,
    /// r1: input pulley radius (m).
    pub input_radius_m: f64,
    /// r2: output pulley radius (m).
    pub output_radius_m: f64,
    /// I: inertia about the output axis (kg m^2).
    pub output_inertia_kg_m2: f64,
    /// C: viscous resistance of the output shaft (N m s) (eq. 8); may be 0.
    pub output_damping_n_m_s: f64,
    /// Idler pulleys each rope runs over.
    pub relay_pulleys: u32,
    /// Radius of the relay pulleys (m).
    pub relay_radius_m: f64,
    /// Tensioner type.
    pub tensioner: Tensioner,
}

/// A sine-sweep dataset (`kind = "sine_sweep"`).
#[derive(Debug, Clone, PartialEq)]
pub struct SweepDataset {
    /// The rig.
    pub rig: RigSpec,
    /// The runs, in file order.
    pub runs: Vec<SweepRun>,
}

/// A frequency response computed by the rig software (`frf_file`): output angle over
/// input angle, one row per test frequency.
#[derive(Debug, Clone, PartialEq)]
pub struct Frf {
    /// File name relative to the dataset folder.
    pub file: String,
    /// Test frequencies (Hz).
    pub frequency_hz: Vec<f64>,
    /// Gain (dB).
    pub gain_db: Vec<f64>,
    /// Phase (deg).
    pub phase_deg: Vec<f64>,
}

/// One stepped-sine run of the rig.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepRun {
    /// File stem of `file` (e.g. `run_01`).
    pub name: String,
    /// Time-series file name relative to the dataset folder.
    pub file: String,
    /// The rig software's frequency response, if `frf_file` was given.
    pub frf: Option<Frf>,
    /// Tensioner setting (N).
    pub mean_tension_n: f64,
    /// Amplitude of the commanded input angle (rad).
    pub amplitude_rad: f64,
    /// Transient time at the start of each frequency step (s).
    pub settle_s: f64,
    /// Time since the run started (s), fixed rate.
    pub time_s: Vec<f64>,
    /// Commanded frequency of the current step (Hz).
    pub frequency_hz: Vec<f64>,
    /// Commanded input pulley angle (rad).
    pub command_rad: Vec<f64>,
    /// Measured input pulley angle (rad).
    pub input_angle_rad: Vec<f64>,
    /// Measured output pulley angle (rad).
    pub output_angle_rad: Vec<f64>,
    /// Rope 1 tension next to the input pulley (N).
    pub tension_in_1_n: Option<Vec<f64>>,
    /// Rope 2 tension next to the input pulley (N).
    pub tension_in_2_n: Option<Vec<f64>>,
    /// Rope 1 tension next to the output pulley (N).
    pub tension_out_1_n: Option<Vec<f64>>,
    /// Rope 2 tension next to the output pulley (N).
    pub tension_out_2_n: Option<Vec<f64>>,
}

/// One frequency step of a stepped-sine run (indices into the run's series).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Frequency of the step (Hz).
    pub frequency_hz: f64,
    /// First sample of the step.
    pub start_index: usize,
    /// One past the last sample of the step.
    pub end_index: usize,
    /// First sample of the part to analyse (at or after `settle_s` into the step).
    pub analysis_start_index: usize,
    /// One past the last sample of the part to analyse: `analysis_start_index..
    /// analysis_end_index` spans `cycles` whole cycles, to the nearest sample.
    pub analysis_end_index: usize,
    /// Whole cycles in the analysed part (>= 2).
    pub cycles: usize,
}

/// Where the analysed whole cycles of a frequency step are taken (see
/// [`SweepRun::segments_aligned`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WindowAlignment {
    /// Starting at the first sample at or after `settle_s` into the step. This is what
    /// the rig software that wrote the example `frf_file`s does (checked: it reproduces
    /// their gains within 0.001 dB and phases within 0.01 deg).
    AfterSettle,
    /// Ending at the last sample of the step (the latest, most settled cycles).
    EndOfStep,
}

impl SweepRun {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// True if the run holds no samples (never the case for a loaded run).
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// Sampling interval (s): mean interval over the run (the reader checked it is fixed).
    pub fn dt_s(&self) -> f64 {
        mean_interval(&self.time_s)
    }

    /// The distinct test frequencies in order of appearance (Hz).
    pub fn test_frequencies_hz(&self) -> Vec<f64> {
        let mut out: Vec<f64> = Vec::new();
        for &f in &self.frequency_hz {
            if out.last().is_none_or(|&last| !same_frequency(last, f)) {
                out.push(f);
            }
        }
        out
    }

    /// Splits the run into its frequency steps (runs of equal `frequency_hz`), with the
    /// analysed part placed as the rig software does ([`WindowAlignment::AfterSettle`]).
    pub fn segments(&self) -> Result<Vec<Segment>, DatasetError> {
        self.segments_aligned(WindowAlignment::AfterSettle)
    }

    /// Splits the run into its frequency steps (runs of equal `frequency_hz`).
    ///
    /// In each step the first `settle_s` seconds are transient (`ceil(settle_s / dt)`
    /// samples). Of the `m` samples after them, the analysed part is the largest whole
    /// number of cycles `n = floor(m dt f)` that fits, `round(n / (f dt))` samples long,
    /// placed as `alignment` says. Errors if a frequency is not positive or if `n < 2`.
    pub fn segments_aligned(
        &self,
        alignment: WindowAlignment,
    ) -> Result<Vec<Segment>, DatasetError> {
        let dt_s = self.dt_s();
        let file = PathBuf::from(&self.file);
        let mut out = Vec::new();
        let mut start = 0usize;
        let n = self.frequency_hz.len();
        while start < n {
            let f = self.frequency_hz[start];
            let mut end = start + 1;
            while end < n && same_frequency(self.frequency_hz[end], f) {
                end += 1;
            }
            if f <= 0.0 {
                return Err(DatasetError::BadCell {
                    file,
                    line: start as u64 + 2,
                    column: "frequency_hz".into(),
                    value: f,
                    requirement: "must be > 0 in a stepped sine".into(),
                });
            }
            // samples dropped for settling: up to the first sample at or after settle_s
            let settle_samples = ((self.settle_s / dt_s) - 1e-6).ceil().max(0.0) as usize;
            let available = (end - start).saturating_sub(settle_samples);
            let cycles_f = available as f64 * dt_s * f;
            let cycles = (cycles_f + 1e-6).floor();
            if cycles < 2.0 {
                return Err(DatasetError::StepTooShort {
                    file,
                    line: start as u64 + 2,
                    last_line: end as u64 + 1,
                    frequency_hz: f,
                    cycles: cycles_f,
                    settle_s: self.settle_s,
                });
            }
            let len = ((cycles / (f * dt_s)).round() as usize).min(available);
            let (a, b) = match alignment {
                WindowAlignment::AfterSettle => {
                    (start + settle_samples, start + settle_samples + len)
                }
                WindowAlignment::EndOfStep => (end - len, end),
            };
            out.push(Segment {
                frequency_hz: f,
                start_index: start,
                end_index: end,
                analysis_start_index: a,
                analysis_end_index: b,
                cycles: cycles as usize,
            });
            start = end;
        }
        Ok(out)
    }
}

/// The `[specimen]` of a relaxation test.
#[derive(Debug, Clone, PartialEq)]
pub struct RelaxationSpecimen {
    /// Rope name in the rope catalog.
    pub rope: String,
    /// Initial length after the pre-stretch process (m).
    pub length_m: f64,
    /// Strain applied at t = 0 and held (elongation / length) (-); a run may hold its
    /// own ([`RelaxationRun::strain`]).
    pub strain: f64,
}

/// One relaxation run: tension over time at constant strain (paper Sec. III), each
/// run a test of its own from the rope as pre-stretched.
#[derive(Debug, Clone, PartialEq)]
pub struct RelaxationRun {
    /// File stem.
    pub name: String,
    /// File name relative to the dataset folder.
    pub file: String,
    /// Time since the strain was applied (s).
    pub time_s: Vec<f64>,
    /// Measured tension (N).
    pub tension_n: Vec<f64>,
    /// The strain this run holds when it is not the specimen's (`[[run]] strain`):
    /// relaxations at two or more strains tell laws of tension apart that one strain
    /// cannot (a stiffening head spring sets the tension each strain starts from, a
    /// tension-dependent creep how fast it falls).
    pub strain: Option<f64>,
}

/// A relaxation dataset (`kind = "relaxation"`).
#[derive(Debug, Clone, PartialEq)]
pub struct RelaxationDataset {
    /// The specimen.
    pub specimen: RelaxationSpecimen,
    /// The runs.
    pub runs: Vec<RelaxationRun>,
}

impl RelaxationDataset {
    /// The strain run `run` holds: its own, else the specimen's.
    pub fn strain_of(&self, run: usize) -> f64 {
        self.runs
            .get(run)
            .and_then(|r| r.strain)
            .unwrap_or(self.specimen.strain)
    }
}

/// The `[specimen]` of a cyclic test.
#[derive(Debug, Clone, PartialEq)]
pub struct CyclicSpecimen {
    /// Rope name in the rope catalog.
    pub rope: String,
    /// Initial length (m).
    pub length_m: f64,
}

/// One cyclic load-strain run (paper Sec. II).
#[derive(Debug, Clone, PartialEq)]
pub struct CyclicRun {
    /// File stem.
    pub name: String,
    /// File name relative to the dataset folder.
    pub file: String,
    /// Time (s).
    pub time_s: Vec<f64>,
    /// Strain (elongation / length) (-).
    pub strain: Vec<f64>,
    /// Tension (N).
    pub tension_n: Vec<f64>,
}

/// A cyclic dataset (`kind = "cyclic"`).
#[derive(Debug, Clone, PartialEq)]
pub struct CyclicDataset {
    /// The specimen.
    pub specimen: CyclicSpecimen,
    /// The runs.
    pub runs: Vec<CyclicRun>,
}

/// An arm dataset (`kind = "arm_moves"`): a long-reach arm moved by its servos, what
/// its sensors recorded.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmMovesDataset {
    /// `[arm] scenario`: the arm scenario, as written in `dataset.toml` (relative to
    /// the dataset folder).
    pub scenario: String,
    /// The scenario file (the dataset folder joined with [`Self::scenario`]).
    pub scenario_path: std::path::PathBuf,
    /// The joints the scenario drives (one rope pair each), in the order of its
    /// transmissions: the `J` of every per-joint column.
    pub joints: Vec<String>,
    /// The flexible links of the scenario (`[[flex]]`, URDF names, in the arm's link
    /// order): where an effect on a link's bending may be restricted
    /// ([`crate::model::EffectUse::at`]). Empty for a rigid arm.
    pub flex_links: Vec<String>,
    /// The rope of the scenario's first transmission (the model's rope: its `k1_scale`
    /// and rope-law effects act on every pair's own law).
    pub rope: String,
    /// The runs (moves), in file order.
    pub runs: Vec<ArmRun>,
}

/// What an arm run measured besides time and the commands: one column of the run file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ArmQuantity {
    /// `motor_J_rad`: motor pulley angle of pair `J` (rad).
    Motor,
    /// `joint_J_rad`: link-side joint angle (rad).
    Joint,
    /// `tension_J_1_n`: a rope of side 1 of pair `J`, next to the motor pulley (N).
    Tension1,
    /// `tension_J_2_n`: a rope of side 2 (N).
    Tension2,
    /// `tip_x_m`, `tip_y_m`, `tip_z_m` (axis 0, 1, 2): tip position (m).
    Tip(u8),
    /// `tip_acc_x_m_s2`, ...: tip acceleration, gravity not included (m/s^2).
    TipAcc(u8),
}

impl ArmQuantity {
    /// The column name of this quantity at joint `joint` (ignored for the tip).
    pub fn column(self, joint: &str) -> String {
        const AXES: [&str; 3] = ["x", "y", "z"];
        match self {
            Self::Motor => format!("motor_{joint}_rad"),
            Self::Joint => format!("joint_{joint}_rad"),
            Self::Tension1 => format!("tension_{joint}_1_n"),
            Self::Tension2 => format!("tension_{joint}_2_n"),
            Self::Tip(a) => format!("tip_{}_m", AXES[usize::from(a) % 3]),
            Self::TipAcc(a) => format!("tip_acc_{}_m_s2", AXES[usize::from(a) % 3]),
        }
    }

    /// True for the tip's quantities (no joint).
    pub fn is_tip(self) -> bool {
        matches!(self, Self::Tip(_) | Self::TipAcc(_))
    }

    /// Unit of the quantity.
    pub fn unit(self) -> &'static str {
        match self {
            Self::Motor | Self::Joint => "rad",
            Self::Tension1 | Self::Tension2 => "N",
            Self::Tip(_) => "m",
            Self::TipAcc(_) => "m/s^2",
        }
    }
}

/// One measured channel of an arm run.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmChannel {
    /// Column name (`motor_j1_rad`, `tip_x_m`, ...).
    pub name: String,
    /// What it measures.
    pub quantity: ArmQuantity,
    /// Index into [`ArmMovesDataset::joints`] (`None` for the tip).
    pub joint: Option<usize>,
    /// One value per sample.
    pub values: Vec<f64>,
}

/// One move of the arm.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmRun {
    /// File stem.
    pub name: String,
    /// File name relative to the dataset folder.
    pub file: String,
    /// `title`, if given.
    pub title: Option<String>,
    /// `payload_kg`: the payload of this run (overrides the scenario's), if given.
    pub payload_kg: Option<f64>,
    /// Time since the run started (s), fixed rate.
    pub time_s: Vec<f64>,
    /// `command_J_rad` of every driven joint (in [`ArmMovesDataset::joints`] order).
    pub command_rad: Vec<Vec<f64>>,
    /// The measured channels: every driven joint's motor angle first (joint order),
    /// then the optional channels the file holds, per joint (joint angle, tensions),
    /// then the tip.
    pub channels: Vec<ArmChannel>,
}

impl ArmRun {
    /// Sampling interval (s).
    pub fn dt_s(&self) -> f64 {
        mean_interval(&self.time_s)
    }

    /// The channel that shows where driven joint `k` is: its joint angle when the run
    /// measured it, else its motor angle (index into [`Self::channels`]).
    pub fn angle_channel(&self, k: usize) -> Option<usize> {
        let find = |q: ArmQuantity| {
            self.channels
                .iter()
                .position(|c| c.joint == Some(k) && c.quantity == q)
        };
        find(ArmQuantity::Joint).or_else(|| find(ArmQuantity::Motor))
    }

    /// The channel called `name`.
    pub fn channel(&self, name: &str) -> Option<&ArmChannel> {
        self.channels.iter().find(|c| c.name == name)
    }
}

/// True if two `frequency_hz` cells belong to the same step (equal within 1e-9 relative;
/// the column holds the commanded frequency, identical within a step).
fn same_frequency(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs())
}

/// Mean sampling interval of `time_s` (NaN with fewer than two samples).
pub(super) fn mean_interval(time_s: &[f64]) -> f64 {
    match (time_s.first(), time_s.last()) {
        (Some(a), Some(b)) if time_s.len() >= 2 => (b - a) / (time_s.len() - 1) as f64,
        _ => f64::NAN,
    }
}

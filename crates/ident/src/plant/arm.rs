//! The arm plant: a long-reach arm (`arm_moves` datasets, crates/arm) driven by each
//! run's recorded commands.
//!
//! Built once: the dataset's scenario is compiled once per distinct payload (a run's
//! `payload_kg` overrides the scenario's `[payload]` mass). Each simulation rebuilds
//! the [`DrivenArm`] from those parts with the model's numbers:
//!
//! - base parameters (`k1_scale`, ...) and rope-law effects act on every pair's own
//!   rope law (the pairs may hold different ropes; the model's rope is the first
//!   pair's);
//! - pair-site effects (`relay_friction`, `motor_friction`) act on every pair,
//!   joint-site effects (`joint_friction`) at every driven joint, with the same values,
//!   or only at the joints a model's effect is restricted to (`joints`: its values per
//!   joint, [`crate::model::EffectUse::joints`]); a rope-law effect so restricted acts
//!   on those joints' pairs;
//! - sensor-site effects act on the channels they name;
//! - link-site effects that act on a link's bending (`link_flexibility`) act on every
//!   flexible link of the scenario (`[[flex]]`, the scenario's own link effects kept),
//!   or only on the links a model's effect is restricted to (`links`: its values per
//!   link), and are refused on an arm without flexible links (no `E I` to scale);
//! - link-site effects that change the payload (`payload_mass`) change each run's
//!   payload (the scenario's `[payload]` mass, or the run's `payload_kg`) at the
//!   scenario's payload point (`[payload]` link and offset; the tip frame's origin
//!   without one), before the dynamics, the gravity feed-forward and the statics are
//!   built.
//!
//! A run starts at rest in the static equilibrium at its first commanded pose (the
//! scenario's `initial_q_rad` for joints without a transmission). The commands are the
//! run's `command_J_rad` columns, linearly interpolated between samples (as a `csv`
//! command of a scenario: offsets from the first row, velocity reference the slope of
//! the interpolation). The arm steps at the sample interval divided into
//! [`substeps_for`] equal steps of at most [`ARM_MAX_STEP_S`], each divided again into
//! the plant's refinement ([`ArmPlant::with_refinement`]; `compare` and `diagnose`
//! choose it from the data: `crate::analysis::choose_arm_step`).

use std::borrow::Cow;

use longreach_arm::scenario::{self, ArmScenario};
use longreach_arm::{ArmSpec, Command, DrivenArm, DrivenState};
pub use longreach_drive::effects::bends_links;
use longreach_drive::effects::{Applied, Argument, DataKind, Effect, LinkBending, Site};
use longreach_drive::transmission::PairSpec;
use longreach_drive::InputSignal;

use super::{apply_sensors, Channel, Channels, Plant};
use crate::dataset::{ArmMovesDataset, ArmQuantity, ArmRun};
use crate::error::IdentError;
use crate::model::PlantParams;

/// Name of the arm plant's compared channel (first of its channels; what `fit` and
/// `diagnose` fit): every measured channel minus its measured mean, over its noise,
/// concatenated in the run's channel order ([`stacking`]).
pub const ARM_STACKED: &str = "arm_stacked";

/// How each channel of run `r` enters the compared channel: its measured mean and its
/// noise standard deviation (encoders `q / sqrt(12)` at 1e-4 rad; tensions and the tip
/// from the second differences of the measurement).
pub fn stacking(r: &ArmRun) -> Vec<(f64, f64)> {
    r.channels
        .iter()
        .map(|c| {
            let n = c.values.len().max(1) as f64;
            let mean = c.values.iter().sum::<f64>() / n;
            let sigma = match c.quantity {
                ArmQuantity::Motor | ArmQuantity::Joint => {
                    crate::dataset::ARM_ENCODER_RESOLUTION_RAD / 12f64.sqrt()
                }
                _ => crate::metrics::noise_sigma_second_difference(&c.values).max(1e-12),
            };
            (mean, sigma)
        })
        .collect()
}

/// The compared channel of a run: channel `k`'s values (`values(k)`) minus its mean
/// over its noise (`weights[k]`, from [`stacking`]), concatenated.
pub fn stack<'v>(weights: &[(f64, f64)], values: impl Fn(usize) -> &'v [f64]) -> Vec<f64> {
    weights
        .iter()
        .enumerate()
        .flat_map(|(k, &(mean, sigma))| values(k).iter().map(move |v| (v - mean) / sigma))
        .collect()
}

/// Longest simulation step of the arm plant, s (the arm scenarios' 1 ms).
pub const ARM_MAX_STEP_S: f64 = 1e-3;

/// The finest refinement of [`ARM_MAX_STEP_S`] `compare` and `diagnose` try
/// (`crate::analysis::choose_arm_step`): 0.25 ms, a diagnosis' cost 4x that at 1 ms.
pub const ARM_MAX_REFINEMENT: usize = 4;

/// The refinement `synth` simulates its truth at (1/8 ms), finer than any `compare`
/// chooses.
pub const SYNTH_ARM_REFINEMENT: usize = 8;

/// Steps per sample interval `dt_s`: the fewest that make each step at most
/// [`ARM_MAX_STEP_S`].
pub fn substeps_for(dt_s: f64) -> usize {
    ((dt_s / ARM_MAX_STEP_S) - 1e-9).ceil().max(1.0) as usize
}

/// The longest simulation step of any run of `ds`, s, with every step of at most
/// [`ARM_MAX_STEP_S`] divided into `refinement` ([`ArmPlant::with_refinement`]).
pub fn longest_step_s(ds: &ArmMovesDataset, refinement: usize) -> f64 {
    ds.runs
        .iter()
        .map(|r| {
            let dt = r.dt_s();
            dt / (substeps_for(dt) * refinement) as f64
        })
        .fold(0.0, f64::max)
}

/// What the scenario compiles to, before the model's numbers.
#[derive(Debug, Clone)]
struct ArmParts {
    spec: ArmSpec,
    pairs: Vec<PairSpec>,
    joint_effects: Vec<(usize, Applied)>,
    flex_links: Vec<longreach_arm::FlexLinkSpec>,
    initial_q_rad: Vec<f64>,
    /// The payload the scenario gives the run (kg) and the point where payload effects
    /// add mass: the frame and the offset in it.
    payload_kg: f64,
    payload_at: (String, [f64; 3]),
    /// The arm the servos' references are computed for when the scenario's own effects
    /// give it a payload the controller does not know
    /// ([`DrivenArm::with_controller_spec`]).
    controller: Option<ArmSpec>,
}

impl ArmParts {
    fn of(sc: ArmScenario) -> Self {
        Self {
            spec: sc.arm.spec().clone(),
            pairs: sc.arm.pairs().iter().map(|p| p.spec.clone()).collect(),
            joint_effects: sc.joint_effects,
            flex_links: sc.flex_links,
            initial_q_rad: sc.arm.initial_q_rad().to_vec(),
            payload_kg: sc.payload_kg,
            payload_at: sc.payload_at,
            controller: sc.arm.controller_spec().cloned(),
        }
    }
}

/// The arm of an `arm_moves` dataset ([`crate::dataset::ArmMovesDataset`]).
#[derive(Debug)]
pub struct ArmPlant<'a> {
    ds: &'a ArmMovesDataset,
    /// The compiled scenario of each run (shared between runs of one payload), or why
    /// it does not compile.
    parts: Vec<Result<std::sync::Arc<ArmParts>, String>>,
    /// Each run's [`stacking`].
    weights: Vec<Vec<(f64, f64)>>,
    /// Simulation steps per [`ARM_MAX_STEP_S`]-sized step ([`Self::with_refinement`]).
    refinement: usize,
}

/// The scenario text with the payload mass set to `mass_kg` (the rest of `[payload]`
/// kept).
fn with_payload(text: &str, mass_kg: f64) -> Result<String, String> {
    let mut doc: toml::Table = text.parse().map_err(|e| format!("{e}"))?;
    let payload = doc
        .entry("payload")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    let t = payload
        .as_table_mut()
        .ok_or("`payload` is not a table in the scenario")?;
    t.insert("mass_kg".into(), toml::Value::Float(mass_kg));
    toml::to_string(&doc).map_err(|e| e.to_string())
}

impl<'a> ArmPlant<'a> {
    /// Compiles the dataset's scenario once per distinct payload; steps of at most
    /// [`ARM_MAX_STEP_S`].
    pub fn new(ds: &'a ArmMovesDataset) -> Self {
        Self::with_refinement(ds, 1)
    }

    /// [`Self::new`] with every step divided into `refinement` (>= 1) equal steps.
    pub fn with_refinement(ds: &'a ArmMovesDataset, refinement: usize) -> Self {
        let path = &ds.scenario_path;
        let file = path.display().to_string();
        let base = path.parent().unwrap_or(std::path::Path::new("."));
        let text = std::fs::read_to_string(path).map_err(|e| format!("{file}: {e}"));
        let mut cache: Vec<(Option<u64>, Result<std::sync::Arc<ArmParts>, String>)> = Vec::new();
        let mut parts = Vec::with_capacity(ds.runs.len());
        for run in &ds.runs {
            let key = run.payload_kg.map(f64::to_bits);
            if let Some((_, p)) = cache.iter().find(|(k, _)| *k == key) {
                parts.push(p.clone());
                continue;
            }
            let built = text.clone().and_then(|text| {
                let text = match run.payload_kg {
                    Some(m) => with_payload(&text, m).map_err(|e| format!("{file}: {e}"))?,
                    None => text,
                };
                scenario::parse(&text, &file, base)
                    .map(|sc| std::sync::Arc::new(ArmParts::of(sc)))
                    .map_err(|e| e.to_string())
            });
            cache.push((key, built.clone()));
            parts.push(built);
        }
        let weights = ds.runs.iter().map(stacking).collect();
        Self {
            ds,
            parts,
            weights,
            refinement: refinement.max(1),
        }
    }

    /// The arm of run `run` with the numbers `params`, for steps of `dt_s`.
    fn build(&self, params: &PlantParams, run: usize, dt_s: f64) -> Result<DrivenArm, IdentError> {
        let r = &self.ds.runs[run];
        let err = |message: String| IdentError::ArmBuild {
            run: r.name.clone(),
            message,
        };
        let parts = self.parts[run].as_ref().map_err(|m| err(m.clone()))?;
        // An effect restricted to some joints ([`PlantParams::effect_at`]) acts at
        // the pairs and bearings of those joints only.
        let at = |i: usize, joint: usize| -> bool {
            match params.effect_at.get(i).and_then(Option::as_ref) {
                None => true,
                Some(names) => names.contains(&parts.spec.joints[joint].name),
            }
        };
        let mut pairs = parts.pairs.clone();
        for pair in &mut pairs {
            let mut p = PlantParams {
                law: pair.law.clone(),
                output_damping_n_m_s: None,
                effects: Vec::new(),
                base: Vec::new(),
                rope_effects: Vec::new(),
                effect_at: Vec::new(),
            };
            for &(b, v) in &params.base {
                b.apply(v, &mut p).map_err(|e| err(e.to_string()))?;
            }
            pair.law = p.law;
            let joint = pair.joint;
            for a in params
                .rope_effects
                .iter()
                .chain(params.effects.iter().enumerate().filter_map(|(i, a)| {
                    (!matches!(a.effect.site(), Site::Joint | Site::Sensor | Site::Link)
                        && at(i, joint))
                    .then_some(a)
                }))
            {
                a.apply_to_pair(pair)
                    .map_err(|e| err(format!("effect {}: {e}", a.effect.name())))?;
                pair.effects.push(a.effect.name().to_string());
            }
        }
        let mut joint_effects = parts.joint_effects.clone();
        for (i, a) in params
            .effects
            .iter()
            .enumerate()
            .filter(|(_, a)| a.effect.site() == Site::Joint)
        {
            for pair in parts.pairs.iter().filter(|p| at(i, p.joint)) {
                joint_effects.retain(|(j, b)| {
                    *j != pair.joint || !longreach_drive::effects::same(a.effect, b.effect)
                });
                joint_effects.push((pair.joint, a.clone()));
            }
        }
        let mut flex_links = parts.flex_links.clone();
        for (i, a) in params
            .effects
            .iter()
            .enumerate()
            .filter(|(_, a)| a.effect.site() == Site::Link)
        {
            if !bends_links(a.effect) {
                continue;
            }
            if flex_links.is_empty() {
                return Err(err(rigid_arm_reason(a.effect.name())));
            }
            // (restricted to some links: those links only, [`PlantParams::effect_at`])
            let on = |l: &longreach_arm::FlexLinkSpec| match params.effect_at.get(i) {
                Some(Some(names)) => parts
                    .spec
                    .links
                    .get(l.link)
                    .is_some_and(|x| names.contains(&x.name)),
                _ => true,
            };
            for l in flex_links.iter_mut().filter(|l| on(l)) {
                let mut b = LinkBending {
                    ei_n_m2: l.ei_n_m2,
                    damping_ratio: l.damping_ratio,
                };
                a.apply_to_link(&mut b)
                    .map_err(|e| err(format!("effect {}: {e}", a.effect.name())))?;
                l.ei_n_m2 = b.ei_n_m2;
                l.damping_ratio = b.damping_ratio;
            }
        }
        let spec = payload_changed(parts, params).map_err(err)?;
        // A payload effect's mass is unknown to the servos: their references keep the
        // arm without it.
        let controller = match (&parts.controller, &spec) {
            (Some(c), _) => Some(c.clone()),
            (None, Some(_)) => Some(parts.spec.clone()),
            (None, None) => None,
        };
        let (initial, commands) = run_commands(&parts.spec, &parts.pairs, &parts.initial_q_rad, r)
            .map_err(|e| err(e.to_string()))?;
        DrivenArm::with_joint_effects(
            spec.unwrap_or_else(|| parts.spec.clone()),
            pairs,
            joint_effects,
            commands,
            initial,
            dt_s,
        )
        .and_then(|arm| arm.with_flexible_links(flex_links))
        .and_then(|arm| match controller {
            Some(c) => arm.with_controller_spec(c),
            None => Ok(arm),
        })
        .map_err(|e| err(e.to_string()))
    }
}

/// The arm's spec with the payload the model's payload effects give (`None`: no such
/// effect, or one that leaves the payload as it is): the difference from the scenario's
/// payload added as a point mass (negative: removed) at the payload's point.
fn payload_changed(parts: &ArmParts, params: &PlantParams) -> Result<Option<ArmSpec>, String> {
    let mut payload = longreach_drive::effects::Payload {
        mass_kg: parts.payload_kg,
    };
    let mut any = false;
    for a in params
        .effects
        .iter()
        .filter(|a| a.effect.site() == Site::Link && !bends_links(a.effect))
    {
        a.apply_to_payload(&mut payload)
            .map_err(|e| format!("effect {}: {e}", a.effect.name()))?;
        any = true;
    }
    let delta_kg = payload.mass_kg - parts.payload_kg;
    if !any || delta_kg == 0.0 {
        return Ok(None);
    }
    let mut spec = parts.spec.clone();
    let (frame, offset) = &parts.payload_at;
    spec.add_point_mass(frame, delta_kg, *offset)
        .map_err(|e| e.to_string())?;
    Ok(Some(spec))
}

/// Why a link-bending effect has nothing to act on in an arm without flexible links.
fn rigid_arm_reason(effect: &str) -> String {
    format!(
        "{effect} scales the bending stiffness of the arm's flexible links, and the \
         dataset's arm scenario has none ([[flex]], docs/arm.md): a rigid arm has no E I to \
         scale"
    )
}

/// The initial pose and the commands of run `r`: every driven joint starts at its first
/// commanded angle and follows the recorded commands (linear interpolation, offsets from
/// the first row); the other joints hold the scenario's initial angle.
fn run_commands(
    spec: &ArmSpec,
    pairs: &[PairSpec],
    scenario_q_rad: &[f64],
    r: &ArmRun,
) -> Result<(Vec<f64>, Vec<Command>), longreach_drive::DriveError> {
    let mut initial = scenario_q_rad.to_vec();
    let mut commands = vec![Command::Hold; spec.ndofs()];
    let t0 = r.time_s.first().copied().unwrap_or(0.0);
    let time: Vec<f64> = r.time_s.iter().map(|t| t - t0).collect();
    for (pair, cmd) in pairs.iter().zip(&r.command_rad) {
        let c0 = cmd.first().copied().unwrap_or(0.0);
        initial[pair.joint] = c0;
        let offsets = cmd.iter().map(|c| c - c0).collect();
        commands[pair.joint] = Command::Signal(InputSignal::series(time.clone(), offsets)?);
    }
    Ok((initial, commands))
}

/// One sample of every channel of `r` from the state.
fn record(
    arm: &DrivenArm,
    st: &DrivenState,
    r: &ArmRun,
    tip: &mut [Vec<f64>; 3],
    out: &mut [Vec<f64>],
) {
    let need_tip = r.channels.iter().any(|c| c.quantity.is_tip());
    let tip_now = if need_tip {
        arm.tip_m(&st.q_rad).ok()
    } else {
        None
    };
    if let Some(t) = tip_now {
        for a in 0..3 {
            tip[a].push(t[a]);
        }
    }
    for (c, o) in r.channels.iter().zip(out.iter_mut()) {
        let pair = c.joint.unwrap_or(0);
        let joint = arm.pairs().get(pair).map_or(0, |p| p.spec.joint);
        let v = match c.quantity {
            ArmQuantity::Motor => st.motor_rad[pair],
            ArmQuantity::Joint => st.q_rad[joint],
            ArmQuantity::Tension1 | ArmQuantity::Tension2 => {
                let spans = arm.span_tensions_n(st, pair);
                let side = usize::from(c.quantity == ArmQuantity::Tension2);
                spans.first().map_or(f64::NAN, |s| s[side])
            }
            ArmQuantity::Tip(a) => tip_now.map_or(f64::NAN, |t| t[usize::from(a)]),
            // Filled in from the tip positions once the run is done.
            ArmQuantity::TipAcc(_) => 0.0,
        };
        o.push(v);
    }
}

/// Second differences of `x` sampled every `dt_s` (the ends copy their neighbours).
fn second_difference(x: &[f64], dt_s: f64) -> Vec<f64> {
    let n = x.len();
    if n < 3 {
        return vec![0.0; n];
    }
    let mut out = vec![0.0; n];
    for i in 1..n - 1 {
        out[i] = (x[i + 1] - 2.0 * x[i] + x[i - 1]) / (dt_s * dt_s);
    }
    out[0] = out[1];
    out[n - 1] = out[n - 2];
    out
}

/// Steps the arm `arm` through run `r` from its initial state, `substeps` steps per
/// sample, and shows `visit` the state at every sample (the first included).
fn each_sample(
    arm: &DrivenArm,
    r: &ArmRun,
    substeps: usize,
    mut visit: impl FnMut(&DrivenState),
) -> Result<(), IdentError> {
    let mut st = arm.initial_state();
    visit(&st);
    for _ in 1..r.time_s.len() {
        for _ in 0..substeps {
            arm.step(&mut st).map_err(|e| IdentError::ArmSimulation {
                run: r.name.clone(),
                time_s: st.time_s,
                message: e.to_string(),
            })?;
        }
        visit(&st);
    }
    Ok(())
}

/// Simulates the arm `arm` on run `r`: the channels of `r` at its sample times (tip
/// accelerations by second differences of the sampled tip positions). With `poses`,
/// the generalised coordinates (joints, then the flexible links' modes) of every
/// sample go into it too.
pub(crate) fn simulate_run(
    arm: &DrivenArm,
    r: &ArmRun,
    substeps: usize,
    mut poses: Option<&mut Vec<Vec<f64>>>,
) -> Result<Vec<Vec<f64>>, IdentError> {
    let n = r.time_s.len();
    let mut out: Vec<Vec<f64>> = r.channels.iter().map(|_| Vec::with_capacity(n)).collect();
    let mut tip: [Vec<f64>; 3] = Default::default();
    each_sample(arm, r, substeps, |st| {
        record(arm, st, r, &mut tip, &mut out);
        if let Some(p) = poses.as_deref_mut() {
            p.push(st.q_rad.clone());
        }
    })?;
    let dt = r.dt_s();
    for (c, o) in r.channels.iter().zip(out.iter_mut()) {
        if let ArmQuantity::TipAcc(a) = c.quantity {
            *o = second_difference(&tip[usize::from(a)], dt);
        }
    }
    Ok(out)
}

impl ArmPlant<'_> {
    /// The arm of run `run` built with `params` at the run's simulation step, and its
    /// substeps per sample.
    pub fn arm_for(
        &self,
        params: &PlantParams,
        run: usize,
    ) -> Result<(DrivenArm, usize), IdentError> {
        let dt = self.ds.runs[run].dt_s();
        let k = substeps_for(dt) * self.refinement;
        Ok((self.build(params, run, dt / k as f64)?, k))
    }
}

impl Plant for ArmPlant<'_> {
    fn kind(&self) -> DataKind {
        DataKind::ArmMoves
    }

    fn runs(&self) -> usize {
        self.ds.runs.len()
    }

    fn excludes(&self, effect: &dyn Effect) -> Option<String> {
        let rigid = self
            .parts
            .iter()
            .all(|p| p.as_ref().map_or(true, |p| p.flex_links.is_empty()));
        (effect.site() == Site::Link
            && rigid
            && longreach_drive::effects::find(effect.name()).is_some_and(bends_links))
        .then(|| rigid_arm_reason(effect.name()))
    }

    /// The compared channel ([`ARM_STACKED`]), then every measured channel of the run
    /// in the run's order (the motor angles first).
    fn simulate(&self, params: &PlantParams, run: usize) -> Result<Channels, IdentError> {
        self.simulate_posed(params, run, None).map(|(c, _)| c)
    }

    /// At every sample of the run, for every driven joint: its rate's magnitude
    /// (`rate_rad_s`), the tension of every span of both its ropes (`tension_n`), or
    /// the hub load of every relay pulley, the sum of the tensions of the spans either
    /// side (`hub_load_n`; none on a pair without relay friction, whose rope is one
    /// span).
    fn argument_samples(
        &self,
        params: &PlantParams,
        run: usize,
        arg: Argument,
        at: Option<&[String]>,
    ) -> Result<Vec<f64>, IdentError> {
        let r = &self.ds.runs[run];
        let (arm, substeps) = self.arm_for(params, run)?;
        let names = &arm.spec().joints;
        let wanted = |joint: usize| at.is_none_or(|a| a.contains(&names[joint].name));
        let mut out = Vec::new();
        each_sample(&arm, r, substeps, |st| {
            for (p, pair) in arm.pairs().iter().enumerate() {
                if !wanted(pair.spec.joint) {
                    continue;
                }
                match arg {
                    Argument::JointRateRadS => out.push(st.qd_rad_s[pair.spec.joint].abs()),
                    Argument::TensionN => {
                        out.extend(arm.span_tensions_n(st, p).iter().flatten());
                    }
                    Argument::HubLoadN => {
                        let spans = arm.span_tensions_n(st, p);
                        for w in spans.windows(2) {
                            out.extend([w[0][0] + w[1][0], w[0][1] + w[1][1]]);
                        }
                    }
                }
            }
        })?;
        Ok(out)
    }
}

/// The model arm of a run and its coordinates at every sample, for drawing it.
#[derive(Debug, Clone)]
pub struct ArmPoses {
    /// The arm the run was simulated with.
    pub arm: DrivenArm,
    /// Generalised coordinates at every sample of the run: the joints (rad), then the
    /// flexible links' modal coordinates (m).
    pub q: Vec<Vec<f64>>,
}

impl ArmPlant<'_> {
    /// [`Plant::simulate`], and the arm with its coordinates at every sample.
    pub fn simulate_with_poses(
        &self,
        params: &PlantParams,
        run: usize,
    ) -> Result<(Channels, ArmPoses), IdentError> {
        let mut q = Vec::with_capacity(self.ds.runs[run].time_s.len());
        let (channels, arm) = self.simulate_posed(params, run, Some(&mut q))?;
        Ok((channels, ArmPoses { arm, q }))
    }

    fn simulate_posed(
        &self,
        params: &PlantParams,
        run: usize,
        poses: Option<&mut Vec<Vec<f64>>>,
    ) -> Result<(Channels, DrivenArm), IdentError> {
        let r = &self.ds.runs[run];
        let (arm, k) = self.arm_for(params, run)?;
        let values = simulate_run(&arm, r, k, poses)?;
        let mut channels = Channels(
            r.channels
                .iter()
                .zip(values)
                .map(|(c, values)| Channel {
                    name: Cow::Owned(c.name.clone()),
                    values,
                })
                .collect(),
        );
        apply_sensors(params, &r.time_s, &mut channels)?;
        let stacked = stack(&self.weights[run], |k| channels.0[k].values.as_slice());
        channels.0.insert(
            0,
            Channel {
                name: Cow::Borrowed(ARM_STACKED),
                values: stacked,
            },
        );
        Ok((channels, arm))
    }
}

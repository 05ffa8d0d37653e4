//! Arm scenario files (`longreach run`): TOML -> [`DrivenArm`], with errors that name
//! the file, line, field and fix. The schema is documented in `docs/arm.md`.

use std::path::{Path, PathBuf};

use longreach_rope::LawKind;
use longreach_scenario::spec::{field_error, resolve_rope, toml_error, RopeRef};
use longreach_scenario::ScenarioError;
use serde::Deserialize;

use crate::command::Command;
use crate::transmission::{
    chain_lengths_m, proximal_joints, relay_span_lengths_m, MotorMode, MotorSpec, PairSpec, Relay,
    Tensioner,
};
use crate::{load_urdf, DrivenArm};
use longreach_drive::effects::{Applied, Payload, Site};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ArmFile {
    arm: ArmSection,
    sim: SimSection,
    #[serde(default)]
    transmission_defaults: Option<toml::Table>,
    #[serde(default)]
    transmission: Vec<toml::Table>,
    #[serde(default)]
    payload: Option<PayloadSection>,
    #[serde(default)]
    effect: Vec<ArmEffectSection>,
    #[serde(default)]
    flex_defaults: Option<toml::Table>,
    #[serde(default)]
    flex: Vec<toml::Table>,
}

/// `[[effect]]`: a registered effect on the whole arm, at each of its sites.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ArmEffectSection {
    name: String,
    #[serde(default)]
    params: Vec<f64>,
    /// Only these joints (their pairs and bearings); default: every joint.
    #[serde(default)]
    joints: Option<Vec<String>>,
    /// The effect's law as a table (`[effect.shape]`: its argument's knots and the
    /// values there, under their names; docs/models.md), replacing its formula.
    #[serde(default)]
    shape: Option<toml::Table>,
}

/// `[[flex]]`: a flexible link (`link = "*"`: every moving link).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FlexSection {
    link: String,
    #[serde(default)]
    ei_n_m2: Option<f64>,
    #[serde(default)]
    youngs_modulus_pa: Option<f64>,
    #[serde(default)]
    outer_diameter_m: Option<f64>,
    #[serde(default)]
    inner_diameter_m: Option<f64>,
    #[serde(default)]
    mass_per_length_kg_m: Option<f64>,
    #[serde(default)]
    density_kg_m3: Option<f64>,
    #[serde(default = "flex_damping")]
    damping_ratio: f64,
    #[serde(default = "two")]
    modes: usize,
    #[serde(default)]
    rigid: bool,
    #[serde(default)]
    effects: Vec<EffectSection>,
}

fn flex_damping() -> f64 {
    0.01
}
fn two() -> usize {
    2
}

/// `[payload]`: a point mass carried by a link.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PayloadSection {
    mass_kg: f64,
    #[serde(default)]
    link: Option<String>,
    #[serde(default)]
    offset_m: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ArmSection {
    urdf: String,
    #[serde(default)]
    tip_frame: Option<String>,
    #[serde(default = "yes")]
    gravity: bool,
    #[serde(default)]
    initial_q_rad: Option<Vec<f64>>,
    #[serde(default = "half_metre")]
    motor_offset_m: f64,
}

fn yes() -> bool {
    true
}
fn half_metre() -> f64 {
    0.5
}
fn one() -> u32 {
    1
}

/// `[sim]`: time step, duration and output options.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimSection {
    /// Step, s.
    pub dt_s: f64,
    /// Length of the run, s.
    pub duration_s: f64,
    /// Write every n-th step to the time series (1 = every step).
    #[serde(default = "one_usize")]
    pub output_every: usize,
    /// Residual vibration is measured over the last this many seconds.
    #[serde(default = "one_f")]
    pub residual_window_s: f64,
}

fn one_usize() -> usize {
    1
}
fn one_f() -> f64 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TransmissionSection {
    joint: String,
    rope: RopeRef,
    #[serde(default)]
    law: Option<LawKind>,
    /// Multiplies the rope's k1 (an identified arm's ropes: `--write-scenario`).
    #[serde(default = "one_f")]
    k1_scale: f64,
    #[serde(default = "one")]
    ropes_in_parallel: u32,
    joint_radius_m: f64,
    #[serde(default)]
    motor_radius_m: Option<f64>,
    #[serde(default)]
    route: Option<Vec<RelaySection>>,
    #[serde(default)]
    length_m: Option<f64>,
    preload_n: f64,
    #[serde(default)]
    prestretch_n: f64,
    #[serde(default)]
    tensioner: Option<String>,
    #[serde(default)]
    effects: Vec<EffectSection>,
    #[serde(default)]
    relay_friction: Option<RelayFrictionSection>,
    motor: MotorSection,
    #[serde(default)]
    command: Option<CommandSection>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RelaySection {
    joint: String,
    radius_m: f64,
    #[serde(default = "plus")]
    sign: f64,
}

fn plus() -> f64 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RelayFrictionSection {
    coefficient: f64,
    inertia_kg_m2: f64,
    #[serde(default = "slip_rate")]
    slip_rate_rad_s: f64,
}

fn slip_rate() -> f64 {
    longreach_drive::RelayFriction::DEFAULT_SLIP_RATE_RAD_S
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct EffectSection {
    name: String,
    #[serde(default)]
    params: Vec<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MotorSection {
    #[serde(default)]
    mode: Option<String>,
    #[serde(default)]
    inertia_kg_m2: f64,
    #[serde(default)]
    damping_n_m_s: f64,
    #[serde(default)]
    kp_n_m_per_rad: f64,
    #[serde(default)]
    kd_n_m_s_per_rad: f64,
    #[serde(default)]
    torque_limit_n_m: Option<f64>,
    #[serde(default = "yes")]
    gravity_feedforward: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CommandSection {
    kind: String,
    #[serde(default)]
    to_rad: Option<f64>,
    #[serde(default)]
    at_s: Option<f64>,
    #[serde(default)]
    start_s: Option<f64>,
    #[serde(default)]
    max_velocity_rad_s: Option<f64>,
    #[serde(default)]
    max_accel_rad_s2: Option<f64>,
    #[serde(default)]
    amplitude_rad: Option<f64>,
    #[serde(default)]
    frequency_hz: Option<f64>,
    #[serde(default)]
    file: Option<String>,
    #[serde(default)]
    column: Option<String>,
}

/// A parsed arm scenario, ready to run.
#[derive(Debug, Clone)]
pub struct ArmScenario {
    /// The compiled arm.
    pub arm: DrivenArm,
    /// `[sim]`.
    pub sim: SimSection,
    /// The URDF file used.
    pub urdf_path: PathBuf,
    /// The registered effects the transmissions put at their joints (joint index, the
    /// effect with its values), as given to [`DrivenArm::with_joint_effects`] (the
    /// URDF's `<dynamics friction>` is not among them: the arm adds it itself). With
    /// the compiled pairs' specs ([`DrivenArm::pairs`]) they rebuild the arm with other
    /// numbers (the measurement loop's arm plant).
    pub joint_effects: Vec<(usize, Applied)>,
    /// The flexible links (`[[flex]]`), as given to [`DrivenArm::with_flexible_links`]:
    /// a rebuilt arm bends as the scenario's does.
    pub flex_links: Vec<crate::FlexLinkSpec>,
    /// The payload the arm carries, kg (`[payload]`'s mass with the `[[effect]]`s'
    /// changes), already in the spec.
    pub payload_kg: f64,
    /// Where a payload is (and a payload effect adds mass): a frame of the URDF and
    /// the offset in it, m (`[payload]`'s link and offset; the tip frame's origin
    /// without a `[payload]`).
    pub payload_at: (String, [f64; 3]),
    /// Warnings for the user (printed once by the CLI and recorded in its JSON): what
    /// the URDF loader dropped, what `<dynamics friction>` became, a coarse time step.
    pub warnings: Vec<String>,
}

impl ArmScenario {
    /// The URDF names of the flexible links ([`Self::flex_links`]), in their order.
    pub fn flex_link_names(&self) -> Vec<String> {
        let links = &self.arm.spec().links;
        self.flex_links
            .iter()
            .filter_map(|f| links.get(f.link).map(|l| l.name.clone()))
            .collect()
    }
}

/// Merges `defaults` into `t` (keys absent from `t`; nested tables recursively).
fn merge(t: &mut toml::Table, defaults: &toml::Table) {
    for (k, v) in defaults {
        match (t.get_mut(k), v) {
            (Some(toml::Value::Table(a)), toml::Value::Table(b)) => merge(a, b),
            (Some(_), _) => {}
            (None, _) => {
                t.insert(k.clone(), v.clone());
            }
        }
    }
}

/// Reads and compiles an arm scenario file.
pub fn load(path: &Path) -> Result<ArmScenario, ScenarioError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ScenarioError {
        file: file.clone(),
        line: None,
        field: String::new(),
        message: format!("cannot read: {e}"),
        fix: "check the path".into(),
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    parse(&text, &file, base)
}

/// The scenario `text` (whose relative paths resolve against `base`) with every file
/// it names (`arm.urdf`, `transmission[].command.file`) made absolute, so that the text
/// runs from any folder (the batch runner's `--keep-outputs` copies). Text that is not
/// a TOML table comes back unchanged (parsing it reports the error).
pub fn with_absolute_paths(text: &str, base: &Path) -> String {
    let Ok(mut doc) = text.parse::<toml::Table>() else {
        return text.to_string();
    };
    let absolute = |v: &mut toml::Value| {
        if let Some(p) = v.as_str().map(Path::new).filter(|p| p.is_relative()) {
            let full = base.join(p);
            let full = full.canonicalize().unwrap_or(full);
            *v = toml::Value::String(full.display().to_string());
        }
    };
    if let Some(urdf) = doc
        .get_mut("arm")
        .and_then(|a| a.as_table_mut())
        .and_then(|a| a.get_mut("urdf"))
    {
        absolute(urdf);
    }
    if let Some(ts) = doc.get_mut("transmission").and_then(|t| t.as_array_mut()) {
        for t in ts {
            if let Some(file) = t
                .get_mut("command")
                .and_then(|c| c.as_table_mut())
                .and_then(|c| c.get_mut("file"))
            {
                absolute(file);
            }
        }
    }
    toml::to_string(&doc).unwrap_or_else(|_| text.to_string())
}

/// Compiles the scenario `text` (from `file`; relative paths resolve against `base`).
pub fn parse(text: &str, file: &str, base: &Path) -> Result<ArmScenario, ScenarioError> {
    let doc: ArmFile = toml::from_str(text).map_err(|e| toml_error(text, file, &e))?;
    let ferr = |field: &str, msg: String, fix: &str| field_error(text, file, field, msg, fix);
    let urdf_path = base.join(&doc.arm.urdf);
    let mut spec = load_urdf(&urdf_path).map_err(|e| {
        let fix = if matches!(e, crate::UrdfError::Io { .. }) {
            "give the URDF path relative to the scenario file"
        } else {
            "correct the URDF where the message points (docs/arm.md says what the loader accepts)"
        };
        ferr("arm.urdf", e.to_string(), fix)
    })?;
    if let Some(tip) = &doc.arm.tip_frame {
        spec.set_tip_frame(tip)
            .map_err(|e| ferr("arm.tip_frame", e.to_string(), "name a link of the URDF"))?;
    }
    if !doc.arm.gravity {
        spec.gravity_m_s2 = nalgebra::Vector3::zeros();
    }
    // Flexible links, from the URDF's own masses (a payload rides on the link's end).
    let flex = parse_flex(&doc, &spec, text, file)?;
    // Arm-wide effects (`[[effect]]`), each applied at its sites: the payload's first,
    // before anything is built from the spec; the pairs' and joints' below.
    let mut arm_effects = Vec::new();
    for (i, e) in doc.effect.iter().enumerate() {
        let field = format!("effect.{i}");
        let mut a = registered(&e.name, &e.params, &field, &ferr)?;
        if let Some(t) = &e.shape {
            a = shaped(a, t, &format!("{field}.shape"), &ferr)?;
        }
        if a.effect.site() == Site::Sensor {
            return Err(ferr(
                &field,
                format!(
                    "'{}' acts at a sensor, which an arm run does not model",
                    e.name
                ),
                "keep sensor effects in model files for compare/diagnose",
            ));
        }
        let mut probe = longreach_drive::effects::LinkBending {
            ei_n_m2: 1.0,
            damping_ratio: 0.0,
        };
        if a.apply_to_link(&mut probe)
            .map_err(|err| ferr(&field, err.to_string(), "give values within the bounds"))?
        {
            return Err(ferr(
                &field,
                format!("'{}' acts on a flexible link's bending", e.name),
                "give it in the effects of that link's [[flex]] table (docs/arm.md)",
            ));
        }
        arm_effects.push((field, a));
    }
    let mut payload = Payload {
        mass_kg: doc.payload.as_ref().map_or(0.0, |p| p.mass_kg),
    };
    if let Some(pl) = &doc.payload {
        if !(pl.mass_kg.is_finite() && pl.mass_kg >= 0.0) {
            return Err(ferr(
                "payload.mass_kg",
                format!("mass_kg = {}", pl.mass_kg),
                "give the payload mass in kg, >= 0",
            ));
        }
        if let Some(o) = pl.offset_m.filter(|o| o.iter().any(|v| !v.is_finite())) {
            return Err(ferr(
                "payload.offset_m",
                format!("offset_m = {o:?}"),
                "give three finite coordinates in m, in the frame of the payload link",
            ));
        }
    }
    for (field, a) in &arm_effects {
        a.apply_to_payload(&mut payload).map_err(|e| {
            ferr(
                field,
                e.to_string(),
                "keep the payload (scenario's plus effects') >= 0 kg",
            )
        })?;
    }
    // The payload's point: `[payload]`'s link and offset; the tip frame's origin for a
    // payload that only effects give. No payload at all: the arm as the URDF says.
    let pl = doc.payload.as_ref();
    let payload_at = (
        match pl {
            Some(pl) => pl
                .link
                .clone()
                .or_else(|| spec.links.last().map(|l| l.name.clone()))
                .unwrap_or_default(),
            None => spec.tip.name.clone(),
        },
        pl.and_then(|p| p.offset_m).unwrap_or([0.0; 3]),
    );
    // The servos' references know the `[payload]`, not what effects add to it (an
    // unknown payload: `payload_mass`): their arm is the one before the effects'.
    let stated_kg = doc.payload.as_ref().map_or(0.0, |p| p.mass_kg);
    let mut controller = None;
    if payload.mass_kg - stated_kg != 0.0 {
        let mut c = spec.clone();
        if doc.payload.is_some() {
            let (link, offset) = (&payload_at.0, nalgebra::Vector3::from(payload_at.1));
            // (a bad link is reported for the arm's own payload below)
            if c.add_payload(link, stated_kg, offset).is_ok() {
                controller = Some(c);
            }
        } else {
            controller = Some(c);
        }
    }
    if doc.payload.is_some() || payload.mass_kg != 0.0 {
        let (link, offset) = (&payload_at.0, nalgebra::Vector3::from(payload_at.1));
        spec.add_payload(link, payload.mass_kg, offset)
            .map_err(|e| {
                ferr(
                    match pl {
                        Some(p) if p.link.is_some() => "payload.link",
                        _ => "payload",
                    },
                    e.to_string(),
                    "name a moving URDF link (or a link fixed to one, such as the tip) in payload.link",
                )
            })?;
    }
    let n = spec.ndofs();
    let s = &doc.sim;
    if !(s.dt_s.is_finite() && s.dt_s > 0.0 && s.dt_s <= 0.05) {
        return Err(ferr(
            "sim.dt_s",
            format!("dt_s = {} s", s.dt_s),
            "give a step in (0, 0.05] s; 1e-3 resolves the arm's modes",
        ));
    }
    if !(s.duration_s.is_finite() && s.duration_s > 0.0) {
        return Err(ferr(
            "sim.duration_s",
            format!("duration_s = {}", s.duration_s),
            "give a positive duration in s",
        ));
    }
    if let Err(steps) = longreach_scenario::limits::check_steps(s.duration_s, s.dt_s) {
        return Err(ferr(
            "sim.duration_s",
            format!(
                "duration_s = {} s at dt_s = {} s is {steps:.3e} steps, past the limit of {:.0e} steps per run",
                s.duration_s,
                s.dt_s,
                longreach_scenario::limits::MAX_STEPS_PER_RUN
            ),
            "shorten duration_s (or lengthen dt_s), or split the run into several scenarios",
        ));
    }
    if s.output_every == 0 {
        return Err(ferr("sim.output_every", "0".into(), "give 1 or more"));
    }
    if !(s.residual_window_s.is_finite() && s.residual_window_s > 0.0) {
        return Err(ferr(
            "sim.residual_window_s",
            format!(
                "residual_window_s = {} s is not a window of the run",
                s.residual_window_s
            ),
            "give a positive window in s, e.g. 2.0 for the last 2 s",
        ));
    }
    let initial = doc
        .arm
        .initial_q_rad
        .clone()
        .unwrap_or_else(|| vec![0.0; n]);
    if initial.len() != n || initial.iter().any(|v| !v.is_finite()) {
        return Err(ferr(
            "arm.initial_q_rad",
            format!(
                "{} values for {n} joints (or a non-finite value)",
                initial.len()
            ),
            "give one finite angle per moving joint, in rad",
        ));
    }
    // Parse every transmission (defaults merged in).
    let mut sections = Vec::new();
    for (i, t) in doc.transmission.iter().enumerate() {
        let sec: TransmissionSection = table_entry(
            t,
            doc.transmission_defaults.as_ref(),
            "transmission",
            i,
            &ferr,
        )?;
        sections.push(sec);
    }
    let joint_of = |name: &str, field: &str| {
        spec.joint_index(name).ok_or_else(|| {
            ferr(
                field,
                format!("no moving joint named '{name}'"),
                &format!(
                    "use one of: {}",
                    spec.joints
                        .iter()
                        .map(|j| j.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )
        })
    };
    let mut joints = Vec::new();
    for (i, sec) in sections.iter().enumerate() {
        joints.push(joint_of(&sec.joint, &format!("transmission.{i}.joint"))?);
    }
    let mut joint_radius = vec![None; n];
    for (sec, &j) in sections.iter().zip(&joints) {
        joint_radius[j] = Some(sec.joint_radius_m);
    }
    let mut pairs = Vec::new();
    let mut joint_effects = Vec::new();
    let mut commands = vec![Command::Hold; n];
    for (i, (sec, &j)) in sections.iter().zip(&joints).enumerate() {
        let f = |k: &str| format!("transmission.{i}.{k}");
        let (rope_name, params, mut law) =
            resolve_rope(text, file, &f("rope"), &sec.rope, sec.law)?;
        if !(sec.k1_scale.is_finite() && sec.k1_scale > 0.0) {
            return Err(ferr(
                &f("k1_scale"),
                format!("k1_scale must be a positive number, got {}", sec.k1_scale),
                "give the factor on the rope's k1 (1: the rope as catalogued)",
            ));
        }
        law.k1_n *= sec.k1_scale;
        // Registered effects of this transmission, `effects = [{ name, params = [...] }]`
        // (parameters in the effect's order; none: its defaults), applied at their
        // sites once the pair is built: the rope law and the pair, or the driven joint.
        let mut applied = Vec::new();
        for (e_i, e) in sec.effects.iter().enumerate() {
            let field = f(&format!("effects.{e_i}"));
            let a = registered(&e.name, &e.params, &field, &ferr)?;
            let eff = a.effect;
            if matches!(eff.site(), Site::Link | Site::Sensor) {
                return Err(ferr(
                    &field,
                    format!(
                        "'{}' acts at the {} site, not at a transmission",
                        e.name,
                        eff.site().as_str()
                    ),
                    "give it as an arm-wide [[effect]] table (docs/arm.md)",
                ));
            }
            if eff.site() == Site::RelayPulley && sec.relay_friction.is_some() {
                return Err(ferr(
                    &field,
                    "relay friction given twice (as an effect and as relay_friction = {...})"
                        .into(),
                    "keep one of the two",
                ));
            }
            if eff.site() == Site::Link {
                return Err(ferr(
                    &field,
                    format!("'{}' acts at the link site, not on a rope pair", e.name),
                    "give it to a [[flex]] link: effects = [{ name = \"link_flexibility\", params = [...] }]",
                ));
            }
            applied.push((field, a));
        }
        let route = match &sec.route {
            Some(r) => {
                let mut out = Vec::new();
                for (k, relay) in r.iter().enumerate() {
                    out.push(Relay {
                        joint: Some(joint_of(&relay.joint, &f(&format!("route.{k}.joint")))?),
                        radius_m: relay.radius_m,
                        sign: relay.sign,
                    });
                }
                out
            }
            None => {
                let mut out = Vec::new();
                for k in proximal_joints(&spec, j) {
                    let radius_m = joint_radius[k].ok_or_else(|| {
                        ferr(
                            &f("route"),
                            format!(
                                "the rope passes joint '{}', which has no transmission to take the relay radius from",
                                spec.joints[k].name
                            ),
                            "give route = [{ joint = \"...\", radius_m = ..., sign = 1 }, ...] explicitly",
                        )
                    })?;
                    out.push(Relay {
                        joint: Some(k),
                        radius_m,
                        sign: 1.0,
                    });
                }
                out
            }
        };
        let chain = chain_lengths_m(&spec, j, doc.arm.motor_offset_m);
        let length_m = sec.length_m.unwrap_or_else(|| chain.iter().sum());
        let spans = relay_span_lengths_m(&spec, j, &chain, &route, length_m);
        let tensioner = match sec.tensioner.as_deref() {
            None | Some("fixed") => Tensioner::Fixed,
            Some("constant_force") => Tensioner::ConstantForce,
            Some(other) => {
                return Err(ferr(
                    &f("tensioner"),
                    format!("unknown tensioner '{other}'"),
                    "use \"fixed\" or \"constant_force\"",
                ))
            }
        };
        let m = &sec.motor;
        let mode = match m.mode.as_deref() {
            None | Some("servo") => MotorMode::Servo {
                kp_n_m_per_rad: m.kp_n_m_per_rad,
                kd_n_m_s_per_rad: m.kd_n_m_s_per_rad,
                torque_limit_n_m: m.torque_limit_n_m.unwrap_or(f64::INFINITY),
                gravity_feedforward: m.gravity_feedforward,
            },
            Some("kinematic") => MotorMode::Kinematic,
            Some(other) => {
                return Err(ferr(
                    &f("motor.mode"),
                    format!("unknown motor mode '{other}'"),
                    "use \"servo\" or \"kinematic\"",
                ))
            }
        };
        let relay_friction = match &sec.relay_friction {
            None => None,
            Some(r) => {
                let rf = longreach_drive::RelayFriction {
                    coefficient: r.coefficient,
                    inertia_kg_m2: r.inertia_kg_m2,
                    slip_rate_rad_s: r.slip_rate_rad_s,
                    coefficient_table: None,
                };
                if let Err(e) = rf.validate() {
                    // Point at the key in this transmission, or in the defaults.
                    let key = match &e {
                        longreach_drive::DriveError::BadParameter { field, .. } => field
                            .rsplit('.')
                            .next()
                            .unwrap_or("coefficient")
                            .to_string(),
                        _ => "coefficient".into(),
                    };
                    let own = format!("transmission.{i}.relay_friction");
                    let in_own = doc.transmission[i].contains_key("relay_friction");
                    let field = if in_own || doc.transmission_defaults.is_none() {
                        format!("{own}.{key}")
                    } else {
                        format!("transmission_defaults.relay_friction.{key}")
                    };
                    return Err(ferr(
                        &field,
                        e.to_string(),
                        "coefficient in [0, 1) (bearing mu_b r_b / r, typically 0.001-0.05), inertia_kg_m2 >= 0, slip_rate_rad_s > 0",
                    ));
                }
                Some(rf)
            }
        };
        let mut pair = PairSpec {
            joint: j,
            rope_name,
            rope: params,
            law,
            ropes_in_parallel: sec.ropes_in_parallel,
            joint_radius_m: sec.joint_radius_m,
            motor_radius_m: sec.motor_radius_m.unwrap_or(sec.joint_radius_m),
            route,
            length_m,
            span_lengths_m: spans,
            preload_n: sec.preload_n,
            prestretch_n: sec.prestretch_n,
            tensioner,
            motor: MotorSpec {
                inertia_kg_m2: m.inertia_kg_m2,
                damping_n_m_s: m.damping_n_m_s,
                mode,
                friction: None,
            },
            effects: Vec::new(),
            relay_friction,
        };
        for (field, a) in applied {
            a.apply_to_pair(&mut pair).map_err(|err| {
                ferr(
                    &field,
                    err.to_string(),
                    "give one value per parameter, within its bounds",
                )
            })?;
            pair.effects.push(a.effect.name().to_string());
            if a.effect.site() == Site::Joint {
                joint_effects.push((j, a));
            }
        }
        pairs.push(pair);
        if let Some(c) = &sec.command {
            commands[j] = parse_command(c, &f("command"), base, &ferr)?;
        }
    }
    apply_arm_effects(
        &doc.effect,
        &arm_effects,
        n,
        &joint_of,
        &mut pairs,
        &mut joint_effects,
        &ferr,
    )?;
    // What the URDF loader dropped or changed, and what its `<dynamics friction>`
    // becomes (the joint_friction effect, unless the scenario gives that joint its own).
    let mut warnings: Vec<String> = spec
        .warnings
        .iter()
        .map(|w| format!("{}: {w}", urdf_path.display()))
        .collect();
    for (j, joint) in spec.joints.iter().enumerate() {
        let given = joint_effects.iter().any(|(k, a)| {
            *k == j
                && longreach_drive::effects::same(
                    a.effect,
                    &longreach_drive::effects::JointFriction,
                )
        });
        if joint.friction_n_m > 0.0 && !given {
            warnings.push(format!(
                "{}: joint {}: <dynamics friction=\"{}\"> becomes the joint_friction effect (dry friction {} N*m at that joint)",
                urdf_path.display(),
                joint.name,
                joint.friction_n_m,
                joint.friction_n_m
            ));
        }
    }
    warnings.extend(time_step_warnings(file, &spec, &pairs, &initial, s.dt_s));
    let arm = DrivenArm::with_joint_effects(
        spec,
        pairs,
        joint_effects.clone(),
        commands,
        initial,
        s.dt_s,
    )
    .map_err(|e| ferr("transmission", e.to_string(), "correct the named field"))?;
    let mut arm = arm.with_flexible_links(flex.clone()).map_err(|e| {
        ferr(
            "flex",
            e.to_string(),
            "correct the named link's [[flex]] entry",
        )
    })?;
    if let Some(c) = controller {
        arm = arm
            .with_controller_spec(c)
            .map_err(|e| ferr("effect", e.to_string(), "correct the named field"))?;
    }
    Ok(ArmScenario {
        arm,
        sim: doc.sim,
        urdf_path,
        joint_effects,
        flex_links: flex,
        payload_kg: payload.mass_kg,
        payload_at,
        warnings,
    })
}

/// `a` with its law as the table `t` (`[effect.shape]`: the knots under the argument's
/// name, the values under the value's); errors name `field`.
fn shaped(
    a: Applied,
    t: &toml::Table,
    field: &str,
    ferr: &dyn Fn(&str, String, &str) -> ScenarioError,
) -> Result<Applied, ScenarioError> {
    let name = a.effect.name();
    let Some(shape) = a.effect.shape() else {
        return Err(ferr(
            field,
            format!("'{name}' has no shape-free form"),
            "remove [effect.shape]",
        ));
    };
    let (arg, val) = (shape.argument.name(), shape.value);
    let fix = format!(
        "write [effect.shape] with {arg} = [0, ...] (knots from 0, increasing) and {val} = [...] (one value per knot)"
    );
    let list = |key: &str| -> Result<Vec<f64>, ScenarioError> {
        t.get(key)
            .and_then(|v| v.as_array())
            .and_then(|a| {
                a.iter()
                    .map(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
                    .collect::<Option<Vec<f64>>>()
            })
            .ok_or_else(|| {
                ferr(
                    &format!("{field}.{key}"),
                    format!("needs {key} = [numbers]"),
                    &fix,
                )
            })
    };
    if let Some(k) = t.keys().find(|k| ![arg, val, "fit"].contains(&k.as_str())) {
        return Err(ferr(
            &format!("{field}.{k}"),
            format!("unknown key `{k}`"),
            &fix,
        ));
    }
    let table = longreach_rope::Table::new(&list(arg)?, &list(val)?)
        .map_err(|e| ferr(field, e.to_string(), &fix))?;
    Applied::shaped(a.effect, a.values, table).map_err(|e| ferr(field, e.to_string(), &fix))
}

/// The registered effect `name` with `params` (in its order; none: its defaults),
/// checked; errors name `field`.
fn registered(
    name: &str,
    params: &[f64],
    field: &str,
    ferr: &dyn Fn(&str, String, &str) -> ScenarioError,
) -> Result<Applied, ScenarioError> {
    let eff = longreach_drive::effects::find(name).ok_or_else(|| {
        ferr(
            field,
            format!("unknown effect '{name}'"),
            &format!(
                "use one of the registered effects: {}",
                longreach_drive::effects::names().join(", ")
            ),
        )
    })?;
    let values = if params.is_empty() {
        eff.params().iter().map(|p| p.default).collect()
    } else {
        params.to_vec()
    };
    Applied::new(eff, values).map_err(|err| {
        ferr(
            field,
            err.to_string(),
            "give one value per parameter, within its bounds",
        )
    })
}

/// Applies the arm-wide effects (`[[effect]]`, parsed into `applied`) at their pair and
/// joint sites: the rope-law, relay and motor hooks to the pair of every joint in the
/// effect's `joints` (default: every pair), the joint hook at each of those joints
/// (default: every moving joint). An effect a transmission already names is refused.
fn apply_arm_effects(
    sections: &[ArmEffectSection],
    applied: &[(String, Applied)],
    ndofs: usize,
    joint_of: &dyn Fn(&str, &str) -> Result<usize, ScenarioError>,
    pairs: &mut [PairSpec],
    joint_effects: &mut Vec<(usize, Applied)>,
    ferr: &dyn Fn(&str, String, &str) -> ScenarioError,
) -> Result<(), ScenarioError> {
    for (sec, (field, a)) in sections.iter().zip(applied) {
        let joints: Vec<usize> = match &sec.joints {
            None => (0..ndofs).collect(),
            Some(names) => names
                .iter()
                .enumerate()
                .map(|(k, j)| joint_of(j, &format!("{field}.joints.{k}")))
                .collect::<Result<_, _>>()?,
        };
        let name = a.effect.name();
        let twice = |what: &str| {
            ferr(
                field,
                format!("'{name}' given twice on {what}"),
                "keep it in the transmission or in [[effect]], not both",
            )
        };
        for pair in pairs.iter_mut().filter(|p| joints.contains(&p.joint)) {
            if pair.effects.iter().any(|e| e == name)
                || (a.effect.site() == Site::RelayPulley && pair.relay_friction.is_some())
            {
                return Err(twice(&format!("the pair of joint index {}", pair.joint)));
            }
            a.apply_to_pair(pair)
                .map_err(|e| ferr(field, e.to_string(), "give values within the bounds"))?;
            pair.effects.push(name.to_string());
        }
        if a.effect.site() == Site::Joint {
            for &j in &joints {
                if joint_effects
                    .iter()
                    .any(|(k, b)| *k == j && longreach_drive::effects::same(a.effect, b.effect))
                {
                    return Err(twice(&format!("joint index {j}")));
                }
                joint_effects.push((j, a.clone()));
            }
        }
    }
    Ok(())
}

/// Entry `i` of the array of tables `what` (`[[transmission]]`, `[[flex]]`) with its
/// defaults merged in, deserialised; errors name the entry.
fn table_entry<T: serde::de::DeserializeOwned>(
    t: &toml::Table,
    defaults: Option<&toml::Table>,
    what: &str,
    i: usize,
    ferr: &dyn Fn(&str, String, &str) -> ScenarioError,
) -> Result<T, ScenarioError> {
    let mut t = t.clone();
    if let Some(d) = defaults {
        merge(&mut t, d);
    }
    toml::Value::Table(t)
        .try_into()
        .map_err(|e: toml::de::Error| {
            ferr(
                &format!("{what}.{i}"),
                format!("{what} {i}: {}", e.message().trim()),
                &format!("see docs/arm.md for the fields of a [[{what}]] table"),
            )
        })
}

/// `[[flex]]` entries (with `[flex_defaults]` merged in) -> flexible links; entries
/// with `rigid = true` stay rigid. A link named twice takes its own entry over `"*"`.
fn parse_flex(
    doc: &ArmFile,
    spec: &crate::ArmSpec,
    text: &str,
    file: &str,
) -> Result<Vec<crate::FlexLinkSpec>, ScenarioError> {
    let ferr = |field: &str, msg: String, fix: &str| field_error(text, file, field, msg, fix);
    let mut by_link: Vec<Option<(bool, crate::FlexLinkSpec)>> = vec![None; spec.links.len()];
    for (i, t) in doc.flex.iter().enumerate() {
        let f = |k: &str| format!("flex.{i}.{k}");
        let sec: FlexSection = table_entry(t, doc.flex_defaults.as_ref(), "flex", i, &ferr)?;
        let all = sec.link == "*";
        let links: Vec<usize> = if all {
            (1..spec.links.len()).collect()
        } else {
            match spec.link_index(&sec.link).filter(|&l| l > 0) {
                Some(l) => vec![l],
                None => {
                    return Err(ferr(
                        &f("link"),
                        format!("no moving link named '{}'", sec.link),
                        &format!(
                            "use \"*\" or one of: {}",
                            spec.links[1..]
                                .iter()
                                .map(|l| l.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    ))
                }
            }
        };
        let ei = match (sec.ei_n_m2, sec.youngs_modulus_pa, sec.outer_diameter_m) {
            (Some(ei), None, None) => ei,
            (None, Some(e), Some(od)) => {
                let id = sec.inner_diameter_m.unwrap_or(0.0);
                if !(od > 0.0 && (0.0..od).contains(&id) && e > 0.0) {
                    return Err(ferr(
                        &f("outer_diameter_m"),
                        format!("E = {e} Pa, D = {od} m, d = {id} m"),
                        "give E > 0 and diameters 0 <= inner < outer, in m",
                    ));
                }
                crate::tube_ei_n_m2(e, od, id)
            }
            _ => {
                return Err(ferr(
                    &format!("flex.{i}"),
                    "bending stiffness missing or given twice".into(),
                    "give either ei_n_m2, or youngs_modulus_pa with outer_diameter_m (and inner_diameter_m)",
                ))
            }
        };
        if !sec.rigid && !(1..=crate::flex::MAX_MODES).contains(&sec.modes) {
            return Err(ferr(
                &f("modes"),
                format!("modes = {}", sec.modes),
                "give 1 to 4 assumed modes per transverse direction (2 is the default)",
            ));
        }
        let mut bending = longreach_drive::effects::LinkBending {
            ei_n_m2: ei,
            damping_ratio: sec.damping_ratio,
        };
        for (e_i, e) in sec.effects.iter().enumerate() {
            let field = f(&format!("effects.{e_i}"));
            let eff = longreach_drive::effects::find(&e.name)
                .filter(|e| e.site() == Site::Link)
                .ok_or_else(|| {
                    ferr(
                        &field,
                        format!("'{}' is not a registered effect at the link site", e.name),
                        "use link_flexibility",
                    )
                })?;
            let values = if e.params.is_empty() {
                eff.params().iter().map(|p| p.default).collect()
            } else {
                e.params.clone()
            };
            Applied::new(eff, values)
                .and_then(|a| a.apply_to_link(&mut bending))
                .map_err(|err| {
                    ferr(
                        &field,
                        err.to_string(),
                        "give one value per parameter, within its bounds",
                    )
                })?;
        }
        for l in links {
            let mu = match (sec.mass_per_length_kg_m, sec.density_kg_m3) {
                (Some(m), None) => Some(m),
                (None, Some(rho)) => {
                    let (Some(od), id) =
                        (sec.outer_diameter_m, sec.inner_diameter_m.unwrap_or(0.0))
                    else {
                        return Err(ferr(
                            &f("density_kg_m3"),
                            "a density needs the tube's section".into(),
                            "give outer_diameter_m (and inner_diameter_m), or mass_per_length_kg_m",
                        ));
                    };
                    Some(rho * std::f64::consts::PI * (od * od - id * id) / 4.0)
                }
                // The link's own URDF mass (before any payload) along its length.
                (None, None) => crate::flex::beam_end(spec, l)
                    .ok()
                    .map(|e| spec.links[l].inertial.mass_kg / e.norm().max(1e-9)),
                _ => {
                    return Err(ferr(
                        &f("density_kg_m3"),
                        "mass per length given twice".into(),
                        "give mass_per_length_kg_m or density_kg_m3, not both",
                    ))
                }
            };
            let entry = crate::FlexLinkSpec {
                link: l,
                ei_n_m2: bending.ei_n_m2,
                damping_ratio: bending.damping_ratio,
                modes: sec.modes,
                mass_per_length_kg_m: mu,
            };
            // A link's own entry wins over "*".
            let keep = match &by_link[l] {
                Some((was_all, _)) => *was_all || !all,
                None => true,
            };
            if keep {
                by_link[l] = Some((
                    all,
                    if sec.rigid {
                        crate::FlexLinkSpec { modes: 0, ..entry }
                    } else {
                        entry
                    },
                ));
            }
        }
    }
    let out: Vec<crate::FlexLinkSpec> = by_link
        .into_iter()
        .flatten()
        .map(|(_, s)| s)
        .filter(|s| s.modes > 0)
        .collect();
    // Check them now (the arm is built after the payload).
    crate::FlexDynamics::new(spec, &out).map_err(|e| {
        let i = doc
            .flex
            .iter()
            .position(|t| t.get("link").and_then(|v| v.as_str()) == Some(e.link.as_str()))
            .unwrap_or(0);
        ferr(
            &format!("flex.{i}"),
            format!("link '{}': {}", e.link, e.reason),
            "correct the link's [[flex]] entry",
        )
    })?;
    Ok(out)
}

/// Relative frequency error of a mode above which `run` warns about the time step:
/// an arm's metrics are settling times and overshoots, for which 1% is the resolution.
pub const ARM_MODE_ERROR_WARN: f64 = 1e-2;

/// The arm's fastest modes against the time step: each pair's joint on its ropes (the
/// head springs of both ropes, the joint's effective inertia `1 / (M^-1)_jj` at the
/// initial pose) and its servo motor on them; a warning, with the step that resolves
/// it, for each mode the trapezoidal rule moves by more than [`ARM_MODE_ERROR_WARN`].
/// (Relay pulleys' own modes are not resolved by design: they carry no metric.)
fn time_step_warnings(
    file: &str,
    spec: &crate::ArmSpec,
    pairs: &[PairSpec],
    initial: &[f64],
    dt_s: f64,
) -> Vec<String> {
    let minv = crate::dynamics::mass_matrix(spec, initial)
        .ok()
        .and_then(|m| m.try_inverse());
    let mut worst: Option<(f64, String)> = None;
    for p in pairs {
        let k = 2.0 * f64::from(p.ropes_in_parallel) * p.law.k1_n / p.length_m;
        let joint = &spec.joints[p.joint].name;
        let mut modes = Vec::new();
        if let Some(minv) = &minv {
            let inv_inertia = minv[(p.joint, p.joint)];
            if inv_inertia > 0.0 {
                modes.push((
                    (k * p.joint_radius_m.powi(2) * inv_inertia).sqrt(),
                    format!("joint {joint} on its ropes"),
                ));
            }
        }
        if matches!(p.motor.mode, MotorMode::Servo { .. }) && p.motor.inertia_kg_m2 > 0.0 {
            modes.push((
                (k * p.motor_radius_m.powi(2) / p.motor.inertia_kg_m2).sqrt(),
                format!("the motor of joint {joint} on its ropes"),
            ));
        }
        for (omega, what) in modes {
            if omega.is_finite() && worst.as_ref().is_none_or(|w| omega > w.0) {
                worst = Some((omega, what));
            }
        }
    }
    let Some((omega, what)) = worst else {
        return Vec::new();
    };
    let error = longreach_scenario::bode::trapezoid_frequency_error(omega, dt_s);
    if error <= ARM_MODE_ERROR_WARN {
        return Vec::new();
    }
    let good_dt = (12.0 * ARM_MODE_ERROR_WARN).sqrt() / omega;
    vec![format!(
        "{file}: sim.dt_s = {dt_s} s resolves the fastest mode ({what}, {:.1} Hz) to {:.1}% in frequency; sim.dt_s <= {good_dt:.3e} s resolves it to {:.0}%",
        omega / std::f64::consts::TAU,
        100.0 * error,
        100.0 * ARM_MODE_ERROR_WARN
    )]
}

fn parse_command(
    c: &CommandSection,
    field: &str,
    base: &Path,
    ferr: &dyn Fn(&str, String, &str) -> ScenarioError,
) -> Result<Command, ScenarioError> {
    let need = |v: Option<f64>, k: &str| {
        v.filter(|x| x.is_finite()).ok_or_else(|| {
            ferr(
                &format!("{field}.{k}"),
                format!("a '{}' command needs a finite `{k}`", c.kind),
                &format!("add {k} = <value> to the command table"),
            )
        })
    };
    let positive = |v: f64, k: &str| {
        if v > 0.0 {
            Ok(v)
        } else {
            Err(ferr(
                &format!("{field}.{k}"),
                format!("{k} = {v}"),
                "give a value > 0",
            ))
        }
    };
    // A time the command starts at: finite and >= 0 (a NaN would never fire).
    let time = |v: Option<f64>, k: &str| {
        let v = v.unwrap_or(0.0);
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(ferr(
                &format!("{field}.{k}"),
                format!("{k} = {v} is not a time"),
                "give a finite time >= 0 in s, within sim.duration_s",
            ))
        }
    };
    Ok(match c.kind.as_str() {
        "hold" => Command::Hold,
        "step" => Command::Step {
            to_rad: need(c.to_rad, "to_rad")?,
            at_s: time(
                c.at_s.or(c.start_s),
                if c.at_s.is_some() { "at_s" } else { "start_s" },
            )?,
        },
        "trapezoid" => Command::Trapezoid {
            to_rad: need(c.to_rad, "to_rad")?,
            start_s: time(c.start_s, "start_s")?,
            max_velocity_rad_s: positive(
                need(c.max_velocity_rad_s, "max_velocity_rad_s")?,
                "max_velocity_rad_s",
            )?,
            max_accel_rad_s2: positive(
                need(c.max_accel_rad_s2, "max_accel_rad_s2")?,
                "max_accel_rad_s2",
            )?,
        },
        "sine" => Command::Sine {
            amplitude_rad: need(c.amplitude_rad, "amplitude_rad")?,
            frequency_hz: positive(need(c.frequency_hz, "frequency_hz")?, "frequency_hz")?,
            start_s: time(c.start_s, "start_s")?,
        },
        "csv" => {
            let file = c.file.as_ref().ok_or_else(|| {
                ferr(&format!("{field}.file"), "a csv command needs `file`".into(), "add file = \"path.csv\" (columns time_s and an angle column, rad, offset from the initial angle)")
            })?;
            let column = c.column.clone().unwrap_or_else(|| "angle_rad".into());
            let path = base.join(file);
            let series = read_series(&path, &column).map_err(|m| {
                ferr(
                    &format!("{field}.file"),
                    m,
                    "give a CSV with a header, a time_s column and the named angle column",
                )
            })?;
            Command::Signal(series)
        }
        other => {
            return Err(ferr(
                &format!("{field}.kind"),
                format!("unknown command kind '{other}'"),
                "use hold, step, trapezoid, sine or csv",
            ))
        }
    })
}

fn read_series(path: &Path, column: &str) -> Result<longreach_drive::InputSignal, String> {
    let mut rdr = csv::Reader::from_path(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let headers = rdr.headers().map_err(|e| e.to_string())?.clone();
    let ti = headers
        .iter()
        .position(|h| h == "time_s")
        .ok_or("no time_s column")?;
    let ai = headers
        .iter()
        .position(|h| h == column)
        .ok_or_else(|| format!("no column '{column}'"))?;
    let (mut t, mut a) = (Vec::new(), Vec::new());
    for rec in rdr.records() {
        let rec = rec.map_err(|e| {
            let line = e
                .position()
                .map_or(String::new(), |p| format!(":{}", p.line()));
            format!("{}{line}: {e}", path.display())
        })?;
        let line = rec.position().map_or(0, |p| p.line());
        let parse = |i: usize| -> Result<f64, String> {
            let cell = rec.get(i).unwrap_or("").trim();
            let v = cell.parse::<f64>().map_err(|_| {
                format!(
                    "{}:{line}: column '{}': \"{cell}\" is not a number",
                    path.display(),
                    &headers[i]
                )
            })?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(format!(
                    "{}:{line}: column '{}': {v} is not a finite number",
                    path.display(),
                    &headers[i]
                ))
            }
        };
        t.push(parse(ti)?);
        a.push(parse(ai)?);
    }
    longreach_drive::InputSignal::series(t, a).map_err(|e| format!("{}: {e}", path.display()))
}

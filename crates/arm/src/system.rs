//! The driven arm: links + rope pairs + motors + servos, integrated together in
//! reduced coordinates with an implicit, energy-consistent scheme.
//!
//! # Equations
//!
//! ```text
//! M(q) qdd + C(q, qd) qd + g(q) + D qd = R^T phi + tau_loads     (arm, phi_p = n_p (f+ - f-))
//! J_m thdd_p + b_m thd_p = tau_servo,p - r_m phi_p                (motor p)
//! f+- = rope law of strain (x_p +- u_p) / L_p,  u_p = r_m th_p - R[p] . q
//! f+ + f- = 2 T_p                                                 (constant-force tensioner)
//! tau_servo = sat(kp (th_ref - th) + kd (thd_ref - thd) + r_m phi_static(q_ref))
//! ```
//!
//! The arm is the joint side ([`JointSide`]: the links' dynamics by allocation-free
//! Newton-Euler and composite rigid bodies, [`crate::fast`]) of the transmission core's
//! implicit step ([`Drivetrain::step`], crates/drive/src/transmission): the pairs, their
//! motors, tensioners and relay pulleys, and the effects at the joints are the core's.
//! What is the arm's own is its references stage: joint commands -> motor references,
//! reference rates and gravity feed-forward ([`DrivenArm::step`]).
//!
//! # Integration (why not rapier's step)
//!
//! rapier's multibody step is semi-implicit Euler with explicit joint forces: with
//! ropes of 10^5..10^6 N/m on 25 mm pulleys it needs tiny steps and it loses energy
//! at first order. Here every unknown of the step is implicit, exactly like the rig
//! plant ([`longreach_drive::RigModel`]): the trapezoidal rule (Newmark average
//! acceleration: unconditionally stable, second order, no numerical damping) for the
//! joints and motors, the exact-hold step for each rope, and Newton's method on the
//! end-of-step state (see [`longreach_drive::transmission::step`]).

use crate::command::Command;
use crate::error::ArmError;
use crate::fast::{FastDynamics, Kin};
use crate::flex::{FlexDynamics, FlexKin, FlexLinkSpec};
use crate::spec::ArmSpec;
use longreach_drive::effects::{self, Applied, JointFriction};
use longreach_drive::transmission::{
    CompiledPair, Drivetrain, JointLoad, JointSide, MotorInputs, PairSpec, PlantState,
    RoutingMatrix,
};
use longreach_drive::DriveError;
use nalgebra::{DMatrix, Vector3};

pub use longreach_drive::transmission::{StaticPair, RELAY_NEWTON_TOLERANCE};

/// A compiled driven arm (immutable; share it between runs).
#[derive(Debug, Clone)]
pub struct DrivenArm {
    spec: ArmSpec,
    dynamics: FastDynamics,
    /// The rope pairs (compiled for `dt_s`) and the effects at the joints.
    drive: Drivetrain,
    routing: RoutingMatrix,
    commands: Vec<Command>,
    initial_q_rad: Vec<f64>,
    compensate_routing: bool,
    dt_s: f64,
    damping: Vec<f64>,
    /// `phi = ff_map * g_driven`: inverse of `R^T` restricted to the driven joints.
    ff_map: Vec<f64>,
    /// Driven joint of each row of `ff_map`'s input.
    driven: Vec<usize>,
    /// The links' dynamics when some bend ([`crate::flex`]); `None`: every link rigid
    /// (the rigid code path, unchanged).
    flex: Option<FlexDynamics>,
    /// The flexible links `flex` was built from (for [`Controller::flex`]).
    flex_links: Vec<FlexLinkSpec>,
    /// The arm the servos' references are computed for, when it is not the arm
    /// simulated ([`Self::with_controller_spec`]); `None`: the servos know the arm.
    controller: Option<Box<Controller>>,
}

/// The arm as the servos' references see it ([`DrivenArm::with_controller_spec`]): a
/// payload the controller does not know (the `payload_mass` effect) loads the arm
/// simulated, not the gravity feed-forward and static stretch of the references.
#[derive(Debug, Clone)]
struct Controller {
    spec: ArmSpec,
    dynamics: FastDynamics,
    /// Its flexible links' dynamics, when the arm's links bend.
    flex: Option<FlexDynamics>,
}

/// Mutable state of a [`DrivenArm`]: the transmission core's state with the arm's own
/// buffers ([`ArmScratch`]).
pub type DrivenState = PlantState<ArmScratch>;

/// The arm's buffers and caches in a [`DrivenState`]: kinematics scratch, and the
/// gravity torques, feed-forward and reference rates of the last joint references (a
/// cache of a pure function of the references: recomputed whenever they change).
#[derive(Debug, Clone)]
pub struct ArmScratch {
    kin: Kin,
    tau: Vec<f64>,
    zero: Vec<f64>,
    g: Vec<f64>,
    ff: Vec<f64>,
    ref_rate: Vec<f64>,
    /// Joint references the motor references and feed-forward were computed for.
    last_qref: Vec<f64>,
    /// Flexible arms: kinematics scratch, the trial coordinates of the iteration, the
    /// generalised forces, and the sagged pose of the last references.
    fkin: FlexKin,
    q1: Vec<f64>,
    ftau: Vec<f64>,
    sag_q: Vec<f64>,
    fzero: Vec<f64>,
}

/// Energy of the driven arm, J.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SystemEnergy {
    /// Links (and armatures).
    pub links_kinetic_j: f64,
    /// Gravity.
    pub potential_j: f64,
    /// Motor rotors.
    pub motors_kinetic_j: f64,
    /// Rope springs (every rope in parallel counted).
    pub ropes_j: f64,
    /// Constant-force tensioners, `-2 n T x`.
    pub tensioners_j: f64,
    /// Relay pulleys (rotation relative to their mounts; every parallel rope's own).
    pub relays_kinetic_j: f64,
    /// Energy stored in the states of effects at the joints.
    pub effects_j: f64,
    /// Bending of flexible links.
    pub links_elastic_j: f64,
}

impl SystemEnergy {
    /// Sum of every term, J.
    pub fn total_j(&self) -> f64 {
        self.links_kinetic_j
            + self.potential_j
            + self.motors_kinetic_j
            + self.ropes_j
            + self.tensioners_j
            + self.relays_kinetic_j
            + self.effects_j
            + self.links_elastic_j
    }
}

fn bad(field: &str, reason: String) -> ArmError {
    ArmError::BadTransmission {
        field: field.to_string(),
        reason,
    }
}

/// One command per joint of an arm of `n` joints.
fn check_commands(commands: &[Command], n: usize) -> Result<(), ArmError> {
    if commands.len() == n {
        Ok(())
    } else {
        Err(bad(
            "command",
            format!(
                "{} commands for {n} joints: give one per joint",
                commands.len()
            ),
        ))
    }
}

impl From<DriveError> for ArmError {
    fn from(e: DriveError) -> Self {
        match e {
            DriveError::BlowUp { time_s, what } => ArmError::BlowUp {
                time_s,
                detail: what,
            },
            DriveError::BadTransmission { field, reason } => {
                ArmError::BadTransmission { field, reason }
            }
            other => ArmError::BadTransmission {
                field: "transmission".into(),
                reason: other.to_string(),
            },
        }
    }
}

impl DrivenArm {
    /// Compiles the arm with its pairs and commands for steps of `dt_s`.
    pub fn new(
        spec: ArmSpec,
        pairs: Vec<PairSpec>,
        commands: Vec<Command>,
        initial_q_rad: Vec<f64>,
        dt_s: f64,
    ) -> Result<Self, ArmError> {
        Self::with_joint_effects(spec, pairs, Vec::new(), commands, initial_q_rad, dt_s)
    }

    /// [`Self::new`] with registered effects at joints (`joint_effects`: joint index and
    /// the effect with its values; [`longreach_drive::effects`]): each adds its passive
    /// torque at its joint. Effects at the pairs' sites (rope law, relays) are applied
    /// to the [`PairSpec`]s before ([`longreach_drive::effects::Applied::apply_to_pair`]).
    pub fn with_joint_effects(
        spec: ArmSpec,
        pairs: Vec<PairSpec>,
        joint_effects: Vec<(usize, Applied)>,
        commands: Vec<Command>,
        initial_q_rad: Vec<f64>,
        dt_s: f64,
    ) -> Result<Self, ArmError> {
        spec.validate()?;
        let n = spec.ndofs();
        if !(dt_s.is_finite() && dt_s > 0.0 && dt_s <= 0.05) {
            return Err(ArmError::BadTimeStep { dt_s });
        }
        crate::error::check_joint_vector(&spec.name, n, "initial_q_rad", &initial_q_rad)?;
        check_commands(&commands, n)?;
        let mut seen = vec![false; n];
        let mut compiled = Vec::with_capacity(pairs.len());
        for (i, p) in pairs.iter().enumerate() {
            let jn = spec.joints.get(p.joint).map_or("?", |j| j.name.as_str());
            let field = format!("transmission[{i}] (joint {jn})");
            if p.joint < n && seen[p.joint] {
                return Err(bad(
                    &format!("{field}.joint"),
                    "a second transmission on the same joint: give one pair per joint".into(),
                ));
            }
            let pair = CompiledPair::new(p.clone(), n, dt_s, &field)?;
            seen[p.joint] = true;
            compiled.push(pair);
        }
        let routing = RoutingMatrix::new(&pairs, n);
        // Feed-forward map: R^T phi = g on the driven joints.
        let driven: Vec<usize> = compiled.iter().map(|p| p.spec.joint).collect();
        let np = driven.len();
        let mut rt = DMatrix::zeros(np, np);
        for (a, &j) in driven.iter().enumerate() {
            for b in 0..np {
                rt[(a, b)] = compiled[b].row[j];
            }
        }
        let ff_map = if np == 0 {
            vec![]
        } else {
            let inv = rt.try_inverse().ok_or_else(|| {
                bad(
                    "route",
                    "the routing matrix restricted to the driven joints is singular".into(),
                )
            })?;
            let mut v = Vec::with_capacity(np * np);
            for a in 0..np {
                for b in 0..np {
                    v.push(inv[(a, b)]);
                }
            }
            v
        };
        // The URDF's `<dynamics friction>` is the dry friction of that joint's bearing:
        // a `joint_friction` effect there, unless the caller gives that joint its own.
        let mut joint_effects = joint_effects;
        for (j, joint) in spec.joints.iter().enumerate() {
            let given = joint_effects
                .iter()
                .any(|(k, a)| *k == j && effects::same(a.effect, &JointFriction));
            if joint.friction_n_m > 0.0 && !given {
                let a = JointFriction::dry(joint.friction_n_m).map_err(|e| {
                    bad(
                        &format!("joint {} <dynamics friction>", joint.name),
                        e.to_string(),
                    )
                })?;
                joint_effects.push((j, a));
            }
        }
        let mut loads = Vec::new();
        for (joint, a) in joint_effects {
            let field = format!(
                "joint {} effect {}",
                spec.joints.get(joint).map_or("?", |j| j.name.as_str()),
                a.effect.name()
            );
            let force = a
                .joint_force()
                .map_err(|e| bad(&field, e.to_string()))?
                .ok_or_else(|| {
                    bad(
                        &field,
                        format!(
                            "acts at the {} site, not at a joint: give it to a transmission",
                            a.effect.site().as_str()
                        ),
                    )
                })?;
            loads.push(JointLoad {
                joint,
                effect: a.effect.name(),
                force,
            });
        }
        let drive = Drivetrain::new(compiled, loads, n, dt_s, None)?;
        Ok(Self {
            dynamics: FastDynamics::new(&spec),
            damping: spec
                .joints
                .iter()
                .map(|j| j.damping_n_m_s_per_rad)
                .collect(),
            spec,
            drive,
            routing,
            commands,
            initial_q_rad,
            compensate_routing: true,
            dt_s,
            ff_map,
            driven,
            flex: None,
            flex_links: Vec::new(),
            controller: None,
        })
    }

    /// The same arm with the links `links` flexible ([`crate::flex`]): each adds
    /// `2 * modes` coordinates after the joints. An empty list leaves the arm rigid
    /// (bitwise the rigid arm's results).
    pub fn with_flexible_links(mut self, links: Vec<FlexLinkSpec>) -> Result<Self, ArmError> {
        if links.is_empty() {
            self.flex_links.clear();
            if let Some(c) = &mut self.controller {
                c.flex = None;
            }
            if self.flex.take().is_some() {
                let n = self.spec.ndofs();
                return self.recompile(n);
            }
            return Ok(self);
        }
        let fd = self.flex_dynamics(&self.spec, &links)?;
        let nq = fd.ncoords();
        self.flex = Some(fd);
        if let Some(mut c) = self.controller.take() {
            c.flex = Some(self.flex_dynamics(&c.spec, &links)?);
            self.controller = Some(c);
        }
        self.flex_links = links;
        self.recompile(nq)
    }

    /// The dynamics of `spec` with the flexible links `links`, under the arm's gravity.
    fn flex_dynamics(
        &self,
        spec: &ArmSpec,
        links: &[FlexLinkSpec],
    ) -> Result<FlexDynamics, ArmError> {
        let mut fd = FlexDynamics::new(spec, links)
            .map_err(|e| bad(&format!("flex (link {})", e.link), e.reason))?;
        fd.set_gravity(self.spec.gravity_m_s2);
        Ok(fd)
    }

    /// The same arm with its servos' references (gravity feed-forward, static stretch
    /// `u_static`, motor reference angles) computed for the arm `spec` instead of the
    /// arm simulated: the controller's belief, e.g. the payload it was told, while the
    /// arm carries another (the `payload_mass` effect: a payload unknown to the
    /// controller). `spec` must have the arm's joints (the same URDF; masses may
    /// differ). The arm then starts at rest where the real statics put it with the
    /// servos holding the first command ([`Self::initial_state`]): a heavier payload
    /// sags. Call it after [`Self::with_flexible_links`] or before, either way.
    pub fn with_controller_spec(mut self, spec: ArmSpec) -> Result<Self, ArmError> {
        spec.validate()?;
        let same_joints = spec.ndofs() == self.spec.ndofs()
            && spec
                .joints
                .iter()
                .zip(&self.spec.joints)
                .all(|(a, b)| a.name == b.name);
        if !same_joints {
            return Err(bad(
                "controller",
                "the controller's arm must have the simulated arm's joints (the same URDF)".into(),
            ));
        }
        let flex = match self.flex {
            Some(_) => Some(self.flex_dynamics(&spec, &self.flex_links)?),
            None => None,
        };
        let mut dynamics = FastDynamics::new(&spec);
        dynamics.set_gravity(self.spec.gravity_m_s2);
        self.controller = Some(Box::new(Controller {
            spec,
            dynamics,
            flex,
        }));
        Ok(self)
    }

    /// The arm the servos' references are computed for when it is not the arm
    /// simulated ([`Self::with_controller_spec`]); `None`: the servos know the arm.
    pub fn controller_spec(&self) -> Option<&ArmSpec> {
        self.controller.as_ref().map(|c| &c.spec)
    }

    /// The drivetrain again, for `nq` coordinates.
    fn recompile(mut self, nq: usize) -> Result<Self, ArmError> {
        let tol = Some(self.drive.newton_tolerance());
        let mut compiled = Vec::with_capacity(self.drive.pairs.len());
        for (i, p) in self.drive.pairs.iter().enumerate() {
            let jn = self
                .spec
                .joints
                .get(p.spec.joint)
                .map_or("?", |j| j.name.as_str());
            let field = format!("transmission[{i}] (joint {jn})");
            compiled.push(CompiledPair::new(p.spec.clone(), nq, self.dt_s, &field)?);
        }
        self.drive = Drivetrain::new(compiled, self.drive.loads.clone(), nq, self.dt_s, tol)?
            .with_free_coords(nq - self.spec.ndofs())?;
        Ok(self)
    }

    /// Number of joints.
    pub fn njoints(&self) -> usize {
        self.spec.ndofs()
    }

    /// Number of generalised coordinates (the joints, then the flexible links' modes):
    /// the length of a state's `q_rad`.
    pub fn ncoords(&self) -> usize {
        self.flex
            .as_ref()
            .map_or(self.spec.ndofs(), |f| f.ncoords())
    }

    /// The flexible links' dynamics, if any link bends.
    pub fn flex(&self) -> Option<&FlexDynamics> {
        self.flex.as_ref()
    }

    /// Step, s.
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// The arm (with the gravity it is simulated under).
    pub fn spec(&self) -> &ArmSpec {
        &self.spec
    }

    /// Routing matrix (pairs x joints).
    pub fn routing(&self) -> &RoutingMatrix {
        &self.routing
    }

    /// The rope pairs, compiled for `dt_s`.
    pub fn pairs(&self) -> &[CompiledPair] {
        &self.drive.pairs
    }

    /// The passive torques of effects at the joints.
    pub fn loads(&self) -> &[JointLoad] {
        &self.drive.loads
    }

    /// Reference of every joint.
    pub fn commands(&self) -> &[Command] {
        &self.commands
    }

    /// Initial joint angles, rad.
    pub fn initial_q_rad(&self) -> &[f64] {
        &self.initial_q_rad
    }

    /// Relative tolerance on the Newton updates of the implicit step (angles, rad):
    /// 1e-12 without relay friction, [`RELAY_NEWTON_TOLERANCE`] with.
    pub fn newton_tolerance(&self) -> f64 {
        self.drive.newton_tolerance()
    }

    /// Whether motor references include `R q_ref` of every joint a rope passes, so that
    /// a held distal joint stays put when a proximal joint moves (default true).
    pub fn compensates_routing(&self) -> bool {
        self.compensate_routing
    }

    /// The same arm with another Newton tolerance (rad; see [`Self::newton_tolerance`]).
    pub fn with_newton_tolerance(mut self, tol: f64) -> Result<Self, ArmError> {
        let n = self.ncoords();
        self.drive = Drivetrain::new(
            self.drive.pairs.clone(),
            self.drive.loads.clone(),
            n,
            self.dt_s,
            Some(tol),
        )?
        .with_free_coords(self.drive.free_coords())?;
        Ok(self)
    }

    /// The same arm under another gravity vector (e.g. zero for conservation
    /// studies), m/s^2.
    pub fn with_gravity(mut self, g: Vector3<f64>) -> Self {
        self.dynamics.set_gravity(g);
        if let Some(f) = &mut self.flex {
            f.set_gravity(g);
        }
        if let Some(c) = &mut self.controller {
            c.dynamics.set_gravity(g);
            if let Some(f) = &mut c.flex {
                f.set_gravity(g);
            }
            c.spec.gravity_m_s2 = g;
        }
        self.spec.gravity_m_s2 = g;
        self
    }

    /// The same arm with the viscous damping of every joint set to `d`, N*m*s/rad.
    pub fn with_joint_damping(mut self, d: f64) -> Self {
        self.damping.fill(d);
        self
    }

    /// The same arm whose motor references follow only their own joint
    /// (`compensate = false`) or also `R q_ref` of every joint their rope passes
    /// (`true`, the default).
    pub fn with_routing_compensation(mut self, compensate: bool) -> Self {
        self.compensate_routing = compensate;
        self
    }

    /// The same arm starting (and held, by commands that hold) at other joint angles.
    pub fn with_initial_q_rad(mut self, q_rad: Vec<f64>) -> Result<Self, ArmError> {
        crate::error::check_joint_vector(&self.spec.name, self.spec.ndofs(), "pose", &q_rad)?;
        self.initial_q_rad = q_rad;
        Ok(self)
    }

    /// The same arm driven by other commands (one per joint).
    pub fn with_commands(mut self, commands: Vec<Command>) -> Result<Self, ArmError> {
        check_commands(&commands, self.spec.ndofs())?;
        self.commands = commands;
        Ok(self)
    }

    fn make_scratch(&self) -> ArmScratch {
        let n = self.spec.ndofs();
        let np = self.drive.pairs.len();
        ArmScratch {
            kin: self.dynamics.make_kin(),
            tau: vec![0.0; n],
            zero: vec![0.0; n],
            g: vec![0.0; n],
            ff: vec![0.0; np],
            ref_rate: vec![0.0; np],
            last_qref: vec![f64::NAN; n],
            fkin: self
                .flex
                .as_ref()
                .map_or_else(FlexKin::default, |f| f.make_kin()),
            q1: vec![0.0; self.ncoords()],
            ftau: vec![0.0; self.ncoords()],
            sag_q: vec![0.0; self.ncoords()],
            fzero: vec![0.0; self.ncoords()],
        }
    }

    /// Flexible arm: the modal coordinates that hold the links bent under gravity at
    /// the joint angles `q[..n]` (from the guess in `q`'s modal part), and the joints'
    /// gravity torques there into `g`.
    fn sagged_gravity(
        &self,
        f: &FlexDynamics,
        q: &mut [f64],
        kin: &mut FlexKin,
        tau: &mut [f64],
        g: &mut [f64],
    ) {
        let zero = vec![0.0; q.len()];
        f.sag(kin, q, &zero, tau);
        let n = g.len();
        g.copy_from_slice(&tau[..n]);
    }

    /// Static pair forces, tensions and stretches that hold the arm at `q_rad` under
    /// gravity (`R^T phi = g(q)` on the driven joints, split by the preload).
    pub fn static_pairs(&self, q_rad: &[f64]) -> Vec<StaticPair> {
        let mut g = vec![0.0; self.spec.ndofs()];
        let mut q = self.padded(q_rad);
        self.static_gravity(&self.dynamics, self.flex.as_ref(), &mut q, &mut g);
        (0..self.drive.pairs.len())
            .map(|p| self.static_pair(p, &g))
            .collect()
    }

    /// The joints' gravity torques `g` of the arm `dynamics` (with flexible links
    /// `flex`: bent under gravity, `q`'s modal coordinates set to that bending) at the
    /// coordinates `q`: the simulated arm's, or the controller's.
    fn static_gravity(
        &self,
        dynamics: &FastDynamics,
        flex: Option<&FlexDynamics>,
        q: &mut [f64],
        g: &mut [f64],
    ) {
        match flex {
            Some(f) => {
                let mut tau = vec![0.0; q.len()];
                self.sagged_gravity(f, q, &mut f.make_kin(), &mut tau, g);
            }
            None => {
                let n = g.len();
                let zero = vec![0.0; n];
                let mut kin = dynamics.make_kin();
                dynamics.kinematics(&q[..n], &mut kin);
                dynamics.rnea(&mut kin, &zero, &zero, g);
            }
        }
    }

    /// Pair force of pair `p` from the gravity torques `g`.
    fn phi_static(&self, p: usize, g: &[f64]) -> f64 {
        let np = self.driven.len();
        (0..np)
            .map(|b| self.ff_map[p * np + b] * g[self.driven[b]])
            .sum()
    }

    fn static_pair(&self, p: usize, g: &[f64]) -> StaticPair {
        self.drive.pairs[p].static_split(self.phi_static(p, g))
    }

    /// The arm at rest at its initial angles, held by the ropes against gravity, motors
    /// at the angles that hold it.
    pub fn initial_state(&self) -> DrivenState {
        if let Some(c) = &self.controller {
            return self.sagged_initial_state(c);
        }
        let Some(f) = &self.flex else {
            let statics = self.static_pairs(&self.initial_q_rad);
            return self
                .drive
                .rest_state(&self.initial_q_rad, &statics, self.make_scratch());
        };
        // Flexible links start bent under gravity, at rest.
        let n = self.spec.ndofs();
        let mut q = self.padded(&self.initial_q_rad);
        let mut tau = vec![0.0; q.len()];
        let mut g = vec![0.0; n];
        self.sagged_gravity(f, &mut q, &mut f.make_kin(), &mut tau, &mut g);
        let statics: Vec<StaticPair> = (0..self.drive.pairs.len())
            .map(|p| self.static_pair(p, &g))
            .collect();
        let mut st = self.drive.rest_state(&q, &statics, self.make_scratch());
        // The references of the modes: the straight links (the tip error counts the
        // sag); the sagged pose is the guess of the references' own balance.
        st.joint_scratch.sag_q.copy_from_slice(&q);
        st.q_ref_rad[n..].fill(0.0);
        st
    }

    /// The arm at rest where the real statics put it, when the servos' references were
    /// computed for another arm ([`Self::with_controller_spec`]). Each servo holds the
    /// reference the controller computes for the initial pose: at rest its torque
    /// `kp (th_ref - th) + ff` (ff the controller's feed-forward, 0 without one) equals
    /// the ropes' load `r_m phi`, so the motor gives way by `(ff - r_m phi) / kp`; the
    /// ropes carry the real gravity load `R^T phi = g(q)` at the stretch `u_static(phi)`,
    /// and the joints sit where `R q = r_m th - u` puts them (a payload the controller
    /// does not know sags the arm, and a distal joint whose rope runs over a sagging
    /// proximal joint's relay turns by the relay's wrap). The driven joints' angles
    /// solve `q = S(q)` ([`Self::sag_map`]) by Newton's method (finite-difference
    /// Jacobian, step halved until the residual falls), to 1e-13 rad.
    fn sagged_initial_state(&self, c: &Controller) -> DrivenState {
        let n = self.spec.ndofs();
        let np = self.drive.pairs.len();
        let mut q = self.padded(&self.initial_q_rad);
        let mut g = vec![0.0; n];
        // The controller's references at the initial pose: motor angle, feed-forward.
        self.static_gravity(&c.dynamics, c.flex.as_ref(), &mut q.clone(), &mut g);
        let refs: Vec<(f64, f64)> = (0..np)
            .map(|p| {
                let pair = &self.drive.pairs[p];
                let sp = self.static_pair(p, &g);
                let rq: f64 = pair
                    .row
                    .iter()
                    .zip(&self.initial_q_rad)
                    .map(|(a, b)| a * b)
                    .sum();
                let r_m = pair.spec.motor_radius_m;
                ((rq + sp.u_m) / r_m, r_m * sp.phi_n)
            })
            .collect();
        // F(q) = q - S(q) on the driven joints, and its largest entry.
        let residual = |q: &mut Vec<f64>| -> (Vec<f64>, f64) {
            let (mapped, _) = self.sag_map(&refs, q);
            let f: Vec<f64> = (0..np).map(|a| q[self.driven[a]] - mapped[a]).collect();
            let worst = f.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            (f, if worst.is_nan() { f64::INFINITY } else { worst })
        };
        let (mut f, mut worst) = residual(&mut q);
        for _ in 0..50 {
            if worst <= 1e-13 {
                break;
            }
            let h = 1e-7;
            let mut jac = DMatrix::<f64>::identity(np, np);
            for b in 0..np {
                let mut qh = q.clone();
                qh[self.driven[b]] += h;
                let (fh, _) = residual(&mut qh);
                for a in 0..np {
                    jac[(a, b)] = (fh[a] - f[a]) / h;
                }
            }
            let Some(step) = jac.lu().solve(&nalgebra::DVector::from_vec(f.clone())) else {
                break;
            };
            let mut lambda = 1.0;
            let mut accepted = false;
            while lambda >= 1e-4 {
                let mut qt = q.clone();
                for a in 0..np {
                    qt[self.driven[a]] -= lambda * step[a];
                }
                let (ft, wt) = residual(&mut qt);
                if wt < worst {
                    (q, f, worst, accepted) = (qt, ft, wt, true);
                    break;
                }
                lambda *= 0.5;
            }
            if !accepted {
                break;
            }
        }
        let (_, statics) = self.sag_map(&refs, &mut q);
        let mut st = self.drive.rest_state(&q, &statics, self.make_scratch());
        for (p, &(th_ref, _)) in refs.iter().enumerate() {
            st.motor_ref_rad[p] = th_ref;
        }
        st.q_ref_rad[..n].copy_from_slice(&self.initial_q_rad);
        if self.flex.is_some() {
            st.joint_scratch.sag_q.copy_from_slice(&q);
            st.q_ref_rad[n..].fill(0.0);
        }
        st
    }

    /// One pass of the sagged statics ([`Self::sagged_initial_state`]) from the
    /// coordinates `q` (a flexible arm's modal coordinates set to the links' bending
    /// there): the real gravity at `q`, each pair's statics under it, each motor's
    /// angle where its servo balances that load against the reference `refs[p]` =
    /// (motor reference, feed-forward), and the driven joints' angles `R q = r_m th - u`
    /// gives (returned, in pair order, with the statics).
    fn sag_map(&self, refs: &[(f64, f64)], q: &mut [f64]) -> (Vec<f64>, Vec<StaticPair>) {
        let n = self.spec.ndofs();
        let np = self.drive.pairs.len();
        let mut g = vec![0.0; n];
        self.static_gravity(&self.dynamics, self.flex.as_ref(), q, &mut g);
        let statics: Vec<StaticPair> = (0..np).map(|p| self.static_pair(p, &g)).collect();
        let rhs: Vec<f64> = self
            .drive
            .pairs
            .iter()
            .enumerate()
            .map(|(p, pair)| {
                let r_m = pair.spec.motor_radius_m;
                let (th_ref, ff) = refs[p];
                let th = match pair.spec.motor.mode {
                    longreach_drive::transmission::MotorMode::Servo {
                        kp_n_m_per_rad,
                        gravity_feedforward,
                        ..
                    } => {
                        let ff = if gravity_feedforward { ff } else { 0.0 };
                        th_ref + (ff - r_m * statics[p].phi_n) / kp_n_m_per_rad
                    }
                    _ => th_ref,
                };
                // the joints no pair drives keep their angles
                let undriven: f64 = pair
                    .row
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| !self.driven.contains(k))
                    .map(|(k, a)| a * q[k])
                    .sum();
                r_m * th - statics[p].u_m - undriven
            })
            .collect();
        // R_d q_d = rhs, with (R_d^-1)[a][b] = ff_map[b np + a] (ff_map: (R_d^T)^-1)
        let mapped = (0..np)
            .map(|a| (0..np).map(|b| self.ff_map[b * np + a] * rhs[b]).sum())
            .collect();
        (mapped, statics)
    }

    /// `q` (joint angles, or every coordinate) with the modal coordinates, zero when
    /// not given.
    fn padded(&self, q: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.ncoords()];
        let k = q.len().min(out.len());
        out[..k].copy_from_slice(&q[..k]);
        out
    }

    /// Energy of the state, J (see [`SystemEnergy`]).
    pub fn energy(&self, st: &DrivenState) -> SystemEnergy {
        let (links_kinetic_j, potential_j, links_elastic_j) = match &self.flex {
            None => {
                let mut kin = self.dynamics.make_kin();
                self.dynamics.kinematics(&st.q_rad, &mut kin);
                let ke = self.dynamics.kinetic_energy(&mut kin, &st.qd_rad_s);
                (ke, self.dynamics.potential_energy(&kin), 0.0)
            }
            Some(f) => {
                let mut kin = f.make_kin();
                f.kinematics(&st.q_rad, &mut kin);
                let mut m = vec![0.0; f.ncoords() * f.ncoords()];
                let ke = f.kinetic_energy(&mut kin, &st.qd_rad_s, &mut m);
                (ke, f.potential_energy(&kin), f.elastic_energy(&st.q_rad))
            }
        };
        let d = self.drive.energy(st);
        SystemEnergy {
            links_kinetic_j,
            potential_j,
            motors_kinetic_j: d.motors_kinetic_j,
            ropes_j: d.ropes_j,
            tensioners_j: d.tensioners_j,
            relays_kinetic_j: d.relays_kinetic_j,
            effects_j: d.loads_j,
            links_elastic_j,
        }
    }

    /// World position of the tip at `q_rad`, m.
    /// With flexible links, `q_rad` may hold the modal coordinates after the joints
    /// (the deflected tip; joint angles alone: the straight links).
    pub fn tip_m(&self, q_rad: &[f64]) -> Result<Vector3<f64>, ArmError> {
        match &self.flex {
            None => crate::dynamics::tip_position_m(&self.spec, q_rad),
            Some(f) => {
                crate::error::check_joint_vector(
                    &self.spec.name,
                    self.spec.ndofs(),
                    "q_rad",
                    &q_rad[..self.spec.ndofs().min(q_rad.len())],
                )?;
                let q = self.padded(q_rad);
                let mut kin = f.make_kin();
                f.kinematics(&q, &mut kin);
                let tip = &self.spec.tip;
                Ok(f.point(&kin, &q, tip.link, &tip.link_from_frame.translation.vector))
            }
        }
    }

    /// Tensions `[+, -]` (N, per rope) every pair would have at the end of a step from
    /// `st` that ends at joint angles `q_rad`, motor angles `motor_rad` and tensioner
    /// stretches `carriage_m` (nothing is committed). For pairs without relay friction
    /// only: a pair with friction has one tension per span, and its relay angles are
    /// unknowns of the step ([`Self::span_tensions_n`] gives them at a state).
    pub fn tensions_at(
        &self,
        st: &DrivenState,
        q_rad: &[f64],
        motor_rad: &[f64],
        carriage_m: &[f64],
    ) -> Vec<[f64; 2]> {
        self.drive
            .pairs
            .iter()
            .enumerate()
            .map(|(p, pair)| {
                let rq: f64 = pair.row.iter().zip(q_rad).map(|(a, b)| a * b).sum();
                let u = pair.spec.motor_radius_m * motor_rad[p] - rq;
                let x = carriage_m[p];
                let f = |side: usize, s: f64| {
                    let prep = pair.stepper.prepare(&st.ropes[p][side]);
                    pair.stepper.tension(&prep, s * pair.inv_length).0
                };
                [f(0, x + u), f(1, x - u)]
            })
            .collect()
    }

    /// Joint torques the ropes exert at the state, `R^T phi`, N*m (with relay
    /// friction, each span loads the joints its pulleys turn with).
    pub fn rope_joint_torques(&self, st: &DrivenState) -> Vec<f64> {
        let mut tau = vec![0.0; self.spec.ndofs()];
        for (p, pair) in self.drive.pairs.iter().enumerate() {
            pair.add_joint_torques(&st.ropes[p], &st.relays[p], &mut tau);
        }
        tau
    }

    /// Tensions `[+, -]` of every span of pair `p` at the state (motor side first), N
    /// per rope; one entry for a pair without relay friction.
    pub fn span_tensions_n(&self, st: &DrivenState, p: usize) -> Vec<[f64; 2]> {
        self.drive.pairs[p].span_tensions_n(&st.ropes[p], &st.relays[p])
    }

    /// Advances one step of `dt_s`: the references stage (joint commands at the end of
    /// the step, motor references, their rates and the gravity feed-forward), then the
    /// transmission core's implicit step.
    pub fn step(&self, st: &mut DrivenState) -> Result<(), ArmError> {
        self.references(st);
        let sc = &mut st.joint_scratch;
        let ff = std::mem::take(&mut sc.ff);
        let ref_rate = std::mem::take(&mut sc.ref_rate);
        let done = self.drive.step(
            self,
            st,
            MotorInputs {
                ref_rate_rad_s: &ref_rate,
                feedforward_n_m: &ff,
            },
        );
        let sc = &mut st.joint_scratch;
        (sc.ff, sc.ref_rate) = (ff, ref_rate);
        done.map_err(ArmError::from)
    }

    /// The references stage: joint references at the end of the step, and for every
    /// pair its motor reference (`(R[p] q_ref + u_static(q_ref)) / r_m`), reference rate
    /// and gravity feed-forward (`r_m phi_static(q_ref)`), recomputed only when the
    /// joint references changed.
    fn references(&self, st: &mut DrivenState) {
        let n = self.spec.ndofs();
        let h = self.dt_s;
        let t1 = st.time_s + h;
        for j in 0..n {
            st.q_ref_rad[j] = self.commands[j].angle_rad(self.initial_q_rad[j], t1);
        }
        let sc = &mut st.joint_scratch;
        // The references only change while a command moves: reuse them otherwise.
        let same_ref = sc.last_qref[..] == st.q_ref_rad[..n];
        // (the controller's arm when it is not the one simulated)
        let (dynamics, flex) = match &self.controller {
            Some(c) => (&c.dynamics, c.flex.as_ref()),
            None => (&self.dynamics, self.flex.as_ref()),
        };
        if !same_ref && !self.drive.pairs.is_empty() {
            if let Some(f) = flex {
                // Gravity of the arm bent under it at the references.
                sc.sag_q[..n].copy_from_slice(&st.q_ref_rad[..n]);
                f.sag(&mut sc.fkin, &mut sc.sag_q, &sc.fzero, &mut sc.ftau);
                sc.g.copy_from_slice(&sc.ftau[..n]);
            } else {
                dynamics.kinematics(&st.q_ref_rad, &mut sc.kin);
                dynamics.rnea(&mut sc.kin, &sc.zero, &sc.zero, &mut sc.g);
            }
            sc.last_qref.copy_from_slice(&st.q_ref_rad[..n]);
        }
        for (p, pair) in self.drive.pairs.iter().enumerate() {
            if same_ref {
                sc.ref_rate[p] = 0.0;
                continue;
            }
            let sp = self.static_pair(p, &sc.g);
            let rq: f64 = if self.compensate_routing {
                pair.nz.iter().map(|&k| pair.row[k] * st.q_ref_rad[k]).sum()
            } else {
                pair.nz
                    .iter()
                    .map(|&k| {
                        let q = if k == pair.spec.joint {
                            st.q_ref_rad[k]
                        } else {
                            self.initial_q_rad[k]
                        };
                        pair.row[k] * q
                    })
                    .sum()
            };
            let th = (rq + sp.u_m) / pair.spec.motor_radius_m;
            let smooth = !matches!(self.commands[pair.spec.joint], Command::Step { .. });
            sc.ref_rate[p] = if smooth {
                (th - st.motor_ref_rad[p]) / h
            } else {
                0.0
            };
            st.motor_ref_rad[p] = th;
            sc.ff[p] = pair.spec.motor_radius_m * sp.phi_n;
        }
    }
}

/// The links: rigid dynamics by allocation-free Newton-Euler and composite rigid bodies
/// ([`crate::fast`]), with the joints' viscous damping.
impl JointSide for DrivenArm {
    type Scratch = ArmScratch;

    fn ndofs(&self) -> usize {
        self.ncoords()
    }

    fn begin_iteration(&self, sc: &mut ArmScratch, q1: &[f64]) {
        match &self.flex {
            None => self.dynamics.kinematics(q1, &mut sc.kin),
            Some(f) => {
                f.kinematics(q1, &mut sc.fkin);
                sc.q1.copy_from_slice(q1);
            }
        }
    }

    fn matrix(&self, sc: &mut ArmScratch, four_h2: f64, two_h: f64, out: &mut [f64]) {
        let Some(f) = &self.flex else {
            let n = self.spec.ndofs();
            self.dynamics.mass_matrix(&mut sc.kin, out);
            for v in out.iter_mut() {
                *v *= four_h2;
            }
            for j in 0..n {
                out[j * n + j] += two_h * self.damping[j];
            }
            return;
        };
        // The bending stiffness and damping are the links' own: in the matrix too.
        let nq = f.ncoords();
        f.mass_matrix(&mut sc.fkin, out);
        for v in out.iter_mut() {
            *v *= four_h2;
        }
        for j in 0..self.spec.ndofs() {
            out[j * nq + j] += two_h * self.damping[j];
        }
        f.add_stiffness(1.0, two_h, out);
    }

    fn residual(&self, sc: &mut ArmScratch, v1: &[f64], a1: &[f64], out: &mut [f64]) {
        let Some(f) = &self.flex else {
            self.dynamics.rnea(&mut sc.kin, v1, a1, &mut sc.tau);
            for j in 0..out.len() {
                out[j] = -(sc.tau[j] + self.damping[j] * v1[j]);
            }
            return;
        };
        f.rnea(&mut sc.fkin, &sc.q1, v1, a1, &mut sc.ftau);
        let n = self.spec.ndofs();
        for j in 0..n {
            out[j] = -(sc.ftau[j] + self.damping[j] * v1[j]);
        }
        for c in n..out.len() {
            out[c] = -sc.ftau[c];
        }
    }
}

//! The arm as a rapier3d-f64 multibody in reduced (joint) coordinates.
//!
//! Model/data split (MuJoCo's mjModel/mjData): an immutable [`ArmModel`] (the
//! validated [`ArmSpec`] plus options) and a mutable [`ArmData`] holding the rapier
//! world, the time and the joint state. One model can serve many data (e.g. a rayon
//! batch); [`step`] advances one data.
//!
//! How the rapier world is built (facts in `shared/notes/crates.md`):
//! - one fixed rigid body for the base and one dynamic body per moving link, with the
//!   link's mass, centre of mass and full inertia tensor (principal axes computed
//!   here); no colliders, so the collision stages of the pipeline have nothing to do;
//! - one multibody joint per URDF joint: a `GenericJoint` with all axes locked but
//!   the local X rotation, `local_frame1 = parent_from_joint * R`,
//!   `local_frame2 = R`, where `R` turns X onto the joint axis; so the joint angle is
//!   exactly the URDF angle (right-hand rule about `axis`) and the zero pose is the
//!   URDF zero pose even for joint origins with rpy;
//! - per-DoF damping (URDF `<dynamics damping>`, 0 when absent), dry friction and
//!   armature are written after every joint is inserted (rapier gives each new DoF a
//!   default damping of 0.1 that would otherwise stay);
//! - joint torques are applied each step as equal and opposite body torques
//!   `+tau * axis` on the child and `-tau * axis` on the parent (a pure couple, whose
//!   generalized force is exactly `tau` on that joint), after resetting the torques
//!   of every body (rapier keeps user torques between steps).
//!
//! Integration: rapier's multibody step is a semi-implicit (symplectic-like) Euler
//! with implicit damping and a linearised implicit Coriolis/gyroscopic term, repeated
//! [`ModelOptions::substeps`] times per [`step`] (rapier's `num_solver_iterations`;
//! the mass matrix is rebuilt and factorised at each substep).

use crate::dynamics::{self, Energy};
use crate::error::{check_joint_vector, ArmError};
use crate::spec::ArmSpec;
use nalgebra::{Isometry3, SymmetricEigen, UnitQuaternion, Vector3};
use rapier3d_f64::prelude::{
    BroadPhaseBvh, CCDSolver, ColliderSet, GenericJointBuilder, ImpulseJointSet,
    IntegrationParameters, IslandManager, JointAxesMask, JointAxis, MassProperties,
    MultibodyJointHandle, MultibodyJointSet, NarrowPhase, PhysicsPipeline, RigidBodyBuilder,
    RigidBodyHandle, RigidBodySet, SoftBodySet,
};
use std::fmt;
use std::sync::atomic::{AtomicU64, Ordering};

/// Index of the rotation about the joint's local X axis in rapier's joint coordinates.
const ANG_X: usize = 3;

static NEXT_MODEL_ID: AtomicU64 = AtomicU64::new(1);

/// Simulation options of an [`ArmModel`].
#[derive(Debug, Clone, PartialEq)]
pub struct ModelOptions {
    /// Rapier substeps per [`step`] (its `num_solver_iterations`); each substep
    /// rebuilds and factorises the mass matrix, so the cost is about proportional.
    /// 1 = plain semi-implicit Euler at `dt_s`.
    pub substeps: usize,
    /// Enforce URDF position limits (rapier limit constraints; they cost solver work).
    pub enforce_limits: bool,
}

impl Default for ModelOptions {
    fn default() -> Self {
        Self {
            substeps: 1,
            enforce_limits: true,
        }
    }
}

/// Immutable compiled arm: validated spec plus options. Cheap to share (`&ArmModel`).
#[derive(Debug, Clone)]
pub struct ArmModel {
    spec: ArmSpec,
    options: ModelOptions,
    id: u64,
}

impl ArmModel {
    /// Compiles a spec with default options (validates it first).
    pub fn new(spec: ArmSpec) -> Result<Self, ArmError> {
        Self::with_options(spec, ModelOptions::default())
    }

    /// Compiles a spec with the given options (validates both).
    pub fn with_options(spec: ArmSpec, options: ModelOptions) -> Result<Self, ArmError> {
        spec.validate()?;
        if options.substeps == 0 {
            return Err(ArmError::InvalidSpec(crate::spec::SpecError {
                source_name: spec.source.clone(),
                element: crate::spec::Element::Arm,
                reason: "ModelOptions::substeps must be >= 1".into(),
            }));
        }
        Ok(Self {
            spec,
            options,
            id: NEXT_MODEL_ID.fetch_add(1, Ordering::Relaxed),
        })
    }

    /// The spec this model was compiled from.
    pub fn spec(&self) -> &ArmSpec {
        &self.spec
    }

    /// The options.
    pub fn options(&self) -> &ModelOptions {
        &self.options
    }

    /// Number of joints (degrees of freedom).
    pub fn ndofs(&self) -> usize {
        self.spec.ndofs()
    }

    /// Joint names in DoF order.
    pub fn joint_names(&self) -> Vec<&str> {
        self.spec.joints.iter().map(|j| j.name.as_str()).collect()
    }

    /// A fresh simulation state at q = 0, qd = 0, t = 0.
    pub fn make_data(&self) -> ArmData {
        let spec = &self.spec;
        let mut bodies = RigidBodySet::new();
        let mut multibody_joints = MultibodyJointSet::new();
        let poses = dynamics::link_poses(spec, &vec![0.0; spec.ndofs()])
            .unwrap_or_else(|_| vec![Isometry3::identity(); spec.links.len()]);

        let mut link_bodies: Vec<RigidBodyHandle> = Vec::with_capacity(spec.links.len());
        link_bodies.push(bodies.insert(RigidBodyBuilder::fixed().pose(poses[0].into())));
        for (i, link) in spec.links.iter().enumerate().skip(1) {
            let builder = RigidBodyBuilder::dynamic()
                .pose(poses[i].into())
                .additional_mass_properties(mass_properties(&link.inertial))
                .can_sleep(false);
            link_bodies.push(bodies.insert(builder));
        }

        let mut first_joint: Option<MultibodyJointHandle> = None;
        for joint in &spec.joints {
            let align = align_x_to(&joint.axis);
            let frame1 = joint.parent_from_joint * align;
            let mut builder = GenericJointBuilder::new(JointAxesMask::LOCKED_REVOLUTE_AXES)
                .local_frame1(frame1.into())
                .local_frame2(align.into());
            if let (true, Some((lo, hi))) = (self.options.enforce_limits, joint.limits_rad) {
                builder = builder.limits(JointAxis::AngX, [lo, hi]);
            }
            let handle = multibody_joints
                .insert(
                    link_bodies[joint.parent_link],
                    link_bodies[joint.child_link],
                    builder.build(),
                    false,
                )
                // The spec is a validated tree (each child inserted once, parents first).
                .expect("internal invariant: a validated spec is a tree");
            first_joint.get_or_insert(handle);
        }
        let mb_handle = first_joint.expect("internal invariant: a validated spec has joints");

        // Link ids and DoF (assembly) ids in the multibody, per spec link / joint.
        let mut rapier_link_id = vec![0usize; spec.links.len()];
        let mut dof_id = vec![0usize; spec.ndofs()];
        {
            let (mb, _) = multibody_joints
                .get_mut(mb_handle)
                .expect("internal invariant: the multibody exists");
            // Resolves the root type first: until then rapier gives the (fixed) root a
            // free joint with 6 DoFs, which shifts every DoF index.
            mb.forward_kinematics(&bodies, true);
            for (i, h) in link_bodies.iter().enumerate() {
                if let Some(id) = mb.links().position(|l| l.rigid_body_handle() == *h) {
                    rapier_link_id[i] = id;
                }
            }
            for (j, joint) in spec.joints.iter().enumerate() {
                let link = mb
                    .link(rapier_link_id[joint.child_link])
                    .expect("internal invariant: every link is in the multibody");
                dof_id[j] = link.assembly_id();
            }
            // Damping, friction, armature: after all insertions (rapier's default
            // damping of 0.1 per new DoF must be overwritten).
            mb.damping_mut().fill(0.0);
            mb.frictions_mut().fill(0.0);
            mb.armature_mut().fill(0.0);
            for (j, joint) in spec.joints.iter().enumerate() {
                mb.damping_mut()[dof_id[j]] = joint.damping_n_m_s_per_rad;
                mb.frictions_mut()[dof_id[j]] = joint.friction_n_m;
                mb.armature_mut()[dof_id[j]] = joint.armature_kg_m2;
            }
            mb.forward_kinematics(&bodies, false);
            mb.update_rigid_bodies(&mut bodies, true);
        }

        let params = IntegrationParameters {
            num_solver_iterations: self.options.substeps,
            max_ccd_substeps: 0,
            normalized_max_linear_velocity: f64::MAX,
            ..IntegrationParameters::default()
        };

        let n = spec.ndofs();
        let mut data = ArmData {
            model_id: self.id,
            time_s: 0.0,
            q_rad: vec![0.0; n],
            qd_rad_s: vec![0.0; n],
            world_from_link: poses,
            body_torque: vec![Vector3::zeros(); spec.links.len()],
            world: RapierWorld {
                bodies,
                colliders: ColliderSet::new(),
                impulse_joints: ImpulseJointSet::new(),
                multibody_joints,
                soft_bodies: SoftBodySet::new(),
                islands: IslandManager::new(),
                broad_phase: BroadPhaseBvh::new(),
                narrow_phase: NarrowPhase::new(),
                ccd: CCDSolver::new(),
                pipeline: PhysicsPipeline::new(),
                params,
                link_bodies,
                mb_handle,
                rapier_link_id,
                dof_id,
            },
        };
        data.read_back();
        data
    }
}

/// Rotation taking the X axis onto `axis`.
fn align_x_to(axis: &nalgebra::Unit<Vector3<f64>>) -> Isometry3<f64> {
    let rot = UnitQuaternion::rotation_between(&Vector3::x(), axis).unwrap_or_else(|| {
        // axis = -X: any half-turn about an axis orthogonal to X.
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI)
    });
    Isometry3::from_parts(nalgebra::Translation3::identity(), rot)
}

/// Rapier mass properties from an inertial (principal axes by a symmetric eigen-decomposition).
fn mass_properties(inertial: &crate::spec::Inertial) -> MassProperties {
    let eig = SymmetricEigen::new(inertial.inertia_kg_m2);
    let mut vectors = eig.eigenvectors;
    let mut values = eig.eigenvalues;
    if vectors.determinant() < 0.0 {
        vectors.swap_columns(1, 2);
        values.swap_rows(1, 2);
    }
    let frame = UnitQuaternion::from_matrix(&vectors);
    MassProperties::with_principal_inertia_frame(
        inertial.com_m.into(),
        inertial.mass_kg,
        values.into(),
        frame.into(),
    )
}

/// The rapier world of one [`ArmData`].
struct RapierWorld {
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    soft_bodies: SoftBodySet,
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    ccd: CCDSolver,
    pipeline: PhysicsPipeline,
    params: IntegrationParameters,
    /// Rigid body of each spec link.
    link_bodies: Vec<RigidBodyHandle>,
    /// Handle of one joint, to reach the multibody.
    mb_handle: MultibodyJointHandle,
    /// Multibody link id of each spec link.
    rapier_link_id: Vec<usize>,
    /// Multibody DoF index of each spec joint.
    dof_id: Vec<usize>,
}

/// Mutable simulation state of one arm: rapier world, time, joint state, link poses.
pub struct ArmData {
    model_id: u64,
    time_s: f64,
    q_rad: Vec<f64>,
    qd_rad_s: Vec<f64>,
    world_from_link: Vec<Isometry3<f64>>,
    body_torque: Vec<Vector3<f64>>,
    world: RapierWorld,
}

impl fmt::Debug for ArmData {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ArmData")
            .field("time_s", &self.time_s)
            .field("q_rad", &self.q_rad)
            .field("qd_rad_s", &self.qd_rad_s)
            .finish_non_exhaustive()
    }
}

impl ArmData {
    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Joint angles, rad (DoF order of [`ArmSpec::joints`]).
    pub fn q_rad(&self) -> &[f64] {
        &self.q_rad
    }

    /// Joint velocities, rad/s.
    pub fn qd_rad_s(&self) -> &[f64] {
        &self.qd_rad_s
    }

    /// World poses of all links (`[0]` is the base), for display.
    pub fn world_from_links(&self) -> &[Isometry3<f64>] {
        &self.world_from_link
    }

    /// World pose of link `link` (index in [`ArmSpec::links`]); `None` if out of range.
    pub fn world_from_link(&self, link: usize) -> Option<Isometry3<f64>> {
        self.world_from_link.get(link).copied()
    }

    /// World pose of the named frame (any URDF link, merged or not).
    pub fn world_from_frame(&self, model: &ArmModel, name: &str) -> Option<Isometry3<f64>> {
        let f = model.spec.frame(name)?;
        Some(self.world_from_link.get(f.link)? * f.link_from_frame)
    }

    /// World position of the model's tip frame ([`ArmSpec::tip`]), m.
    pub fn tip_position_m(&self, model: &ArmModel) -> Vector3<f64> {
        let tip = &model.spec.tip;
        (self.world_from_link[tip.link] * tip.link_from_frame)
            .translation
            .vector
    }

    /// Energy of the current state from the independent dynamics ([`dynamics::energy`]).
    pub fn energy(&self, model: &ArmModel) -> Result<Energy, ArmError> {
        dynamics::energy(&model.spec, &self.q_rad, &self.qd_rad_s)
    }

    /// Sets joint angles (rad) and velocities (rad/s); time is kept.
    pub fn set_state(
        &mut self,
        model: &ArmModel,
        q_rad: &[f64],
        qd_rad_s: &[f64],
    ) -> Result<(), ArmError> {
        self.check_model(model)?;
        let n = model.ndofs();
        check_joint_vector(&model.spec.name, n, "q_rad", q_rad)?;
        check_joint_vector(&model.spec.name, n, "qd_rad_s", qd_rad_s)?;
        let w = &mut self.world;
        let (mb, _) = w
            .multibody_joints
            .get_mut(w.mb_handle)
            .expect("internal invariant: the multibody exists");
        let mut disp = vec![0.0; mb.ndofs()];
        for j in 0..n {
            disp[w.dof_id[j]] = q_rad[j] - self.q_rad[j];
        }
        mb.apply_displacements(&disp);
        {
            let mut v = mb.generalized_velocity_mut();
            for j in 0..n {
                v[w.dof_id[j]] = qd_rad_s[j];
            }
        }
        mb.forward_kinematics(&w.bodies, false);
        mb.update_rigid_bodies(&mut w.bodies, true);
        self.read_back();
        Ok(())
    }

    fn check_model(&self, model: &ArmModel) -> Result<(), ArmError> {
        if self.model_id == model.id {
            Ok(())
        } else {
            Err(ArmError::ModelMismatch {
                arm: model.spec.name.clone(),
                model_dofs: model.ndofs(),
                data_dofs: self.q_rad.len(),
            })
        }
    }

    /// Copies joint state and link poses out of rapier.
    fn read_back(&mut self) {
        let w = &self.world;
        let Some((mb, _)) = w.multibody_joints.get(w.mb_handle) else {
            return;
        };
        let v = mb.generalized_velocity();
        for (j, &dof) in w.dof_id.iter().enumerate() {
            let link_id = w.rapier_link_id[j + 1];
            if let Some(link) = mb.link(link_id) {
                self.q_rad[j] = link.joint().coords()[ANG_X];
            }
            self.qd_rad_s[j] = v[dof];
        }
        for (i, &link_id) in w.rapier_link_id.iter().enumerate().skip(1) {
            if let Some(link) = mb.link(link_id) {
                self.world_from_link[i] = (*link.local_to_world()).into();
            }
        }
    }
}

/// Advances `data` by `dt_s` seconds with joint torques `joint_torques_n_m` (N*m, one
/// per joint, positive about the joint axis) held constant over the step, plus
/// gravity, joint damping and friction from the model.
///
/// The torques are applied as world-frame body couples computed from the joint axes
/// at the start of the step; with `substeps > 1` they keep that world direction over
/// the substeps (exact for parallel axes, as in planar arms; otherwise an error of
/// order of the axis rotation within one step).
///
/// Errors (state unchanged unless said): wrong length or non-finite torques, bad
/// `dt_s`, data from another model; [`ArmError::BlowUp`] if the step produced
/// non-finite values (the state is then invalid: reset it with [`ArmData::set_state`]).
pub fn step(
    model: &ArmModel,
    data: &mut ArmData,
    joint_torques_n_m: &[f64],
    dt_s: f64,
) -> Result<(), ArmError> {
    data.check_model(model)?;
    let spec = &model.spec;
    check_joint_vector(
        &spec.name,
        spec.ndofs(),
        "joint_torques_n_m",
        joint_torques_n_m,
    )?;
    if !(dt_s.is_finite() && dt_s > 0.0) {
        return Err(ArmError::BadTimeStep { dt_s });
    }

    // Joint torques as couples on the bodies (world frame, current axis directions).
    data.body_torque.fill(Vector3::zeros());
    for (j, joint) in spec.joints.iter().enumerate() {
        let axis_world = data.world_from_link[joint.child_link].rotation * joint.axis.into_inner();
        let t = axis_world * joint_torques_n_m[j];
        data.body_torque[joint.child_link] += t;
        data.body_torque[joint.parent_link] -= t;
    }
    let w = &mut data.world;
    for (i, &h) in w.link_bodies.iter().enumerate().skip(1) {
        if let Some(rb) = w.bodies.get_mut(h) {
            rb.reset_torques(false);
            rb.add_torque(data.body_torque[i].into(), false);
        }
    }

    w.params.dt = dt_s;
    w.pipeline.step(
        spec.gravity_m_s2.into(),
        &w.params,
        &mut w.islands,
        &mut w.broad_phase,
        &mut w.narrow_phase,
        &mut w.bodies,
        &mut w.colliders,
        &mut w.impulse_joints,
        &mut w.multibody_joints,
        &mut w.soft_bodies,
        &mut w.ccd,
        &(),
        &(),
    );
    let quarantined = !w.pipeline.quarantine().is_empty();
    data.time_s += dt_s;
    data.read_back();

    let bad_q = data.q_rad.iter().position(|x| !x.is_finite());
    let bad_qd = data.qd_rad_s.iter().position(|x| !x.is_finite());
    if quarantined || bad_q.is_some() || bad_qd.is_some() {
        let detail = match (bad_q, bad_qd) {
            (Some(j), _) => format!("joint '{}' angle is {}", spec.joints[j].name, data.q_rad[j]),
            (_, Some(j)) => format!(
                "joint '{}' velocity is {}",
                spec.joints[j].name, data.qd_rad_s[j]
            ),
            _ => "rapier quarantined a body with a non-finite pose or velocity".into(),
        };
        return Err(ArmError::BlowUp {
            time_s: data.time_s,
            detail,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arm_data_is_send() {
        fn is_send<T: Send>() {}
        is_send::<ArmData>();
        is_send::<ArmModel>();
        fn is_sync<T: Sync>() {}
        is_sync::<ArmModel>();
    }

    #[test]
    fn align_maps_x_onto_axis() {
        for a in [
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::new(-1.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.3, -0.5, 0.8),
        ] {
            let u = nalgebra::Unit::new_normalize(a);
            let r = align_x_to(&u);
            assert!((r.rotation * Vector3::x() - u.into_inner()).norm() < 1e-14);
        }
    }
}

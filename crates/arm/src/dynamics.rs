//! Independent rigid-body dynamics of an [`ArmSpec`] (no rapier): forward
//! kinematics, recursive Newton-Euler inverse dynamics, gravity torques, mass matrix
//! and energy. Used for the servo's gravity feed-forward and to cross-check the rapier
//! multibody.
//!
//! Everything is computed in the world frame. For each moving link `i` (joint `j =
//! i - 1`, parent `p`), with `a` the joint axis, `o` the joint origin and `c` the
//! centre of mass, all in world coordinates:
//!
//! ```text
//! w_i = w_p + a qd_j                 alpha_i = alpha_p + a qdd_j + w_p x a qd_j
//! acc(o_i) = acc(o_p) + alpha_p x (o_i - o_p) + w_p x (w_p x (o_i - o_p))
//! acc(c_i) = acc(o_i) + alpha_i x (c_i - o_i) + w_i x (w_i x (c_i - o_i))
//! F_i = m (acc(c_i) - g)             N_i = I alpha_i + w_i x I w_i
//! f_i = F_i + sum_children f_k       n_i = N_i + (c_i - o_i) x F_i
//!                                          + sum_children [n_k + (o_k - o_i) x f_k]
//! tau_j = a . n_i + armature_j qdd_j
//! ```
//!
//! Viscous joint damping and dry friction are *not* part of these functions (they
//! are joint-level forces: `tau_damping = -d qd`), except in [`forward_dynamics`].

use crate::error::{check_joint_vector, ArmError};
use crate::spec::ArmSpec;
use nalgebra::{DMatrix, DVector, Isometry3, Matrix3, UnitQuaternion, Vector3};

/// Kinetic and potential energy of the arm, J.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Energy {
    /// Kinetic energy of the links (and armatures), J.
    pub kinetic_j: f64,
    /// Gravitational potential energy `-sum m g . c` (zero at the world origin), J.
    pub potential_j: f64,
}

impl Energy {
    /// Kinetic plus potential energy, J.
    pub fn total_j(&self) -> f64 {
        self.kinetic_j + self.potential_j
    }
}

/// Poses of every link in the world frame at joint angles `q_rad`
/// (`world_from_link[0]` is the base, identity).
pub fn link_poses(spec: &ArmSpec, q_rad: &[f64]) -> Result<Vec<Isometry3<f64>>, ArmError> {
    check_joint_vector(&spec.name, spec.ndofs(), "q_rad", q_rad)?;
    Ok(poses_unchecked(spec, q_rad))
}

fn poses_unchecked(spec: &ArmSpec, q_rad: &[f64]) -> Vec<Isometry3<f64>> {
    let mut poses = Vec::with_capacity(spec.links.len());
    poses.push(Isometry3::identity());
    for (j, joint) in spec.joints.iter().enumerate() {
        let rot = UnitQuaternion::from_axis_angle(&joint.axis, q_rad[j]);
        let pose = poses[joint.parent_link]
            * joint.parent_from_joint
            * Isometry3::from_parts(nalgebra::Translation3::identity(), rot);
        poses.push(pose);
    }
    poses
}

/// World position of the tip frame ([`ArmSpec::tip`]) at `q_rad`, m.
pub fn tip_position_m(spec: &ArmSpec, q_rad: &[f64]) -> Result<Vector3<f64>, ArmError> {
    let poses = link_poses(spec, q_rad)?;
    Ok((poses[spec.tip.link] * spec.tip.link_from_frame)
        .translation
        .vector)
}

/// Per-link world-frame quantities shared by the recursions.
struct LinkState {
    origin: Vector3<f64>,
    axis: Vector3<f64>,
    com: Vector3<f64>,
    inertia: Matrix3<f64>,
}

fn link_states(spec: &ArmSpec, poses: &[Isometry3<f64>]) -> Vec<LinkState> {
    spec.links
        .iter()
        .enumerate()
        .map(|(i, link)| {
            let pose = &poses[i];
            let r = pose.rotation.to_rotation_matrix();
            let axis = if i == 0 {
                Vector3::zeros()
            } else {
                pose.rotation * spec.joints[i - 1].axis.into_inner()
            };
            LinkState {
                origin: pose.translation.vector,
                axis,
                com: pose.transform_point(&link.inertial.com_m.into()).coords,
                inertia: r.matrix() * link.inertial.inertia_kg_m2 * r.matrix().transpose(),
            }
        })
        .collect()
}

/// Recursive Newton-Euler with gravity vector `g`; no input checks.
fn rnea(spec: &ArmSpec, q: &[f64], qd: &[f64], qdd: &[f64], g: &Vector3<f64>) -> Vec<f64> {
    let poses = poses_unchecked(spec, q);
    let st = link_states(spec, &poses);
    let nl = spec.links.len();
    let mut w = vec![Vector3::zeros(); nl];
    let mut alpha = vec![Vector3::zeros(); nl];
    let mut acc_o = vec![Vector3::zeros(); nl];
    let mut f = vec![Vector3::zeros(); nl];
    let mut n = vec![Vector3::zeros(); nl];
    for i in 1..nl {
        let j = i - 1;
        let p = spec.joints[j].parent_link;
        let s = &st[i];
        let d_po = s.origin - st[p].origin;
        w[i] = w[p] + s.axis * qd[j];
        alpha[i] = alpha[p] + s.axis * qdd[j] + w[p].cross(&(s.axis * qd[j]));
        acc_o[i] = acc_o[p] + alpha[p].cross(&d_po) + w[p].cross(&w[p].cross(&d_po));
        let r_oc = s.com - s.origin;
        let acc_c = acc_o[i] + alpha[i].cross(&r_oc) + w[i].cross(&w[i].cross(&r_oc));
        let m = spec.links[i].inertial.mass_kg;
        let force = m * (acc_c - g);
        let moment = s.inertia * alpha[i] + w[i].cross(&(s.inertia * w[i]));
        f[i] = force;
        n[i] = moment + r_oc.cross(&force);
    }
    let mut tau = vec![0.0; spec.ndofs()];
    for i in (1..nl).rev() {
        let j = i - 1;
        tau[j] = st[i].axis.dot(&n[i]) + spec.joints[j].armature_kg_m2 * qdd[j];
        let p = spec.joints[j].parent_link;
        if p > 0 {
            let d = st[i].origin - st[p].origin;
            let (fi, ni) = (f[i], n[i]);
            f[p] += fi;
            n[p] += ni + d.cross(&fi);
        }
    }
    tau
}

/// Joint torques, N*m, that produce accelerations `qdd_rad_s2` at state
/// (`q_rad`, `qd_rad_s`) under the spec's gravity: `tau = M(q) qdd + C(q, qd) qd + g(q)`
/// (no damping or friction).
pub fn inverse_dynamics(
    spec: &ArmSpec,
    q_rad: &[f64],
    qd_rad_s: &[f64],
    qdd_rad_s2: &[f64],
) -> Result<Vec<f64>, ArmError> {
    let n = spec.ndofs();
    check_joint_vector(&spec.name, n, "q_rad", q_rad)?;
    check_joint_vector(&spec.name, n, "qd_rad_s", qd_rad_s)?;
    check_joint_vector(&spec.name, n, "qdd_rad_s2", qdd_rad_s2)?;
    Ok(rnea(spec, q_rad, qd_rad_s, qdd_rad_s2, &spec.gravity_m_s2))
}

/// Joint torques, N*m, that hold the arm still at `q_rad` against the spec's gravity
/// (`g(q)` of `M qdd + C qd + g = tau`).
pub fn gravity_torques(spec: &ArmSpec, q_rad: &[f64]) -> Result<Vec<f64>, ArmError> {
    check_joint_vector(&spec.name, spec.ndofs(), "q_rad", q_rad)?;
    let zero = vec![0.0; spec.ndofs()];
    Ok(rnea(spec, q_rad, &zero, &zero, &spec.gravity_m_s2))
}

/// Joint-space mass matrix `M(q)`, kg*m^2 (armature on the diagonal), column `k`
/// computed as the inverse dynamics of a unit acceleration of joint `k` with no
/// gravity and no velocity.
pub fn mass_matrix(spec: &ArmSpec, q_rad: &[f64]) -> Result<DMatrix<f64>, ArmError> {
    let n = spec.ndofs();
    check_joint_vector(&spec.name, n, "q_rad", q_rad)?;
    let zero = vec![0.0; n];
    let mut m = DMatrix::zeros(n, n);
    let mut e = vec![0.0; n];
    for k in 0..n {
        e.fill(0.0);
        e[k] = 1.0;
        let col = rnea(spec, q_rad, &zero, &e, &Vector3::zeros());
        m.column_mut(k).copy_from_slice(&col);
    }
    Ok(0.5 * (&m + m.transpose()))
}

/// Joint accelerations, rad/s^2, under torques `tau_n_m`, gravity and the joints'
/// viscous damping: `qdd = M^-1 (tau - d qd - C qd - g)` (dry friction excluded).
pub fn forward_dynamics(
    spec: &ArmSpec,
    q_rad: &[f64],
    qd_rad_s: &[f64],
    tau_n_m: &[f64],
) -> Result<Vec<f64>, ArmError> {
    let n = spec.ndofs();
    check_joint_vector(&spec.name, n, "q_rad", q_rad)?;
    check_joint_vector(&spec.name, n, "qd_rad_s", qd_rad_s)?;
    check_joint_vector(&spec.name, n, "tau_n_m", tau_n_m)?;
    let zero = vec![0.0; n];
    let bias = rnea(spec, q_rad, qd_rad_s, &zero, &spec.gravity_m_s2);
    let rhs = DVector::from_iterator(
        n,
        (0..n).map(|j| tau_n_m[j] - spec.joints[j].damping_n_m_s_per_rad * qd_rad_s[j] - bias[j]),
    );
    let m = mass_matrix(spec, q_rad)?;
    let qdd = m
        .cholesky()
        .ok_or_else(|| ArmError::SingularMassMatrix {
            arm: spec.name.clone(),
        })?
        .solve(&rhs);
    Ok(qdd.iter().copied().collect())
}

/// Kinetic energy (from the links' spatial velocities plus armature) and gravitational
/// potential energy `-sum m g . c` of the arm at (`q_rad`, `qd_rad_s`), J.
pub fn energy(spec: &ArmSpec, q_rad: &[f64], qd_rad_s: &[f64]) -> Result<Energy, ArmError> {
    let n = spec.ndofs();
    check_joint_vector(&spec.name, n, "q_rad", q_rad)?;
    check_joint_vector(&spec.name, n, "qd_rad_s", qd_rad_s)?;
    let poses = poses_unchecked(spec, q_rad);
    let st = link_states(spec, &poses);
    let nl = spec.links.len();
    let mut w = vec![Vector3::zeros(); nl];
    let mut v_o = vec![Vector3::zeros(); nl];
    let mut kinetic_j = 0.0;
    let mut potential_j = 0.0;
    for i in 1..nl {
        let j = i - 1;
        let p = spec.joints[j].parent_link;
        let s = &st[i];
        w[i] = w[p] + s.axis * qd_rad_s[j];
        v_o[i] = v_o[p] + w[p].cross(&(s.origin - st[p].origin));
        let v_c = v_o[i] + w[i].cross(&(s.com - s.origin));
        let m = spec.links[i].inertial.mass_kg;
        kinetic_j += 0.5 * m * v_c.norm_squared()
            + 0.5 * w[i].dot(&(s.inertia * w[i]))
            + 0.5 * spec.joints[j].armature_kg_m2 * qd_rad_s[j] * qd_rad_s[j];
        potential_j -= m * spec.gravity_m_s2.dot(&s.com);
    }
    Ok(Energy {
        kinetic_j,
        potential_j,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::{Frame, Inertial, JointKind, JointSpec, LinkSpec};
    use nalgebra::Unit;

    /// Planar two-link arm about y with point-ish masses, to compare with textbook formulas.
    fn two_link(m1: f64, m2: f64, l1: f64, l2: f64) -> ArmSpec {
        let link = |name: &str, m: f64, l: f64| LinkSpec {
            name: name.into(),
            merged_links: vec![],
            inertial: Inertial {
                mass_kg: m,
                com_m: Vector3::new(l, 0.0, 0.0),
                inertia_kg_m2: Matrix3::identity() * 1e-9,
            },
            visuals: vec![],
        };
        let joint = |name: &str, parent: usize, x: f64| JointSpec {
            name: name.into(),
            kind: JointKind::Continuous,
            parent_link: parent,
            child_link: parent + 1,
            parent_from_joint: Isometry3::translation(x, 0.0, 0.0),
            axis: Unit::new_normalize(Vector3::new(0.0, -1.0, 0.0)),
            limits_rad: None,
            effort_limit_n_m: f64::INFINITY,
            velocity_limit_rad_s: f64::INFINITY,
            damping_n_m_s_per_rad: 0.0,
            friction_n_m: 0.0,
            armature_kg_m2: 0.0,
        };
        ArmSpec {
            name: "two".into(),
            source: "test".into(),
            links: vec![
                LinkSpec {
                    name: "base".into(),
                    merged_links: vec![],
                    inertial: Inertial::zero(),
                    visuals: vec![],
                },
                link("l1", m1, l1),
                link("l2", m2, l2),
            ],
            joints: vec![joint("j1", 0, 0.0), joint("j2", 1, l1)],
            frames: vec![],
            tip: Frame {
                name: "l2".into(),
                link: 2,
                link_from_frame: Isometry3::translation(l2, 0.0, 0.0),
            },
            gravity_m_s2: Vector3::new(0.0, 0.0, -9.81),
            warnings: vec![],
        }
    }

    #[test]
    fn two_link_matches_textbook_point_mass_dynamics() {
        // Axis -y: positive q raises the arm in the x-z plane (angle from +x towards +z).
        let (m1, m2, l1, l2, g) = (2.0, 1.5, 0.7, 0.4, 9.81);
        let spec = two_link(m1, m2, l1, l2);
        let (q1, q2) = (0.3, -0.8);
        let (qd1, qd2) = (0.9, -1.3);
        let (qdd1, qdd2) = (0.2, 0.5);
        let tau = inverse_dynamics(&spec, &[q1, q2], &[qd1, qd2], &[qdd1, qdd2]).unwrap();
        // Textbook (Spong) planar 2R with point masses at the link ends.
        let c2 = f64::cos(q2);
        let s2 = f64::sin(q2);
        let m11 = m1 * l1 * l1 + m2 * (l1 * l1 + l2 * l2 + 2.0 * l1 * l2 * c2);
        let m12 = m2 * (l2 * l2 + l1 * l2 * c2);
        let m22 = m2 * l2 * l2;
        let h = -m2 * l1 * l2 * s2;
        let g1 = (m1 + m2) * g * l1 * q1.cos() + m2 * g * l2 * (q1 + q2).cos();
        let g2 = m2 * g * l2 * (q1 + q2).cos();
        let t1 = m11 * qdd1 + m12 * qdd2 + h * (2.0 * qd1 * qd2 + qd2 * qd2) + g1;
        let t2 = m12 * qdd1 + m22 * qdd2 - h * qd1 * qd1 + g2;
        // The 1e-9 kg*m^2 rotational inertia adds at most ~1e-9 N*m.
        assert!((tau[0] - t1).abs() < 1e-8, "{} vs {t1}", tau[0]);
        assert!((tau[1] - t2).abs() < 1e-8, "{} vs {t2}", tau[1]);
        let e = energy(&spec, &[q1, q2], &[qd1, qd2]).unwrap();
        let ke = 0.5 * (m11 * qd1 * qd1 + 2.0 * m12 * qd1 * qd2 + m22 * qd2 * qd2);
        let pe = (m1 + m2) * g * l1 * q1.sin() + m2 * g * l2 * (q1 + q2).sin();
        assert!((e.kinetic_j - ke).abs() < 1e-8);
        assert!((e.potential_j - pe).abs() < 1e-12);
    }

    #[test]
    fn kinetic_energy_equals_half_qd_m_qd() {
        let spec = two_link(2.0, 1.5, 0.7, 0.4);
        let q = [0.4, 1.2];
        let qd = [-0.7, 2.1];
        let m = mass_matrix(&spec, &q).unwrap();
        let v = DVector::from_row_slice(&qd);
        let ke = 0.5 * v.dot(&(&m * &v));
        let e = energy(&spec, &q, &qd).unwrap();
        assert!((e.kinetic_j - ke).abs() < 1e-12 * ke.max(1.0));
    }

    #[test]
    fn wrong_length_is_an_error() {
        let spec = two_link(1.0, 1.0, 1.0, 1.0);
        let err = gravity_torques(&spec, &[0.0]).unwrap_err();
        assert!(err.to_string().contains("expected 2"), "{err}");
        let err = gravity_torques(&spec, &[0.0, f64::NAN]).unwrap_err();
        assert!(matches!(err, ArmError::NonFinite { index: 1, .. }));
    }
}

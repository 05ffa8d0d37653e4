//! The validated description of an arm: links with inertials, revolute joints, frames.
//!
//! An [`ArmSpec`] is what a URDF file compiles into ([`crate::urdf`]) and what
//! [`crate::ArmModel`] and the independent dynamics ([`crate::dynamics`]) read.
//! Conventions (the same as URDF):
//!
//! - `links[0]` is the base, bolted to the world (`world_from_base` = identity).
//! - `joints[j]` moves `links[j + 1]`; its parent link has a smaller index, so a
//!   serial chain is `links[0] -j0- links[1] -j1- links[2] ...` and a tree is allowed.
//! - A link frame coincides with the frame of the joint that moves it; the joint
//!   angle `q[j]` rotates the child about `axis` (unit vector in the joint frame) by
//!   the right-hand rule: `parent_from_child = parent_from_joint * Rot(axis, q[j])`.
//! - Inertials are expressed in the link frame: mass, centre of mass, and the
//!   inertia tensor about the centre of mass with link-frame axes.

use nalgebra::{Isometry3, Matrix3, SymmetricEigen, Unit, Vector3};
use std::fmt;

/// Standard gravity, m/s^2, pointing along -z of the world frame.
pub const STANDARD_GRAVITY_M_S2: f64 = 9.81;

/// Mass properties of one body, in the frame of the link that owns it.
#[derive(Debug, Clone, PartialEq)]
pub struct Inertial {
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass in the link frame, m.
    pub com_m: Vector3<f64>,
    /// Inertia tensor about the centre of mass, link-frame axes, kg*m^2 (symmetric).
    pub inertia_kg_m2: Matrix3<f64>,
}

impl Inertial {
    /// No mass at all (a pure frame).
    pub fn zero() -> Self {
        Self {
            mass_kg: 0.0,
            com_m: Vector3::zeros(),
            inertia_kg_m2: Matrix3::zeros(),
        }
    }

    /// The same body expressed in another frame: `parent_from_self` maps points of the
    /// frame this inertial is written in to the new frame (I' = R I R^T, c' = T c).
    pub fn transformed(&self, parent_from_self: &Isometry3<f64>) -> Self {
        let r = parent_from_self.rotation.to_rotation_matrix();
        let r = r.matrix();
        Self {
            mass_kg: self.mass_kg,
            com_m: parent_from_self.transform_point(&self.com_m.into()).coords,
            inertia_kg_m2: r * self.inertia_kg_m2 * r.transpose(),
        }
    }

    /// Inertia tensor of this body about the point `p_m` (parallel-axis theorem):
    /// `I_p = I_c + m (|d|^2 E - d d^T)`, `d = c - p`.
    pub fn inertia_about_point(&self, p_m: &Vector3<f64>) -> Matrix3<f64> {
        let d = self.com_m - p_m;
        self.inertia_kg_m2
            + self.mass_kg * (Matrix3::identity() * d.norm_squared() - d * d.transpose())
    }

    /// Two bodies rigidly joined, both written in the same frame: total mass, combined
    /// centre of mass, and the inertia about the new centre of mass (parallel-axis
    /// theorem for each part). Two massless parts give a massless result at the origin.
    pub fn combined(&self, other: &Inertial) -> Self {
        let mass_kg = self.mass_kg + other.mass_kg;
        if mass_kg <= 0.0 {
            return Self {
                mass_kg,
                com_m: Vector3::zeros(),
                inertia_kg_m2: self.inertia_kg_m2 + other.inertia_kg_m2,
            };
        }
        let com_m = (self.com_m * self.mass_kg + other.com_m * other.mass_kg) / mass_kg;
        let inertia_kg_m2 = self.inertia_about_point(&com_m) + other.inertia_about_point(&com_m);
        Self {
            mass_kg,
            com_m,
            inertia_kg_m2: 0.5 * (inertia_kg_m2 + inertia_kg_m2.transpose()),
        }
    }

    /// Eigenvalues (principal moments, kg*m^2) of the inertia tensor, ascending.
    pub fn principal_moments_kg_m2(&self) -> [f64; 3] {
        let eig = SymmetricEigen::new(self.inertia_kg_m2);
        let mut v = [eig.eigenvalues[0], eig.eigenvalues[1], eig.eigenvalues[2]];
        v.sort_by(f64::total_cmp);
        v
    }
}

/// Shape of a visual element (display only; no contact is simulated).
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// Box with full side lengths along x, y, z, m.
    Box {
        /// Side lengths, m.
        size_m: Vector3<f64>,
    },
    /// Cylinder along the local z axis, centred on the origin.
    Cylinder {
        /// Radius, m.
        radius_m: f64,
        /// Length along z, m.
        length_m: f64,
    },
    /// Capsule along the local z axis (length of the cylindrical part).
    Capsule {
        /// Radius, m.
        radius_m: f64,
        /// Length of the cylindrical part along z, m.
        length_m: f64,
    },
    /// Sphere centred on the origin.
    Sphere {
        /// Radius, m.
        radius_m: f64,
    },
    /// Mesh file, as written in the URDF (may be `package://...`), with its scale.
    Mesh {
        /// File name as written in the URDF.
        filename: String,
        /// Scale factors along x, y, z.
        scale: Vector3<f64>,
    },
}

/// One visual element, kept for display.
#[derive(Debug, Clone, PartialEq)]
pub struct Visual {
    /// The URDF link that declared it (differs from the owning link after fixed-joint merging).
    pub source_link: String,
    /// Pose of the geometry in the owning link frame.
    pub link_from_visual: Isometry3<f64>,
    /// The shape.
    pub geometry: Geometry,
    /// Colour (r, g, b, a in 0..1) if the URDF gave one.
    pub rgba: Option<[f64; 4]>,
}

/// A rigid body of the multibody: one moving URDF link plus every link fixed to it.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkSpec {
    /// Name of the URDF link whose frame this body uses.
    pub name: String,
    /// Names of the URDF links merged into this body through fixed joints.
    pub merged_links: Vec<String>,
    /// Combined mass properties (zero for a massless base).
    pub inertial: Inertial,
    /// Visual elements, in this link's frame.
    pub visuals: Vec<Visual>,
}

/// Kind of a moving joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// Revolute joint with position limits.
    Revolute,
    /// Revolute joint without position limits.
    Continuous,
}

impl fmt::Display for JointKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            JointKind::Revolute => write!(f, "revolute"),
            JointKind::Continuous => write!(f, "continuous"),
        }
    }
}

/// One moving (revolute) joint: one degree of freedom.
#[derive(Debug, Clone, PartialEq)]
pub struct JointSpec {
    /// URDF joint name.
    pub name: String,
    /// Revolute (limited) or continuous.
    pub kind: JointKind,
    /// Index of the parent link in [`ArmSpec::links`].
    pub parent_link: usize,
    /// Index of the child link in [`ArmSpec::links`] (always the joint index + 1).
    pub child_link: usize,
    /// Pose of the joint frame (= child link frame at q = 0) in the parent link frame.
    pub parent_from_joint: Isometry3<f64>,
    /// Rotation axis, unit vector in the joint frame.
    pub axis: Unit<Vector3<f64>>,
    /// Position limits `(lower, upper)`, rad; `None` for no limit.
    pub limits_rad: Option<(f64, f64)>,
    /// Effort limit from the URDF, N*m (infinite when not given). Informational.
    pub effort_limit_n_m: f64,
    /// Velocity limit from the URDF, rad/s (infinite when not given). Informational.
    pub velocity_limit_rad_s: f64,
    /// Viscous damping, N*m*s/rad (URDF `<dynamics damping>`, 0 when absent).
    pub damping_n_m_s_per_rad: f64,
    /// Coulomb (dry) friction torque, N*m (URDF `<dynamics friction>`, 0 when absent).
    pub friction_n_m: f64,
    /// Reflected rotor inertia added on this degree of freedom, kg*m^2 (not in URDF; 0).
    pub armature_kg_m2: f64,
}

/// A named frame rigidly attached to a link (every merged URDF link is one).
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Frame name (the URDF link name for merged links).
    pub name: String,
    /// Index of the link in [`ArmSpec::links`] that carries the frame.
    pub link: usize,
    /// Pose of the frame in the link frame.
    pub link_from_frame: Isometry3<f64>,
}

/// A validated arm: see the module documentation for the conventions.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmSpec {
    /// Robot name from the URDF.
    pub name: String,
    /// Where it came from (file path, or a label for in-memory text); used in messages.
    pub source: String,
    /// Bodies; `links[0]` is the fixed base.
    pub links: Vec<LinkSpec>,
    /// Moving joints; `joints[j]` moves `links[j + 1]`.
    pub joints: Vec<JointSpec>,
    /// Named frames (every URDF link, merged or not), in file order of discovery.
    pub frames: Vec<Frame>,
    /// The tool-centre point reported as the arm tip.
    pub tip: Frame,
    /// Gravity acceleration in the world frame, m/s^2 (default `(0, 0, -9.81)`).
    pub gravity_m_s2: Vector3<f64>,
    /// Content of the source that is not simulated, each entry naming the element.
    pub warnings: Vec<String>,
}

/// What a [`SpecError`] is about.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Element {
    /// A link (by URDF name).
    Link(String),
    /// A joint (by URDF name).
    Joint(String),
    /// The arm as a whole.
    Arm,
}

impl fmt::Display for Element {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Element::Link(n) => write!(f, "link '{n}'"),
            Element::Joint(n) => write!(f, "joint '{n}'"),
            Element::Arm => write!(f, "arm"),
        }
    }
}

/// A physically or structurally invalid [`ArmSpec`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{source_name}: {element}: {reason}")]
pub struct SpecError {
    /// [`ArmSpec::source`].
    pub source_name: String,
    /// The offending element.
    pub element: Element,
    /// What is wrong and what to do.
    pub reason: String,
}

/// Relative tolerance for "positive definite" inertia: smallest principal moment must
/// exceed this times the largest (and be > 0).
const INERTIA_PD_REL_TOL: f64 = 1e-12;

impl ArmSpec {
    /// Number of degrees of freedom (moving joints).
    pub fn ndofs(&self) -> usize {
        self.joints.len()
    }

    /// Index of the joint with this name.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Index of the link (body) with this name.
    pub fn link_index(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }

    /// The frame with this name (any URDF link, merged or not).
    pub fn frame(&self, name: &str) -> Option<&Frame> {
        self.frames.iter().find(|f| f.name == name)
    }

    /// Total mass of the moving links, kg.
    pub fn moving_mass_kg(&self) -> f64 {
        self.links.iter().skip(1).map(|l| l.inertial.mass_kg).sum()
    }

    /// Makes the frame `name` the tip; errors if no such frame.
    pub fn set_tip_frame(&mut self, name: &str) -> Result<(), SpecError> {
        match self.frame(name) {
            Some(f) => {
                self.tip = f.clone();
                Ok(())
            }
            None => Err(self.err(
                Element::Arm,
                format!(
                    "no frame named '{name}' to use as tip; frames: {}",
                    self.frames
                        .iter()
                        .map(|f| f.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )),
        }
    }

    /// Adds a payload: a point mass of `mass_kg` at `offset_m` in the frame `frame`
    /// (any URDF link, merged or not), merged into the inertial of the moving link that
    /// carries the frame (parallel-axis theorem, [`Inertial::combined`]). Everything
    /// built from the spec afterwards (dynamics, gravity feed-forward, statics) sees it.
    pub fn add_payload(
        &mut self,
        frame: &str,
        mass_kg: f64,
        offset_m: Vector3<f64>,
    ) -> Result<(), SpecError> {
        if !(mass_kg.is_finite() && mass_kg >= 0.0) || offset_m.iter().any(|v| !v.is_finite()) {
            return Err(self.err(
                Element::Link(frame.to_string()),
                format!("payload mass {mass_kg} kg at {offset_m:?} m: need a finite mass >= 0 and a finite offset"),
            ));
        }
        let (link, point) = self.point_on(frame, mass_kg, offset_m)?;
        let link = &mut self.links[link];
        link.inertial = link.inertial.combined(&point);
        Ok(())
    }

    /// Adds a point mass of `mass_kg` at `offset_m` (in frame `frame`'s coordinates) to
    /// the moving link that carries the frame, or removes one where `mass_kg` < 0 (the
    /// exact inverse of [`Self::add_payload`]): the correction of a payload known wrong.
    /// The link must keep a mass > 0 and a positive-definite inertia.
    pub fn add_point_mass(
        &mut self,
        frame: &str,
        mass_kg: f64,
        offset_m: [f64; 3],
    ) -> Result<(), SpecError> {
        let offset = Vector3::from(offset_m);
        if mass_kg >= 0.0 || !mass_kg.is_finite() || offset.iter().any(|v| !v.is_finite()) {
            return self.add_payload(frame, mass_kg, offset);
        }
        let (link, point) = self.point_on(frame, mass_kg, offset)?;
        let combined = self.links[link].inertial.combined(&point);
        let moments = combined.principal_moments_kg_m2();
        if !(combined.mass_kg > 0.0 && moments[0] > 0.0) {
            return Err(self.err(
                Element::Link(frame.to_string()),
                format!(
                    "removing {:.6} kg there leaves the link {} kg and principal moments {moments:?} kg*m^2: \
                     a payload lighter than the link can carry",
                    -mass_kg, combined.mass_kg
                ),
            ));
        }
        self.links[link].inertial = combined;
        Ok(())
    }

    /// The moving link that carries frame `frame` and a point mass of `mass_kg` at
    /// `offset_m` in that frame, in the link's coordinates; refused for a frame the
    /// URDF does not have or one fixed to the base.
    fn point_on(
        &self,
        frame: &str,
        mass_kg: f64,
        offset_m: Vector3<f64>,
    ) -> Result<(usize, Inertial), SpecError> {
        let Some(f) = self.frame(frame) else {
            return Err(self.err(
                Element::Arm,
                format!(
                    "no link named '{frame}' to carry the payload; links: {}",
                    self.frames
                        .iter()
                        .map(|f| f.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        };
        if f.link == 0 {
            return Err(self.err(
                Element::Link(frame.to_string()),
                "is fixed to the base: a payload there does not load any joint; name a moving link"
                    .into(),
            ));
        }
        let point = Inertial {
            mass_kg,
            com_m: f.link_from_frame.transform_point(&offset_m.into()).coords,
            inertia_kg_m2: Matrix3::zeros(),
        };
        Ok((f.link, point))
    }

    fn err(&self, element: Element, reason: String) -> SpecError {
        SpecError {
            source_name: self.source.clone(),
            element,
            reason,
        }
    }

    /// Checks every structural and physical requirement the simulator relies on:
    /// joint/link indexing, finite numbers, unit axes, mass > 0 and a positive-definite
    /// inertia on every moving link, limits with lower < upper, non-negative damping,
    /// friction and armature, finite gravity, tip on an existing link.
    pub fn validate(&self) -> Result<(), SpecError> {
        if self.links.is_empty() {
            return Err(self.err(Element::Arm, "no links".into()));
        }
        if self.joints.is_empty() {
            return Err(self.err(
                Element::Arm,
                "no moving joint: an arm needs at least one revolute or continuous joint".into(),
            ));
        }
        if self.links.len() != self.joints.len() + 1 {
            return Err(self.err(
                Element::Arm,
                format!(
                    "{} links for {} joints: expected exactly one link per joint plus the base",
                    self.links.len(),
                    self.joints.len()
                ),
            ));
        }
        if !self.gravity_m_s2.iter().all(|g| g.is_finite()) {
            return Err(self.err(
                Element::Arm,
                format!("gravity {:?} m/s^2 is not finite", self.gravity_m_s2),
            ));
        }
        for (j, joint) in self.joints.iter().enumerate() {
            let el = || Element::Joint(joint.name.clone());
            if joint.child_link != j + 1 || joint.parent_link >= joint.child_link {
                return Err(self.err(
                    el(),
                    format!(
                        "joint {j} must move link {} from a parent with a smaller index (has parent {}, child {})",
                        j + 1,
                        joint.parent_link,
                        joint.child_link
                    ),
                ));
            }
            let t = joint.parent_from_joint.translation.vector;
            let q = joint.parent_from_joint.rotation.coords;
            if !t.iter().chain(q.iter()).all(|x| x.is_finite()) {
                return Err(self.err(el(), "origin is not finite".into()));
            }
            let a = joint.axis.into_inner();
            if !a.iter().all(|x| x.is_finite()) || (a.norm() - 1.0).abs() > 1e-9 {
                return Err(self.err(
                    el(),
                    format!(
                        "axis {:?} is not a finite unit vector: give a non-zero axis xyz",
                        a.as_slice()
                    ),
                ));
            }
            if let Some((lo, hi)) = joint.limits_rad {
                if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                    return Err(self.err(
                        el(),
                        format!(
                            "limits lower = {lo} rad, upper = {hi} rad: need finite lower < upper (use a continuous joint for no limits, a fixed joint for no motion)"
                        ),
                    ));
                }
            }
            for (what, v) in [
                ("damping (N*m*s/rad)", joint.damping_n_m_s_per_rad),
                ("friction (N*m)", joint.friction_n_m),
                ("armature (kg*m^2)", joint.armature_kg_m2),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(self.err(el(), format!("{what} = {v}: must be finite and >= 0")));
                }
            }
        }
        for link in self.links.iter().skip(1) {
            check_moving_inertial(&link.name, &link.inertial)
                .map_err(|reason| self.err(Element::Link(link.name.clone()), reason))?;
        }
        let base = &self.links[0].inertial;
        if !(base.mass_kg.is_finite() && base.mass_kg >= 0.0) {
            return Err(self.err(
                Element::Link(self.links[0].name.clone()),
                format!("mass {} kg must be finite and >= 0", base.mass_kg),
            ));
        }
        if self.tip.link >= self.links.len() {
            return Err(self.err(
                Element::Arm,
                format!(
                    "tip frame '{}' is on link index {} but there are {} links",
                    self.tip.name,
                    self.tip.link,
                    self.links.len()
                ),
            ));
        }
        Ok(())
    }
}

/// Mass and inertia requirements on a moving body; returns the reason on failure.
pub(crate) fn check_moving_inertial(name: &str, inertial: &Inertial) -> Result<(), String> {
    let m = inertial.mass_kg;
    if !(m.is_finite() && m > 0.0) {
        return Err(format!(
            "mass {m} kg on a moving link: must be > 0 (give link '{name}' an <inertial> with a positive <mass>, or merge it into its parent with a fixed joint)"
        ));
    }
    if !inertial.com_m.iter().all(|x| x.is_finite()) {
        return Err(format!(
            "centre of mass {:?} m is not finite",
            inertial.com_m.as_slice()
        ));
    }
    let i = &inertial.inertia_kg_m2;
    if !i.iter().all(|x| x.is_finite()) {
        return Err("inertia tensor has non-finite entries".into());
    }
    if (i - i.transpose()).abs().max() > 1e-12 * i.abs().max().max(1e-300) {
        return Err("inertia tensor is not symmetric".into());
    }
    let ev = inertial.principal_moments_kg_m2();
    if !(ev[0] > 0.0 && ev[0] > INERTIA_PD_REL_TOL * ev[2]) {
        return Err(format!(
            "inertia tensor is not positive definite (principal moments {:.6e}, {:.6e}, {:.6e} kg*m^2): every moving link needs ixx, iyy, izz > 0 and a valid tensor",
            ev[0], ev[1], ev[2]
        ));
    }
    Ok(())
}

/// Whether the principal moments satisfy the triangle inequality (each at most the sum
/// of the other two), which every physical body does. Small violations (relative
/// 1e-9) are tolerated.
pub(crate) fn satisfies_triangle_inequality(inertial: &Inertial) -> bool {
    let [a, b, c] = inertial.principal_moments_kg_m2();
    c <= (a + b) * (1.0 + 1e-9)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn rod(mass_kg: f64, length_m: f64) -> Inertial {
        // Thin rod along x, centred at x = length/2.
        let i_perp = mass_kg * length_m * length_m / 12.0;
        Inertial {
            mass_kg,
            com_m: Vector3::new(length_m / 2.0, 0.0, 0.0),
            inertia_kg_m2: Matrix3::from_diagonal(&Vector3::new(1e-6, i_perp, i_perp)),
        }
    }

    #[test]
    fn combining_two_halves_gives_the_whole_rod() {
        // Two 1 m rods of 1 kg end to end = one 2 m rod of 2 kg: I_c = m L^2 / 12.
        let a = rod(1.0, 1.0);
        let b = rod(1.0, 1.0).transformed(&Isometry3::translation(1.0, 0.0, 0.0));
        let c = a.combined(&b);
        assert!((c.mass_kg - 2.0).abs() < 1e-15);
        assert!((c.com_m - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-15);
        let expected = 2.0 * 4.0 / 12.0;
        assert!((c.inertia_kg_m2[(1, 1)] - expected).abs() < 1e-12);
        assert!((c.inertia_kg_m2[(2, 2)] - expected).abs() < 1e-12);
    }

    #[test]
    fn rotation_of_inertia_tensor() {
        // Rod along x rotated 90 deg about z lies along y: its small moment moves to yy.
        let r = rod(1.0, 1.0);
        let rot = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
        );
        let t = r.transformed(&rot);
        assert!((t.inertia_kg_m2[(1, 1)] - 1e-6).abs() < 1e-12);
        assert!((t.inertia_kg_m2[(0, 0)] - 1.0 / 12.0).abs() < 1e-12);
        assert!((t.com_m - Vector3::new(0.0, 0.5, 0.0)).norm() < 1e-15);
    }

    #[test]
    fn non_positive_definite_inertia_is_rejected() {
        let mut r = rod(1.0, 1.0);
        r.inertia_kg_m2[(0, 0)] = 0.0;
        assert!(check_moving_inertial("r", &r).is_err());
        r.inertia_kg_m2[(0, 0)] = 1e-6;
        assert!(check_moving_inertial("r", &r).is_ok());
        r.mass_kg = 0.0;
        assert!(check_moving_inertial("r", &r)
            .unwrap_err()
            .contains("mass 0 kg"));
    }
}

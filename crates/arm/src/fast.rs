//! Allocation-free rigid-body dynamics of an [`ArmSpec`] for the time-stepping loop:
//! forward kinematics, recursive Newton-Euler (the same equations as
//! [`crate::dynamics`], written once per step into preallocated buffers) and the
//! composite-rigid-body mass matrix (O(n * depth), spatial quantities at the world
//! origin). [`crate::dynamics`] stays the independent reference the tests compare with.

use crate::spec::ArmSpec;
use nalgebra::{Matrix3, Rotation3, Vector3};

/// Constant per-link data, extracted from the spec once.
#[derive(Debug, Clone)]
struct LinkConst {
    parent: usize,
    /// Rotation and translation of the joint frame in the parent link frame.
    rot_pj: Matrix3<f64>,
    trans_pj: Vector3<f64>,
    axis: Vector3<f64>,
    mass: f64,
    com: Vector3<f64>,
    inertia: Matrix3<f64>,
    armature: f64,
}

/// Compiled dynamics of one arm (immutable).
#[derive(Debug, Clone)]
pub struct FastDynamics {
    links: Vec<LinkConst>,
    gravity: Vector3<f64>,
}

/// World-frame kinematics and scratch of [`FastDynamics`] (mutable, reused).
#[derive(Debug, Clone)]
pub struct Kin {
    /// World rotation of every link (index 0 = base).
    pub rot: Vec<Matrix3<f64>>,
    /// World position of every link's joint origin, m.
    pub origin: Vec<Vector3<f64>>,
    /// World joint axis of every link.
    pub axis: Vec<Vector3<f64>>,
    /// World centre of mass of every link, m.
    pub com: Vec<Vector3<f64>>,
    /// World inertia about the centre of mass, kg*m^2.
    pub inertia: Vec<Matrix3<f64>>,
    w: Vec<Vector3<f64>>,
    alpha: Vec<Vector3<f64>>,
    acc: Vec<Vector3<f64>>,
    f: Vec<Vector3<f64>>,
    n: Vec<Vector3<f64>>,
    // Composite bodies: mass, first moment, inertia about the world origin.
    cm: Vec<f64>,
    ch: Vec<Vector3<f64>>,
    ci: Vec<Matrix3<f64>>,
}

impl Kin {
    /// Scratch with no links (a placeholder that allocates nothing).
    pub fn empty() -> Self {
        Self {
            rot: vec![],
            origin: vec![],
            axis: vec![],
            com: vec![],
            inertia: vec![],
            w: vec![],
            alpha: vec![],
            acc: vec![],
            f: vec![],
            n: vec![],
            cm: vec![],
            ch: vec![],
            ci: vec![],
        }
    }
}

impl FastDynamics {
    /// Extracts the constant data of `spec` (assumed validated).
    pub fn new(spec: &ArmSpec) -> Self {
        let mut links = Vec::with_capacity(spec.links.len());
        links.push(LinkConst {
            parent: 0,
            rot_pj: Matrix3::identity(),
            trans_pj: Vector3::zeros(),
            axis: Vector3::zeros(),
            mass: 0.0,
            com: Vector3::zeros(),
            inertia: Matrix3::zeros(),
            armature: 0.0,
        });
        for (j, joint) in spec.joints.iter().enumerate() {
            let link = &spec.links[j + 1];
            links.push(LinkConst {
                parent: joint.parent_link,
                rot_pj: *joint
                    .parent_from_joint
                    .rotation
                    .to_rotation_matrix()
                    .matrix(),
                trans_pj: joint.parent_from_joint.translation.vector,
                axis: joint.axis.into_inner(),
                mass: link.inertial.mass_kg,
                com: link.inertial.com_m,
                inertia: link.inertial.inertia_kg_m2,
                armature: joint.armature_kg_m2,
            });
        }
        Self {
            links,
            gravity: spec.gravity_m_s2,
        }
    }

    /// Number of degrees of freedom.
    pub fn ndofs(&self) -> usize {
        self.links.len() - 1
    }

    /// Gravity used by [`Self::rnea`], m/s^2 (world frame).
    pub fn gravity(&self) -> Vector3<f64> {
        self.gravity
    }

    /// Replaces gravity (e.g. zero for conservation studies).
    pub fn set_gravity(&mut self, g: Vector3<f64>) {
        self.gravity = g;
    }

    /// Fresh scratch for this arm.
    pub fn make_kin(&self) -> Kin {
        let nl = self.links.len();
        let z = vec![Vector3::zeros(); nl];
        Kin {
            rot: vec![Matrix3::identity(); nl],
            origin: z.clone(),
            axis: z.clone(),
            com: z.clone(),
            inertia: vec![Matrix3::zeros(); nl],
            w: z.clone(),
            alpha: z.clone(),
            acc: z.clone(),
            f: z.clone(),
            n: z.clone(),
            cm: vec![0.0; nl],
            ch: z,
            ci: vec![Matrix3::zeros(); nl],
        }
    }

    /// Forward kinematics at `q` (rad) into `k`.
    pub fn kinematics(&self, q: &[f64], k: &mut Kin) {
        for i in 1..self.links.len() {
            let l = &self.links[i];
            let p = l.parent;
            let rj = Rotation3::from_axis_angle(&nalgebra::Unit::new_unchecked(l.axis), q[i - 1]);
            let rot_p = k.rot[p];
            let rot = rot_p * l.rot_pj * rj.matrix();
            k.origin[i] = k.origin[p] + rot_p * l.trans_pj;
            k.axis[i] = rot * l.axis;
            k.com[i] = k.origin[i] + rot * l.com;
            k.inertia[i] = rot * l.inertia * rot.transpose();
            k.rot[i] = rot;
        }
    }

    /// Inverse dynamics `M(q) qdd + C(q, qd) qd + g(q)` (N*m) after
    /// [`Self::kinematics`] at `q`; writes into `tau`.
    pub fn rnea(&self, k: &mut Kin, qd: &[f64], qdd: &[f64], tau: &mut [f64]) {
        let nl = self.links.len();
        let g = self.gravity;
        for i in 1..nl {
            let j = i - 1;
            let l = &self.links[i];
            let p = l.parent;
            let a = k.axis[i];
            let d_po = k.origin[i] - k.origin[p];
            let (wp, alp) = (k.w[p], k.alpha[p]);
            k.w[i] = wp + a * qd[j];
            k.alpha[i] = alp + a * qdd[j] + wp.cross(&(a * qd[j]));
            k.acc[i] = k.acc[p] + alp.cross(&d_po) + wp.cross(&wp.cross(&d_po));
            let r_oc = k.com[i] - k.origin[i];
            let wi = k.w[i];
            let acc_c = k.acc[i] + k.alpha[i].cross(&r_oc) + wi.cross(&wi.cross(&r_oc));
            let force = l.mass * (acc_c - g);
            let moment = k.inertia[i] * k.alpha[i] + wi.cross(&(k.inertia[i] * wi));
            k.f[i] = force;
            k.n[i] = moment + r_oc.cross(&force);
        }
        for i in (1..nl).rev() {
            let j = i - 1;
            tau[j] = k.axis[i].dot(&k.n[i]) + self.links[i].armature * qdd[j];
            let p = self.links[i].parent;
            if p > 0 {
                let d = k.origin[i] - k.origin[p];
                let (fi, ni) = (k.f[i], k.n[i]);
                k.f[p] += fi;
                k.n[p] += ni + d.cross(&fi);
            }
        }
    }

    /// Mass matrix (kg*m^2, row-major `n x n` into `m`) after [`Self::kinematics`]:
    /// composite rigid bodies with spatial inertias at the world origin.
    pub fn mass_matrix(&self, k: &mut Kin, m: &mut [f64]) {
        let nl = self.links.len();
        let n = nl - 1;
        for i in 1..nl {
            let mass = self.links[i].mass;
            let c = k.com[i];
            k.cm[i] = mass;
            k.ch[i] = c * mass;
            k.ci[i] =
                k.inertia[i] + mass * (Matrix3::identity() * c.norm_squared() - c * c.transpose());
        }
        for i in (2..nl).rev() {
            let p = self.links[i].parent;
            if p > 0 {
                let (cm, ch, ci) = (k.cm[i], k.ch[i], k.ci[i]);
                k.cm[p] += cm;
                k.ch[p] += ch;
                k.ci[p] += ci;
            }
        }
        for i in 1..nl {
            let j = i - 1;
            // Unit motion of joint j: w = a, v0 = o x a (velocity of the world origin point).
            let a = k.axis[i];
            let v0 = k.origin[i].cross(&a);
            let lin = k.ch[i].cross(&a) * -1.0 + v0 * k.cm[i];
            let ang = k.ci[i] * a + k.ch[i].cross(&v0);
            // Walk up the ancestors (the joint itself included).
            let mut anc = i;
            while anc > 0 {
                let jj = anc - 1;
                let aa = k.axis[anc];
                let vv = k.origin[anc].cross(&aa);
                let val = aa.dot(&ang) + vv.dot(&lin);
                m[jj * n + j] = val;
                m[j * n + jj] = val;
                anc = self.links[anc].parent;
            }
            m[j * n + j] += self.links[i].armature;
        }
    }

    /// Kinetic energy of the links (and armatures) at velocity `qd`, J, after
    /// [`Self::kinematics`].
    pub fn kinetic_energy(&self, k: &mut Kin, qd: &[f64]) -> f64 {
        let mut ke = 0.0;
        let mut v_o = vec![Vector3::zeros(); self.links.len()];
        for i in 1..self.links.len() {
            let l = &self.links[i];
            let p = l.parent;
            k.w[i] = k.w[p] + k.axis[i] * qd[i - 1];
            v_o[i] = v_o[p] + k.w[p].cross(&(k.origin[i] - k.origin[p]));
            let v_c = v_o[i] + k.w[i].cross(&(k.com[i] - k.origin[i]));
            ke += 0.5 * l.mass * v_c.norm_squared()
                + 0.5 * k.w[i].dot(&(k.inertia[i] * k.w[i]))
                + 0.5 * l.armature * qd[i - 1] * qd[i - 1];
        }
        ke
    }

    /// Gravitational potential energy `-sum m g . c`, J, after [`Self::kinematics`].
    pub fn potential_energy(&self, k: &Kin) -> f64 {
        (1..self.links.len())
            .map(|i| -self.links[i].mass * self.gravity.dot(&k.com[i]))
            .sum()
    }
}

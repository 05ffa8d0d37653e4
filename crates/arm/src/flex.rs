//! Flexible links: the arm's links as Euler-Bernoulli beams bending in both transverse
//! directions, by assumed modes (the clamped-free beam's eigenfunctions), in the same
//! reduced coordinates as the joints.
//!
//! # Model
//!
//! A flexible link is a uniform beam from its joint origin to the origin of its child
//! joint (the last link: to the tip frame), of length `L`, bending stiffness `EI` and
//! mass per length `mu`, clamped in its joint frame. Its deflection, in the link frame,
//!
//! ```text
//! d(x) = sum_m phi_m(x) (eta_1m e_1 + eta_2m e_2),   0 <= x <= L
//! phi_m(x) = cosh b x - cos b x - s_m (sinh b x - sin b x),   b = beta_m / L
//! ```
//!
//! (`beta_m L` = 1.8751, 4.6941, 7.8548, 10.9955; `int phi_m^2 = L`, `phi_m(L) = +-2`),
//! `e_1` in the plane of the joint's rotation (`e_2 x e_a`), `e_2` along the component of
//! the joint axis across the link. The modal coordinates `eta` follow the joint angles
//! in the generalised coordinates `q`. The child joint (and whatever the link carries
//! beyond its tube: joint housings, the payload) rides on the deflected end: displaced
//! by `d(L)` and turned by the end slopes (`Rot(e_2, d_1'(L)) Rot(e_1, -d_2'(L))`).
//!
//! The beam's mass is a set of point masses at Gauss-Legendre stations (`2 m + 6` of
//! them for `m` modes per direction: the modal masses exact to 1e-10 for two modes);
//! the rest of the link's URDF inertial (its mass, first moment and inertia less the
//! stations') is a rigid body on the deflected end. The step never visits the stations
//! one by one: what it sums over them is linear or quadratic in their positions
//! `(x_s, w_1(x_s), w_2(x_s))` in the link's basis `[e_a e_1 e_2]`, so it uses their mass
//! moments (`sum m`, `sum m x`, `sum m x^2`, per mode `sum m phi` and `sum m x phi`, the
//! modal mass), made once, times the modal coordinates. At `eta = 0` the link's inertia is
//! exactly its URDF inertial, so a stiff beam is the rigid arm. The equations are
//! Kane's (virtual power) for that discretised mass: inverse dynamics by a recursion
//! over the links (Newton-Euler, with the stations and the end's rigid motion), the
//! mass matrix by composite bodies, both consistent with the kinetic energy
//! `1/2 qd^T M(q) qd`; the elastic energy is `1/2 sum K_m eta_m^2` with
//! `K_m = EI beta_m^4 / L^3` (the eigenfunctions are orthogonal), and structural damping
//! `c_m = 2 zeta sqrt(K_m mu L)` (ratio `zeta` of the clamped beam's own modes).
//! Neglected: rotary inertia and shear of the sections (slender tubes), axial
//! shortening (no geometric stiffening by gravity or rotation), torsion.

use crate::spec::ArmSpec;
use nalgebra::{Matrix3, Rotation3, Unit, Vector3};

/// `beta_m L` of the clamped-free beam's first four modes.
pub const BETA_L: [f64; 4] = [
    1.875_104_068_711_961,
    4.694_091_132_974_175,
    7.854_757_438_237_613,
    10.995_540_734_875_467,
];

/// Largest number of modes per direction.
pub const MAX_MODES: usize = 4;

/// One flexible link, as given by the user (scenario `[[flex]]`, or a program).
#[derive(Debug, Clone, PartialEq)]
pub struct FlexLinkSpec {
    /// Index of the link in [`ArmSpec::links`] (>= 1; moved by joint `link - 1`).
    pub link: usize,
    /// Bending stiffness `E I`, N*m^2 (the same in both directions: a tube).
    pub ei_n_m2: f64,
    /// Structural damping ratio of each bending mode (0: undamped).
    pub damping_ratio: f64,
    /// Assumed modes per transverse direction (1..=4).
    pub modes: usize,
    /// Mass of the beam per length, kg/m; `None`: the link's whole mass spread over
    /// its length.
    pub mass_per_length_kg_m: Option<f64>,
}

/// `E I` of a tube: `E pi (D^4 - d^4) / 64`, N*m^2.
pub fn tube_ei_n_m2(youngs_modulus_pa: f64, outer_diameter_m: f64, inner_diameter_m: f64) -> f64 {
    youngs_modulus_pa * std::f64::consts::PI * (outer_diameter_m.powi(4) - inner_diameter_m.powi(4))
        / 64.0
}

/// Mode `m` of the clamped-free beam at `xi = x / L`: `(phi, L dphi/dx)`.
pub fn mode_shape(m: usize, xi: f64) -> (f64, f64) {
    let b = BETA_L[m];
    let s = (b.cosh() + b.cos()) / (b.sinh() + b.sin());
    let (bx, (sn, cs)) = (b * xi, (b * xi).sin_cos());
    let (sh, ch) = (bx.sinh(), bx.cosh());
    (ch - cs - s * (sh - sn), b * (sh + sn - s * (ch - cs)))
}

/// The end of link `link`'s beam in its frame (the child joint's origin; the last
/// link: the tip frame), m; the reason when it has none.
pub fn beam_end(spec: &ArmSpec, link: usize) -> Result<Vector3<f64>, String> {
    let children: Vec<usize> = (0..spec.ndofs())
        .filter(|&j| spec.joints[j].parent_link == link)
        .collect();
    match children.as_slice() {
        [c] => Ok(spec.joints[*c].parent_from_joint.translation.vector),
        [] if spec.tip.link == link => Ok(spec.tip.link_from_frame.translation.vector),
        [] => Err("no child joint and not the tip's link: its length is unknown".into()),
        _ => Err("more than one child joint: only serial links can bend".into()),
    }
}

/// Gauss-Legendre nodes and weights on [0, 1].
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let kf = k as f64;
                let p2 = ((2.0 * kf - 1.0) * x * p1 - (kf - 1.0) * p0) / kf;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-16 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out.push((0.5 * (1.0 - x), 0.5 * w));
    }
    out
}

/// Spatial inertia of a rigid body about a frame origin, frame axes: mass, first
/// moment, inertia about the origin.
#[derive(Debug, Clone, Copy)]
struct Body {
    m: f64,
    h: Vector3<f64>,
    i: Matrix3<f64>,
}

fn skew_sq(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::identity() * v.norm_squared() - v * v.transpose()
}

impl Body {
    /// The same body about the point `p` (frame coordinates).
    fn about(&self, p: &Vector3<f64>) -> Body {
        let hf = self.h - self.m * p;
        let i = self.i - self.m * skew_sq(p) - Matrix3::identity() * (2.0 * hf.dot(p))
            + hf * p.transpose()
            + p * hf.transpose();
        Body {
            m: self.m,
            h: hf,
            i,
        }
    }
}

/// A flexible link compiled for the step.
#[derive(Debug, Clone)]
pub struct FlexLink {
    /// Link index.
    pub link: usize,
    /// Modes per direction.
    pub nm: usize,
    /// Index of its first modal coordinate in `q` (direction 1's modes, then 2's).
    pub offset: usize,
    /// Beam length, m.
    pub length_m: f64,
    /// Axis, in-plane and out-of-plane directions, link frame.
    pub ea: Vector3<f64>,
    /// In-plane bending direction (link frame).
    pub e1: Vector3<f64>,
    /// Out-of-plane bending direction (link frame).
    pub e2: Vector3<f64>,
    /// The link-frame basis `[e_a e_1 e_2]` (columns; right-handed: `e_a x e_1 = e_2`).
    basis: Matrix3<f64>,
    /// Moments of the stations' mass (`m_s` at `x_s`, mode values `phi_m(x_s)`), the
    /// sums the dynamics need of them: `sum m_s` (kg), `sum m_s x_s` (kg*m),
    /// `sum m_s x_s^2` (kg*m^2), per mode `sum m_s phi_m` (kg) and `sum m_s x_s phi_m`
    /// (kg*m).
    beam_m: f64,
    beam_x: f64,
    beam_xx: f64,
    beam_p: [f64; MAX_MODES],
    beam_q: [f64; MAX_MODES],
    /// Modal mass of the stations, `sum_s m_s phi_a phi_b`, kg.
    modal_mass: [[f64; MAX_MODES]; MAX_MODES],
    /// `phi_m(L)`, `phi_m'(L)` (1/m).
    phi_l: [f64; MAX_MODES],
    dphi_l: [f64; MAX_MODES],
    /// Modal stiffness and damping per mode (both directions).
    pub stiffness: [f64; MAX_MODES],
    /// Modal damping, N*s/m.
    pub damping: [f64; MAX_MODES],
    /// Beam mass per length, kg/m.
    pub mass_per_length_kg_m: f64,
    /// `E I`, N*m^2.
    pub ei_n_m2: f64,
    /// The rest of the link's inertial, about the beam's end (end frame at `eta = 0`).
    rest: Body,
}

impl FlexLink {
    /// Number of modal coordinates (both directions).
    pub fn ncoords(&self) -> usize {
        2 * self.nm
    }

    /// Deflection `d(x)` (link frame, m) at `x` for the link's modal coordinates `eta`.
    pub fn deflection(&self, eta: &[f64], x_m: f64) -> Vector3<f64> {
        let xi = (x_m / self.length_m).clamp(0.0, 1.0);
        let (mut w1, mut w2) = (0.0, 0.0);
        for m in 0..self.nm {
            let (p, _) = mode_shape(m, xi);
            w1 += p * eta[m];
            w2 += p * eta[self.nm + m];
        }
        self.e1 * w1 + self.e2 * w2
    }

    fn end_slopes(&self, eta: &[f64]) -> (f64, f64) {
        let (mut s1, mut s2) = (0.0, 0.0);
        for m in 0..self.nm {
            s1 += self.dphi_l[m] * eta[m];
            s2 += self.dphi_l[m] * eta[self.nm + m];
        }
        (s1, s2)
    }

    /// The clamped beam's natural frequencies, Hz (per mode).
    pub fn clamped_frequencies_hz(&self) -> Vec<f64> {
        (0..self.nm)
            .map(|m| {
                (self.stiffness[m] / (self.mass_per_length_kg_m * self.length_m)).sqrt()
                    / (2.0 * std::f64::consts::PI)
            })
            .collect()
    }
}

#[derive(Debug, Clone)]
struct LinkC {
    parent: usize,
    rot_pj: Matrix3<f64>,
    trans_pj: Vector3<f64>,
    axis: Vector3<f64>,
    /// Rigid body of a rigid link (about its origin).
    body: Body,
    armature: f64,
    /// Index into `FlexDynamics::flex`.
    flex: Option<usize>,
}

/// Dynamics of an arm some of whose links bend (immutable).
#[derive(Debug, Clone)]
pub struct FlexDynamics {
    links: Vec<LinkC>,
    /// The flexible links.
    pub flex: Vec<FlexLink>,
    gravity: Vector3<f64>,
    nj: usize,
    nq: usize,
}

/// World-frame kinematics and scratch of [`FlexDynamics`] (reused).
#[derive(Debug, Clone, Default)]
pub struct FlexKin {
    rot: Vec<Matrix3<f64>>,
    origin: Vec<Vector3<f64>>,
    axis: Vec<Vector3<f64>>,
    /// Frame children attach to (the end section for a flexible link).
    end_rot: Vec<Matrix3<f64>>,
    end_origin: Vec<Vector3<f64>>,
    /// Per flexible link: world slope axes u1, u2 and direction vectors R e1, R e2.
    u1: Vec<Vector3<f64>>,
    u2: Vec<Vector3<f64>>,
    d1: Vec<Vector3<f64>>,
    d2: Vec<Vector3<f64>>,
    /// Per flexible link: its basis in the world (`R [e_a e_1 e_2]`), and the beam's
    /// mass moments at the modal coordinates in that basis: the first moment about the
    /// link origin, `sum m_s r_s`, the second, `sum m_s r_s r_s^T`, and `N eta` of each
    /// direction (`N` the modal mass).
    eb: Vec<Matrix3<f64>>,
    hl: Vec<Vector3<f64>>,
    jl: Vec<Matrix3<f64>>,
    n1: Vec<[f64; MAX_MODES]>,
    n2: Vec<[f64; MAX_MODES]>,
    w: Vec<Vector3<f64>>,
    alpha: Vec<Vector3<f64>>,
    acc: Vec<Vector3<f64>>,
    ew: Vec<Vector3<f64>>,
    ealpha: Vec<Vector3<f64>>,
    eacc: Vec<Vector3<f64>>,
    f: Vec<Vector3<f64>>,
    n: Vec<Vector3<f64>>,
    ef: Vec<Vector3<f64>>,
    en: Vec<Vector3<f64>>,
    // Composite bodies about the world origin: of the link and beyond (root), of its
    // end and beyond (flexible links).
    rm: Vec<f64>,
    rh: Vec<Vector3<f64>>,
    ri: Vec<Matrix3<f64>>,
    tm: Vec<f64>,
    th: Vec<Vector3<f64>>,
    ti: Vec<Matrix3<f64>>,
    /// Per coordinate: momentum of its unit rate (lin, ang) and its end motion (w, v0).
    mom_l: Vec<Vector3<f64>>,
    mom_a: Vec<Vector3<f64>>,
    /// Per modal coordinate: the momentum of its unit rate of the link's end and what it
    /// carries (lin, ang), the stations left out.
    end_l: Vec<Vector3<f64>>,
    end_a: Vec<Vector3<f64>>,
    mw: Vec<Vector3<f64>>,
    mv: Vec<Vector3<f64>>,
}

/// A flexible link that cannot be built, with the reason.
#[derive(Debug, Clone, PartialEq)]
pub struct FlexError {
    /// Link name.
    pub link: String,
    /// What is wrong and the fix.
    pub reason: String,
}

impl FlexDynamics {
    /// Compiles `spec` with the flexible links `flex` (every other link rigid).
    pub fn new(spec: &ArmSpec, flex: &[FlexLinkSpec]) -> Result<Self, FlexError> {
        let nj = spec.ndofs();
        let mut links = Vec::with_capacity(spec.links.len());
        links.push(LinkC {
            parent: 0,
            rot_pj: Matrix3::identity(),
            trans_pj: Vector3::zeros(),
            axis: Vector3::zeros(),
            body: Body {
                m: 0.0,
                h: Vector3::zeros(),
                i: Matrix3::zeros(),
            },
            armature: 0.0,
            flex: None,
        });
        for (j, joint) in spec.joints.iter().enumerate() {
            let inr = &spec.links[j + 1].inertial;
            links.push(LinkC {
                parent: joint.parent_link,
                rot_pj: *joint
                    .parent_from_joint
                    .rotation
                    .to_rotation_matrix()
                    .matrix(),
                trans_pj: joint.parent_from_joint.translation.vector,
                axis: joint.axis.into_inner(),
                body: Body {
                    m: inr.mass_kg,
                    h: inr.com_m * inr.mass_kg,
                    i: inr.inertia_about_point(&Vector3::zeros()),
                },
                armature: joint.armature_kg_m2,
                flex: None,
            });
        }
        let mut out = Vec::new();
        let mut offset = nj;
        let mut sorted = flex.to_vec();
        sorted.sort_by_key(|f| f.link);
        for f in &sorted {
            let name = spec
                .links
                .get(f.link)
                .map_or_else(|| format!("#{}", f.link), |l| l.name.clone());
            let err = |reason: String| FlexError {
                link: name.clone(),
                reason,
            };
            if f.link == 0 || f.link >= spec.links.len() {
                return Err(err("not a moving link: give a link moved by a joint".into()));
            }
            if out.iter().any(|l: &FlexLink| l.link == f.link) {
                return Err(err("flexible twice: give each link once".into()));
            }
            if !(f.ei_n_m2.is_finite() && f.ei_n_m2 > 0.0) {
                return Err(err(format!(
                    "EI = {}: give a positive bending stiffness",
                    f.ei_n_m2
                )));
            }
            if !(f.damping_ratio.is_finite() && f.damping_ratio >= 0.0) {
                return Err(err(format!(
                    "damping ratio {}: give a ratio >= 0",
                    f.damping_ratio
                )));
            }
            if f.modes == 0 || f.modes > MAX_MODES {
                return Err(err(format!(
                    "{} modes: give 1 to {MAX_MODES} per direction",
                    f.modes
                )));
            }
            let end = beam_end(spec, f.link).map_err(err)?;
            let length = end.norm();
            if length < 1e-6 {
                return Err(err(
                    "its child joint is at its origin: nothing to bend".into()
                ));
            }
            let ea = end / length;
            let axis = spec.joints[f.link - 1].axis.into_inner();
            let across = axis - ea * axis.dot(&ea);
            let e2 = if across.norm() > 1e-6 {
                across.normalize()
            } else {
                // The joint turns about the link's own axis: any transverse pair.
                let t = if ea.x.abs() < 0.9 {
                    Vector3::x()
                } else {
                    Vector3::y()
                };
                (t - ea * t.dot(&ea)).normalize()
            };
            let e1 = e2.cross(&ea);
            let inr = &spec.links[f.link].inertial;
            let mu = f.mass_per_length_kg_m.unwrap_or(inr.mass_kg / length);
            if !(mu.is_finite() && mu > 0.0) {
                return Err(err(format!("mass per length {mu}: give a positive value")));
            }
            let ns = 2 * f.modes + 6;
            let mut xs = Vec::with_capacity(ns);
            let mut ms = Vec::with_capacity(ns);
            let mut phi = Vec::with_capacity(ns);
            let mut stations = Body {
                m: 0.0,
                h: Vector3::zeros(),
                i: Matrix3::zeros(),
            };
            for (xi, w) in gauss_legendre(ns) {
                let x = xi * length;
                let m = mu * length * w;
                let mut ph = [0.0; MAX_MODES];
                for (k, v) in ph.iter_mut().enumerate().take(f.modes) {
                    *v = mode_shape(k, xi).0;
                }
                let p = ea * x;
                stations.m += m;
                stations.h += p * m;
                stations.i += skew_sq(&p) * m;
                xs.push(x);
                ms.push(m);
                phi.push(ph);
            }
            let whole = links[f.link].body;
            let rest = Body {
                m: whole.m - stations.m,
                h: whole.h - stations.h,
                i: whole.i - stations.i,
            };
            if rest.m < -1e-9 * whole.m.max(1.0) {
                return Err(err(format!(
                    "the beam ({:.4} kg) is heavier than the link ({:.4} kg): lower the mass per length or the density",
                    stations.m, whole.m
                )));
            }
            // What the beam leaves of the link must be a body: a mass distribution
            // with a positive moment of inertia about its own centre of mass (a beam
            // heavier near the link's end than the link is there leaves none).
            if rest.m > 1e-9 * whole.m.max(1.0) {
                let c = rest.h / rest.m;
                let about_c = rest.i - skew_sq(&c) * rest.m;
                let least = about_c.symmetric_eigenvalues().min();
                if least < -1e-9 * whole.i.norm().max(1e-12) {
                    return Err(err(format!(
                        "without its beam ({:.4} kg) the link's other {:.4} kg would sit at {:.3} m along it with a negative moment of inertia ({:.4} kg*m^2): the beam carries more mass than the link has along its length; lower the mass per length or the density",
                        stations.m,
                        rest.m,
                        c.dot(&ea),
                        least
                    )));
                }
            }
            let rest = rest.about(&(ea * length));
            let mut phi_l = [0.0; MAX_MODES];
            let mut dphi_l = [0.0; MAX_MODES];
            let mut stiffness = [0.0; MAX_MODES];
            let mut damping = [0.0; MAX_MODES];
            for m in 0..f.modes {
                let (p, dp) = mode_shape(m, 1.0);
                phi_l[m] = p;
                dphi_l[m] = dp / length;
                stiffness[m] = f.ei_n_m2 * BETA_L[m].powi(4) / length.powi(3);
                damping[m] = 2.0 * f.damping_ratio * (stiffness[m] * mu * length).sqrt();
            }
            let mut modal_mass = [[0.0; MAX_MODES]; MAX_MODES];
            let (mut beam_m, mut beam_x, mut beam_xx) = (0.0, 0.0, 0.0);
            let mut beam_p = [0.0; MAX_MODES];
            let mut beam_q = [0.0; MAX_MODES];
            for (s_i, ph) in phi.iter().enumerate() {
                let (m, x) = (ms[s_i], xs[s_i]);
                beam_m += m;
                beam_x += m * x;
                beam_xx += m * x * x;
                for a in 0..f.modes {
                    beam_p[a] += m * ph[a];
                    beam_q[a] += m * x * ph[a];
                    for b in 0..f.modes {
                        modal_mass[a][b] += m * ph[a] * ph[b];
                    }
                }
            }
            links[f.link].flex = Some(out.len());
            out.push(FlexLink {
                link: f.link,
                nm: f.modes,
                offset,
                length_m: length,
                ea,
                e1,
                e2,
                basis: Matrix3::from_columns(&[ea, e1, e2]),
                beam_m,
                beam_x,
                beam_xx,
                beam_p,
                beam_q,
                modal_mass,
                phi_l,
                dphi_l,
                stiffness,
                damping,
                mass_per_length_kg_m: mu,
                ei_n_m2: f.ei_n_m2,
                rest,
            });
            offset += 2 * f.modes;
        }
        Ok(Self {
            links,
            flex: out,
            gravity: spec.gravity_m_s2,
            nj,
            nq: offset,
        })
    }

    /// Joints.
    pub fn njoints(&self) -> usize {
        self.nj
    }

    /// Generalised coordinates: the joints, then every flexible link's modes.
    pub fn ncoords(&self) -> usize {
        self.nq
    }

    /// Replaces gravity, m/s^2.
    pub fn set_gravity(&mut self, g: Vector3<f64>) {
        self.gravity = g;
    }

    /// The flexible link of link `link`, if it bends.
    pub fn flex_of(&self, link: usize) -> Option<&FlexLink> {
        self.links.get(link)?.flex.map(|k| &self.flex[k])
    }

    /// Fresh scratch.
    pub fn make_kin(&self) -> FlexKin {
        let nl = self.links.len();
        let nf = self.flex.len();
        let z = vec![Vector3::zeros(); nl];
        FlexKin {
            rot: vec![Matrix3::identity(); nl],
            origin: z.clone(),
            axis: z.clone(),
            end_rot: vec![Matrix3::identity(); nl],
            end_origin: z.clone(),
            u1: vec![Vector3::zeros(); nf],
            u2: vec![Vector3::zeros(); nf],
            d1: vec![Vector3::zeros(); nf],
            d2: vec![Vector3::zeros(); nf],
            eb: vec![Matrix3::identity(); nf],
            hl: vec![Vector3::zeros(); nf],
            jl: vec![Matrix3::zeros(); nf],
            n1: vec![[0.0; MAX_MODES]; nf],
            n2: vec![[0.0; MAX_MODES]; nf],
            w: z.clone(),
            alpha: z.clone(),
            acc: z.clone(),
            ew: z.clone(),
            ealpha: z.clone(),
            eacc: z.clone(),
            f: z.clone(),
            n: z.clone(),
            ef: z.clone(),
            en: z.clone(),
            rm: vec![0.0; nl],
            rh: z.clone(),
            ri: vec![Matrix3::zeros(); nl],
            tm: vec![0.0; nl],
            th: z,
            ti: vec![Matrix3::zeros(); nl],
            mom_l: vec![Vector3::zeros(); self.nq],
            mom_a: vec![Vector3::zeros(); self.nq],
            end_l: vec![Vector3::zeros(); self.nq],
            end_a: vec![Vector3::zeros(); self.nq],
            mw: vec![Vector3::zeros(); self.nq],
            mv: vec![Vector3::zeros(); self.nq],
        }
    }

    /// Kinematics at `q` (joints then modes) into `k`.
    pub fn kinematics(&self, q: &[f64], k: &mut FlexKin) {
        for i in 1..self.links.len() {
            let l = &self.links[i];
            let p = l.parent;
            let rj = Rotation3::from_axis_angle(&Unit::new_unchecked(l.axis), q[i - 1]);
            let (prot, pend) = (k.end_rot[p], k.end_origin[p]);
            // The joint's offset from the parent's end (zero for a flexible parent).
            let off = match self.links[p].flex {
                Some(fi) => {
                    let f = &self.flex[fi];
                    l.trans_pj - f.ea * f.length_m
                }
                None => l.trans_pj,
            };
            let rot = prot * l.rot_pj * rj.matrix();
            k.origin[i] = pend + prot * off;
            k.axis[i] = rot * l.axis;
            k.rot[i] = rot;
            match l.flex {
                None => {
                    k.end_rot[i] = rot;
                    k.end_origin[i] = k.origin[i];
                }
                Some(fi) => {
                    let f = &self.flex[fi];
                    let nm = f.nm;
                    let eta = &q[f.offset..f.offset + 2 * nm];
                    let (s1, s2) = f.end_slopes(eta);
                    let (mut w1, mut w2) = (0.0, 0.0);
                    let (mut p1, mut p2, mut q1, mut q2) = (0.0, 0.0, 0.0, 0.0);
                    let mut n1 = [0.0; MAX_MODES];
                    let mut n2 = [0.0; MAX_MODES];
                    for m in 0..nm {
                        let (a, b) = (eta[m], eta[nm + m]);
                        w1 += f.phi_l[m] * a;
                        w2 += f.phi_l[m] * b;
                        p1 += f.beam_p[m] * a;
                        p2 += f.beam_p[m] * b;
                        q1 += f.beam_q[m] * a;
                        q2 += f.beam_q[m] * b;
                        for c in 0..nm {
                            n1[m] += f.modal_mass[m][c] * eta[c];
                            n2[m] += f.modal_mass[m][c] * eta[nm + c];
                        }
                    }
                    let (mut j11, mut j12, mut j22) = (0.0, 0.0, 0.0);
                    for m in 0..nm {
                        j11 += eta[m] * n1[m];
                        j12 += eta[m] * n2[m];
                        j22 += eta[nm + m] * n2[m];
                    }
                    // The beam's mass moments in the basis [e_a e_1 e_2]: a station at
                    // x_s is at (x_s, w_1(x_s), w_2(x_s)).
                    k.hl[fi] = Vector3::new(f.beam_x, p1, p2);
                    k.jl[fi] = Matrix3::new(f.beam_xx, q1, q2, q1, j11, j12, q2, j12, j22);
                    k.n1[fi] = n1;
                    k.n2[fi] = n2;
                    let tip = f.ea * f.length_m + f.e1 * w1 + f.e2 * w2;
                    k.end_origin[i] = k.origin[i] + rot * tip;
                    // The end section: Rot(e_2, d_1'(L)) Rot(e_1, -d_2'(L)).
                    let r1 = Rotation3::from_axis_angle(&Unit::new_unchecked(f.e2), s1);
                    let r2 = Rotation3::from_axis_angle(&Unit::new_unchecked(f.e1), -s2);
                    k.end_rot[i] = rot * (r1 * r2).matrix();
                    let eb = rot * f.basis;
                    k.eb[fi] = eb;
                    k.d1[fi] = eb.column(1).into_owned();
                    k.d2[fi] = eb.column(2).into_owned();
                    k.u1[fi] = k.d2[fi];
                    k.u2[fi] = rot * (r1 * (-f.e1));
                }
            }
        }
    }

    /// Inverse dynamics after [`Self::kinematics`] at `q`: `M qdd + C qd + g` of every
    /// coordinate, plus `K eta + C_s eta'` of the modes (N*m for joints, N for modes),
    /// into `tau` (length [`Self::ncoords`]).
    pub fn rnea(&self, k: &mut FlexKin, q: &[f64], qd: &[f64], qdd: &[f64], tau: &mut [f64]) {
        let nl = self.links.len();
        let g = self.gravity;
        for i in 1..nl {
            let j = i - 1;
            let l = &self.links[i];
            let p = l.parent;
            let a = k.axis[i];
            let (wp, alp, accp) = (k.ew[p], k.ealpha[p], k.eacc[p]);
            let d_po = k.origin[i] - k.end_origin[p];
            let wi = wp + a * qd[j];
            let ali = alp + a * qdd[j] + wp.cross(&(a * qd[j]));
            let acci = accp + alp.cross(&d_po) + wp.cross(&wp.cross(&d_po));
            k.w[i] = wi;
            k.alpha[i] = ali;
            k.acc[i] = acci;
            match l.flex {
                None => {
                    let rot = k.rot[i];
                    let h = rot * l.body.h;
                    let ib = rot * l.body.i * rot.transpose();
                    let ag = acci - g;
                    k.f[i] = ag * l.body.m + ali.cross(&h) + wi.cross(&wi.cross(&h));
                    k.n[i] = ib * ali + wi.cross(&(ib * wi)) + h.cross(&ag);
                    k.ew[i] = wi;
                    k.ealpha[i] = ali;
                    k.eacc[i] = acci;
                }
                Some(fi) => {
                    let f = &self.flex[fi];
                    let o = f.offset;
                    let nm = f.nm;
                    let (d1, d2) = (k.d1[fi], k.d2[fi]);
                    // End point: velocity and acceleration relative to the link frame.
                    let (mut v1, mut v2, mut a1, mut a2) = (0.0, 0.0, 0.0, 0.0);
                    let (mut sv1, mut sv2, mut sa1, mut sa2) = (0.0, 0.0, 0.0, 0.0);
                    for m in 0..nm {
                        v1 += f.phi_l[m] * qd[o + m];
                        v2 += f.phi_l[m] * qd[o + nm + m];
                        a1 += f.phi_l[m] * qdd[o + m];
                        a2 += f.phi_l[m] * qdd[o + nm + m];
                        sv1 += f.dphi_l[m] * qd[o + m];
                        sv2 += f.dphi_l[m] * qd[o + nm + m];
                        sa1 += f.dphi_l[m] * qdd[o + m];
                        sa2 += f.dphi_l[m] * qdd[o + nm + m];
                    }
                    let r_t = k.end_origin[i] - k.origin[i];
                    let vrel = d1 * v1 + d2 * v2;
                    let arel = d1 * a1 + d2 * a2;
                    k.eacc[i] = acci
                        + ali.cross(&r_t)
                        + wi.cross(&wi.cross(&r_t))
                        + wi.cross(&vrel) * 2.0
                        + arel;
                    let (u1, u2) = (k.u1[fi], k.u2[fi]);
                    let w1 = wi + u1 * sv1;
                    let al1 = ali + u1 * sa1 + wi.cross(&(u1 * sv1));
                    let we = w1 + u2 * sv2;
                    let ale = al1 + u2 * sa2 + w1.cross(&(u2 * sv2));
                    k.ew[i] = we;
                    k.ealpha[i] = ale;
                    // The rest of the link, on the end.
                    let er = k.end_rot[i];
                    let h = er * f.rest.h;
                    let ag = k.eacc[i] - g;
                    k.ef[i] = ag * f.rest.m + ale.cross(&h) + we.cross(&we.cross(&h));
                    // Its inertia in the end frame: I al + w x I w there, turned back.
                    let (we_e, ale_e) = (er.tr_mul(&we), er.tr_mul(&ale));
                    let iw = f.rest.i * we_e;
                    k.en[i] = er * (f.rest.i * ale_e + we_e.cross(&iw)) + h.cross(&ag);
                    // The beam: its stations' forces `m_s (acc_s - g)`, summed by the
                    // mass moments (in the basis E = [e_a e_1 e_2]: a station at
                    // r_s = (x_s, w_1, w_2), moving at (0, w_1', w_2') relative to the
                    // link, accelerating at (0, w_1'', w_2'')).
                    let eb = k.eb[fi];
                    let gl = eb.tr_mul(&(acci - g));
                    let al = eb.tr_mul(&ali);
                    let wl = eb.tr_mul(&wi);
                    let (hl, jl) = (k.hl[fi], k.jl[fi]);
                    let (n1, n2) = (&k.n1[fi], &k.n2[fi]);
                    let (qd1, qd2) = (&qd[o..o + nm], &qd[o + nm..o + 2 * nm]);
                    let (qdd1, qdd2) = (&qdd[o..o + nm], &qdd[o + nm..o + 2 * nm]);
                    let (mut pv1, mut pv2, mut pa1, mut pa2) = (0.0, 0.0, 0.0, 0.0);
                    let (mut qv1, mut qv2, mut qa1, mut qa2) = (0.0, 0.0, 0.0, 0.0);
                    let mut nv1 = [0.0; MAX_MODES];
                    let mut nv2 = [0.0; MAX_MODES];
                    let mut na1 = [0.0; MAX_MODES];
                    let mut na2 = [0.0; MAX_MODES];
                    for m in 0..nm {
                        pv1 += f.beam_p[m] * qd1[m];
                        pv2 += f.beam_p[m] * qd2[m];
                        pa1 += f.beam_p[m] * qdd1[m];
                        pa2 += f.beam_p[m] * qdd2[m];
                        qv1 += f.beam_q[m] * qd1[m];
                        qv2 += f.beam_q[m] * qd2[m];
                        qa1 += f.beam_q[m] * qdd1[m];
                        qa2 += f.beam_q[m] * qdd2[m];
                        for c in 0..nm {
                            let nmc = f.modal_mass[m][c];
                            nv1[m] += nmc * qd1[c];
                            nv2[m] += nmc * qd2[c];
                            na1[m] += nmc * qdd1[c];
                            na2[m] += nmc * qdd2[c];
                        }
                    }
                    let dn = |x: &[f64], n: &[f64; MAX_MODES]| -> f64 {
                        x.iter().zip(n).map(|(a, b)| a * b).sum()
                    };
                    // sum m_s w_d' r_s and sum m_s w_d'' r_s.
                    let c1 = Vector3::new(qv1, dn(qd1, n1), dn(qd1, n2));
                    let c2 = Vector3::new(qv2, dn(qd2, n1), dn(qd2, n2));
                    let b1 = Vector3::new(qa1, dn(qdd1, n1), dn(qdd1, n2));
                    let b2 = Vector3::new(qa2, dn(qdd2, n1), dn(qdd2, n2));
                    let hv = Vector3::new(0.0, pv1, pv2);
                    let ha = Vector3::new(0.0, pa1, pa2);
                    let fl = gl * f.beam_m
                        + al.cross(&hl)
                        + wl.cross(&wl.cross(&hl))
                        + wl.cross(&hv) * 2.0
                        + ha;
                    // sum r x (alpha x r) = tr(J) alpha - J alpha,
                    // sum r x (w x (w x r)) = -w x J w,
                    // sum r x (w x v) = w sum r.v - sum v (r.w),
                    // sum r x a = b_1 x e_1 + b_2 x e_2.
                    let nl = hl.cross(&gl) + al * jl.trace() - jl * al - wl.cross(&(jl * wl))
                        + (wl * (c1.y + c2.z) - Vector3::new(0.0, c1.dot(&wl), c2.dot(&wl))) * 2.0
                        + Vector3::new(b2.y - b1.z, -b2.x, b1.x);
                    // Generalised forces of the modes: sum_s phi_m(x_s) e_d . f_s.
                    for m in 0..nm {
                        let rho = Vector3::new(f.beam_q[m], n1[m], n2[m]);
                        let nu = Vector3::new(0.0, nv1[m], nv2[m]);
                        let fm = gl * f.beam_p[m]
                            + al.cross(&rho)
                            + wl.cross(&wl.cross(&rho))
                            + wl.cross(&nu) * 2.0;
                        tau[o + m] = fm.y + na1[m];
                        tau[o + nm + m] = fm.z + na2[m];
                    }
                    k.f[i] = eb * fl;
                    k.n[i] = eb * nl;
                }
            }
        }
        for i in (1..nl).rev() {
            let j = i - 1;
            let l = &self.links[i];
            if let Some(fi) = l.flex {
                let f = &self.flex[fi];
                let (o, nm) = (f.offset, f.nm);
                let (ft, nt) = (k.ef[i], k.en[i]);
                let (p1, p2) = (k.d1[fi].dot(&ft), k.d2[fi].dot(&ft));
                let (m1, m2) = (k.u1[fi].dot(&nt), k.u2[fi].dot(&nt));
                for m in 0..nm {
                    tau[o + m] += f.phi_l[m] * p1
                        + f.dphi_l[m] * m1
                        + f.stiffness[m] * q[o + m]
                        + f.damping[m] * qd[o + m];
                    tau[o + nm + m] += f.phi_l[m] * p2
                        + f.dphi_l[m] * m2
                        + f.stiffness[m] * q[o + nm + m]
                        + f.damping[m] * qd[o + nm + m];
                }
                let r_t = k.end_origin[i] - k.origin[i];
                k.f[i] += ft;
                k.n[i] += nt + r_t.cross(&ft);
            }
            tau[j] = k.axis[i].dot(&k.n[i]) + l.armature * qdd[j];
            let p = l.parent;
            if p > 0 {
                let (fi, ni) = (k.f[i], k.n[i]);
                let d = k.origin[i] - k.end_origin[p];
                if self.links[p].flex.is_some() {
                    k.ef[p] += fi;
                    k.en[p] += ni + d.cross(&fi);
                } else {
                    k.f[p] += fi;
                    k.n[p] += ni + d.cross(&fi);
                }
            }
        }
    }

    /// Mass matrix (row-major `ncoords x ncoords` into `m`) after [`Self::kinematics`]:
    /// composite bodies about the world origin.
    pub fn mass_matrix(&self, k: &mut FlexKin, m: &mut [f64]) {
        let nl = self.links.len();
        let nq = self.nq;
        // A body about the world origin from one about a frame (rot, origin).
        let world = |b: &Body, rot: &Matrix3<f64>, o: &Vector3<f64>| -> Body {
            let h = rot * b.h;
            let i = rot * b.i * rot.transpose();
            let hw = h + o * b.m;
            Body {
                m: b.m,
                h: hw,
                i: i + skew_sq(o) * b.m + Matrix3::identity() * (2.0 * h.dot(o))
                    - h * o.transpose()
                    - o * h.transpose(),
            }
        };
        for i in 1..nl {
            let l = &self.links[i];
            match l.flex {
                None => {
                    let b = world(&l.body, &k.rot[i], &k.origin[i]);
                    (k.rm[i], k.rh[i], k.ri[i]) = (b.m, b.h, b.i);
                }
                Some(fi) => {
                    let f = &self.flex[fi];
                    let b = world(&f.rest, &k.end_rot[i], &k.end_origin[i]);
                    (k.tm[i], k.th[i], k.ti[i]) = (b.m, b.h, b.i);
                    // The beam about the world origin from its mass moments.
                    let (o, eb) = (k.origin[i], k.eb[fi]);
                    let sm = f.beam_m;
                    let hw = eb * k.hl[fi];
                    let pp = o * o.transpose() * sm
                        + o * hw.transpose()
                        + hw * o.transpose()
                        + eb * k.jl[fi] * eb.transpose();
                    let si = Matrix3::identity() * pp.trace() - pp;
                    (k.rm[i], k.rh[i], k.ri[i]) = (sm, o * sm + hw, si);
                }
            }
        }
        for i in (1..nl).rev() {
            if self.links[i].flex.is_some() {
                let (a, b, c) = (k.tm[i], k.th[i], k.ti[i]);
                k.rm[i] += a;
                k.rh[i] += b;
                k.ri[i] += c;
            }
            let p = self.links[i].parent;
            if p > 0 {
                let (a, b, c) = (k.rm[i], k.rh[i], k.ri[i]);
                if self.links[p].flex.is_some() {
                    k.tm[p] += a;
                    k.th[p] += b;
                    k.ti[p] += c;
                } else {
                    k.rm[p] += a;
                    k.rh[p] += b;
                    k.ri[p] += c;
                }
            }
        }
        let mom =
            |cm: f64, ch: &Vector3<f64>, ci: &Matrix3<f64>, w: &Vector3<f64>, v0: &Vector3<f64>| {
                (w.cross(ch) + v0 * cm, ci * w + ch.cross(v0))
            };
        // Unit motions and momenta of every coordinate.
        for i in 1..nl {
            let j = i - 1;
            let a = k.axis[i];
            let v0 = k.origin[i].cross(&a);
            k.mw[j] = a;
            k.mv[j] = v0;
            let (ml, ma) = mom(k.rm[i], &k.rh[i], &k.ri[i], &a, &v0);
            k.mom_l[j] = ml;
            k.mom_a[j] = ma;
            if let Some(fi) = self.links[i].flex {
                let f = &self.flex[fi];
                let ot = k.end_origin[i];
                let (o, eb) = (k.origin[i], k.eb[fi]);
                for dir in 0..2 {
                    let (dv, u) = if dir == 0 {
                        (k.d1[fi], k.u1[fi])
                    } else {
                        (k.d2[fi], k.u2[fi])
                    };
                    for md in 0..f.nm {
                        let c = f.offset + dir * f.nm + md;
                        let w = u * f.dphi_l[md];
                        let v0 = dv * f.phi_l[md] - w.cross(&ot);
                        k.mw[c] = w;
                        k.mv[c] = v0;
                        let (ml, ma) = mom(k.tm[i], &k.th[i], &k.ti[i], &w, &v0);
                        k.end_l[c] = ml;
                        k.end_a[c] = ma;
                        // The stations: sum m_s phi(x_s) (dv, p_s x dv).
                        let rho = o * f.beam_p[md]
                            + eb * Vector3::new(f.beam_q[md], k.n1[fi][md], k.n2[fi][md]);
                        k.mom_l[c] = ml + dv * f.beam_p[md];
                        k.mom_a[c] = ma + rho.cross(&dv);
                    }
                }
            }
        }
        let set = |m: &mut [f64], a: usize, b: usize, v: f64| {
            m[a * nq + b] = v;
            m[b * nq + a] = v;
        };
        let dot =
            |k: &FlexKin, a: usize, b: usize| k.mw[a].dot(&k.mom_a[b]) + k.mv[a].dot(&k.mom_l[b]);
        // Every coordinate `b` of link i (its joint, then its modes) against the
        // coordinates of link i before it and of every ancestor.
        let ancestors = |k: &FlexKin, m: &mut [f64], i: usize, b: usize| {
            let mut anc = self.links[i].parent;
            while anc > 0 {
                set(m, anc - 1, b, dot(k, anc - 1, b));
                if let Some(fa) = self.links[anc].flex {
                    let fa = &self.flex[fa];
                    for a in fa.offset..fa.offset + 2 * fa.nm {
                        set(m, a, b, dot(k, a, b));
                    }
                }
                anc = self.links[anc].parent;
            }
        };
        for i in 1..nl {
            let j = i - 1;
            set(m, j, j, dot(k, j, j) + self.links[i].armature);
            ancestors(k, m, i, j);
            let Some(fi) = self.links[i].flex else {
                continue;
            };
            let f = &self.flex[fi];
            let nm = f.nm;
            for db in 0..2 {
                for mb in 0..nm {
                    let b = f.offset + db * nm + mb;
                    set(m, j, b, dot(k, j, b));
                    // Two modes of the same link: the stations' modal mass plus the
                    // end's composite body.
                    let (el, ea) = (k.end_l[b], k.end_a[b]);
                    for da in 0..=db {
                        let top = if da == db { mb + 1 } else { nm };
                        for ma in 0..top {
                            let a = f.offset + da * nm + ma;
                            let st = if da == db { f.modal_mass[ma][mb] } else { 0.0 };
                            set(m, a, b, st + k.mw[a].dot(&ea) + k.mv[a].dot(&el));
                        }
                    }
                    ancestors(k, m, i, b);
                }
            }
        }
    }

    /// Modal stiffness and damping terms' derivatives: `K` and `C_s` on the diagonal of
    /// the modal coordinates (`out += ks K + cs C_s`).
    pub fn add_stiffness(&self, ks: f64, cs: f64, out: &mut [f64]) {
        let nq = self.nq;
        for f in &self.flex {
            for dir in 0..2 {
                for m in 0..f.nm {
                    let c = f.offset + dir * f.nm + m;
                    out[c * nq + c] += ks * f.stiffness[m] + cs * f.damping[m];
                }
            }
        }
    }

    /// Kinetic energy `1/2 qd^T M qd` (J) after [`Self::kinematics`]; `m` is scratch of
    /// `ncoords^2`.
    pub fn kinetic_energy(&self, k: &mut FlexKin, qd: &[f64], m: &mut [f64]) -> f64 {
        self.mass_matrix(k, m);
        let n = self.nq;
        let mut e = 0.0;
        for a in 0..n {
            for b in 0..n {
                e += qd[a] * m[a * n + b] * qd[b];
            }
        }
        0.5 * e
    }

    /// Gravitational potential energy (J) after [`Self::kinematics`].
    pub fn potential_energy(&self, k: &FlexKin) -> f64 {
        let mut mh = Vector3::zeros();
        for i in 1..self.links.len() {
            let l = &self.links[i];
            match l.flex {
                None => mh += k.origin[i] * l.body.m + k.rot[i] * l.body.h,
                Some(fi) => {
                    let f = &self.flex[fi];
                    mh += k.end_origin[i] * f.rest.m + k.end_rot[i] * f.rest.h;
                    mh += k.origin[i] * f.beam_m + k.eb[fi] * k.hl[fi];
                }
            }
        }
        -self.gravity.dot(&mh)
    }

    /// Elastic energy of the bent links, J.
    pub fn elastic_energy(&self, q: &[f64]) -> f64 {
        let mut e = 0.0;
        for f in &self.flex {
            for dir in 0..2 {
                for m in 0..f.nm {
                    let v = q[f.offset + dir * f.nm + m];
                    e += 0.5 * f.stiffness[m] * v * v;
                }
            }
        }
        e
    }

    /// World position of the point `r` (link frame of link `link`) of the bent arm,
    /// after [`Self::kinematics`] at `q`: on a flexible link, displaced with the beam's
    /// deflection at its axial position.
    pub fn point(&self, k: &FlexKin, q: &[f64], link: usize, r: &Vector3<f64>) -> Vector3<f64> {
        match self.links[link].flex {
            None => k.origin[link] + k.rot[link] * r,
            Some(fi) => {
                let f = &self.flex[fi];
                let eta = &q[f.offset..f.offset + 2 * f.nm];
                k.origin[link] + k.rot[link] * (r + f.deflection(eta, r.dot(&f.ea)))
            }
        }
    }

    /// World rotation and origin of link `link`'s frame after [`Self::kinematics`].
    pub fn link_pose(&self, k: &FlexKin, link: usize) -> (Matrix3<f64>, Vector3<f64>) {
        (k.rot[link], k.origin[link])
    }

    /// The modal coordinates that hold the links bent under gravity at the joint
    /// angles of `q` (written into `q`'s modal part, used as the start), at rest:
    /// the static balance `K eta + g_eta(q, eta) = 0`, solved by iterating on the
    /// (diagonal) `K`. Then the joints' gravity torques at that pose into `tau`.
    pub fn sag(&self, k: &mut FlexKin, q: &mut [f64], zero: &[f64], tau: &mut [f64]) {
        for _ in 0..200 {
            self.kinematics(q, k);
            self.rnea(k, q, zero, zero, tau);
            let mut big = 0.0f64;
            for f in &self.flex {
                for dir in 0..2 {
                    for m in 0..f.nm {
                        let c = f.offset + dir * f.nm + m;
                        let d = tau[c] / f.stiffness[m];
                        q[c] -= d;
                        big = big.max(d.abs() / (1e-3 * f.length_m + q[c].abs()));
                    }
                }
            }
            if big < 1e-15 {
                break;
            }
        }
        self.kinematics(q, k);
        self.rnea(k, q, zero, zero, tau);
    }
}

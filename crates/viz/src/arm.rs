//! An arm run in Rerun: links with their URDF visuals, ropes through their pulleys
//! coloured by tension, and the time series of joints, motors, tensions and tip.
//!
//! Entity paths (see docs/rerun.md):
//!
//! ```text
//! /world                        view coordinates (right-handed, z up)
//! /world/arm/<link>             pose of every moving link (sim_time); its URDF visual
//!                               geometry and the joint and relay pulleys on its joint
//!                               axis (static, one batch per shape kind)
//! /world/motors                 motor pulleys at the base (static)
//! /world/ropes                  every rope, a strip per span, coloured by tension
//! /series/joints/angle_rad      "<joint> q" then "<joint> ref" for every joint
//! /series/motors/angle_rad      "<joint> motor" then "<joint> motor ref" for every pair
//! /series/motors/torque_n_m     servo torque of every pair, named by its joint
//! /series/tensions/tension_n    "<joint> +" then "<joint> -" (one rope of the parallel ones)
//! /series/tip/error_m           distance of the tip from where the commands put it
//! ```
//!
//! Each `/series/...` entity is a group of series (one instance per name), so that a
//! recording has a handful of chunks per send whatever the number of joints.

use longreach_arm::fast::{FastDynamics, Kin};
use longreach_arm::spec::Geometry;
use longreach_arm::{DrivenArm, DrivenState};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use rerun::blueprint::{
    Blueprint, BlueprintActivation, Horizontal, Spatial3DView, TimeSeriesView, Vertical,
};
use rerun::components::RotationQuat;
use rerun::{Boxes3D, Capsules3D, Color, Cylinders3D, Ellipsoids3D, Quaternion, ViewCoordinates};

use crate::{
    tension_color, Columns, RateGate, Recorder, SeriesId, StripsId, TransformId, SIM_TIME,
};

/// Logs one driven-arm run; feed it every state with [`ArmLogger::observe`].
#[derive(Debug)]
pub struct ArmLogger<'a> {
    rec: &'a Recorder,
    arm: &'a DrivenArm,
    dynamics: FastDynamics,
    kin: Kin,
    gate: RateGate,
    cols: Columns,
    /// Kinematics at the commanded angles (for the tip error) and those angles.
    kin_ref: Kin,
    q_ref_rad: Vec<f64>,
    links: Vec<TransformId>,
    ropes: StripsId,
    joint_angles: SeriesId,
    motor_angles: SeriesId,
    motor_torques: SeriesId,
    tensions: SeriesId,
    tip_error: SeriesId,
    motor_points_m: Vec<Vector3<f64>>,
    /// Pulleys of every pair's rope, motor first: `None` = the motor pulley,
    /// `Some(j)` = the pulley on joint `j`'s axis, with its radius.
    rope_pulleys: Vec<Vec<(Option<usize>, f64)>>,
    /// Scratch: rope points of one side.
    points_m: Vec<[f64; 3]>,
    /// Drawing scale, m ([`draw_scale_m`]).
    scale_m: f64,
    frames: usize,
}

impl<'a> ArmLogger<'a> {
    /// Logs the static scene of `arm` (visuals, pulleys, motors) and the default
    /// blueprint, and prepares the per-frame channels.
    pub fn new(rec: &'a Recorder, arm: &'a DrivenArm) -> Self {
        let dynamics = FastDynamics::new(&arm.spec);
        let kin = dynamics.make_kin();
        let mut cols = Columns::on_duration(SIM_TIME);
        let links = arm.spec.links[1..]
            .iter()
            .map(|l| cols.pose(format!("/world/arm/{}", l.name)))
            .collect();
        let scale_m = draw_scale_m(arm);
        let rope_radius_m = 0.004 * scale_m;
        let ropes = cols.strips("/world/ropes", rope_radius_m);
        let joint_name = |p: usize| arm.spec.joints[arm.pairs[p].spec.joint].name.clone();
        let joints: Vec<&str> = arm.spec.joints.iter().map(|j| j.name.as_str()).collect();
        let pairs: Vec<String> = (0..arm.pairs.len()).map(joint_name).collect();
        let named = |suffixes: &[&str], of: &[&str]| -> Vec<String> {
            suffixes
                .iter()
                .flat_map(|s| of.iter().map(move |j| format!("{j}{s}")))
                .collect()
        };
        let pairs: Vec<&str> = pairs.iter().map(String::as_str).collect();
        let joint_angles =
            cols.series_group("/series/joints/angle_rad", named(&[" q", " ref"], &joints));
        let motor_angles = cols.series_group(
            "/series/motors/angle_rad",
            named(&[" motor", " motor ref"], &pairs),
        );
        let motor_torques = cols.series_group("/series/motors/torque_n_m", named(&[""], &pairs));
        let tensions =
            cols.series_group("/series/tensions/tension_n", named(&[" +", " -"], &pairs));
        let tip_error = cols.series("/series/tip/error_m");
        let rope_pulleys = arm
            .pairs
            .iter()
            .map(|pair| {
                let mut route = pair.spec.route.clone();
                route.sort_by_key(|r| r.joint);
                std::iter::once((None, pair.spec.motor_radius_m))
                    .chain(route.iter().map(|r| (Some(r.joint), r.radius_m)))
                    .chain(std::iter::once((
                        Some(pair.spec.joint),
                        pair.spec.joint_radius_m,
                    )))
                    .collect()
            })
            .collect();
        let np = arm.pairs.len();
        let motor_points_m = (0..np)
            .map(|p| {
                let s = scale_m;
                Vector3::new(
                    -0.3 * s,
                    (p as f64 - 0.5 * (np as f64 - 1.0)) * 0.12 * s,
                    0.0,
                )
            })
            .collect();
        let kin_ref = dynamics.make_kin();
        let me = Self {
            rec,
            arm,
            dynamics,
            kin,
            kin_ref,
            q_ref_rad: Vec::new(),
            gate: RateGate::new(rec.hz()),
            cols,
            links,
            ropes,
            joint_angles,
            motor_angles,
            motor_torques,
            tensions,
            tip_error,
            motor_points_m,
            rope_pulleys,
            points_m: Vec::new(),
            scale_m,
            frames: 0,
        };
        if rec.is_enabled() {
            me.log_static();
        }
        me
    }

    fn log_static(&self) {
        let rec = self.rec;
        let s = rec.stream();
        rec.report(
            "view coordinates",
            s.log_static("/world", &ViewCoordinates::RIGHT_HAND_Z_UP()),
        );
        let spec = &self.arm.spec;
        // Every link's URDF visuals and the pulleys on its joint axis, one static row
        // per link (one batch per shape kind): a handful of chunks for the whole arm.
        let mut shapes: Vec<LinkShapes> = vec![LinkShapes::default(); spec.links.len()];
        let mut mesh_warned = false;
        for (link, shapes) in spec.links.iter().zip(shapes.iter_mut()) {
            for v in &link.visuals {
                // The visual's pose in the link frame goes into the shape itself.
                let t = v.link_from_visual.translation.vector;
                let q = v.link_from_visual.rotation;
                let rot = RotationQuat::from(quat(&q));
                let color = v.rgba.map_or(Color::from_rgb(170, 170, 180), |c| {
                    let b = |x: f64| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
                    Color::from_unmultiplied_rgba(b(c[0]), b(c[1]), b(c[2]), b(c[3]))
                });
                match &v.geometry {
                    Geometry::Box { size_m } => shapes.boxes.push((
                        [size_m.x as f32, size_m.y as f32, size_m.z as f32],
                        point(t),
                        rot,
                        color,
                    )),
                    Geometry::Cylinder { radius_m, length_m } => shapes.cylinders.push((
                        *length_m as f32,
                        *radius_m as f32,
                        point(t),
                        rot,
                        color,
                    )),
                    // Rerun's capsule starts at its translation; URDF's is centred.
                    Geometry::Capsule { radius_m, length_m } => shapes.capsules.push((
                        *length_m as f32,
                        *radius_m as f32,
                        point(t + q * Vector3::new(0.0, 0.0, -0.5 * length_m)),
                        rot,
                        color,
                    )),
                    Geometry::Sphere { radius_m } => {
                        shapes.spheres.push((*radius_m as f32, point(t), color));
                    }
                    Geometry::Mesh { filename, .. } => {
                        if !mesh_warned {
                            mesh_warned = true;
                            eprintln!(
                                "rerun: mesh visual `{filename}` of link `{}` is not drawn (only box, cylinder, \
                                 capsule and sphere visuals are); the run goes on",
                                link.name
                            );
                        }
                    }
                }
            }
        }
        // Pulleys: every pulley on a joint axis, in the child link's frame (whose
        // origin is the joint origin).
        for (j, joint) in spec.joints.iter().enumerate() {
            let mut radii = Vec::new();
            for p in &self.arm.pairs {
                if p.spec.joint == j {
                    radii.push(p.spec.joint_radius_m);
                }
                radii.extend(
                    p.spec
                        .route
                        .iter()
                        .filter(|r| r.joint == j)
                        .map(|r| r.radius_m),
                );
            }
            let axis = joint.axis.into_inner();
            let rot = UnitQuaternion::rotation_between(&Vector3::z(), &axis).unwrap_or_else(|| {
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
            });
            let width = 0.02 * self.scale_m;
            let n = radii.len();
            for (i, r) in radii.iter().enumerate() {
                let c = axis * (i as f64 - 0.5 * (n as f64 - 1.0)) * 1.5 * width;
                shapes[joint.child_link].cylinders.push((
                    width as f32,
                    *r as f32,
                    point(c),
                    RotationQuat::from(quat(&rot)),
                    Color::from_rgb(120, 120, 130),
                ));
            }
        }
        for (link, shapes) in spec.links.iter().zip(&shapes) {
            let path = format!("/world/arm/{}", link.name);
            let archetypes = shapes.archetypes();
            if !archetypes.is_empty() {
                rec.report(&path, s.log_static(path.as_str(), &archetypes));
            }
        }
        let np = self.arm.pairs.len();
        rec.report(
            "/world/motors",
            s.log_static(
                "/world/motors",
                &Cylinders3D::from_lengths_and_radii(
                    vec![0.03 * self.scale_m as f32; np],
                    self.arm.pairs.iter().map(|p| p.spec.motor_radius_m as f32),
                )
                .with_centers(
                    self.motor_points_m
                        .iter()
                        .map(|m| [m.x as f32, m.y as f32, m.z as f32]),
                )
                .with_quaternions(vec![
                    RotationQuat::from(Quaternion::from_xyzw([
                        std::f32::consts::FRAC_1_SQRT_2,
                        0.0,
                        0.0,
                        std::f32::consts::FRAC_1_SQRT_2
                    ]));
                    np
                ])
                .with_colors(vec![Color::from_rgb(60, 60, 70); np]),
            ),
        );
        let joints = Vertical::new([
            TimeSeriesView::new("Joint and command angles")
                .with_origin("/series/joints")
                .into(),
            TimeSeriesView::new("Rope tensions")
                .with_origin("/series/tensions")
                .into(),
            TimeSeriesView::new("Motors and servo torque")
                .with_origin("/series/motors")
                .into(),
            TimeSeriesView::new("Tip error")
                .with_origin("/series/tip")
                .into(),
        ]);
        let bp = Blueprint::new(Horizontal::new([
            Spatial3DView::new("Arm and ropes")
                .with_origin("/world")
                .into(),
            joints.into(),
        ]));
        rec.report("blueprint", bp.send(s, BlueprintActivation::default()));
        // The scene is encoded in the background while the run goes on.
        rec.report("static scene", s.flush_async());
    }

    /// Logs `st` when it is due at the logging rate (reads it only).
    pub fn observe(&mut self, st: &DrivenState) {
        if !self.rec.is_enabled() || !self.gate.due(st.time_s) {
            return;
        }
        let arm = self.arm;
        self.cols.frame_at_s(st.time_s);
        self.dynamics.kinematics(&st.q_rad, &mut self.kin);
        for (i, id) in self.links.iter().enumerate() {
            let r = Rotation3::from_matrix_unchecked(self.kin.rot[i + 1]);
            let q = UnitQuaternion::from_rotation_matrix(&r);
            let o = self.kin.origin[i + 1];
            self.cols
                .push_pose(*id, [o.x, o.y, o.z], [q.i, q.j, q.k, q.w]);
        }
        // Strips of this frame: consecutive spans of the same colour are one strip (an
        // ideal pair is one strip per rope side; relay friction splits it where the
        // span tensions differ).
        let mut strips: Vec<(Vec<[f64; 3]>, [u8; 4])> = Vec::new();
        for (p, pair) in arm.pairs.iter().enumerate() {
            let full = 2.0 * pair.spec.preload_n;
            // Spans motor side first; a pair without relay friction has one tension
            // along its whole rope.
            let spans = arm.span_tensions_n(st, p);
            for (side, sign) in [1.0, -1.0].into_iter().enumerate() {
                self.rope_points(p, sign);
                let mut current: Option<(Vec<[f64; 3]>, [u8; 4])> = None;
                for (i, w) in self.points_m.windows(2).enumerate() {
                    let color = tension_color(spans[i.min(spans.len() - 1)][side], full);
                    match &mut current {
                        Some((points, c)) if *c == color => points.push(w[1]),
                        _ => {
                            strips.extend(current.take());
                            current = Some((vec![w[0], w[1]], color));
                        }
                    }
                }
                strips.extend(current);
            }
        }
        self.cols.push_strips(self.ropes, strips);
        let np = arm.pairs.len();
        self.cols.push_group(
            self.joint_angles,
            st.q_rad.iter().chain(&st.q_ref_rad).copied(),
        );
        self.cols.push_group(
            self.motor_angles,
            st.motor_rad[..np]
                .iter()
                .chain(&st.motor_ref_rad[..np])
                .copied(),
        );
        self.cols.push_group(
            self.motor_torques,
            st.motor_torque_n_m[..np].iter().copied(),
        );
        self.cols.push_group(
            self.tensions,
            (0..2).flat_map(|side| st.ropes[..np].iter().map(move |r| r[side].tension_n)),
        );
        if self.q_ref_rad != st.q_ref_rad {
            self.dynamics.kinematics(&st.q_ref_rad, &mut self.kin_ref);
            self.q_ref_rad.clone_from(&st.q_ref_rad);
        }
        let tip = self.tip_m(&self.kin);
        let err = (tip - self.tip_m(&self.kin_ref)).norm();
        self.cols.push(self.tip_error, err);
        self.frames += 1;
        self.cols.flush_when_due(self.rec);
    }

    /// World position of the arm's tip frame from kinematics `kin`, m.
    fn tip_m(&self, kin: &Kin) -> Vector3<f64> {
        let tip = &self.arm.spec.tip;
        kin.origin[tip.link] + kin.rot[tip.link] * tip.link_from_frame.translation.vector
    }

    /// Frames logged so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Sends what is buffered.
    pub fn finish(mut self) -> usize {
        self.cols.flush(self.rec);
        self.frames
    }

    /// World points of rope `sign` (+1 / -1) of pair `p` into `self.points_m`: motor
    /// pulley, relay pulleys, joint pulley, each offset by its radius to the rope's side
    /// (after kinematics).
    fn rope_points(&mut self, p: usize, sign: f64) {
        let centre = |&(joint, radius_m): &(Option<usize>, f64)| match joint {
            None => (self.motor_points_m[p], Vector3::z(), radius_m),
            Some(j) => (self.kin.origin[j + 1], self.kin.axis[j + 1], radius_m),
        };
        let pulleys = &self.rope_pulleys[p];
        let n = pulleys.len();
        let mut points = std::mem::take(&mut self.points_m);
        points.clear();
        for i in 0..n {
            let (c, axis, r) = centre(&pulleys[i]);
            let prev = centre(&pulleys[i.saturating_sub(1)]).0;
            let next = centre(&pulleys[(i + 1).min(n - 1)]).0;
            let d = next - prev;
            let mut side = axis.cross(&d);
            if side.norm() < 1e-9 {
                side = axis.cross(&Vector3::x());
                if side.norm() < 1e-9 {
                    side = axis.cross(&Vector3::y());
                }
            }
            let pt = c + side.normalize() * (sign * r);
            points.push([pt.x, pt.y, pt.z]);
        }
        self.points_m = points;
    }
}

/// The static shapes of one link, by kind: `(size or length and radius, centre or
/// start, rotation, colour)` in the link frame.
#[derive(Debug, Clone, Default)]
struct LinkShapes {
    boxes: Vec<([f32; 3], [f32; 3], RotationQuat, Color)>,
    cylinders: Vec<(f32, f32, [f32; 3], RotationQuat, Color)>,
    capsules: Vec<(f32, f32, [f32; 3], RotationQuat, Color)>,
    spheres: Vec<(f32, [f32; 3], Color)>,
}

impl LinkShapes {
    /// One archetype per kind present (logged together: one row, one chunk).
    fn archetypes(&self) -> Vec<Box<dyn rerun::AsComponents>> {
        let mut out: Vec<Box<dyn rerun::AsComponents>> = Vec::new();
        if !self.boxes.is_empty() {
            out.push(Box::new(
                Boxes3D::from_sizes(self.boxes.iter().map(|b| b.0))
                    .with_centers(self.boxes.iter().map(|b| b.1))
                    .with_quaternions(self.boxes.iter().map(|b| b.2))
                    .with_colors(self.boxes.iter().map(|b| b.3))
                    .with_fill_mode(rerun::FillMode::Solid),
            ));
        }
        if !self.cylinders.is_empty() {
            out.push(Box::new(
                Cylinders3D::from_lengths_and_radii(
                    self.cylinders.iter().map(|c| c.0),
                    self.cylinders.iter().map(|c| c.1),
                )
                .with_centers(self.cylinders.iter().map(|c| c.2))
                .with_quaternions(self.cylinders.iter().map(|c| c.3))
                .with_colors(self.cylinders.iter().map(|c| c.4))
                .with_fill_mode(rerun::FillMode::Solid),
            ));
        }
        if !self.capsules.is_empty() {
            out.push(Box::new(
                Capsules3D::from_lengths_and_radii(
                    self.capsules.iter().map(|c| c.0),
                    self.capsules.iter().map(|c| c.1),
                )
                .with_translations(self.capsules.iter().map(|c| c.2))
                .with_quaternions(self.capsules.iter().map(|c| c.3))
                .with_colors(self.capsules.iter().map(|c| c.4)),
            ));
        }
        if !self.spheres.is_empty() {
            out.push(Box::new(
                Ellipsoids3D::from_radii(self.spheres.iter().map(|e| e.0))
                    .with_centers(self.spheres.iter().map(|e| e.1))
                    .with_colors(self.spheres.iter().map(|e| e.2))
                    .with_fill_mode(rerun::FillMode::Solid),
            ));
        }
        out
    }
}

/// `p` as a Rerun point.
fn point(p: Vector3<f64>) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}

fn quat(q: &UnitQuaternion<f64>) -> Quaternion {
    Quaternion::from_xyzw([q.i as f32, q.j as f32, q.k as f32, q.w as f32])
}

/// Length scale for drawing sizes: a tenth of the arm's reach at its initial pose,
/// clamped to 0.1..1 m.
fn draw_scale_m(arm: &DrivenArm) -> f64 {
    (0.1 * arm.tip_m(&arm.initial_q_rad).norm()).clamp(0.1, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tip_from_the_logger_kinematics_is_the_arm_tip() {
        let arm = longreach_arm::anchor_chain(6, longreach_rope::LawKind::Elastic, 1e-3).unwrap();
        let rec = Recorder::off();
        let mut logger = ArmLogger::new(&rec, &arm);
        for k in 0..5 {
            let q: Vec<f64> = (0..arm.spec.ndofs())
                .map(|j| 0.3 * ((k * 7 + j * 3) as f64).sin())
                .collect();
            logger.dynamics.kinematics(&q, &mut logger.kin);
            let d = (logger.tip_m(&logger.kin) - arm.tip_m(&q)).norm();
            assert!(d < 1e-12, "pose {k}: {d} m");
            assert!(arm.tip_m(&q).norm() > 1.0);
        }
    }
}

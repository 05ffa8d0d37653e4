//! An arm run in Rerun: links with their URDF visuals, ropes through their pulleys
//! coloured by tension, and the time series of joints, motors, tensions and tip.
//!
//! Entity paths (see docs/rerun.md):
//!
//! ```text
//! /world                                   view coordinates (right-handed, z up)
//! /world/arm/<link>                        pose of every moving link (sim_time)
//! /world/arm/<link>/visual_<i>             its URDF visual geometry (static)
//! /world/arm/<link>/pulleys                joint and relay pulleys on its joint axis (static)
//! /world/motors                            motor pulleys at the base (static)
//! /world/ropes/<joint>                     the pair's + and - ropes, a strip per span, coloured by tension
//! /series/joints/<joint>/{q_rad,q_ref_rad} joint and command angles
//! /series/motors/<joint>/{angle_rad,ref_rad,torque_n_m}  motor angle, reference, servo torque
//! /series/tensions/<joint>/{pos_n,neg_n}   rope tensions (one rope of the parallel ones)
//! /series/tip/error_m                      distance of the tip from where the commands put it
//! ```

use longreach_arm::fast::{FastDynamics, Kin};
use longreach_arm::spec::Geometry;
use longreach_arm::{DrivenArm, DrivenState};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use rerun::blueprint::{
    Blueprint, BlueprintActivation, Horizontal, Spatial3DView, TimeSeriesView, Vertical,
};
use rerun::components::RotationQuat;
use rerun::{
    Boxes3D, Capsules3D, Color, Cylinders3D, Ellipsoids3D, Quaternion, Transform3D, ViewCoordinates,
};

use crate::{
    tension_color, Columns, RateGate, Recorder, SeriesId, StripsId, TransformId, SIM_TIME,
};

/// Frames buffered between two sends (one simulated second at 60 Hz).
const FLUSH_FRAMES: usize = 60;

/// Logs one driven-arm run; feed it every state with [`ArmLogger::observe`].
#[derive(Debug)]
pub struct ArmLogger<'a> {
    rec: &'a Recorder,
    arm: &'a DrivenArm,
    dynamics: FastDynamics,
    kin: Kin,
    gate: RateGate,
    cols: Columns,
    links: Vec<TransformId>,
    ropes: Vec<StripsId>,
    q: Vec<(SeriesId, SeriesId)>,
    motors: Vec<(SeriesId, SeriesId, SeriesId)>,
    tensions: Vec<(SeriesId, SeriesId)>,
    tip_error: SeriesId,
    motor_points_m: Vec<Vector3<f64>>,
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
        let joint_name = |p: usize| arm.spec.joints[arm.pairs[p].spec.joint].name.clone();
        let ropes = (0..arm.pairs.len())
            .map(|p| cols.strips(format!("/world/ropes/{}", joint_name(p)), rope_radius_m))
            .collect();
        let q = arm
            .spec
            .joints
            .iter()
            .map(|j| {
                (
                    cols.series(format!("/series/joints/{}/q_rad", j.name)),
                    cols.series(format!("/series/joints/{}/q_ref_rad", j.name)),
                )
            })
            .collect();
        let motors = (0..arm.pairs.len())
            .map(|p| {
                let j = joint_name(p);
                (
                    cols.series(format!("/series/motors/{j}/angle_rad")),
                    cols.series(format!("/series/motors/{j}/ref_rad")),
                    cols.series(format!("/series/motors/{j}/torque_n_m")),
                )
            })
            .collect();
        let tensions = (0..arm.pairs.len())
            .map(|p| {
                let j = joint_name(p);
                (
                    cols.series(format!("/series/tensions/{j}/pos_n")),
                    cols.series(format!("/series/tensions/{j}/neg_n")),
                )
            })
            .collect();
        let tip_error = cols.series("/series/tip/error_m");
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
        let me = Self {
            rec,
            arm,
            dynamics,
            kin,
            gate: RateGate::new(rec.hz()),
            cols,
            links,
            ropes,
            q,
            motors,
            tensions,
            tip_error,
            motor_points_m,
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
        let mut mesh_warned = false;
        for link in &spec.links {
            let base = format!("/world/arm/{}", link.name);
            for (i, v) in link.visuals.iter().enumerate() {
                let path = format!("{base}/visual_{i}");
                let t = v.link_from_visual.translation.vector;
                let q = v.link_from_visual.rotation;
                rec.report(
                    &path,
                    s.log_static(
                        path.as_str(),
                        &Transform3D::from_translation_rotation(
                            [t.x as f32, t.y as f32, t.z as f32],
                            quat(&q),
                        ),
                    ),
                );
                let color = v.rgba.map_or(Color::from_rgb(170, 170, 180), |c| {
                    let b = |x: f64| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
                    Color::from_unmultiplied_rgba(b(c[0]), b(c[1]), b(c[2]), b(c[3]))
                });
                let logged = match &v.geometry {
                    Geometry::Box { size_m } => s.log_static(
                        path.as_str(),
                        &Boxes3D::from_sizes([[size_m.x as f32, size_m.y as f32, size_m.z as f32]])
                            .with_colors([color])
                            .with_fill_mode(rerun::FillMode::Solid),
                    ),
                    Geometry::Cylinder { radius_m, length_m } => s.log_static(
                        path.as_str(),
                        &Cylinders3D::from_lengths_and_radii(
                            [*length_m as f32],
                            [*radius_m as f32],
                        )
                        .with_colors([color])
                        .with_fill_mode(rerun::FillMode::Solid),
                    ),
                    Geometry::Capsule { radius_m, length_m } => s.log_static(
                        path.as_str(),
                        &Capsules3D::from_lengths_and_radii([*length_m as f32], [*radius_m as f32])
                            .with_translations([[0.0, 0.0, -0.5 * *length_m as f32]])
                            .with_colors([color]),
                    ),
                    Geometry::Sphere { radius_m } => s.log_static(
                        path.as_str(),
                        &Ellipsoids3D::from_radii([*radius_m as f32])
                            .with_colors([color])
                            .with_fill_mode(rerun::FillMode::Solid),
                    ),
                    Geometry::Mesh { filename, .. } => {
                        if !mesh_warned {
                            mesh_warned = true;
                            eprintln!(
                                "rerun: mesh visual `{filename}` of link `{}` is not drawn (only box, cylinder, \
                                 capsule and sphere visuals are); the run goes on",
                                link.name
                            );
                        }
                        Ok(())
                    }
                };
                rec.report(&path, logged);
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
            if radii.is_empty() {
                continue;
            }
            let axis = joint.axis.into_inner();
            let rot = UnitQuaternion::rotation_between(&Vector3::z(), &axis).unwrap_or_else(|| {
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
            });
            let width = 0.02 * self.scale_m;
            let n = radii.len();
            let centers: Vec<[f32; 3]> = (0..n)
                .map(|i| {
                    let c = axis * (i as f64 - 0.5 * (n as f64 - 1.0)) * 1.5 * width;
                    [c.x as f32, c.y as f32, c.z as f32]
                })
                .collect();
            let path = format!("/world/arm/{}/pulleys", spec.links[joint.child_link].name);
            rec.report(
                &path,
                s.log_static(
                    path.as_str(),
                    &Cylinders3D::from_lengths_and_radii(
                        vec![width as f32; n],
                        radii.iter().map(|r| *r as f32),
                    )
                    .with_centers(centers)
                    .with_quaternions(vec![RotationQuat::from(quat(&rot)); n])
                    .with_colors(vec![Color::from_rgb(120, 120, 130); n]),
                ),
            );
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
        for (p, pair) in arm.pairs.iter().enumerate() {
            let full = 2.0 * pair.spec.preload_n;
            // Spans motor side first; a pair without relay friction has one tension
            // along its whole rope.
            let spans = arm.span_tensions_n(st, p);
            let strips = [1.0, -1.0]
                .into_iter()
                .enumerate()
                .flat_map(|(side, sign)| {
                    let points = self.rope_points(p, sign);
                    // One strip per span, each coloured by its tension.
                    points
                        .windows(2)
                        .enumerate()
                        .map(|(i, w)| {
                            let tension = spans[i.min(spans.len() - 1)][side];
                            (vec![w[0], w[1]], tension_color(tension, full))
                        })
                        .collect::<Vec<_>>()
                });
            let strips: Vec<_> = strips.collect();
            self.cols.push_strips(self.ropes[p], strips);
        }
        for (j, (q, r)) in self.q.iter().enumerate() {
            self.cols.push(*q, st.q_rad[j]);
            self.cols.push(*r, st.q_ref_rad[j]);
        }
        for (p, (a, r, t)) in self.motors.iter().enumerate() {
            self.cols.push(*a, st.motor_rad[p]);
            self.cols.push(*r, st.motor_ref_rad[p]);
            self.cols.push(*t, st.motor_torque_n_m[p]);
        }
        for (p, (pos, neg)) in self.tensions.iter().enumerate() {
            self.cols.push(*pos, st.ropes[p][0].tension_n);
            self.cols.push(*neg, st.ropes[p][1].tension_n);
        }
        let err = (arm.tip_m(&st.q_rad) - arm.tip_m(&st.q_ref_rad)).norm();
        self.cols.push(self.tip_error, err);
        self.frames += 1;
        if self.cols.frames() >= FLUSH_FRAMES {
            self.cols.flush(self.rec);
        }
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

    /// World points of rope `sign` (+1 / -1) of pair `p`: motor pulley, relay pulleys,
    /// joint pulley, each offset by its radius to the rope's side (after kinematics).
    fn rope_points(&self, p: usize, sign: f64) -> Vec<[f64; 3]> {
        let spec = &self.arm.pairs[p].spec;
        let mut centers: Vec<(Vector3<f64>, Vector3<f64>, f64)> =
            Vec::with_capacity(spec.route.len() + 2);
        centers.push((self.motor_points_m[p], Vector3::z(), spec.motor_radius_m));
        let mut route = spec.route.clone();
        route.sort_by_key(|r| r.joint);
        for r in &route {
            centers.push((
                self.kin.origin[r.joint + 1],
                self.kin.axis[r.joint + 1],
                r.radius_m,
            ));
        }
        centers.push((
            self.kin.origin[spec.joint + 1],
            self.kin.axis[spec.joint + 1],
            spec.joint_radius_m,
        ));
        let n = centers.len();
        (0..n)
            .map(|i| {
                let (c, axis, r) = centers[i];
                let prev = centers[i.saturating_sub(1)].0;
                let next = centers[(i + 1).min(n - 1)].0;
                let d = next - prev;
                let mut side = axis.cross(&d);
                if side.norm() < 1e-9 {
                    side = axis.cross(&Vector3::x());
                    if side.norm() < 1e-9 {
                        side = axis.cross(&Vector3::y());
                    }
                }
                let pt = c + side.normalize() * (sign * r);
                [pt.x, pt.y, pt.z]
            })
            .collect()
    }
}

fn quat(q: &UnitQuaternion<f64>) -> Quaternion {
    Quaternion::from_xyzw([q.i as f32, q.j as f32, q.k as f32, q.w as f32])
}

/// Length scale for drawing sizes: a tenth of the arm's reach at its initial pose,
/// clamped to 0.1..1 m.
fn draw_scale_m(arm: &DrivenArm) -> f64 {
    (0.1 * arm.tip_m(&arm.initial_q_rad).norm()).clamp(0.1, 1.0)
}

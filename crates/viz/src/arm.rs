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
//! /world/arm/<link>/beam        flexible links: the centre line through the deflected
//!                               shape (link frame)
//! /world/tip                    flexible arms: the deflected tip, then the straight one
//! /series/joints/angle_rad      "<joint> q" then "<joint> ref" for every joint
//! /series/motors/angle_rad      "<joint> motor" then "<joint> motor ref" for every pair
//! /series/motors/torque_n_m     servo torque of every pair, named by its joint
//! /series/tensions/tension_n    "<joint> +" then "<joint> -" (one rope of the parallel ones)
//! /series/tip/error_m           distance of the tip from where the commands put it
//! /series/tip/deflection_m      flexible arms: deflected tip to the straight links' tip
//! ```
//!
//! A flexible arm ([`longreach_arm::flex`]) is posed by its flexible kinematics: the
//! child frames ride on the deflected ends, so links, pulleys and ropes follow the
//! bending.
//!
//! Each `/series/...` entity is a group of series (one instance per name), so that a
//! recording has a handful of chunks per send whatever the number of joints.

use longreach_arm::fast::{FastDynamics, Kin};
use longreach_arm::flex::{FlexKin, FlexLink};
use longreach_arm::spec::Geometry;
use longreach_arm::{DrivenArm, DrivenState, FlexDynamics};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use rerun::blueprint::{
    Blueprint, BlueprintActivation, Horizontal, Spatial3DView, TimeSeriesView, Vertical,
};
use rerun::components::RotationQuat;
use rerun::{Boxes3D, Capsules3D, Color, Cylinders3D, Ellipsoids3D, Quaternion, ViewCoordinates};

use crate::worker::Worker;

use crate::{
    tension_color, Columns, PointsId, RateGate, Recorder, SeriesId, Sink, StripsId, TransformId,
    SIM_TIME,
};

/// Frames handed to the drawing thread at a time.
const BATCH_FRAMES: usize = 30;

/// Frames the drawing thread buffers before it sends them to Rerun (two seconds of
/// simulated time at the default 60 Hz): Rerun encodes them while the run goes on, and
/// finishing only waits for the last batch (each send costs a fixed encoding effort
/// per channel, so not every batch is sent on its own).
const SEND_FRAMES: usize = 120;

/// Logs one driven-arm run; feed it every state with [`ArmLogger::observe`].
///
/// The run's thread only copies each logged state (a hundred numbers at 60 frames per
/// simulated second) and hands batches of them to a drawing thread of its own, which
/// logs the static scene and the blueprint, computes link poses and rope strips, and
/// sends the columns to Rerun: on a machine with a free core the drawing costs the run
/// almost nothing. [`ArmLogger::finish`] (or dropping the logger) waits for the
/// drawing thread, so that [`Recorder::finish`] closes a complete recording.
#[derive(Debug)]
pub struct ArmLogger<'a> {
    arm: &'a DrivenArm,
    gate: RateGate,
    /// States not yet handed over, [`Layout::width`] values each.
    batch: Vec<f64>,
    layout: Layout,
    frames: usize,
    /// The drawing thread (`None` when not recording).
    worker: Option<Worker<Vec<f64>>>,
}

/// Where the values of one logged state sit in a batch: time, joint angles, joint
/// references, motor angles, motor references, servo torques, rope tensions (`+` of
/// every pair, then `-`), then the `[+, -]` tensions of every span of every pair.
#[derive(Debug, Clone)]
struct Layout {
    joints: usize,
    /// Coordinates drawn: the joints, then the flexible links' modal coordinates.
    coords: usize,
    pairs: usize,
    /// Spans of every pair (1 without relay friction).
    spans: Vec<usize>,
}

impl Layout {
    fn new(arm: &DrivenArm) -> Self {
        Self {
            joints: arm.spec().ndofs(),
            coords: arm.ncoords(),
            pairs: arm.pairs().len(),
            spans: arm
                .pairs()
                .iter()
                .map(|p| p.relays.as_ref().map_or(1, |c| c.spans()))
                .collect(),
        }
    }

    fn width(&self) -> usize {
        1 + self.coords + self.joints + 5 * self.pairs + 2 * self.spans.iter().sum::<usize>()
    }

    /// Appends the values of `st` to `out`.
    fn push(&self, arm: &DrivenArm, st: &DrivenState, out: &mut Vec<f64>) {
        let np = self.pairs;
        out.push(st.time_s);
        // The joints, then a flexible arm's modal coordinates (the bent links).
        out.extend_from_slice(&st.q_rad[..self.coords]);
        out.extend_from_slice(&st.q_ref_rad[..self.joints]);
        out.extend_from_slice(&st.motor_rad[..np]);
        out.extend_from_slice(&st.motor_ref_rad[..np]);
        out.extend_from_slice(&st.motor_torque_n_m[..np]);
        for side in 0..2 {
            out.extend(st.ropes[..np].iter().map(|r| r[side].tension_n));
        }
        for (p, &n) in self.spans.iter().enumerate() {
            let spans = arm.span_tensions_n(st, p);
            debug_assert_eq!(spans.len(), n);
            out.extend(spans.iter().flatten());
        }
    }

    /// The state at `v` (one [`Layout::width`] slice of a batch).
    fn frame<'f>(&self, v: &'f [f64]) -> Frame<'f> {
        let (n, np) = (self.joints, self.pairs);
        let (time, v) = v.split_at(1);
        let (q_rad, v) = v.split_at(self.coords);
        let (q_ref_rad, v) = v.split_at(n);
        let (motor_rad, v) = v.split_at(np);
        let (motor_ref_rad, v) = v.split_at(np);
        let (motor_torque_n_m, v) = v.split_at(np);
        let (tensions_n, spans_n) = v.split_at(2 * np);
        Frame {
            time_s: time[0],
            q_rad,
            q_ref_rad,
            motor_rad,
            motor_ref_rad,
            motor_torque_n_m,
            tensions_n,
            spans_n,
        }
    }
}

/// One logged state, read back from a batch (see [`Layout`]).
struct Frame<'f> {
    time_s: f64,
    /// The joints, then the modal coordinates of the flexible links.
    q_rad: &'f [f64],
    q_ref_rad: &'f [f64],
    motor_rad: &'f [f64],
    motor_ref_rad: &'f [f64],
    motor_torque_n_m: &'f [f64],
    /// `+` tensions of every pair, then `-`.
    tensions_n: &'f [f64],
    /// `[+, -]` of every span, pair after pair.
    spans_n: &'f [f64],
}

impl<'a> ArmLogger<'a> {
    /// Starts the drawing thread, which logs the static scene of `arm` (visuals,
    /// pulleys, motors) and the default blueprint, then every state handed to it.
    pub fn new(rec: &'a Recorder, arm: &'a DrivenArm) -> Self {
        let layout = Layout::new(arm);
        let worker = if rec.is_enabled() {
            let (drawer_sink, drawer_arm, drawer_layout) =
                (rec.sink().clone(), arm.clone(), layout.clone());
            let width = layout.width();
            Worker::<Vec<f64>>::spawn(rec.sink(), "rerun-arm", "drawing the arm", move |rx| {
                let mut d = Drawer::new(drawer_sink, drawer_arm, drawer_layout);
                d.log_static();
                for batch in rx {
                    for v in batch.chunks_exact(width) {
                        d.draw(v);
                    }
                    if d.cols.frames() >= SEND_FRAMES {
                        d.cols.flush(&d.sink);
                    } else {
                        d.cols.flush_when_due(&d.sink);
                    }
                }
                d.cols.flush(&d.sink);
            })
        } else {
            None
        };
        Self {
            arm,
            gate: RateGate::new(rec.hz()),
            batch: Vec::new(),
            layout,
            frames: 0,
            worker,
        }
    }

    /// Logs `st` when it is due at the logging rate (reads it only).
    pub fn observe(&mut self, st: &DrivenState) {
        let Some(worker) = &self.worker else {
            return;
        };
        if !self.gate.due(st.time_s) {
            return;
        }
        self.layout.push(self.arm, st, &mut self.batch);
        self.frames += 1;
        if self.batch.len() >= BATCH_FRAMES * self.layout.width() {
            let batch = std::mem::take(&mut self.batch);
            if !worker.send(batch) {
                // The drawing thread ended early (it panicked): say so when joining.
                self.close();
            }
        }
    }

    /// Frames logged so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Hands over what is buffered and waits for the drawing thread to send it.
    pub fn finish(mut self) -> usize {
        self.close();
        self.frames
    }

    fn close(&mut self) {
        let Some(mut worker) = self.worker.take() else {
            return;
        };
        let batch = std::mem::take(&mut self.batch);
        if !batch.is_empty() {
            // A failed send means the thread is gone: the join below reports it.
            worker.send(batch);
        }
        worker.join();
    }
}

impl Drop for ArmLogger<'_> {
    fn drop(&mut self) {
        self.close();
    }
}

/// Points drawn along a bent link's centre line.
pub(crate) const BEAM_POINTS: usize = 17;

/// Colour of a bent link's centre line.
const BEAM_COLOR: [u8; 4] = [240, 140, 30, 255];
/// Colours of the tip of a flexible arm: where it is, and where straight links would
/// put it.
const TIP_COLOR: [u8; 4] = [230, 40, 40, 255];
const STRAIGHT_TIP_COLOR: [u8; 4] = [150, 150, 160, 160];

/// The link frames of an arm at drawn coordinates: the rigid kinematics, or, when some
/// links bend, the flexible kinematics of [`longreach_arm::flex`] (whose child frames
/// ride on the deflected ends), written into the same [`Kin`] poses.
#[derive(Debug, Clone)]
pub(crate) struct Shape {
    dynamics: FastDynamics,
    /// World pose of every link after [`Shape::at`] (`rot`, `origin`, `axis`).
    pub(crate) kin: Kin,
    flex: Option<(FlexDynamics, FlexKin)>,
    /// The coordinates of the last [`Shape::at`], padded with zero modal coordinates.
    q: Vec<f64>,
    /// Joint axes in their child link frames.
    axes: Vec<Vector3<f64>>,
    tip_link: usize,
    tip_r: Vector3<f64>,
}

impl Shape {
    pub(crate) fn new(arm: &DrivenArm) -> Self {
        let dynamics = FastDynamics::new(arm.spec());
        let kin = dynamics.make_kin();
        let flex = arm.flex().map(|f| (f.clone(), f.make_kin()));
        let spec = arm.spec();
        Self {
            dynamics,
            kin,
            flex,
            q: vec![0.0; arm.ncoords()],
            axes: spec.joints.iter().map(|j| j.axis.into_inner()).collect(),
            tip_link: spec.tip.link,
            tip_r: spec.tip.link_from_frame.translation.vector,
        }
    }

    /// The flexible links (none for a rigid arm).
    pub(crate) fn flex_links(&self) -> &[FlexLink] {
        self.flex.as_ref().map_or(&[], |(f, _)| f.flex.as_slice())
    }

    /// Poses at `q`: the joints, then the flexible links' modal coordinates (missing
    /// ones are zero: the straight links).
    pub(crate) fn at(&mut self, q: &[f64]) {
        let n = self.q.len().min(q.len());
        self.q.fill(0.0);
        self.q[..n].copy_from_slice(&q[..n]);
        match &mut self.flex {
            None => self.dynamics.kinematics(&self.q, &mut self.kin),
            Some((f, fk)) => {
                f.kinematics(&self.q, fk);
                for i in 1..self.kin.rot.len() {
                    let (rot, origin) = f.link_pose(fk, i);
                    self.kin.rot[i] = rot;
                    self.kin.origin[i] = origin;
                    self.kin.axis[i] = rot * self.axes[i - 1];
                }
            }
        }
    }

    /// World position of the tip frame after [`Shape::at`] (on a bent last link, at
    /// its deflected end), m.
    pub(crate) fn tip_m(&self) -> Vector3<f64> {
        match &self.flex {
            None => tip_of(&self.kin, self.tip_link, &self.tip_r),
            Some((f, fk)) => f.point(fk, &self.q, self.tip_link, &self.tip_r),
        }
    }

    /// [`BEAM_POINTS`] points along the centre line of flexible link `f` after
    /// [`Shape::at`], in its link frame, from its joint origin to its deflected end, m.
    pub(crate) fn beam_points(&self, k: usize) -> impl Iterator<Item = [f64; 3]> + '_ {
        let f = &self.flex_links()[k];
        let eta = &self.q[f.offset..f.offset + f.ncoords()];
        (0..BEAM_POINTS).map(move |i| {
            let x = f.length_m * i as f64 / (BEAM_POINTS - 1) as f64;
            let p = f.ea * x + f.deflection(eta, x);
            [p.x, p.y, p.z]
        })
    }
}

/// World position of the point `r` of link `link`'s frame from rigid poses `kin`.
fn tip_of(kin: &Kin, link: usize, r: &Vector3<f64>) -> Vector3<f64> {
    kin.origin[link] + kin.rot[link] * r
}

/// The drawing thread's side of an [`ArmLogger`]: kinematics, rope strips and the
/// buffered columns.
#[derive(Debug)]
struct Drawer {
    sink: Sink,
    arm: DrivenArm,
    layout: Layout,
    /// The links at the drawn coordinates (bent when flexible).
    shape: Shape,
    cols: Columns,
    /// The links at the commanded angles, straight (for the tip error), and those
    /// angles.
    reference: Shape,
    q_ref_rad: Vec<f64>,
    links: Vec<TransformId>,
    /// Flexible arms: the links straight at the drawn joint angles (for the tip's
    /// deflection), every bent link's centre line (in its link frame), the tip points
    /// (deflected, then straight) and the tip's deflection.
    straight: Option<Shape>,
    beams: Vec<StripsId>,
    tip_points: Option<PointsId>,
    tip_deflection: Option<SeriesId>,
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
    /// Scratch: the points of this frame's strips, strip after strip, and where each
    /// strip ends in them with its colour.
    strip_points_m: Vec<[f64; 3]>,
    strip_ends: Vec<(usize, [u8; 4])>,
    /// Drawing scale, m ([`draw_scale_m`]).
    scale_m: f64,
}

impl Drawer {
    /// Prepares the channels of `arm`.
    fn new(sink: Sink, arm: DrivenArm, layout: Layout) -> Self {
        let shape = Shape::new(&arm);
        let mut cols = Columns::on_duration(SIM_TIME);
        let links = arm.spec().links[1..]
            .iter()
            .map(|l| cols.pose(format!("/world/arm/{}", l.name)))
            .collect();
        let scale_m = draw_scale_m(&arm);
        let rope_radius_m = 0.004 * scale_m;
        let ropes = cols.strips("/world/ropes", rope_radius_m);
        let joint_name = |p: usize| arm.spec().joints[arm.pairs()[p].spec.joint].name.clone();
        let joints: Vec<&str> = arm.spec().joints.iter().map(|j| j.name.as_str()).collect();
        let pairs: Vec<String> = (0..arm.pairs().len()).map(joint_name).collect();
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
            .pairs()
            .iter()
            .map(|pair| {
                let mut route = pair.spec.route.clone();
                route.sort_by_key(|r| r.joint);
                std::iter::once((None, pair.spec.motor_radius_m))
                    .chain(route.iter().map(|r| (r.joint, r.radius_m)))
                    .chain(std::iter::once((
                        Some(pair.spec.joint),
                        pair.spec.joint_radius_m,
                    )))
                    .collect()
            })
            .collect();
        let np = arm.pairs().len();
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
        let reference = shape.clone();
        let bent = !shape.flex_links().is_empty();
        let beams = shape
            .flex_links()
            .iter()
            .map(|f| {
                let link = &arm.spec().links[f.link].name;
                cols.strips(format!("/world/arm/{link}/beam"), 0.006 * scale_m)
            })
            .collect();
        let (straight, tip_points, tip_deflection) = if bent {
            (
                Some(shape.clone()),
                Some(cols.points("/world/tip", 0.012 * scale_m)),
                Some(cols.series("/series/tip/deflection_m")),
            )
        } else {
            (None, None, None)
        };
        Self {
            sink,
            arm,
            layout,
            shape,
            reference,
            straight,
            beams,
            tip_points,
            tip_deflection,
            q_ref_rad: Vec::new(),
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
            strip_points_m: Vec::new(),
            strip_ends: Vec::new(),
            scale_m,
        }
    }

    fn log_static(&self) {
        let rec = &self.sink;
        let s = rec.stream();
        rec.report(
            "view coordinates",
            s.log_static("/world", &ViewCoordinates::RIGHT_HAND_Z_UP()),
        );
        log_links(rec, &self.arm, "/world/arm", self.scale_m, None);
        let np = self.arm.pairs().len();
        rec.report(
            "/world/motors",
            s.log_static(
                "/world/motors",
                &Cylinders3D::from_lengths_and_radii(
                    vec![0.03 * self.scale_m as f32; np],
                    self.arm
                        .pairs()
                        .iter()
                        .map(|p| p.spec.motor_radius_m as f32),
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

    /// Adds one logged state (a [`Layout::width`] slice of a batch) to the columns.
    fn draw(&mut self, v: &[f64]) {
        let st = self.layout.frame(v);
        self.cols.frame_at_s(st.time_s);
        self.shape.at(st.q_rad);
        for (i, id) in self.links.iter().enumerate() {
            let r = Rotation3::from_matrix_unchecked(self.shape.kin.rot[i + 1]);
            let q = UnitQuaternion::from_rotation_matrix(&r);
            let o = self.shape.kin.origin[i + 1];
            self.cols
                .push_pose(*id, [o.x, o.y, o.z], [q.i, q.j, q.k, q.w]);
        }
        for (k, id) in self.beams.iter().enumerate() {
            self.cols
                .push_strips(*id, [(self.shape.beam_points(k), BEAM_COLOR)]);
        }
        // Strips of this frame: consecutive spans of the same colour are one strip (an
        // ideal pair is one strip per rope side; relay friction splits it where the
        // span tensions differ).
        // The strips go into two buffers kept from frame to frame: their points, and
        // where each strip ends with its colour.
        self.strip_points_m.clear();
        self.strip_ends.clear();
        let mut spans_n = st.spans_n;
        for p in 0..self.arm.pairs().len() {
            let full = 2.0 * self.arm.pairs()[p].spec.preload_n;
            // Spans motor side first; a pair without relay friction has one tension
            // along its whole rope.
            let count = self.layout.spans[p];
            let (spans, rest) = spans_n.split_at(2 * count);
            spans_n = rest;
            for (side, sign) in [1.0, -1.0].into_iter().enumerate() {
                self.rope_points(p, sign);
                let mut current: Option<[u8; 4]> = None;
                for (i, w) in self.points_m.windows(2).enumerate() {
                    let color = tension_color(spans[2 * i.min(count - 1) + side], full);
                    if current != Some(color) {
                        if let Some(c) = current {
                            self.strip_ends.push((self.strip_points_m.len(), c));
                        }
                        self.strip_points_m.push(w[0]);
                        current = Some(color);
                    }
                    self.strip_points_m.push(w[1]);
                }
                if let Some(c) = current {
                    self.strip_ends.push((self.strip_points_m.len(), c));
                }
            }
        }
        let points = &self.strip_points_m;
        let mut start = 0;
        let strips = self.strip_ends.iter().map(|&(end, color)| {
            let strip = points[start..end].iter().copied();
            start = end;
            (strip, color)
        });
        self.cols.push_strips(self.ropes, strips);
        self.cols.push_group(
            self.joint_angles,
            st.q_rad[..self.layout.joints]
                .iter()
                .chain(st.q_ref_rad)
                .copied(),
        );
        self.cols.push_group(
            self.motor_angles,
            st.motor_rad.iter().chain(st.motor_ref_rad).copied(),
        );
        self.cols
            .push_group(self.motor_torques, st.motor_torque_n_m.iter().copied());
        self.cols
            .push_group(self.tensions, st.tensions_n.iter().copied());
        if self.q_ref_rad != st.q_ref_rad {
            self.reference.at(st.q_ref_rad);
            self.q_ref_rad.clear();
            self.q_ref_rad.extend_from_slice(st.q_ref_rad);
        }
        let tip = self.shape.tip_m();
        let err = (tip - self.reference.tip_m()).norm();
        self.cols.push(self.tip_error, err);
        if let (Some(straight), Some(points), Some(deflection)) =
            (&mut self.straight, self.tip_points, self.tip_deflection)
        {
            straight.at(&st.q_rad[..self.layout.joints]);
            let rigid = straight.tip_m();
            self.cols.push_points(
                points,
                [
                    ([tip.x, tip.y, tip.z], TIP_COLOR),
                    ([rigid.x, rigid.y, rigid.z], STRAIGHT_TIP_COLOR),
                ],
            );
            self.cols.push(deflection, (tip - rigid).norm());
        }
    }

    /// World points of rope `sign` (+1 / -1) of pair `p` into `self.points_m`: motor
    /// pulley, relay pulleys, joint pulley, each offset by its radius to the rope's side
    /// (after kinematics).
    fn rope_points(&mut self, p: usize, sign: f64) {
        let centre = |&(joint, radius_m): &(Option<usize>, f64)| match joint {
            None => (self.motor_points_m[p], Vector3::z(), radius_m),
            Some(j) => (
                self.shape.kin.origin[j + 1],
                self.shape.kin.axis[j + 1],
                radius_m,
            ),
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

/// Logs the static scene of every link of `arm` under `<root>/<link>`: its URDF visuals
/// (coloured `tint` instead of their own colours when given) and the pulleys on its
/// joint axis, one static row per link (one batch per shape kind).
pub(crate) fn log_links(
    rec: &Sink,
    arm: &DrivenArm,
    root: &str,
    scale_m: f64,
    tint: Option<Color>,
) {
    let s = rec.stream();
    let spec = arm.spec();
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
            let color = tint.unwrap_or_else(|| {
                v.rgba.map_or(Color::from_rgb(170, 170, 180), |c| {
                    let b = |x: f64| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
                    Color::from_unmultiplied_rgba(b(c[0]), b(c[1]), b(c[2]), b(c[3]))
                })
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
        for p in arm.pairs() {
            if p.spec.joint == j {
                radii.push(p.spec.joint_radius_m);
            }
            radii.extend(
                p.spec
                    .route
                    .iter()
                    .filter(|r| r.joint == Some(j))
                    .map(|r| r.radius_m),
            );
        }
        let axis = joint.axis.into_inner();
        let rot = UnitQuaternion::rotation_between(&Vector3::z(), &axis).unwrap_or_else(|| {
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        });
        let width = 0.02 * scale_m;
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
        let path = format!("{root}/{}", link.name);
        let archetypes = shapes.archetypes();
        if !archetypes.is_empty() {
            rec.report(&path, s.log_static(path.as_str(), &archetypes));
        }
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
    // The initial angles were checked when the arm was built: the tip is defined.
    let reach_m = arm.tip_m(arm.initial_q_rad()).map_or(1.0, |t| t.norm());
    (0.1 * reach_m).clamp(0.1, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tip_from_the_logger_kinematics_is_the_arm_tip() {
        let arm = longreach_arm::anchor_chain(6, longreach_rope::LawKind::Elastic, 1e-3).unwrap();
        let rec = Recorder::off();
        let mut logger = Drawer::new(rec.sink().clone(), arm.clone(), Layout::new(&arm));
        for k in 0..5 {
            let q: Vec<f64> = (0..arm.spec().ndofs())
                .map(|j| 0.3 * ((k * 7 + j * 3) as f64).sin())
                .collect();
            logger.shape.at(&q);
            let d = (logger.shape.tip_m() - arm.tip_m(&q).unwrap()).norm();
            assert!(d < 1e-12, "pose {k}: {d} m");
            assert!(arm.tip_m(&q).unwrap().norm() > 1.0);
        }
    }

    #[test]
    fn a_bent_link_is_drawn_through_its_deflected_shape_to_the_deflected_tip() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../scenarios/flex_dyneema2_base_step.toml");
        let arm = longreach_arm::scenario::load(&path).unwrap().arm;
        let n = arm.njoints();
        // The links start bent under gravity.
        let st = arm.initial_state();
        assert_eq!(st.q_rad.len(), arm.ncoords());
        let mut shape = Shape::new(&arm);
        let mut straight = shape.clone();
        shape.at(&st.q_rad);
        straight.at(&st.q_rad[..n]);
        let tip = shape.tip_m();
        assert!((tip - arm.tip_m(&st.q_rad).unwrap()).norm() < 1e-12);
        let deflection = (tip - straight.tip_m()).norm();
        let expected = (arm.tip_m(&st.q_rad).unwrap() - arm.tip_m(&st.q_rad[..n]).unwrap()).norm();
        assert!(deflection > 1e-3, "{deflection} m");
        assert!((deflection - expected).abs() < 1e-12);
        assert_eq!(shape.flex_links().len(), 5);
        for (k, f) in shape.flex_links().iter().enumerate() {
            let pts: Vec<[f64; 3]> = shape.beam_points(k).collect();
            assert_eq!(pts.len(), BEAM_POINTS);
            assert!(Vector3::from(pts[0]).norm() == 0.0, "clamped at its joint");
            let end = Vector3::from(pts[BEAM_POINTS - 1]);
            let world = shape.kin.origin[f.link] + shape.kin.rot[f.link] * end;
            if f.link == arm.spec().tip.link {
                // The last link's beam ends at the tip.
                assert!((world - tip).norm() < 1e-12, "{}", (world - tip).norm());
            } else {
                // Its end carries the child joint: the next link's origin.
                let child = shape.kin.origin[f.link + 1];
                assert!((world - child).norm() < 1e-12, "{}", (world - child).norm());
            }
            // Bent: the end is off the straight axis (sag under gravity).
            let off = (end - f.ea * end.dot(&f.ea)).norm();
            assert!(off > 1e-5, "link {}: {off} m", f.link);
        }
    }

    #[test]
    #[allow(clippy::float_cmp)] // a copy: bit for bit
    fn a_state_handed_to_the_drawing_thread_reads_back_unchanged() {
        // Relay friction: pairs of 1 to 5 spans, so the layout's offsets matter.
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../scenarios/arm_dyneema2_base_step_relay_friction.toml");
        let arm = longreach_arm::scenario::load(&path).unwrap().arm;
        let layout = Layout::new(&arm);
        assert!(layout.spans.iter().any(|&s| s > 1), "{:?}", layout.spans);
        let mut st = arm.initial_state();
        for _ in 0..600 {
            arm.step(&mut st).unwrap();
        }
        let mut batch = vec![-1.0];
        layout.push(&arm, &st, &mut batch);
        assert_eq!(batch.len(), 1 + layout.width());
        let f = layout.frame(&batch[1..]);
        let np = arm.pairs().len();
        assert_eq!(f.time_s, st.time_s);
        assert_eq!(f.q_rad, &st.q_rad[..]);
        assert_eq!(f.q_ref_rad, &st.q_ref_rad[..]);
        assert_eq!(f.motor_rad, &st.motor_rad[..np]);
        assert_eq!(f.motor_ref_rad, &st.motor_ref_rad[..np]);
        assert_eq!(f.motor_torque_n_m, &st.motor_torque_n_m[..np]);
        for p in 0..np {
            assert_eq!(f.tensions_n[p], st.ropes[p][0].tension_n);
            assert_eq!(f.tensions_n[np + p], st.ropes[p][1].tension_n);
        }
        let spans: Vec<f64> = (0..np)
            .flat_map(|p| arm.span_tensions_n(&st, p))
            .flatten()
            .collect();
        assert_eq!(f.spans_n, &spans[..]);
        // The base step moved the base joint and loaded the ropes differently per span.
        assert!(st.q_rad[0] > 0.01, "{}", st.q_rad[0]);
        assert!(spans.windows(2).any(|w| w[0] != w[1]));
    }

    #[test]
    fn a_logger_dropped_without_finish_still_closes_a_complete_recording() {
        let arm = longreach_arm::anchor_chain(3, longreach_rope::LawKind::Elastic, 1e-3).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.rrd");
        let rec = Recorder::start(
            "t",
            &crate::Target::Save(Some(path.clone())),
            dir.path(),
            100.0,
        )
        .unwrap();
        let mut st = arm.initial_state();
        {
            let mut logger = ArmLogger::new(&rec, &arm);
            for _ in 0..1000 {
                arm.step(&mut st).unwrap();
                logger.observe(&st);
            }
            // 1 s at 100 Hz: the first step (1 ms), then the steps at 10, 20, ... 1000 ms.
            assert_eq!(logger.frames(), 101);
        }
        assert_eq!(rec.finish(), Some(path.clone()));
        assert!(std::fs::metadata(&path).unwrap().len() > 1000);
    }
}

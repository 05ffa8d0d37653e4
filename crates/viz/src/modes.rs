//! The modes of a linearised arm in Rerun (`longreach modes --rerun`): each mode drawn
//! as the arm oscillating along its shape, with its frequency and damping.
//!
//! Entity paths (see docs/rerun.md), `<m>` being `mode_01`, `mode_02`, ... (lowest
//! natural frequency first):
//!
//! ```text
//! /modes/<m>                          view coordinates (right-handed, z up)
//! /modes/<m>/arm/<link>               pose of every moving link along the mode; static:
//!                                     the link's visuals and pulleys
//! /modes/<m>/arm/<link>/beam          flexible links: the bent centre line (link frame)
//! /modes/<m>/tip                      the tip (points)
//! /modes/<m>/series/joints_rad        every joint's angle from the pose, named by joint
//! /modes/<m>/series/tip_m             distance of the tip from its place at the pose
//! /modes/<m>/info                     frequencies, damping ratio, energy shares, scale
//! ```
//!
//! Every mode moves `q(t) = q_eq + a cos(2 pi f_d t) c`: `q_eq` the equilibrium the arm
//! was linearised about (joints and bent links), `c` the mode's coordinates at 1 J of
//! potential energy, `a` the drawing scale (the largest displacement of a link frame or
//! the tip [`DRAWN_SHARE`] of the arm's reach), `f_d` the damped frequency; the decay
//! is left out (the damping ratio is in the text). Two periods of [`FRAMES_PER_PERIOD`]
//! frames, on two timelines: [`MODE_FRAME`] (every mode at the same pace, a period per
//! 32 frames) and [`MODE_TIME`] (the mode's own time, s).

use longreach_arm::modes::Modes;
use longreach_arm::DrivenArm;
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use rerun::blueprint::{
    Blueprint, BlueprintActivation, Horizontal, Spatial3DView, Tabs, TextDocumentView,
    TimeSeriesView, Vertical,
};
use rerun::{TextDocument, ViewCoordinates};

use crate::arm::{log_links, Shape};
use crate::{Columns, Recorder};

/// Sequence timeline of the mode animations: the frame, a period per
/// [`FRAMES_PER_PERIOD`] frames for every mode.
pub const MODE_FRAME: &str = "mode_frame";
/// Duration timeline of the mode animations: each mode's own time, s.
pub const MODE_TIME: &str = "mode_time";
/// Frames per period of a mode.
pub const FRAMES_PER_PERIOD: usize = 32;
/// Periods drawn.
pub const PERIODS: usize = 2;
/// Largest displacement drawn (of a link frame or the tip), share of the arm's reach.
pub const DRAWN_SHARE: f64 = 0.05;

/// Entity name of mode `i` (0-based): `mode_01`, ...
pub fn mode_name(i: usize) -> String {
    format!("mode_{:02}", i + 1)
}

/// Logs the first `count` modes of `modes` (of `arm`, linearised at its initial pose).
pub fn log_modes(rec: &Recorder, arm: &DrivenArm, modes: &Modes, count: usize) {
    if !rec.is_enabled() {
        return;
    }
    let sink = rec.sink();
    let stream = rec.stream();
    let spec = arm.spec();
    let n = spec.ndofs();
    let mut shape = Shape::new(arm);
    let eq = &modes.equilibrium_q;
    if eq.len() != arm.ncoords() {
        rec.report(
            "/modes",
            Err::<(), _>(format!(
                "{} equilibrium coordinates for an arm of {}",
                eq.len(),
                arm.ncoords()
            )),
        );
        return;
    }
    // Link frames and tip at `q`.
    let points = |shape: &mut Shape, q: &[f64]| -> Vec<Vector3<f64>> {
        shape.at(q);
        let mut p: Vec<Vector3<f64>> = shape.kin.origin[1..].to_vec();
        p.push(shape.tip_m());
        p
    };
    let at_rest = points(&mut shape, eq);
    let tip_rest = *at_rest.last().unwrap_or(&Vector3::zeros());
    let reach_m = tip_rest.norm().max(1e-3);
    let scale_m = (0.1 * reach_m).clamp(0.1, 1.0);
    let joint_names: Vec<String> = spec.joints.iter().map(|j| j.name.clone()).collect();
    let mut tabs = Vec::new();
    for (i, md) in modes.modes.iter().take(count).enumerate() {
        let name = mode_name(i);
        let root = format!("/modes/{name}");
        if md.coords.len() != eq.len() {
            rec.report(
                &root,
                Err::<(), _>(format!("{} coordinates, not {}", md.coords.len(), eq.len())),
            );
            continue;
        }
        // The displacement of the link frames and the tip per unit of the mode
        // (a small step along it), for the drawing scale.
        let big = md.coords.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        let per_unit = if big > 0.0 && big.is_finite() {
            let eps = 1e-6 / big;
            let q: Vec<f64> = eq
                .iter()
                .zip(&md.coords)
                .map(|(e, c)| e + eps * c)
                .collect();
            let moved = points(&mut shape, &q);
            moved
                .iter()
                .zip(&at_rest)
                .map(|(a, b)| (a - b).norm() / eps)
                .fold(0.0, f64::max)
        } else {
            0.0
        };
        let amplitude = if per_unit > 1e-12 && per_unit.is_finite() {
            DRAWN_SHARE * reach_m / per_unit
        } else {
            0.0
        };
        let hz = if md.damped_hz > 0.0 && md.damped_hz.is_finite() {
            md.damped_hz
        } else {
            md.natural_hz
        };
        let period_s = if hz > 0.0 && hz.is_finite() {
            1.0 / hz
        } else {
            1.0
        };
        rec.report(
            &root,
            stream.log_static(root.as_str(), &ViewCoordinates::RIGHT_HAND_Z_UP()),
        );
        log_links(sink, arm, &format!("{root}/arm"), scale_m, None);
        let mut cols = Columns::on_sequence(MODE_FRAME).also_on_duration(MODE_TIME);
        let links: Vec<_> = spec.links[1..]
            .iter()
            .map(|l| cols.pose(format!("{root}/arm/{}", l.name)))
            .collect();
        let beams: Vec<_> = shape
            .flex_links()
            .iter()
            .map(|f| {
                let link = &spec.links[f.link].name;
                cols.strips(format!("{root}/arm/{link}/beam"), 0.006 * scale_m)
            })
            .collect();
        let tip = cols.points(format!("{root}/tip"), 0.012 * scale_m);
        let joints = cols.series_group(format!("{root}/series/joints_rad"), joint_names.clone());
        let tip_m = cols.series(format!("{root}/series/tip_m"));
        let mut q = eq.clone();
        for k in 0..=PERIODS * FRAMES_PER_PERIOD {
            let phase = k as f64 / FRAMES_PER_PERIOD as f64;
            let c = amplitude * (2.0 * std::f64::consts::PI * phase).cos();
            for ((q, e), m) in q.iter_mut().zip(eq).zip(&md.coords) {
                *q = e + c * m;
            }
            cols.frame_at(k as i64);
            cols.also_at_s(phase * period_s);
            shape.at(&q);
            for (j, id) in links.iter().enumerate() {
                let r = Rotation3::from_matrix_unchecked(shape.kin.rot[j + 1]);
                let u = UnitQuaternion::from_rotation_matrix(&r);
                let o = shape.kin.origin[j + 1];
                cols.push_pose(*id, [o.x, o.y, o.z], [u.i, u.j, u.k, u.w]);
            }
            for (b, id) in beams.iter().enumerate() {
                cols.push_strips(*id, [(shape.beam_points(b), [240, 140, 30, 255])]);
            }
            let t = shape.tip_m();
            cols.push_points(tip, [([t.x, t.y, t.z], [230, 40, 40, 255])]);
            cols.push_group(joints, (0..n).map(|j| q[j] - eq[j]));
            cols.push(tip_m, (t - tip_rest).norm());
        }
        cols.flush(sink);
        let shares = md
            .shares
            .iter()
            .filter(|s| s.share >= 0.01)
            .map(|s| format!("{} {:.0}%", s.part, 100.0 * s.share))
            .collect::<Vec<_>>()
            .join(", ");
        let text = format!(
            "# Mode {}\n\n\
             - natural frequency **{:.4} Hz**, damped {:.4} Hz, damping ratio **{:.4}**\n\
             - period drawn {:.6} s (the damped frequency), without its decay\n\
             - potential energy in: {}\n\
             - drawn at {:.4} x its amplitude at 1 J of potential energy (the largest \
             displacement of a link frame or the tip: {:.0}% of the reach, {:.3} m)\n\
             - {} periods of {} frames: timeline `{MODE_FRAME}` (every mode at the same pace) \
             or `{MODE_TIME}` (this mode's own time, s)\n",
            i + 1,
            md.natural_hz,
            md.damped_hz,
            md.damping_ratio,
            period_s,
            if shares.is_empty() { "-" } else { &shares },
            amplitude,
            100.0 * DRAWN_SHARE,
            DRAWN_SHARE * reach_m,
            PERIODS,
            FRAMES_PER_PERIOD,
        );
        let info = format!("{root}/info");
        rec.report(
            &info,
            stream.log_static(info.as_str(), &TextDocument::from_markdown(text)),
        );
        tabs.push(
            Horizontal::new([
                Spatial3DView::new(format!(
                    "mode {}: {:.3} Hz, zeta {:.4}",
                    i + 1,
                    md.natural_hz,
                    md.damping_ratio
                ))
                .with_origin(root.as_str())
                .into(),
                Vertical::new([
                    TextDocumentView::new("Mode")
                        .with_origin(info.as_str())
                        .into(),
                    TimeSeriesView::new("Joints and tip along the mode")
                        .with_origin(format!("{root}/series"))
                        .into(),
                ])
                .into(),
            ])
            .into(),
        );
    }
    if !tabs.is_empty() {
        let bp = Blueprint::new(Tabs::new(tabs));
        rec.report("blueprint", bp.send(stream, BlueprintActivation::default()));
    }
}

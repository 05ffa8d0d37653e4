//! A comparison of the arm model with an arm dataset (`arm_moves`) in Rerun: per run,
//! the measured arm and the model arm side by side in 3D, and every measured channel
//! with the model's overlaid.
//!
//! Entity paths (see docs/rerun.md), `<run>` being the run's name and `<channel>` the
//! dataset's column name (`motor_j1_rad`, `joint_j3_rad`, `tension_j2_1_n`, `tip_x_m`,
//! ...):
//!
//! ```text
//! /compare/<run>/<channel>/measured    the measured channel (sim_time: the run's time)
//! /compare/<run>/<channel>/model       the model's channel on the same samples
//! /compare/<run>/<channel>/residual    measured - model
//! /compare/<run>/<channel>/with_effect diagnose: the model with the winning effect
//! /world/<run>                         view coordinates (right-handed, z up)
//! /world/<run>/measured/<link>         the measured arm: link poses from the measured
//!                                      joint angles (static: URDF visuals and pulleys)
//! /world/<run>/measured/tip            the measured tip position (when measured)
//! /world/<run>/measured/tip_path       the whole measured tip path (static)
//! /world/<run>/model                   the model arm's base, beside the measured one
//! /world/<run>/model/<link>            the model arm: link poses from the simulated
//!                                      states (static: visuals in orange)
//! /world/<run>/model/<link>/beam       flexible links: the model's bent centre line
//! /world/<run>/model/tip               the model's tip
//! /diagnose/ranking, /diagnose/nrmse   diagnose: as for the rig's datasets
//! ```
//!
//! The measured arm's joint angles: the joint encoder of a driven joint when the run
//! measured it; else its motor encoder through the rope routing with rigid ropes
//! (`r_m (theta - theta_0) = sum_k row_k (q_k - q_k0)`, solved joint after joint from
//! the base: the ropes' stretch is not seen); else its command. Joints without a
//! transmission hold the run's initial pose, and the links are drawn straight (no
//! dataset measures the bending).

use longreach_arm::DrivenArm;
use longreach_ident::analysis::Diagnosis;
use longreach_ident::dataset::{ArmMovesDataset, ArmQuantity, ArmRun};
use longreach_ident::plant::{ArmPoses, Channels};
use nalgebra::{Rotation3, UnitQuaternion};
use rerun::blueprint::{
    Blueprint, BlueprintActivation, Horizontal, Spatial3DView, Tabs, TimeSeriesView, Vertical,
};
use rerun::{Color, LineStrip3D, LineStrips3D, Transform3D, ViewCoordinates};

use crate::arm::{log_links, Shape};
use crate::ident::{log_diagnosis, sanitize};
use crate::{Columns, Recorder, TransformId, SIM_TIME};

/// The model arm is drawn this share of its reach beside the measured one (+y).
pub const MODEL_OFFSET_SHARE: f64 = 0.25;

/// Colour of the model arm's visuals.
const MODEL_COLOR: [u8; 4] = [240, 140, 30, 200];
const MEASURED_TIP_COLOR: [u8; 4] = [40, 120, 230, 255];
const MODEL_TIP_COLOR: [u8; 4] = [230, 40, 40, 255];

/// Logs the comparison of arm dataset `am` with the model: `sims[i]` the model's
/// channels on run `i` and `poses[i]` its arm and coordinates at every sample (from
/// `longreach_ident::analysis::simulate_arm_poses`); for `diagnose`, the diagnosis
/// and the channels of the model with the winning effect.
pub fn log_arm_comparison(
    rec: &Recorder,
    am: &ArmMovesDataset,
    sims: &[Channels],
    poses: &[ArmPoses],
    diagnosis: Option<&Diagnosis>,
    with_effect: Option<&[Channels]>,
) {
    if !rec.is_enabled() {
        return;
    }
    let mut tabs = Vec::new();
    for (i, run) in am.runs.iter().enumerate() {
        let (Some(sim), Some(pose)) = (sims.get(i), poses.get(i)) else {
            continue;
        };
        let name = sanitize(&run.name);
        log_channels(rec, run, &name, sim, with_effect.and_then(|w| w.get(i)));
        log_arms(rec, run, &name, pose);
        tabs.push(run_view(run, &name).into());
    }
    let stream = rec.stream();
    let mut top = vec![Tabs::new(tabs).into()];
    if let Some(d) = diagnosis {
        top.push(log_diagnosis(rec, d).into());
    }
    let bp = Blueprint::new(Horizontal::new(top));
    rec.report("blueprint", bp.send(stream, BlueprintActivation::default()));
}

/// Every channel of `run`: measured, model, residual (and with the effect).
fn log_channels(
    rec: &Recorder,
    run: &ArmRun,
    name: &str,
    sim: &Channels,
    with_effect: Option<&Channels>,
) {
    let mut cols = Columns::on_duration(SIM_TIME);
    let mut ids = Vec::new();
    for c in &run.channels {
        let Some(model) = sim.get(&c.name) else {
            continue;
        };
        let root = format!("/compare/{name}/{}", sanitize(&c.name));
        let after = with_effect.and_then(|w| w.get(&c.name));
        ids.push((
            &c.values,
            model,
            after,
            cols.series(format!("{root}/measured")),
            cols.series(format!("{root}/model")),
            cols.series(format!("{root}/residual")),
            after.map(|_| cols.series(format!("{root}/with_effect"))),
        ));
    }
    for (k, t) in run.time_s.iter().enumerate() {
        cols.frame_at_s(*t);
        for (measured, model, after, m, s, r, w) in &ids {
            let (x, y) = (
                measured.get(k).copied().unwrap_or(f64::NAN),
                model.get(k).copied().unwrap_or(f64::NAN),
            );
            cols.push(*m, x);
            cols.push(*s, y);
            cols.push(*r, x - y);
            if let (Some(w), Some(after)) = (w, after) {
                cols.push(*w, after.get(k).copied().unwrap_or(f64::NAN));
            }
        }
    }
    cols.flush(rec.sink());
}

/// The measured and the model arm of `run`, side by side.
fn log_arms(rec: &Recorder, run: &ArmRun, name: &str, pose: &ArmPoses) {
    let sink = rec.sink();
    let stream = rec.stream();
    let arm = &pose.arm;
    let spec = arm.spec();
    let mut model = Shape::new(arm);
    let mut measured = Shape::new(arm);
    let reach_m = arm
        .tip_m(arm.initial_q_rad())
        .map_or(1.0, |t| t.norm())
        .max(1e-3);
    let scale_m = (0.1 * reach_m).clamp(0.1, 1.0);
    let root = format!("/world/{name}");
    rec.report(
        &root,
        stream.log_static(root.as_str(), &ViewCoordinates::RIGHT_HAND_Z_UP()),
    );
    let offset = [0.0, (MODEL_OFFSET_SHARE * reach_m) as f32, 0.0];
    let model_root = format!("{root}/model");
    rec.report(
        &model_root,
        stream.log_static(model_root.as_str(), &Transform3D::from_translation(offset)),
    );
    let measured_root = format!("{root}/measured");
    log_links(sink, arm, &measured_root, scale_m, None);
    let [r, g, b, a] = MODEL_COLOR;
    log_links(
        sink,
        arm,
        &model_root,
        scale_m,
        Some(Color::from_unmultiplied_rgba(r, g, b, a)),
    );
    let mut cols = Columns::on_duration(SIM_TIME);
    let links = |cols: &mut Columns, at: &str| -> Vec<TransformId> {
        spec.links[1..]
            .iter()
            .map(|l| cols.pose(format!("{at}/{}", l.name)))
            .collect()
    };
    let measured_links = links(&mut cols, &measured_root);
    let model_links = links(&mut cols, &model_root);
    let beams: Vec<_> = model
        .flex_links()
        .iter()
        .map(|f| {
            let link = &spec.links[f.link].name;
            cols.strips(format!("{model_root}/{link}/beam"), 0.006 * scale_m)
        })
        .collect();
    let tip_columns: Vec<Option<&Vec<f64>>> = (0..3u8)
        .map(|a| {
            run.channels
                .iter()
                .find(|c| c.quantity == ArmQuantity::Tip(a))
                .map(|c| &c.values)
        })
        .collect();
    let measured_tip = if tip_columns.iter().all(Option::is_some) {
        Some(cols.points(format!("{measured_root}/tip"), 0.012 * scale_m))
    } else {
        None
    };
    let model_tip = cols.points(format!("{model_root}/tip"), 0.012 * scale_m);
    let q_measured = measured_joints(run, arm);
    let mut path = Vec::new();
    for (k, t) in run.time_s.iter().enumerate() {
        let (Some(q_model), Some(q_meas)) = (pose.q.get(k), q_measured.get(k)) else {
            break;
        };
        cols.frame_at_s(*t);
        measured.at(q_meas);
        model.at(q_model);
        for (shape, ids) in [(&measured, &measured_links), (&model, &model_links)] {
            for (j, id) in ids.iter().enumerate() {
                let r = Rotation3::from_matrix_unchecked(shape.kin.rot[j + 1]);
                let u = UnitQuaternion::from_rotation_matrix(&r);
                let o = shape.kin.origin[j + 1];
                cols.push_pose(*id, [o.x, o.y, o.z], [u.i, u.j, u.k, u.w]);
            }
        }
        for (b, id) in beams.iter().enumerate() {
            cols.push_strips(*id, [(model.beam_points(b), [240, 140, 30, 255])]);
        }
        if let Some(id) = measured_tip {
            let p = [0, 1, 2].map(|a| {
                tip_columns[a]
                    .and_then(|v| v.get(k))
                    .copied()
                    .unwrap_or(f64::NAN)
            });
            path.push(p.map(|v| v as f32));
            cols.push_points(id, [(p, MEASURED_TIP_COLOR)]);
        }
        let t = model.tip_m();
        cols.push_points(model_tip, [([t.x, t.y, t.z], MODEL_TIP_COLOR)]);
    }
    cols.flush(sink);
    if !path.is_empty() {
        let e = format!("{measured_root}/tip_path");
        let [r, g, b, a] = MEASURED_TIP_COLOR;
        rec.report(
            &e,
            stream.log_static(
                e.as_str(),
                &LineStrips3D::new([LineStrip3D::from_iter(path)])
                    .with_radii([(0.003 * scale_m) as f32])
                    .with_colors([Color::from_unmultiplied_rgba(r, g, b, a)]),
            ),
        );
    }
}

/// The measured arm's joint angles at every sample of `run` (see the module's doc).
pub fn measured_joints(run: &ArmRun, arm: &DrivenArm) -> Vec<Vec<f64>> {
    let n = arm.njoints();
    let samples = run.time_s.len();
    let initial = arm.initial_q_rad();
    let mut q: Vec<Vec<f64>> = vec![initial.to_vec(); samples];
    let find = |k: usize, what: ArmQuantity| {
        run.channels
            .iter()
            .find(|c| c.joint == Some(k) && c.quantity == what)
            .map(|c| &c.values)
    };
    // Pairs by their joint, from the base: a motor's rope runs over the joints before
    // its own.
    let mut pairs: Vec<usize> = (0..arm.pairs().len()).collect();
    pairs.sort_by_key(|&p| arm.pairs()[p].spec.joint);
    for p in pairs {
        let pair = &arm.pairs()[p];
        let j = pair.spec.joint;
        if j >= n {
            continue;
        }
        let fill = |q: &mut [Vec<f64>], v: &[f64]| {
            for (row, x) in q.iter_mut().zip(v) {
                row[j] = *x;
            }
        };
        if let Some(v) = find(p, ArmQuantity::Joint) {
            fill(&mut q, v);
        } else if let (Some(theta), true) = (
            find(p, ArmQuantity::Motor),
            pair.row.get(j).is_some_and(|r| r.abs() > 1e-12),
        ) {
            let theta0 = theta.first().copied().unwrap_or(0.0);
            for (k, row) in q.iter_mut().enumerate() {
                let Some(th) = theta.get(k) else { break };
                let others: f64 = pair
                    .nz
                    .iter()
                    .filter(|&&c| c != j && c < n)
                    .map(|&c| pair.row[c] * (row[c] - initial[c]))
                    .sum();
                row[j] =
                    initial[j] + (pair.spec.motor_radius_m * (th - theta0) - others) / pair.row[j];
            }
        } else if let Some(cmd) = run.command_rad.get(p) {
            fill(&mut q, cmd);
        }
    }
    q
}

/// The tab of a run: the two arms, and the channels by kind.
fn run_view(run: &ArmRun, name: &str) -> Horizontal {
    let group = |keep: fn(ArmQuantity) -> bool| -> Vec<String> {
        run.channels
            .iter()
            .filter(|c| keep(c.quantity))
            .map(|c| format!("+ /compare/{name}/{}/**", sanitize(&c.name)))
            .collect()
    };
    let kinds: [(&str, fn(ArmQuantity) -> bool); 4] = [
        ("joint angles (rad)", |q| q == ArmQuantity::Joint),
        ("motor angles (rad)", |q| q == ArmQuantity::Motor),
        ("rope tensions (N)", |q| {
            matches!(q, ArmQuantity::Tension1 | ArmQuantity::Tension2)
        }),
        ("tip", ArmQuantity::is_tip),
    ];
    let plots: Vec<_> = kinds
        .iter()
        .filter_map(|(title, keep)| {
            let contents = group(*keep);
            (!contents.is_empty()).then(|| {
                TimeSeriesView::new(format!("{}: {title}, measured vs model", run.name))
                    .with_origin(format!("/compare/{name}"))
                    .with_contents(contents)
                    .into()
            })
        })
        .collect();
    Horizontal::new([
        Spatial3DView::new(format!("{}: measured arm, model arm (orange)", run.name))
            .with_origin(format!("/world/{name}"))
            .into(),
        Vertical::new(plots).into(),
    ])
    .with_name(run.name.clone())
}

#[cfg(test)]
mod tests {
    use super::*;
    use longreach_ident::analysis::{arm_dataset, simulate_arm_poses};
    use longreach_ident::model::Model;
    use longreach_ident::Dataset;

    #[test]
    #[allow(clippy::float_cmp)] // copies: bit for bit
    fn without_joint_encoders_the_measured_arm_follows_its_motors_through_the_routing() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../data/examples/example_arm_control");
        let ds = Dataset::load(&path).unwrap();
        let model = Model::baseline(&ds).unwrap();
        let poses = simulate_arm_poses(&ds, &model, 1).unwrap();
        let am = arm_dataset(&ds).unwrap();
        let mut worst: f64 = 0.0;
        for (run, (_, pose)) in am.runs.iter().zip(&poses) {
            let with_joints = measured_joints(run, &pose.arm);
            // The joint encoders themselves where measured.
            for (k, c) in run.channels.iter().enumerate() {
                if c.quantity == ArmQuantity::Joint {
                    let j = pose.arm.pairs()[c.joint.unwrap()].spec.joint;
                    assert!(with_joints
                        .iter()
                        .zip(&run.channels[k].values)
                        .all(|(q, v)| q[j] == *v));
                }
            }
            // The same run without its joint encoders: the motors through the routing
            // (rigid ropes) put the joints where the encoders saw them, to the ropes'
            // stretch.
            let mut motors_only = run.clone();
            motors_only
                .channels
                .retain(|c| c.quantity != ArmQuantity::Joint);
            let from_motors = measured_joints(&motors_only, &pose.arm);
            let moved = with_joints
                .iter()
                .flat_map(|q| q.iter().zip(&with_joints[0]).map(|(a, b)| (a - b).abs()))
                .fold(0.0, f64::max);
            assert!(moved > 0.09, "{}: moves {moved} rad", run.name);
            // At rest at the end: the ropes' static stretch (the payload's run, 8 kg,
            // the most); during the moves the distal links ring on the ropes, which the
            // motors do not see.
            let (a, b) = (from_motors.last().unwrap(), with_joints.last().unwrap());
            for (x, y) in a.iter().zip(b) {
                worst = worst.max((x - y).abs());
            }
            let base_rms = (from_motors
                .iter()
                .zip(&with_joints)
                .map(|(a, b)| (a[0] - b[0]).powi(2))
                .sum::<f64>()
                / from_motors.len() as f64)
                .sqrt();
            assert!(base_rms < 1e-3, "{}: j1 {base_rms} rad rms", run.name);
            // Without motors either: the commands.
            let mut none = motors_only;
            none.channels.clear();
            let from_commands = measured_joints(&none, &pose.arm);
            for (p, pair) in pose.arm.pairs().iter().enumerate() {
                for (q, c) in from_commands.iter().zip(&run.command_rad[p]) {
                    assert_eq!(q[pair.spec.joint], *c);
                }
            }
        }
        assert!(
            worst < 0.035,
            "motors vs joint encoders at rest: {worst} rad"
        );
        assert!(worst > 1e-3, "the ropes stretch: {worst} rad");
    }
}

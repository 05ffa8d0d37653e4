//! The rig's stepped-sine runs in Rerun: per mean tension the input and output
//! angles and both rope tensions over time, the rig drawn with its ropes coloured by
//! tension, and the simulated and analytic gain and phase per test frequency.
//!
//! Entity paths (see docs/rerun.md), `<run>` = `T<mean tension>N`:
//!
//! ```text
//! /rig/<run>/series/{input_rad,output_rad,tension_1_n,tension_2_n}   on sim_time
//! /rig/<run>/ropes                         rope 1 and 2 between the pulleys, coloured by tension
//! /rig/<run>/pulleys                       input and output pulleys (static)
//! /rig/<run>/spokes                        a spoke on each pulley showing its angle
//! /bode/<run>/gain_db/{simulated,analytic}   per test frequency, timeline frequency_mhz
//! /bode/<run>/phase_deg/{simulated,analytic}
//! ```

use longreach_drive::{FrequencyPoint, RigSpec, RigTrace};
use rerun::blueprint::{
    Blueprint, BlueprintActivation, Horizontal, Spatial3DView, Tabs, TimeSeriesView, Vertical,
};
use rerun::components::RotationQuat;
use rerun::{Color, Cylinders3D, Quaternion, ViewCoordinates};

use crate::ident::FREQUENCY_TIMELINE;
use crate::{tension_color, Columns, RateGate, Recorder, SIM_TIME};

/// Logs the runs of one Bode scenario: `(mean tension, trace, points)` per run.
pub fn log_bode(rec: &Recorder, spec: &RigSpec, runs: &[(f64, &RigTrace, &[FrequencyPoint])]) {
    if !rec.is_enabled() {
        return;
    }
    let stream = rec.stream();
    rec.report(
        "view coordinates",
        stream.log_static("/rig", &ViewCoordinates::RIGHT_HAND_Z_UP()),
    );
    let l = spec.rope_length_m;
    let (r1, r2) = (spec.input_radius_m, spec.output_radius_m);
    let mut tabs = Vec::new();
    for (k, (tension_n, trace, points)) in runs.iter().enumerate() {
        let run = format!("T{tension_n:.0}N");
        let y = k as f64 * 4.0 * r1.max(r2);
        let ax = RotationQuat::from(Quaternion::from_xyzw([
            std::f32::consts::FRAC_1_SQRT_2,
            0.0,
            0.0,
            std::f32::consts::FRAC_1_SQRT_2,
        ]));
        rec.report(
            "pulleys",
            stream.log_static(
                format!("/rig/{run}/pulleys"),
                &Cylinders3D::from_lengths_and_radii([0.01f32, 0.01], [r1 as f32, r2 as f32])
                    .with_centers([[0.0, y as f32, 0.0], [l as f32, y as f32, 0.0]])
                    .with_quaternions([ax, ax])
                    .with_colors([Color::from_rgb(120, 120, 130); 2]),
            ),
        );
        let mut cols = Columns::on_duration(SIM_TIME);
        let ids = [
            cols.series(format!("/rig/{run}/series/input_rad")),
            cols.series(format!("/rig/{run}/series/output_rad")),
            cols.series(format!("/rig/{run}/series/tension_1_n")),
            cols.series(format!("/rig/{run}/series/tension_2_n")),
        ];
        let ropes = cols.strips(format!("/rig/{run}/ropes"), 0.002);
        let spokes = cols.strips(format!("/rig/{run}/spokes"), 0.001);
        let mut gate = RateGate::new(rec.hz());
        let full = 2.0 * tension_n;
        for i in 0..trace.time_s.len() {
            if !gate.due(trace.time_s[i]) {
                continue;
            }
            cols.frame_at_s(trace.time_s[i]);
            let (th, ph) = (trace.input_rad[i], trace.output_rad[i]);
            let (f1, f2) = (trace.tension_1_n[i], trace.tension_2_n[i]);
            for (id, v) in ids.iter().zip([th, ph, f1, f2]) {
                cols.push(*id, v);
            }
            // Rope 1 runs over the top (+z) of both pulleys, rope 2 under them.
            cols.push_strips(
                ropes,
                [
                    (vec![[0.0, y, r1], [l, y, r2]], tension_color(f1, full)),
                    (vec![[0.0, y, -r1], [l, y, -r2]], tension_color(f2, full)),
                ],
            );
            let spoke = |x: f64, r: f64, a: f64| {
                (
                    vec![[x, y, 0.0], [x + r * a.cos(), y, r * a.sin()]],
                    [240, 240, 240, 255],
                )
            };
            cols.push_strips(spokes, [spoke(0.0, r1, th), spoke(l, r2, ph)]);
        }
        cols.flush(rec.sink());
        let mut freq = Columns::on_sequence(FREQUENCY_TIMELINE);
        let g = [
            freq.series(format!("/bode/{run}/gain_db/simulated")),
            freq.series(format!("/bode/{run}/gain_db/analytic")),
            freq.series(format!("/bode/{run}/phase_deg/simulated")),
            freq.series(format!("/bode/{run}/phase_deg/analytic")),
        ];
        for p in points.iter() {
            freq.frame_at((p.frequency_hz * 1e3).round() as i64);
            for (id, v) in g.iter().zip([
                p.simulated_gain_db,
                p.analytic_gain_db,
                p.simulated_phase_deg,
                p.analytic_phase_deg,
            ]) {
                freq.push(*id, v);
            }
        }
        freq.flush(rec.sink());
        tabs.push(
            Vertical::new([
                Spatial3DView::new(format!("{run} rig"))
                    .with_origin(format!("/rig/{run}"))
                    .with_contents([
                        format!("+ /rig/{run}/ropes"),
                        format!("+ /rig/{run}/pulleys"),
                        format!("+ /rig/{run}/spokes"),
                    ])
                    .into(),
                TimeSeriesView::new(format!("{run} angles and tensions"))
                    .with_origin(format!("/rig/{run}/series"))
                    .into(),
                Horizontal::new([
                    TimeSeriesView::new("gain (dB) vs frequency (mHz)")
                        .with_origin(format!("/bode/{run}/gain_db"))
                        .into(),
                    TimeSeriesView::new("phase (deg) vs frequency (mHz)")
                        .with_origin(format!("/bode/{run}/phase_deg"))
                        .into(),
                ])
                .into(),
            ])
            .with_name(run.clone())
            .into(),
        );
    }
    let bp = Blueprint::new(Tabs::new(tabs));
    rec.report("blueprint", bp.send(stream, BlueprintActivation::default()));
}

/// The samples of `trace` a logger at `hz` would log (the rest dropped), so that a
/// long run's trace need not be kept whole.
pub fn decimate(trace: &RigTrace, hz: f64) -> RigTrace {
    let mut gate = RateGate::new(hz);
    let keep: Vec<usize> = (0..trace.time_s.len())
        .filter(|&i| gate.due(trace.time_s[i]))
        .collect();
    let pick = |v: &[f64]| keep.iter().map(|&i| v[i]).collect::<Vec<_>>();
    RigTrace {
        time_s: pick(&trace.time_s),
        input_rad: pick(&trace.input_rad),
        output_rad: pick(&trace.output_rad),
        tension_1_n: pick(&trace.tension_1_n),
        tension_2_n: pick(&trace.tension_2_n),
    }
}

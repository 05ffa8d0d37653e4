//! The rig's stepped-sine runs in Rerun: per mean tension the input and output
//! angles and both rope tensions over time, the rig drawn with its ropes coloured by
//! tension, and the simulated and analytic gain and phase per test frequency.
//!
//! Entity paths (see docs/rerun.md), `<run>` = `T<mean tension>N`:
//!
//! ```text
//! /rig/<run>/series/angles_rad            input and output angles (named instances), on sim_time
//! /rig/<run>/series/tensions_n            rope 1 and rope 2 tensions (named instances)
//! /rig/<run>/ropes                         rope 1 and 2 between the pulleys (static), coloured by tension
//! /rig/<run>/pulleys                       input and output pulleys (static)
//! /rig/<run>/spokes/{input,output}         a spoke on each pulley (static), turned by the pulley's angle
//! /bode/<run>/gain_db/{simulated,analytic}   per test frequency, timeline frequency_mhz
//! /bode/<run>/phase_deg/{simulated,analytic}
//! ```

use longreach_drive::{FrequencyPoint, RigSpec, RigTrace};
use rerun::blueprint::{
    Blueprint, BlueprintActivation, Horizontal, Spatial3DView, Tabs, TimeSeriesView, Vertical,
};
use rerun::components::RotationQuat;
use rerun::{Color, Cylinders3D, LineStrips3D, Quaternion, Transform3D, ViewCoordinates};

use crate::ident::FREQUENCY_TIMELINE;
use crate::worker::Worker;
use crate::{tension_color, Columns, RateGate, Recorder, Sink, SIM_TIME};

/// Logs the runs of one Bode scenario: `(mean tension, trace, points)` per run (the
/// runs of a [`BodeLogger`] given all at once).
pub fn log_bode(rec: &Recorder, spec: &RigSpec, runs: &[(f64, &RigTrace, &[FrequencyPoint])]) {
    let tensions_n: Vec<f64> = runs.iter().map(|r| r.0).collect();
    let logger = BodeLogger::new(rec, spec, &tensions_n);
    for (k, (_, trace, points)) in runs.iter().enumerate() {
        logger.log_run(k, trace, points);
    }
    logger.finish();
}

/// One run handed to the logging thread: its index, its decimated trace, its points.
type BodeRun = (usize, RigTrace, Vec<FrequencyPoint>);

/// Logs the runs of one Bode scenario as they finish, on a thread of its own: the
/// runs of a scenario are simulated in parallel and each is logged (decimated to the
/// recorder's rate, its columns built and sent) while the others are still running.
/// The static scene of every run and the blueprint are logged first.
#[derive(Debug)]
pub struct BodeLogger {
    hz: f64,
    worker: Option<Worker<BodeRun>>,
}

impl BodeLogger {
    /// Starts the logging thread for runs at the mean tensions `tensions_n` (run `k`
    /// at `tensions_n[k]`) of the rig `spec`.
    pub fn new(rec: &Recorder, spec: &RigSpec, tensions_n: &[f64]) -> Self {
        let worker = if rec.is_enabled() {
            let (s, spec, tensions) = (rec.sink().clone(), spec.clone(), tensions_n.to_vec());
            Worker::<BodeRun>::spawn(
                rec.sink(),
                "rerun-bode",
                "logging the Bode runs",
                move |rx| {
                    log_layout(&s, &spec, &tensions);
                    for (k, trace, points) in rx {
                        log_run(&s, tensions[k], &trace, &points);
                    }
                },
            )
        } else {
            None
        };
        Self {
            hz: rec.hz(),
            worker,
        }
    }

    /// Logs run `k` (its full trace is decimated here, on the caller's thread).
    pub fn log_run(&self, k: usize, trace: &RigTrace, points: &[FrequencyPoint]) {
        if let Some(worker) = &self.worker {
            // A failed send means the thread is gone: `finish` reports it.
            worker.send((k, decimate(trace, self.hz), points.to_vec()));
        }
    }

    /// Waits for every run handed over to be logged (dropping the logger waits too).
    pub fn finish(mut self) {
        if let Some(mut worker) = self.worker.take() {
            worker.join();
        }
    }
}

/// Name of the run at `tension_n`.
fn run_name(tension_n: f64) -> String {
    format!("T{tension_n:.0}N")
}

/// The static scene of every run (pulleys, ropes, spokes, side by side along y) and
/// the blueprint (a tab per run).
fn log_layout(sink: &Sink, spec: &RigSpec, tensions_n: &[f64]) {
    let stream = sink.stream();
    sink.report(
        "view coordinates",
        stream.log_static("/rig", &ViewCoordinates::RIGHT_HAND_Z_UP()),
    );
    let l = spec.rope_length_m as f32;
    let (r1, r2) = (spec.input_radius_m as f32, spec.output_radius_m as f32);
    let ax = RotationQuat::from(Quaternion::from_xyzw([
        std::f32::consts::FRAC_1_SQRT_2,
        0.0,
        0.0,
        std::f32::consts::FRAC_1_SQRT_2,
    ]));
    let mut tabs = Vec::new();
    for (k, &tension_n) in tensions_n.iter().enumerate() {
        let run = run_name(tension_n);
        let y = run_y_m(spec, k) as f32;
        sink.report(
            "pulleys",
            stream.log_static(
                format!("/rig/{run}/pulleys"),
                &Cylinders3D::from_lengths_and_radii([0.01f32, 0.01], [r1, r2])
                    .with_centers([[0.0, y, 0.0], [l, y, 0.0]])
                    .with_quaternions([ax, ax])
                    .with_colors([Color::from_rgb(120, 120, 130); 2]),
            ),
        );
        // The geometry is static: rope 1 runs over the top (+z) of both pulleys, rope 2
        // under them, and each spoke points along +x in its pulley's frame. A frame
        // carries the ropes' colours and the pulleys' rotations.
        sink.report(
            "ropes",
            stream.log_static(
                format!("/rig/{run}/ropes"),
                &LineStrips3D::new([[[0.0, y, r1], [l, y, r2]], [[0.0, y, -r1], [l, y, -r2]]])
                    .with_radii([0.002f32]),
            ),
        );
        for (name, x, r) in [("input", 0.0, r1), ("output", l, r2)] {
            let entity = format!("/rig/{run}/spokes/{name}");
            sink.report(
                "spokes",
                stream.log_static(
                    entity.as_str(),
                    &LineStrips3D::new([[[0.0, 0.0, 0.0], [r, 0.0, 0.0]]])
                        .with_radii([0.001f32])
                        .with_colors([Color::from_rgb(240, 240, 240)]),
                ),
            );
            sink.report(
                "spokes",
                stream.log_static(
                    entity.as_str(),
                    &Transform3D::update_fields().with_translation([x, y, 0.0]),
                ),
            );
        }
        tabs.push(
            Vertical::new([
                Spatial3DView::new(format!("{run} rig"))
                    .with_origin(format!("/rig/{run}"))
                    .with_contents([
                        format!("+ /rig/{run}/ropes"),
                        format!("+ /rig/{run}/pulleys"),
                        format!("+ /rig/{run}/spokes/**"),
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
    sink.report("blueprint", bp.send(stream, BlueprintActivation::default()));
}

/// Where run `k` is drawn along y, m.
fn run_y_m(spec: &RigSpec, k: usize) -> f64 {
    k as f64 * 4.0 * spec.input_radius_m.max(spec.output_radius_m)
}

/// The time series of the run at `tension_n` (already decimated) and its gain and
/// phase per frequency.
fn log_run(sink: &Sink, tension_n: f64, trace: &RigTrace, points: &[FrequencyPoint]) {
    let run = run_name(tension_n);
    let mut cols = Columns::on_duration(SIM_TIME);
    let names = |a: &str, b: &str| vec![a.to_string(), b.to_string()];
    let angles = cols.series_group(
        format!("/rig/{run}/series/angles_rad"),
        names("input", "output"),
    );
    let tensions = cols.series_group(
        format!("/rig/{run}/series/tensions_n"),
        names("rope 1", "rope 2"),
    );
    let ropes = cols.strip_colors(format!("/rig/{run}/ropes"));
    let spokes = [
        cols.rotation(format!("/rig/{run}/spokes/input")),
        cols.rotation(format!("/rig/{run}/spokes/output")),
    ];
    let full = 2.0 * tension_n;
    for i in 0..trace.time_s.len() {
        cols.frame_at_s(trace.time_s[i]);
        let (th, ph) = (trace.input_rad[i], trace.output_rad[i]);
        let (f1, f2) = (trace.tension_1_n[i], trace.tension_2_n[i]);
        cols.push_group(angles, [th, ph]);
        cols.push_group(tensions, [f1, f2]);
        cols.push_colors(ropes, [tension_color(f1, full), tension_color(f2, full)]);
        // A rotation about y by -a puts the spoke's end at (r cos a, 0, r sin a).
        for (id, a) in [(spokes[0], th), (spokes[1], ph)] {
            let half = -0.5 * a;
            cols.push_rotation(id, [0.0, half.sin(), 0.0, half.cos()]);
        }
    }
    cols.flush(sink);
    let mut freq = Columns::on_sequence(FREQUENCY_TIMELINE);
    let g = [
        freq.series(format!("/bode/{run}/gain_db/simulated")),
        freq.series(format!("/bode/{run}/gain_db/analytic")),
        freq.series(format!("/bode/{run}/phase_deg/simulated")),
        freq.series(format!("/bode/{run}/phase_deg/analytic")),
    ];
    for p in points {
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
    freq.flush(sink);
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

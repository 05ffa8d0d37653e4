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
//! /bode/gain_db                            per test frequency (timeline frequency_mhz), every run:
//! /bode/phase_deg                          instances "<run> simulated", "<run> analytic"
//! ```
//!
//! The ropes are drawn twenty pulley radii long, not to scale (the paper's 15.2 m rope
//! would hide its 25 mm pulleys), the runs side by side along y. The series are named
//! after their run (`T147N rope 1`). The default blueprint opens on a Bode tab (gain
//! and phase of every run) and the `frequency_mhz` timeline; a rig tab shows every
//! run drawn and its series on `sim_time` (Rerun plots against the time panel's one
//! timeline).

use longreach_drive::{FrequencyPoint, RigSpec, RigTrace};
use rerun::blueprint::components::PlayState;
use rerun::blueprint::{
    Blueprint, BlueprintActivation, Spatial3DView, Tabs, TimePanel, TimeSeriesView, Vertical,
};
use rerun::components::RotationQuat;
use rerun::{Color, Cylinders3D, LineStrips3D, Quaternion, ViewCoordinates};

use crate::ident::{gain_and_phase, FREQUENCY_TIMELINE};
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
/// The static scene of every run and the blueprint are logged first; the gain and
/// phase of every run that was handed over, last ([`BodeLogger::finish`]).
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
                    let mut points: Vec<Option<Vec<FrequencyPoint>>> = vec![None; tensions.len()];
                    for (k, trace, run_points) in rx {
                        let Some(&tension_n) = tensions.get(k) else {
                            continue;
                        };
                        log_trace(&s, tension_n, &trace);
                        points[k] = Some(run_points);
                    }
                    log_points(&s, &tensions, &points);
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

/// The static scene of every run (pulleys and ropes, side by side along y) and the
/// blueprint (a Bode tab and a rig tab).
fn log_layout(sink: &Sink, spec: &RigSpec, tensions_n: &[f64]) {
    let stream = sink.stream();
    sink.report(
        "view coordinates",
        stream.log_static("/rig", &ViewCoordinates::RIGHT_HAND_Z_UP()),
    );
    let l = drawn_span_m(spec) as f32;
    let (r1, r2) = (spec.input_radius_m as f32, spec.output_radius_m as f32);
    let ax = RotationQuat::from(Quaternion::from_xyzw([
        std::f32::consts::FRAC_1_SQRT_2,
        0.0,
        0.0,
        std::f32::consts::FRAC_1_SQRT_2,
    ]));
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
                    .with_colors([Color::from_rgb(120, 120, 130); 2])
                    .with_labels([run.as_str()]),
            ),
        );
        // The geometry is static (rope 1 over the top (+z) of both pulleys, rope 2
        // under them): a frame carries the ropes' colours only.
        sink.report(
            "ropes",
            stream.log_static(
                format!("/rig/{run}/ropes"),
                &LineStrips3D::new([[[0.0, y, r1], [l, y, r2]], [[0.0, y, -r1], [l, y, -r2]]])
                    .with_radii([0.002f32]),
            ),
        );
    }
    // Two tabs, each run a line in every plot: a view or container is a chunk of the
    // blueprint, and a chunk costs Rerun far more than a row (a tab per run made the
    // blueprint half the recording's chunks). Rerun plots every series against the
    // time panel's one timeline (rerun-io/rerun#8050): the recording opens on the Bode
    // tab and its timeline; the rig tab needs the time panel on sim_time.
    let every_run = |what: &str| -> Vec<String> {
        tensions_n
            .iter()
            .map(|&t| format!("+ /rig/{}/series/{what}", run_name(t)))
            .collect()
    };
    let bode = gain_and_phase("/bode", |what| vec![format!("+ /bode/{what}")])
        .with_name(format!("Bode (timeline {FREQUENCY_TIMELINE})"));
    let rig = Vertical::new([
        Spatial3DView::new("the rig at each mean tension (ropes coloured by tension)")
            .with_origin("/rig")
            .into(),
        TimeSeriesView::new("rope tensions (N)")
            .with_origin("/rig")
            .with_contents(every_run("tensions_n"))
            .into(),
        TimeSeriesView::new("pulley angles (rad)")
            .with_origin("/rig")
            .with_contents(every_run("angles_rad"))
            .into(),
    ])
    .with_name(format!("Rig runs (timeline {SIM_TIME})"));
    let tabs = vec![bode.into(), rig.into()];
    // Paused: playing would scroll the plots along the frequencies instead of
    // showing them whole.
    let bp = Blueprint::new(Tabs::new(tabs)).with_time_panel(
        TimePanel::new()
            .with_timeline(FREQUENCY_TIMELINE)
            .with_play_state(PlayState::Paused),
    );
    sink.report("blueprint", bp.send(stream, BlueprintActivation::default()));
}

/// Length of the ropes as drawn, m: twenty pulley radii, whatever the rope's length
/// (drawn to scale, the paper's 15.2 m rope would leave its 25 mm pulleys invisible).
fn drawn_span_m(spec: &RigSpec) -> f64 {
    20.0 * spec.input_radius_m.max(spec.output_radius_m)
}

/// Where run `k` is drawn along y, m.
fn run_y_m(spec: &RigSpec, k: usize) -> f64 {
    k as f64 * 4.0 * spec.input_radius_m.max(spec.output_radius_m)
}

/// The time series of the run at `tension_n` (`trace` already decimated): its two
/// series groups and its ropes' colours, one chunk each.
fn log_trace(sink: &Sink, tension_n: f64, trace: &RigTrace) {
    let run = run_name(tension_n);
    let mut cols = Columns::on_duration(SIM_TIME);
    // Named after the run: a plot shows every run.
    let names = |a: &str, b: &str| vec![format!("{run} {a}"), format!("{run} {b}")];
    let angles = cols.series_group(
        format!("/rig/{run}/series/angles_rad"),
        names("input", "output"),
    );
    let tensions = cols.series_group(
        format!("/rig/{run}/series/tensions_n"),
        names("rope 1", "rope 2"),
    );
    let ropes = cols.strip_colors(format!("/rig/{run}/ropes"));
    // Twice the mean tension at the top of the colour scale.
    let full_n = 2.0 * tension_n;
    cols.reserve(trace.time_s.len());
    for i in 0..trace.time_s.len() {
        let (f1, f2) = (trace.tension_1_n[i], trace.tension_2_n[i]);
        cols.frame_at_s(trace.time_s[i]);
        cols.push_group(angles, [trace.input_rad[i], trace.output_rad[i]]);
        cols.push_group(tensions, [f1, f2]);
        cols.push_colors(
            ropes,
            [tension_color(f1, full_n), tension_color(f2, full_n)],
        );
    }
    cols.flush(sink);
}

/// The simulated and analytic gain and phase of every run that reported its points
/// (`points[k]` for the run at `tensions_n[k]`) per test frequency, once all are in:
/// two entities for all runs (a chunk costs Rerun far more than a value), a line per
/// run and model, NaN where a run lacks a frequency.
fn log_points(sink: &Sink, tensions_n: &[f64], points: &[Option<Vec<FrequencyPoint>>]) {
    let runs: Vec<(String, &[FrequencyPoint])> = tensions_n
        .iter()
        .zip(points)
        .filter_map(|(&t, p)| Some((run_name(t), p.as_deref()?)))
        .collect();
    let mut mhz: Vec<i64> = runs
        .iter()
        .flat_map(|(_, p)| p.iter().map(|p| (p.frequency_hz * 1e3).round() as i64))
        .collect();
    mhz.sort_unstable();
    mhz.dedup();
    if mhz.is_empty() {
        return;
    }
    let names: Vec<String> = runs
        .iter()
        .flat_map(|(run, _)| [format!("{run} simulated"), format!("{run} analytic")])
        .collect();
    let mut freq = Columns::on_sequence(FREQUENCY_TIMELINE);
    let gain = freq.series_group("/bode/gain_db", names.clone());
    let phase = freq.series_group("/bode/phase_deg", names);
    for &f in &mhz {
        freq.frame_at(f);
        let at = |p: &[FrequencyPoint]| {
            p.iter()
                .find(|p| (p.frequency_hz * 1e3).round() as i64 == f)
                .copied()
        };
        let nan = f64::NAN;
        freq.push_group(
            gain,
            runs.iter().flat_map(|(_, p)| {
                at(p).map_or([nan; 2], |p| [p.simulated_gain_db, p.analytic_gain_db])
            }),
        );
        freq.push_group(
            phase,
            runs.iter().flat_map(|(_, p)| {
                at(p).map_or([nan; 2], |p| [p.simulated_phase_deg, p.analytic_phase_deg])
            }),
        );
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

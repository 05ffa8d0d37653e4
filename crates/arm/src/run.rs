//! Running a driven arm: time series and per-joint / per-pair metrics.

use crate::system::{DrivenArm, DrivenState};
use crate::ArmError;

/// Recorded time series (decimated by `output_every`).
#[derive(Debug, Clone, Default)]
pub struct Trace {
    /// Column names (units in the names).
    pub columns: Vec<String>,
    /// Rows, one per recorded step.
    pub rows: Vec<Vec<f64>>,
}

/// Metrics of one joint.
#[derive(Debug, Clone, serde::Serialize)]
pub struct JointMetrics {
    /// Joint name.
    pub joint: String,
    /// Size of the commanded move, rad (0 when held).
    pub move_rad: f64,
    /// Time from the start of the move until the joint stays within 2% of the move of
    /// its target, s (`None` without a move, or when it never settles in the run).
    pub settling_time_s: Option<f64>,
    /// Largest excursion past the target, % of the move.
    pub overshoot_pct: Option<f64>,
    /// Half the peak-to-peak joint angle over the final window, rad.
    pub residual_vibration_rad: f64,
    /// Joint angle minus reference at the end, rad.
    pub final_error_rad: f64,
}

/// Metrics of one rope pair.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PairMetrics {
    /// Driven joint.
    pub joint: String,
    /// Rope name.
    pub rope: String,
    /// Ropes in parallel per side.
    pub ropes_in_parallel: u32,
    /// Largest tension of any one rope (any span, with relay friction) of the pair, N.
    pub peak_tension_n: f64,
    /// Smallest tension of any one rope, N.
    pub min_tension_n: f64,
    /// Times a rope went from taut to slack.
    pub slack_events: u32,
    /// Tensile strength / peak tension.
    pub safety_factor: f64,
    /// Tensile strength / largest tension of any one rope (any span) at the rest the
    /// run starts from (the static equilibrium at the first command; a payload the
    /// servos are not told of sags it).
    pub static_safety_factor: f64,
}

/// Result of a run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunMetrics {
    /// Per joint.
    pub joints: Vec<JointMetrics>,
    /// Per rope pair.
    pub pairs: Vec<PairMetrics>,
    /// Distance between the tip at the end and the tip at the final reference, m.
    pub tip_error_m: f64,
    /// Flexible links: distance between the deflected tip at the end and where the
    /// joint angles alone (straight links) put it, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tip_deflection_m: Option<f64>,
    /// Steps taken.
    pub steps: usize,
    /// Mean Newton iterations per step.
    pub mean_iterations: f64,
}

/// Column names of the trace of `arm`.
pub fn columns(arm: &DrivenArm) -> Vec<String> {
    let mut c = vec!["time_s".to_string()];
    for j in &arm.spec().joints {
        c.push(format!("q_{}_rad", j.name));
        c.push(format!("qref_{}_rad", j.name));
    }
    for p in arm.pairs() {
        c.push(format!(
            "motor_{}_rad",
            arm.spec().joints[p.spec.joint].name
        ));
    }
    for p in arm.pairs() {
        let name = &arm.spec().joints[p.spec.joint].name;
        match &p.relays {
            None => {
                c.push(format!("tension_{name}_pos_n"));
                c.push(format!("tension_{name}_neg_n"));
            }
            Some(r) => {
                // Span 0 starts at the motor pulley, span i at relay i-1.
                for i in 0..r.spans() {
                    c.push(format!("tension_{name}_pos_span{i}_n"));
                    c.push(format!("tension_{name}_neg_span{i}_n"));
                }
            }
        }
    }
    c.extend(["tip_x_m", "tip_y_m", "tip_z_m"].map(String::from));
    if let Some(f) = arm.flex() {
        for l in &f.flex {
            let name = &arm.spec().links[l.link].name;
            c.push(format!("deflection_{name}_in_plane_m"));
            c.push(format!("deflection_{name}_out_of_plane_m"));
        }
    }
    c
}

fn row(arm: &DrivenArm, st: &DrivenState) -> Result<Vec<f64>, ArmError> {
    let mut r = vec![st.time_s];
    for j in 0..arm.njoints() {
        r.push(st.q_rad[j]);
        r.push(st.q_ref_rad[j]);
    }
    r.extend(&st.motor_rad);
    for (p, pr) in st.ropes.iter().enumerate() {
        if arm.pairs()[p].relays.is_some() {
            for span in &st.relays[p].spans {
                r.push(span[0].tension_n);
                r.push(span[1].tension_n);
            }
        } else {
            r.push(pr[0].tension_n);
            r.push(pr[1].tension_n);
        }
    }
    let tip = arm.tip_m(&st.q_rad)?;
    r.extend([tip.x, tip.y, tip.z]);
    if let Some(f) = arm.flex() {
        for l in &f.flex {
            let eta = &st.q_rad[l.offset..l.offset + l.ncoords()];
            let d = l.deflection(eta, l.length_m);
            r.extend([d.dot(&l.e1), d.dot(&l.e2)]);
        }
    }
    Ok(r)
}

/// Runs `arm` for `duration_s` from its initial state, recording every
/// `output_every`-th step; `progress(step, total)` is called every 1000 steps.
pub fn run(
    arm: &DrivenArm,
    duration_s: f64,
    output_every: usize,
    residual_window_s: f64,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Trace, RunMetrics), ArmError> {
    run_observed(
        arm,
        duration_s,
        output_every,
        residual_window_s,
        progress,
        &mut |_| {},
    )
}

/// [`run`], calling `observe` with the state at t = 0 and after every step (a viewer
/// reads the state; it cannot change the run).
pub fn run_observed(
    arm: &DrivenArm,
    duration_s: f64,
    output_every: usize,
    residual_window_s: f64,
    progress: &mut dyn FnMut(usize, usize),
    observe: &mut dyn FnMut(&DrivenState),
) -> Result<(Trace, RunMetrics), ArmError> {
    let steps = (duration_s / arm.dt_s()).round() as usize;
    let mut st = arm.initial_state();
    let n = arm.njoints();
    let np = arm.pairs().len();
    let mut trace = Trace {
        columns: columns(arm),
        rows: Vec::with_capacity(steps / output_every.max(1) + 2),
    };
    trace.rows.push(row(arm, &st)?);
    observe(&st);
    let mut q_hist: Vec<Vec<f64>> = vec![Vec::with_capacity(steps + 1); n];
    let mut t_hist = Vec::with_capacity(steps + 1);
    t_hist.push(0.0);
    for (j, h) in q_hist.iter_mut().enumerate() {
        h.push(st.q_rad[j]);
    }
    let mut peak = vec![0.0f64; np];
    let mut min = vec![f64::INFINITY; np];
    let mut slack = vec![0u32; np];
    // Tension of every rope, or of every span of a rope with relay friction, and the
    // pair it belongs to.
    let tensions_into = |st: &DrivenState, out: &mut Vec<(usize, f64)>| {
        out.clear();
        for p in 0..np {
            if arm.pairs()[p].relays.is_some() {
                for span in &st.relays[p].spans {
                    out.extend(span.iter().map(|r| (p, r.tension_n)));
                }
            } else {
                out.extend(st.ropes[p].iter().map(|r| (p, r.tension_n)));
            }
        }
    };
    let (mut was, mut now) = (Vec::new(), Vec::new());
    tensions_into(&st, &mut was);
    for &(p, f) in &was {
        peak[p] = peak[p].max(f);
        min[p] = min[p].min(f);
    }
    // The static safety factor from the rest the run starts at (the arm's statics as
    // built: sagged under a payload its servos are not told of, flexible links bent
    // under gravity, every span with relay friction), not from the commanded pose.
    let static_sf: Vec<f64> = arm
        .pairs()
        .iter()
        .zip(&peak)
        .map(|(p, &rest)| p.spec.rope.tensile_strength_n / rest)
        .collect();
    let mut iters = 0u64;
    for i in 1..=steps {
        arm.step(&mut st)?;
        observe(&st);
        iters += u64::from(st.iterations);
        tensions_into(&st, &mut now);
        for (&(p, f), &(_, f0)) in now.iter().zip(&was) {
            peak[p] = peak[p].max(f);
            min[p] = min[p].min(f);
            if f0 > 0.0 && f <= 0.0 {
                slack[p] += 1;
            }
        }
        std::mem::swap(&mut was, &mut now);
        t_hist.push(st.time_s);
        for (j, h) in q_hist.iter_mut().enumerate() {
            h.push(st.q_rad[j]);
        }
        if i % output_every == 0 || i == steps {
            trace.rows.push(row(arm, &st)?);
        }
        if i % 1000 == 0 {
            progress(i, steps);
        }
    }
    let t_end = st.time_s;
    let mut joints = Vec::with_capacity(n);
    for j in 0..n {
        let cmd = &arm.commands()[j];
        let q0 = arm.initial_q_rad()[j];
        let hist = &q_hist[j];
        let target = cmd.target_rad(q0);
        let move_rad = target.map_or(0.0, |t| (t - q0).abs());
        let (mut settling, mut overshoot) = (None, None);
        if let (Some(target), true) = (target, move_rad > 0.0) {
            let band = 0.02 * move_rad;
            let start = cmd.start_s();
            let end = cmd.end_s(q0).unwrap_or(start);
            let last_out = t_hist
                .iter()
                .zip(hist)
                .rev()
                .find(|(_, q)| (**q - target).abs() > band)
                .map(|(t, _)| *t);
            settling = match last_out {
                None => Some(0.0),
                Some(t) if t >= t_end - 1e-12 => None,
                Some(t) => Some((t.max(end) - start).max(0.0)),
            };
            let dir = (target - q0).signum();
            let over = t_hist
                .iter()
                .zip(hist)
                .filter(|(t, _)| **t >= start)
                .map(|(_, q)| (q - target) * dir)
                .fold(0.0f64, f64::max);
            overshoot = Some(100.0 * over / move_rad);
        }
        let w0 = t_end - residual_window_s;
        let (lo, hi) = t_hist
            .iter()
            .zip(hist)
            .filter(|(t, _)| **t >= w0)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (_, q)| {
                (lo.min(*q), hi.max(*q))
            });
        joints.push(JointMetrics {
            joint: arm.spec().joints[j].name.clone(),
            move_rad,
            settling_time_s: settling,
            overshoot_pct: overshoot,
            residual_vibration_rad: 0.5 * (hi - lo),
            final_error_rad: st.q_rad[j] - st.q_ref_rad[j],
        });
    }
    let pairs = arm
        .pairs()
        .iter()
        .enumerate()
        .map(|(p, pair)| PairMetrics {
            joint: arm.spec().joints[pair.spec.joint].name.clone(),
            rope: pair.spec.rope_name.clone(),
            ropes_in_parallel: pair.spec.ropes_in_parallel,
            peak_tension_n: peak[p],
            min_tension_n: min[p],
            slack_events: slack[p],
            safety_factor: pair.spec.rope.tensile_strength_n / peak[p],
            static_safety_factor: static_sf[p],
        })
        .collect();
    let tip_error_m = (arm.tip_m(&st.q_rad)? - arm.tip_m(&st.q_ref_rad)?).norm();
    let tip_deflection_m = match arm.flex() {
        None => None,
        Some(_) => Some((arm.tip_m(&st.q_rad)? - arm.tip_m(&st.q_rad[..n])?).norm()),
    };
    Ok((
        trace,
        RunMetrics {
            joints,
            pairs,
            tip_error_m,
            tip_deflection_m,
            steps,
            mean_iterations: iters as f64 / steps.max(1) as f64,
        },
    ))
}

/// Ropes of the comparison, stainless first.
pub const COMPARISON_ROPES: [&str; 5] = ["stainless1", "dyneema2", "zylon2", "vectran2", "kevlar2"];
/// Moves of the comparison (`scenarios/arm_<rope>_<move>.toml`).
pub const COMPARISON_MOVES: [&str; 4] = [
    "base_step",
    "base_trapezoid",
    "distal_step",
    "distal_trapezoid",
];

/// Runs `arm_<rope>_<move>.toml` of `dir` for every rope and move and returns the
/// markdown table of docs/arm.md (settling, overshoot, residual vibration, tensions).
pub fn rope_comparison_table(dir: &std::path::Path) -> Result<String, String> {
    let mut out = String::from(
        "| move | rope | settling 2% (s) | overshoot (%) | residual vib. moved joint (mrad) | residual vib. j5 (mrad) | tip error (mm) | peak tension (N) | min SF |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for mv in COMPARISON_MOVES {
        for rope in COMPARISON_ROPES {
            let path = dir.join(format!("arm_{rope}_{mv}.toml"));
            let sc = crate::scenario::load(&path).map_err(|e| e.to_string())?;
            let (_, m) = run(
                &sc.arm,
                sc.sim.duration_s,
                sc.sim.output_every,
                sc.sim.residual_window_s,
                &mut |_, _| {},
            )
            .map_err(|e| format!("{}: {e}", path.display()))?;
            let j = if mv.starts_with("base") {
                0
            } else {
                m.joints.len() - 1
            };
            let jm = &m.joints[j];
            let last = &m.joints[m.joints.len() - 1];
            let peak = m.pairs.iter().map(|p| p.peak_tension_n).fold(0.0, f64::max);
            let sf = m
                .pairs
                .iter()
                .map(|p| p.safety_factor)
                .fold(f64::INFINITY, f64::min);
            out.push_str(&format!(
                "| {mv} | {rope} | {} | {} | {:.3} | {:.3} | {:.1} | {:.0} | {:.2} |\n",
                jm.settling_time_s
                    .map_or("not in run".into(), |v| format!("{v:.2}")),
                jm.overshoot_pct.map_or("-".into(), |v| format!("{v:.1}")),
                1e3 * jm.residual_vibration_rad,
                1e3 * last.residual_vibration_rad,
                1e3 * m.tip_error_m,
                peak,
                sf
            ));
        }
    }
    Ok(out)
}

//! The stated limits on every size that comes from input: each is checked when the
//! input is validated, before anything is allocated, and an input past one is refused
//! with the field, the limit and the fix (docs/batch.md and scenarios/README.md list
//! them). They are far above any real study and far below what exhausts memory.

/// Time steps in one simulated run (`duration_s / dt_s`; a Bode sweep's settle and
/// hold times over `dt_s`), and so samples of its time series: 1e7 steps is 2.8 hours
/// of simulated time at 1 ms, 400 MB of a Bode run's trace, 15 s of wall clock for the
/// arm.
pub const MAX_STEPS_PER_RUN: f64 = 1e7;

/// Scenarios in one batch (the product of its axes, `samples`, a journal's `total`).
pub const MAX_SCENARIOS: usize = 1_000_000;

/// Worker threads per available core (`-j` is capped at this many times the cores).
pub const JOBS_PER_CORE: usize = 4;

/// The largest `-j` this machine accepts: [`JOBS_PER_CORE`] times its cores.
pub fn max_jobs() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get()) * JOBS_PER_CORE
}

/// Steps of a run of `duration_s` at `dt_s` (both validated positive and finite), and
/// whether they are within [`MAX_STEPS_PER_RUN`]: `Err(steps)` when not.
pub fn check_steps(duration_s: f64, dt_s: f64) -> Result<f64, f64> {
    let steps = duration_s / dt_s;
    if steps.is_finite() && steps <= MAX_STEPS_PER_RUN {
        Ok(steps)
    } else {
        Err(steps)
    }
}

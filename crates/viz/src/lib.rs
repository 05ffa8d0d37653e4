//! Rerun logging for longreach: every command can stream what it simulates to the
//! Rerun viewer (<https://rerun.io>), live or into an `.rrd` recording.
//!
//! - [`Target`] parses `--rerun save:FILE | spawn | connect[:ADDR]`.
//! - [`Recorder`] owns the recording stream. A viewer that cannot be reached never
//!   stops a run: the recorder says so once and goes quiet. A file that cannot be
//!   written is an error before anything runs. Recordings are written beside their
//!   final name and renamed when complete.
//! - [`Columns`] buffers the frames of a run in memory and sends them in columns
//!   (`send_columns`), so logging costs a few pushes per frame instead of one
//!   `log` call per entity per frame.
//! - [`RateGate`] picks the frames to log at `--rerun-hz` of simulated time.
//! - [`arm`], [`rig`], [`ident`] and [`modes`] log the arm runs, the rig's frequency
//!   responses, the comparisons with measurements and the arm's modes, and
//!   [`arm_compare`] the measured and model arms of an arm dataset; each sends a
//!   default blueprint.
//!
//! Entity paths are listed in `docs/rerun.md`. Logging only reads simulation states:
//! it cannot change a result (tested bitwise in `tests/cli/rerun_cli.rs`).

pub mod arm;
pub mod arm_compare;
mod columns;
mod error;
pub mod ident;
pub mod modes;
mod recorder;
pub mod rig;
mod rrd_file;
mod worker;

pub use columns::{ColorsId, Columns, PointsId, RateGate, SeriesId, StripsId, TransformId};
pub use error::VizError;
pub use recorder::{Closing, Recorder, Sink, Target, DEFAULT_HZ, SDK_VERSION};

/// Name of the simulated-time timeline every time series and pose is logged on.
pub const SIM_TIME: &str = "sim_time";

/// Colour of a rope segment carrying `tension_n`: red when slack (< 1 N), otherwise
/// a blue -> green -> yellow ramp of `tension_n / full_scale_n` (clamped to 1).
pub fn tension_color(tension_n: f64, full_scale_n: f64) -> [u8; 4] {
    if tension_n.is_nan() || tension_n < 1.0 {
        return [230, 30, 30, 255];
    }
    let x = (tension_n / full_scale_n.max(1.0)).clamp(0.0, 1.0);
    // Piecewise-linear through blue (0), green (0.5), yellow (1).
    let (r, g, b) = if x < 0.5 {
        let s = x / 0.5;
        (30.0, 90.0 + 130.0 * s, 230.0 - 150.0 * s)
    } else {
        let s = (x - 0.5) / 0.5;
        (30.0 + 220.0 * s, 220.0 + 15.0 * s, 80.0 - 60.0 * s)
    };
    [r as u8, g as u8, b as u8, 255]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slack_is_red_and_the_ramp_is_monotone_in_red() {
        assert_eq!(tension_color(0.0, 100.0), [230, 30, 30, 255]);
        assert_eq!(tension_color(f64::NAN, 100.0), [230, 30, 30, 255]);
        let lo = tension_color(5.0, 100.0);
        let mid = tension_color(50.0, 100.0);
        let hi = tension_color(100.0, 100.0);
        let over = tension_color(300.0, 100.0);
        assert!(lo[2] > hi[2], "low tension is bluer");
        assert!(
            lo[0] < mid[0] + 1 && mid[0] < hi[0],
            "{lo:?} {mid:?} {hi:?}"
        );
        assert_eq!(hi, over, "clamped at full scale");
    }
}

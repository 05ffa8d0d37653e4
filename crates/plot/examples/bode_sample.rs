//! Writes a sample Bode plot: `cargo run -p longreach-plot --example bode_sample -- out.png`.
//!
//! Four rope tensions, analytic second-order responses as lines and perturbed
//! "simulated" samples as markers of the same colour.

use longreach_plot::{bode_figure, write_png, BodeCurve, Style};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path: PathBuf = std::env::args_os()
        .nth(1)
        .map_or_else(|| "bode_sample.png".into(), PathBuf::from);
    let mut curves = Vec::new();
    for (color, tension_n) in [49.0f64, 98.0, 196.0, 392.0].into_iter().enumerate() {
        let fn_hz = 2.0 * (tension_n / 49.0).sqrt();
        let zeta = 0.08;
        let response = |f_hz: f64| {
            let r = f_hz / fn_hz;
            let (re, im) = (1.0 - r * r, 2.0 * zeta * r);
            (
                -10.0 * (re * re + im * im).log10(),
                -im.atan2(re).to_degrees(),
            )
        };
        let dense: Vec<f64> = (0..300)
            .map(|i| 0.1 * 1000f64.powf(i as f64 / 299.0))
            .collect();
        let sparse: Vec<f64> = (0..28)
            .map(|i| 0.12 * 660f64.powf(i as f64 / 27.0))
            .collect();
        let (gain_db, phase_deg): (Vec<f64>, Vec<f64>) = dense.iter().map(|&f| response(f)).unzip();
        curves.push(BodeCurve {
            label: format!("{tension_n} N analytic"),
            frequency_hz: dense,
            gain_db,
            phase_deg,
            style: Style::Line,
            color,
        });
        let (gain_db, phase_deg): (Vec<f64>, Vec<f64>) = sparse
            .iter()
            .enumerate()
            .map(|(i, &f)| {
                let (g, p) = response(f);
                let wobble = 0.4 * (i as f64 * 1.7).sin();
                (g + wobble, p + 3.0 * wobble)
            })
            .unzip();
        curves.push(BodeCurve {
            label: format!("{tension_n} N simulated"),
            frequency_hz: sparse,
            gain_db,
            phase_deg,
            style: Style::Markers,
            color,
        });
    }
    write_png(
        &bode_figure("rope drive: link angle / motor angle", &curves),
        &path,
    )?;
    println!("wrote {}", path.display());
    Ok(())
}

//! Writes real PNGs, decodes them and checks what a reader would see.

mod common;

use image::RgbImage;
use longreach_plot::{
    bode_figure, palette_color, write_png, BodeCurve, Figure, Panel, PlotError, Series, Style,
    BODE_HEIGHT_PX, BODE_WIDTH_PX, PALETTE,
};
use std::path::Path;

fn decode(path: &Path) -> RgbImage {
    image::open(path).expect("decode written PNG").to_rgb8()
}

/// Pixels of exactly palette colour `color` in rows `rows`.
fn count_color(img: &RgbImage, color: usize, rows: std::ops::Range<u32>) -> usize {
    let (r, g, b) = palette_color(color);
    img.enumerate_pixels()
        .filter(|(_, y, p)| rows.contains(y) && p.0 == [r, g, b])
        .count()
}

fn non_white(img: &RgbImage) -> usize {
    img.pixels().filter(|p| p.0 != [255, 255, 255]).count()
}

#[test]
fn bode_png_with_four_curves_is_readable() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bode.png");
    let mut curves: Vec<BodeCurve> = common::rope_curves(49.0, 0).into();
    curves.extend(common::rope_curves(196.0, 1));
    let fig = bode_figure("rope drive, motor angle to link angle", &curves);
    write_png(&fig, &path).unwrap();

    let img = decode(&path);
    assert_eq!(img.dimensions(), (BODE_WIDTH_PX, BODE_HEIGHT_PX));
    let total = (BODE_WIDTH_PX * BODE_HEIGHT_PX) as usize;
    let ink = non_white(&img);
    assert!(
        ink > total / 50 && ink < total / 2,
        "{ink} non-white pixels of {total}"
    );

    // Both colours appear in both panels, far more than a legend swatch would give.
    let (upper, lower) = (0..BODE_HEIGHT_PX / 2, BODE_HEIGHT_PX / 2..BODE_HEIGHT_PX);
    for color in [0, 1] {
        let up = count_color(&img, color, upper.clone());
        let down = count_color(&img, color, lower.clone());
        assert!(up > 1500, "colour {color}: {up} pixels in the gain panel");
        assert!(
            down > 1500,
            "colour {color}: {down} pixels in the phase panel"
        );
    }
    // An unused palette colour is absent.
    assert_eq!(count_color(&img, 2, 0..BODE_HEIGHT_PX), 0);
}

#[test]
fn bode_figure_has_gain_and_phase_panels_over_log_frequency() {
    let curves = common::rope_curves(49.0, 3);
    let fig = bode_figure("t", &curves);
    assert!(fig.log_x);
    assert_eq!(fig.x_label, "frequency [Hz]");
    let labels: Vec<&str> = fig.panels.iter().map(|p| p.y_label.as_str()).collect();
    assert_eq!(labels, ["gain [dB]", "phase [deg]"]);
    let phase = &fig.panels[1].series[1];
    assert_eq!(phase.label, "49 N simulated");
    assert_eq!(phase.y, curves[1].phase_deg);
    assert_eq!((phase.style, phase.color), (Style::Markers, 3));
    // Independent check of the test model: at resonance a second-order system
    // has gain 1/(2 zeta) and phase -90 deg.
    let (g, p) = common::second_order(2.0, 2.0, 0.08);
    assert!((g - 20.0 * (1.0 / 0.16f64).log10()).abs() < 1e-12);
    assert!((p + 90.0).abs() < 1e-12);
}

/// Time series: joint angle and its reference over time, one panel.
fn angle_figure(angle_deg: Vec<f64>, time_s: Vec<f64>) -> Figure {
    let reference_deg: Vec<f64> = time_s.iter().map(|t| 30.0 * (t * 0.8).sin()).collect();
    Figure {
        title: "link 2 angle".into(),
        x_label: "time [s]".into(),
        log_x: false,
        panels: vec![Panel {
            y_label: "angle [deg]".into(),
            series: vec![
                Series {
                    label: "reference".into(),
                    x: time_s.clone(),
                    y: reference_deg,
                    style: Style::DashedLine,
                    color: 8,
                },
                Series {
                    label: "simulated".into(),
                    x: time_s,
                    y: angle_deg,
                    style: Style::Line,
                    color: 0,
                },
            ],
            y_range: None,
            log_y: false,
        }],
        width_px: 1000,
        height_px: 600,
    }
}

#[test]
fn time_series_line_breaks_at_nan_gap() {
    let dir = tempfile::tempdir().unwrap();
    let time_s: Vec<f64> = (0..=1000).map(|i| i as f64 * 0.01).collect();
    let angle: Vec<f64> = time_s
        .iter()
        .map(|t| 30.0 * (t * 0.8 - 0.2).sin())
        .collect();
    // Same data with t in [4, 6) missing: 20 % of the time axis.
    let gappy: Vec<f64> = time_s
        .iter()
        .zip(&angle)
        .map(|(&t, &a)| if (4.0..6.0).contains(&t) { f64::NAN } else { a })
        .collect();

    let full_path = dir.path().join("full.png");
    let gap_path = dir.path().join("gap.png");
    write_png(&angle_figure(angle, time_s.clone()), &full_path).unwrap();
    write_png(&angle_figure(gappy, time_s), &gap_path).unwrap();
    let (full, gap) = (decode(&full_path), decode(&gap_path));
    assert_eq!(full.dimensions(), (1000, 600));

    let full_n = count_color(&full, 0, 0..600) as f64;
    let gap_n = count_color(&gap, 0, 0..600) as f64;
    // A bridged gap would keep ~all pixels; a broken line loses about 20 %.
    let ratio = gap_n / full_n;
    assert!((0.7..0.9).contains(&ratio), "{gap_n} / {full_n} = {ratio}");
    // The dashed reference is drawn too.
    assert!(count_color(&gap, 8, 0..600) > 1000);
}

#[test]
fn fixed_y_range_clips_data_to_the_panel() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("clip.png");
    let time_s: Vec<f64> = (0..=200).map(|i| i as f64 * 0.05).collect();
    // Swings to +-300 deg but the panel shows only +-10 deg.
    let angle: Vec<f64> = time_s.iter().map(|t| 300.0 * t.sin()).collect();
    let mut fig = angle_figure(angle, time_s);
    fig.panels[0].y_range = Some((-10.0, 10.0));
    write_png(&fig, &path).unwrap();
    let img = decode(&path);
    let inside = count_color(&img, 0, 0..600);
    assert!(inside > 200, "{inside}");
    // Nothing of the series above the plot (title strip) or below it (x labels).
    assert_eq!(count_color(&img, 0, 0..40), 0);
    assert_eq!(count_color(&img, 0, 560..600), 0);
}

#[test]
fn sixteen_curves_and_log_y_draw() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("many.png");
    let f = common::log_space(0.1, 100.0, 120);
    let series: Vec<Series> = (0..16)
        .map(|k| Series {
            label: format!(
                "{} N {}",
                49 * (k / 2 + 1),
                ["analytic", "simulated"][k % 2]
            ),
            x: f.clone(),
            y: f.iter().map(|f| (1.0 + k as f64) / (1.0 + f * f)).collect(),
            style: [Style::Line, Style::Markers][k % 2],
            color: k / 2,
        })
        .collect();
    let fig = Figure {
        title: "compliance".into(),
        x_label: "frequency [Hz]".into(),
        log_x: true,
        panels: vec![Panel {
            y_label: "compliance [mrad/(N m)]".into(),
            series,
            y_range: None,
            log_y: true,
        }],
        width_px: 1200,
        height_px: 700,
    };
    write_png(&fig, &path).unwrap();
    let img = decode(&path);
    for color in 0..8 {
        assert!(count_color(&img, color, 0..700) > 300, "colour {color}");
    }
}

#[test]
fn palette_has_ten_distinct_colours() {
    let mut seen: Vec<_> = PALETTE.to_vec();
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(seen.len(), 10);
    assert_eq!(palette_color(13), palette_color(3));
}

// ---- errors -------------------------------------------------------------

fn simple_series(label: &str, x: Vec<f64>, y: Vec<f64>) -> Series {
    Series {
        label: label.into(),
        x,
        y,
        style: Style::Line,
        color: 0,
    }
}

fn one_panel(series: Vec<Series>) -> Figure {
    Figure {
        title: "err".into(),
        x_label: "time [s]".into(),
        log_x: false,
        panels: vec![
            Panel {
                y_label: "angle [deg]".into(),
                series: vec![simple_series("ok", vec![0.0, 1.0], vec![0.0, 1.0])],
                y_range: None,
                log_y: false,
            },
            Panel {
                y_label: "tension [N]".into(),
                series,
                y_range: None,
                log_y: false,
            },
        ],
        width_px: 800,
        height_px: 600,
    }
}

/// Runs `write_png` into a tempdir, expects an error, checks no file was left,
/// and returns the error with its message.
fn expect_error(fig: &Figure) -> (PlotError, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.png");
    let err = write_png(fig, &path).expect_err("figure must be rejected");
    assert!(!path.exists(), "no file on error");
    let text = err.to_string();
    (err, text)
}

#[test]
fn zero_panels_is_an_error() {
    let mut fig = one_panel(vec![]);
    fig.panels.clear();
    let (err, text) = expect_error(&fig);
    assert!(matches!(err, PlotError::NoPanels { .. }), "{err:?}");
    assert!(text.contains("add at least one Panel"), "{text}");
}

#[test]
fn panel_without_series_is_an_error() {
    let (err, text) = expect_error(&one_panel(vec![]));
    assert!(
        matches!(err, PlotError::EmptyPanel { panel: 1, .. }),
        "{err:?}"
    );
    assert!(text.contains("panels[1] (\"tension [N]\")"), "{text}");
}

#[test]
fn empty_series_is_an_error() {
    let fig = one_panel(vec![simple_series("98 N simulated", vec![], vec![])]);
    let (err, text) = expect_error(&fig);
    assert!(
        matches!(
            err,
            PlotError::NoFiniteData {
                panel: 1,
                series: 0,
                len: 0,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(text.contains("\"98 N simulated\""), "{text}");
}

#[test]
fn all_non_finite_series_is_an_error() {
    let fig = one_panel(vec![
        simple_series("ok", vec![0.0], vec![1.0]),
        simple_series(
            "blown up",
            vec![0.0, 1.0, f64::NAN],
            vec![f64::NAN, f64::INFINITY, 2.0],
        ),
    ]);
    let (err, text) = expect_error(&fig);
    assert!(
        matches!(
            err,
            PlotError::NoFiniteData {
                panel: 1,
                series: 1,
                len: 3,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(
        text.contains("\"blown up\"") && text.contains("drop the series"),
        "{text}"
    );
}

#[test]
fn mismatched_lengths_are_an_error() {
    let fig = one_panel(vec![simple_series(
        "short y",
        vec![0.0, 1.0, 2.0],
        vec![1.0, 2.0],
    )]);
    let (err, text) = expect_error(&fig);
    assert!(
        matches!(
            err,
            PlotError::LengthMismatch {
                x_len: 3,
                y_len: 2,
                series: 0,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(
        text.contains("\"short y\"") && text.contains("same length"),
        "{text}"
    );
}

#[test]
fn non_positive_frequency_on_log_axis_is_an_error() {
    let mut curves = common::rope_curves(98.0, 2);
    curves[1].frequency_hz[5] = 0.0;
    let (err, text) = expect_error(&bode_figure("bad", &curves));
    assert!(
        matches!(
            err,
            PlotError::NonPositiveOnLogAxis {
                panel: 0,
                series: 1,
                axis: "x",
                index: 5,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(
        text.contains("\"98 N simulated\"") && text.contains("log_x = false"),
        "{text}"
    );
}

#[test]
fn non_positive_y_on_log_axis_is_an_error() {
    let mut fig = one_panel(vec![simple_series("t", vec![0.0, 1.0], vec![3.0, -1.0])]);
    fig.panels[1].log_y = true;
    let (err, _) = expect_error(&fig);
    assert!(
        matches!(
            err,
            PlotError::NonPositiveOnLogAxis {
                axis: "y",
                index: 1,
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn invalid_fixed_range_is_an_error() {
    let mut fig = one_panel(vec![simple_series("t", vec![0.0, 1.0], vec![3.0, 1.0])]);
    fig.panels[1].y_range = Some((5.0, 5.0));
    let (err, text) = expect_error(&fig);
    assert!(
        matches!(err, PlotError::InvalidRange { panel: 1, .. }),
        "{err:?}"
    );
    assert!(text.contains("y_range = None"), "{text}");
}

#[test]
fn overflowing_data_range_is_an_error() {
    let fig = one_panel(vec![simple_series(
        "huge",
        vec![0.0, 1.0],
        vec![-1e308, 1e308],
    )]);
    let (err, text) = expect_error(&fig);
    assert!(matches!(err, PlotError::RangeOverflow { .. }), "{err:?}");
    assert!(
        text.contains("panels[1] (\"tension [N]\") y axis"),
        "{text}"
    );
}

#[test]
fn too_small_image_is_an_error() {
    let mut fig = one_panel(vec![simple_series("t", vec![0.0, 1.0], vec![3.0, 1.0])]);
    fig.height_px = 200;
    let (err, _) = expect_error(&fig);
    assert!(
        matches!(
            err,
            PlotError::InvalidSize {
                min_height_px: 380,
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn missing_directory_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("no_such_dir").join("plot.png");
    let fig = bode_figure("x", &common::rope_curves(49.0, 0));
    let err = write_png(&fig, &path).expect_err("missing directory");
    assert!(matches!(err, PlotError::MissingDirectory { .. }), "{err:?}");
    let text = err.to_string();
    assert!(
        text.contains("no_such_dir") && text.contains("create_dir_all"),
        "{text}"
    );
}

#[test]
fn non_png_extension_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plot.jpg");
    let fig = bode_figure("x", &common::rope_curves(49.0, 0));
    let err = write_png(&fig, &path).expect_err("not .png");
    assert!(matches!(err, PlotError::NotPng { .. }), "{err:?}");
    assert!(!path.exists());
}

/// A title longer than the picture is wide (a dataset's title and a run's name, as
/// `diagnose --report` writes over a Bode plot) is drawn smaller to fit: the columns at
/// the picture's edges stay white in the title's rows.
#[test]
fn a_long_title_fits_inside_the_picture() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bode_long.png");
    let curves: Vec<BodeCurve> = common::rope_curves(49.0, 0).into();
    let title = "MuJoCo 4.0.0 rig, stainless1, frictionloss 0.0 N*m, ropes T = k1 e (1 + e / 0.005), seed 21 run_02: measured vs model";
    write_png(&bode_figure(title, &curves), &path).unwrap();
    let img = decode(&path);
    let title_rows = 0..40;
    let ink_at = |x: u32| {
        title_rows
            .clone()
            .filter(|&y| img.get_pixel(x, y).0 != [255, 255, 255])
            .count()
    };
    for x in (0..8).chain(BODE_WIDTH_PX - 8..BODE_WIDTH_PX) {
        assert_eq!(ink_at(x), 0, "the title reaches column {x}");
    }
    // and it is drawn: ink in the title's rows
    let ink: usize = (0..BODE_WIDTH_PX).map(ink_at).sum();
    assert!(ink > 500, "{ink} title pixels");
}

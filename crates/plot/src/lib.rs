//! PNG charts for longreach: time series and Bode plots.
//!
//! Drawing uses [plotters] with its pure-Rust `ab_glyph` text backend and an
//! embedded DejaVu Sans (see `assets/LICENSE-DejaVu.txt`), so no system font
//! library (fontconfig, freetype) is needed.
//!
//! A [`Figure`] is one or more [`Panel`]s stacked vertically that share the
//! x axis; each panel has its own y axis, grid and legend. [`write_png`]
//! checks the data (lengths, finite points, positive values on log axes) and
//! reports every problem as a [`PlotError`] that names the panel and series.
//! [`bode_figure`] builds the usual two-panel gain/phase plot over log frequency.
//!
//! ```no_run
//! use longreach_plot::{bode_figure, write_png, BodeCurve, Style};
//! let f: Vec<f64> = (0..50).map(|i| 10f64.powf(-1.0 + i as f64 * 0.06)).collect();
//! let curve = BodeCurve {
//!     label: "49 N analytic".into(),
//!     gain_db: f.iter().map(|f| -20.0 * (1.0 + f * f).sqrt().log10()).collect(),
//!     phase_deg: f.iter().map(|f| -f.atan().to_degrees()).collect(),
//!     frequency_hz: f,
//!     style: Style::Line,
//!     color: 0,
//! };
//! write_png(&bode_figure("rope drive", &[curve]), "bode.png".as_ref())?;
//! # Ok::<(), longreach_plot::PlotError>(())
//! ```

mod axis;
mod render;

use std::path::{Path, PathBuf};

/// How a series is drawn. All styles use the series' palette colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Style {
    /// Solid line, 2 px (scaled with the image), broken at non-finite points.
    Line,
    /// Dashed line, otherwise like [`Style::Line`].
    DashedLine,
    /// A filled circle at every finite point, no line (e.g. simulated samples).
    Markers,
    /// Solid line with a filled circle at every finite point.
    LineMarkers,
}

/// One data series of a [`Panel`].
///
/// Points where `x` or `y` is NaN or infinite are gaps: lines break there.
/// A series with an empty `label` is drawn but left out of the legend.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text, e.g. `"49 N analytic"`.
    pub label: String,
    /// Abscissae in the figure's x unit (see [`Figure::x_label`]).
    pub x: Vec<f64>,
    /// Ordinates in the panel's y unit (see [`Panel::y_label`]); same length as `x`.
    pub y: Vec<f64>,
    /// Line and/or marker style.
    pub style: Style,
    /// Index into [`PALETTE`] (taken modulo its length); equal index, equal colour.
    pub color: usize,
}

/// One chart of a [`Figure`]: a y axis with its series, grid and legend.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    /// Y axis title with unit, e.g. `"gain [dB]"`.
    pub y_label: String,
    /// Series drawn in this panel (at least one).
    pub series: Vec<Series>,
    /// Fixed y range `(low, high)` in data units; `None` = data extent plus a 5 % margin.
    /// Data outside a fixed range is clipped.
    pub y_range: Option<(f64, f64)>,
    /// Base-10 logarithmic y axis (all y values must then be positive).
    pub log_y: bool,
}

/// A picture: a title over panels stacked vertically that share one x axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// Title drawn above the panels (may be empty).
    pub title: String,
    /// X axis title with unit, e.g. `"time [s]"`; drawn under the bottom panel.
    pub x_label: String,
    /// Base-10 logarithmic x axis (all x values must then be positive).
    pub log_x: bool,
    /// Panels from top to bottom; the x range is the extent of all their data.
    pub panels: Vec<Panel>,
    /// Image width in pixels.
    pub width_px: u32,
    /// Image height in pixels.
    pub height_px: u32,
}

/// One transfer function for [`bode_figure`]: gain and phase over frequency.
#[derive(Debug, Clone, PartialEq)]
pub struct BodeCurve {
    /// Legend text, e.g. `"49 N simulated"`.
    pub label: String,
    /// Frequencies in Hz (positive; the axis is logarithmic).
    pub frequency_hz: Vec<f64>,
    /// Gain `20 log10 |H|` in dB at each frequency.
    pub gain_db: Vec<f64>,
    /// Phase of `H` in degrees at each frequency.
    pub phase_deg: Vec<f64>,
    /// Line and/or marker style.
    pub style: Style,
    /// Index into [`PALETTE`] (taken modulo its length).
    pub color: usize,
}

/// Everything that can stop a figure from being drawn.
///
/// Panel and series indices are 0-based positions in [`Figure::panels`] and
/// [`Panel::series`].
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// [`Figure::panels`] is empty.
    #[error("figure \"{title}\" has no panels: add at least one Panel to Figure::panels")]
    NoPanels {
        /// Figure title.
        title: String,
    },
    /// A panel has no series.
    #[error(
        "figure \"{title}\": panels[{panel}] (\"{y_label}\") has no series: \
         add at least one Series or remove the panel"
    )]
    EmptyPanel {
        /// Figure title.
        title: String,
        /// Panel index.
        panel: usize,
        /// Panel y label.
        y_label: String,
    },
    /// `x` and `y` of a series differ in length.
    #[error(
        "panels[{panel}] (\"{y_label}\") series[{series}] (\"{label}\"): x has {x_len} values \
         but y has {y_len}: give x and y the same length (one y per x)"
    )]
    LengthMismatch {
        /// Panel index.
        panel: usize,
        /// Panel y label.
        y_label: String,
        /// Series index.
        series: usize,
        /// Series label.
        label: String,
        /// Length of `x`.
        x_len: usize,
        /// Length of `y`.
        y_len: usize,
    },
    /// A series has no point whose x and y are both finite.
    #[error(
        "panels[{panel}] (\"{y_label}\") series[{series}] (\"{label}\"): none of its {len} points \
         has finite x and y (the series is empty or all NaN/infinite; a NaN often means the \
         computation blew up): check the data that produced it, or drop the series"
    )]
    NoFiniteData {
        /// Panel index.
        panel: usize,
        /// Panel y label.
        y_label: String,
        /// Series index.
        series: usize,
        /// Series label.
        label: String,
        /// Number of points in the series.
        len: usize,
    },
    /// A value at or below zero on a logarithmic axis.
    #[error(
        "panels[{panel}] (\"{y_label}\") series[{series}] (\"{label}\"): {axis}[{index}] = {value} \
         is not positive but the {axis} axis is logarithmic: drop non-positive points or use a \
         linear axis ({flag} = false)"
    )]
    NonPositiveOnLogAxis {
        /// Panel index.
        panel: usize,
        /// Panel y label.
        y_label: String,
        /// Series index.
        series: usize,
        /// Series label.
        label: String,
        /// `"x"` or `"y"`.
        axis: &'static str,
        /// `"Figure::log_x"` or `"Panel::log_y"`.
        flag: &'static str,
        /// Index of the offending point.
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// A fixed `y_range` that cannot be drawn.
    #[error(
        "panels[{panel}] (\"{y_label}\"): y_range ({low}, {high}) is invalid: {reason}; \
         fix it or set y_range = None for an automatic range"
    )]
    InvalidRange {
        /// Panel index.
        panel: usize,
        /// Panel y label.
        y_label: String,
        /// Lower end given.
        low: f64,
        /// Upper end given.
        high: f64,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The data extent of an axis overflows `f64` arithmetic (e.g. values near +-1e308).
    #[error(
        "{axis}: the data spans {min} .. {max}, too wide to draw (the range overflows f64): \
         look for blown-up values, or set Panel::y_range"
    )]
    RangeOverflow {
        /// Which axis: `"x axis"` or `panels[i] ("label") y axis`.
        axis: String,
        /// Smallest finite value.
        min: f64,
        /// Largest finite value.
        max: f64,
    },
    /// Image too small for its panels, or unreasonably large.
    #[error(
        "figure \"{title}\": {width_px}x{height_px} px is out of range for {panels} panel(s): \
         use a width of {min_width_px}..={max_px} px and a height of {min_height_px}..={max_px} px"
    )]
    InvalidSize {
        /// Figure title.
        title: String,
        /// Requested width.
        width_px: u32,
        /// Requested height.
        height_px: u32,
        /// Number of panels.
        panels: usize,
        /// Smallest accepted width.
        min_width_px: u32,
        /// Smallest accepted height for this many panels.
        min_height_px: u32,
        /// Largest accepted side.
        max_px: u32,
    },
    /// The output directory does not exist.
    #[error(
        "cannot write \"{}\": directory \"{}\" does not exist: create it first \
         (e.g. std::fs::create_dir_all) or choose another path",
        .path.display(), .dir.display()
    )]
    MissingDirectory {
        /// Requested output file.
        path: PathBuf,
        /// Its parent directory.
        dir: PathBuf,
    },
    /// The output path does not end in `.png`.
    #[error("cannot write \"{}\": the file name must end in \".png\" (the image is PNG-encoded)", .path.display())]
    NotPng {
        /// Requested output file.
        path: PathBuf,
    },
    /// The embedded font could not be loaded (a corrupted build).
    #[error(
        "the embedded font assets/DejaVuSans.ttf could not be loaded by plotters: \
         rebuild longreach-plot from a clean checkout"
    )]
    Font,
    /// plotters or the PNG encoder failed (e.g. disk full, no permission).
    #[error("drawing or writing \"{}\" failed: {message}", .path.display())]
    Draw {
        /// Requested output file.
        path: PathBuf,
        /// The underlying error.
        message: String,
    },
}

/// Colour-blind-friendly palette: Petroff's 10-colour sequence (M. A. Petroff,
/// "Accessible Color Sequences for Data Visualization", arXiv:2107.02270, 2021;
/// matplotlib's `petroff10`), as 8-bit sRGB. [`Series::color`] indexes it modulo 10.
pub const PALETTE: [(u8, u8, u8); 10] = [
    (0x3f, 0x90, 0xda), // blue
    (0xff, 0xa9, 0x0e), // orange
    (0xbd, 0x1f, 0x01), // red
    (0x94, 0xa4, 0xa2), // grey
    (0x83, 0x2d, 0xb6), // purple
    (0xa9, 0x6b, 0x59), // brown
    (0xe7, 0x63, 0x00), // dark orange
    (0xb9, 0xac, 0x70), // tan
    (0x71, 0x75, 0x81), // slate
    (0x92, 0xda, 0xdd), // light blue
];

/// The sRGB colour of palette index `color` (modulo [`PALETTE`]'s length).
pub fn palette_color(color: usize) -> (u8, u8, u8) {
    PALETTE[color % PALETTE.len()]
}

/// Default Bode image width in pixels.
pub const BODE_WIDTH_PX: u32 = 1200;
/// Default Bode image height in pixels.
pub const BODE_HEIGHT_PX: u32 = 900;

/// Smallest accepted image width in pixels.
pub const MIN_WIDTH_PX: u32 = 320;
/// Largest accepted image side in pixels.
pub const MAX_SIDE_PX: u32 = 16384;

/// Smallest accepted image height for `panels` panels, in pixels.
pub fn min_height_px(panels: usize) -> u32 {
    let panels = u32::try_from(panels).unwrap_or(u32::MAX);
    panels.saturating_mul(140).saturating_add(100)
}

/// Draws `fig` and writes it as a PNG file at `path` (which must end in `.png`
/// and whose directory must exist). Overwrites an existing file.
///
/// # Errors
/// Any [`PlotError`]: bad figure data or size, a missing directory, or an I/O failure.
pub fn write_png(fig: &Figure, path: &Path) -> Result<(), PlotError> {
    let is_png = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !is_png {
        return Err(PlotError::NotPng {
            path: path.to_path_buf(),
        });
    }
    if let Some(dir) = path.parent() {
        if !dir.as_os_str().is_empty() && !dir.is_dir() {
            return Err(PlotError::MissingDirectory {
                path: path.to_path_buf(),
                dir: dir.to_path_buf(),
            });
        }
    }
    let prepared = render::prepare(fig)?;
    render::draw_to_file(fig, &prepared, path)
}

/// Bode plot of `curves`: gain in dB (upper panel) and phase in degrees (lower
/// panel) over frequency in Hz on a log axis, [`BODE_WIDTH_PX`] x
/// [`BODE_HEIGHT_PX`] pixels. Each curve appears in both panels with its label,
/// style and colour. Data problems are reported by [`write_png`].
pub fn bode_figure(title: &str, curves: &[BodeCurve]) -> Figure {
    let panel = |y_label: &str, y: fn(&BodeCurve) -> &Vec<f64>| Panel {
        y_label: y_label.to_string(),
        series: curves
            .iter()
            .map(|c| Series {
                label: c.label.clone(),
                x: c.frequency_hz.clone(),
                y: y(c).clone(),
                style: c.style,
                color: c.color,
            })
            .collect(),
        y_range: None,
        log_y: false,
    };
    Figure {
        title: title.to_string(),
        x_label: "frequency [Hz]".to_string(),
        log_x: true,
        panels: vec![
            panel("gain [dB]", |c| &c.gain_db),
            panel("phase [deg]", |c| &c.phase_deg),
        ],
        width_px: BODE_WIDTH_PX,
        height_px: BODE_HEIGHT_PX,
    }
}

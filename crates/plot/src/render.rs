//! Checking a [`Figure`] and drawing it with plotters.

use crate::axis::{Axis, LabelledAxis};
use crate::{
    min_height_px, palette_color, Figure, Panel, PlotError, Series, Style, MAX_SIDE_PX,
    MIN_WIDTH_PX,
};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;
use std::sync::OnceLock;

/// DejaVu Sans 2.37 (Bitstream Vera license, see `assets/LICENSE-DejaVu.txt`).
static DEJAVU_SANS: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// Relative margin added around automatic x ranges.
const X_MARGIN: f64 = 0.02;
/// Relative margin added around automatic y ranges.
const Y_MARGIN: f64 = 0.06;

/// Registers the embedded font as plotters' `sans-serif` family (once per process).
fn ensure_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, DEJAVU_SANS).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(PlotError::Font)
    }
}

/// A series reduced to what is drawn: clipped line pieces and visible markers, in data units.
#[derive(Debug)]
struct DrawSeries {
    /// Polyline pieces inside the panel (breaks at gaps and where the line leaves the range).
    pieces: Vec<Vec<(f64, f64)>>,
    /// Finite points inside the panel.
    points: Vec<(f64, f64)>,
}

#[derive(Debug)]
struct DrawPanel {
    y: Axis,
    series: Vec<DrawSeries>,
}

/// A checked figure with its axes decided.
#[derive(Debug)]
pub(crate) struct Prepared {
    x: Axis,
    panels: Vec<DrawPanel>,
}

/// Min and max of the finite values seen so far.
#[derive(Debug, Clone, Copy)]
struct Extent(Option<(f64, f64)>);

impl Extent {
    fn add(&mut self, v: f64) {
        self.0 = Some(match self.0 {
            None => (v, v),
            Some((lo, hi)) => (lo.min(v), hi.max(v)),
        });
    }
}

/// Checks `fig` and computes its axes and the visible parts of every series.
pub(crate) fn prepare(fig: &Figure) -> Result<Prepared, PlotError> {
    if fig.panels.is_empty() {
        return Err(PlotError::NoPanels {
            title: fig.title.clone(),
        });
    }
    let mut x_extent = Extent(None);
    let mut y_extents = Vec::with_capacity(fig.panels.len());
    for (pi, panel) in fig.panels.iter().enumerate() {
        if panel.series.is_empty() {
            return Err(PlotError::EmptyPanel {
                title: fig.title.clone(),
                panel: pi,
                y_label: panel.y_label.clone(),
            });
        }
        let mut y_extent = Extent(None);
        for (si, s) in panel.series.iter().enumerate() {
            check_series(fig, pi, panel, si, s)?;
            for (&x, &y) in s.x.iter().zip(&s.y) {
                if x.is_finite() && y.is_finite() {
                    x_extent.add(x);
                    y_extent.add(y);
                }
            }
        }
        y_extents.push(y_extent);
    }
    let Some((x_min, x_max)) = x_extent.0 else {
        unreachable!("check_series rejects series without finite points")
    };
    let x = checked_auto(x_min, x_max, fig.log_x, X_MARGIN, || "x axis".to_string())?;

    let mut panels = Vec::with_capacity(fig.panels.len());
    for (pi, (panel, extent)) in fig.panels.iter().zip(y_extents).enumerate() {
        let y = match panel.y_range {
            Some((low, high)) => {
                let reason = if !(low.is_finite() && high.is_finite()) {
                    Some("both ends must be finite")
                } else if low >= high {
                    Some("low must be below high")
                } else if panel.log_y && low <= 0.0 {
                    Some("both ends must be positive on a logarithmic axis (log_y = true)")
                } else {
                    None
                };
                if let Some(reason) = reason {
                    return Err(PlotError::InvalidRange {
                        panel: pi,
                        y_label: panel.y_label.clone(),
                        low,
                        high,
                        reason,
                    });
                }
                Axis::new(low, high, panel.log_y)
            }
            None => {
                let Some((lo, hi)) = extent.0 else {
                    unreachable!("check_series rejects series without finite points")
                };
                checked_auto(lo, hi, panel.log_y, Y_MARGIN, || {
                    format!("panels[{pi}] (\"{}\") y axis", panel.y_label)
                })?
            }
        };
        let series = panel
            .series
            .iter()
            .map(|s| visible_parts(s, &x, &y))
            .collect();
        panels.push(DrawPanel { y, series });
    }

    let min_h = min_height_px(fig.panels.len());
    if !(MIN_WIDTH_PX..=MAX_SIDE_PX).contains(&fig.width_px)
        || !(min_h..=MAX_SIDE_PX).contains(&fig.height_px)
    {
        return Err(PlotError::InvalidSize {
            title: fig.title.clone(),
            width_px: fig.width_px,
            height_px: fig.height_px,
            panels: fig.panels.len(),
            min_width_px: MIN_WIDTH_PX,
            min_height_px: min_h,
            max_px: MAX_SIDE_PX,
        });
    }
    Ok(Prepared { x, panels })
}

/// [`Axis::auto`], refusing extents whose span overflows `f64`.
fn checked_auto(
    min: f64,
    max: f64,
    log: bool,
    margin: f64,
    axis: impl FnOnce() -> String,
) -> Result<Axis, PlotError> {
    let a = Axis::auto(min, max, log, margin);
    let span = a.param(a.hi()) - a.param(a.lo());
    if span.is_finite() && span > 0.0 && a.lo().is_finite() && a.hi().is_finite() {
        Ok(a)
    } else {
        Err(PlotError::RangeOverflow {
            axis: axis(),
            min,
            max,
        })
    }
}

/// Length, log-axis and finiteness checks of one series.
fn check_series(
    fig: &Figure,
    pi: usize,
    panel: &Panel,
    si: usize,
    s: &Series,
) -> Result<(), PlotError> {
    if s.x.len() != s.y.len() {
        return Err(PlotError::LengthMismatch {
            panel: pi,
            y_label: panel.y_label.clone(),
            series: si,
            label: s.label.clone(),
            x_len: s.x.len(),
            y_len: s.y.len(),
        });
    }
    let non_positive = |values: &[f64], axis, flag| {
        values
            .iter()
            .position(|&v| v.is_finite() && v <= 0.0)
            .map(|index| PlotError::NonPositiveOnLogAxis {
                panel: pi,
                y_label: panel.y_label.clone(),
                series: si,
                label: s.label.clone(),
                axis,
                flag,
                index,
                value: values[index],
            })
    };
    if fig.log_x {
        if let Some(e) = non_positive(&s.x, "x", "Figure::log_x") {
            return Err(e);
        }
    }
    if panel.log_y {
        if let Some(e) = non_positive(&s.y, "y", "Panel::log_y") {
            return Err(e);
        }
    }
    if !s
        .x
        .iter()
        .zip(&s.y)
        .any(|(x, y)| x.is_finite() && y.is_finite())
    {
        return Err(PlotError::NoFiniteData {
            panel: pi,
            y_label: panel.y_label.clone(),
            series: si,
            label: s.label.clone(),
            len: s.x.len(),
        });
    }
    Ok(())
}

/// Splits a series at non-finite points and clips it to the panel's box.
fn visible_parts(s: &Series, x: &Axis, y: &Axis) -> DrawSeries {
    // Work in axis parameter space (log10 on log axes), where lines are straight.
    let bounds = [
        x.param(x.lo()),
        x.param(x.hi()),
        y.param(y.lo()),
        y.param(y.hi()),
    ];
    let to_data = |(tx, ty): (f64, f64)| (x.value_at(tx), y.value_at(ty));
    let mut pieces = Vec::new();
    let mut points = Vec::new();
    let mut run: Vec<(f64, f64)> = Vec::new();
    let finite_points =
        s.x.iter().zip(&s.y).map(|(&xv, &yv)| {
            (xv.is_finite() && yv.is_finite()).then(|| (x.param(xv), y.param(yv)))
        });
    for p in finite_points.chain(std::iter::once(None)) {
        match p {
            Some(t) => {
                if inside(t, bounds) {
                    points.push(to_data(t));
                }
                run.push(t);
            }
            None => {
                for piece in clip_polyline(&run, bounds) {
                    pieces.push(piece.into_iter().map(to_data).collect());
                }
                run.clear();
            }
        }
    }
    DrawSeries { pieces, points }
}

/// Whether `p` is inside `[x0, x1] x [y0, y1]` (with a tolerance for rounding).
fn inside(p: (f64, f64), [x0, x1, y0, y1]: [f64; 4]) -> bool {
    let (ex, ey) = (1e-9 * (x1 - x0), 1e-9 * (y1 - y0));
    p.0 >= x0 - ex && p.0 <= x1 + ex && p.1 >= y0 - ey && p.1 <= y1 + ey
}

/// Clips a polyline to a box; returns the visible pieces (single points stay single).
fn clip_polyline(run: &[(f64, f64)], bounds: [f64; 4]) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    if run.len() == 1 {
        if inside(run[0], bounds) {
            out.push(vec![run[0]]);
        }
        return out;
    }
    let mut current: Vec<(f64, f64)> = Vec::new();
    for w in run.windows(2) {
        match clip_segment(w[0], w[1], bounds) {
            Some((a, b, start_clipped, end_clipped)) => {
                if current.is_empty() || start_clipped {
                    if !current.is_empty() {
                        out.push(std::mem::take(&mut current));
                    }
                    current.push(a);
                }
                current.push(b);
                if end_clipped {
                    out.push(std::mem::take(&mut current));
                }
            }
            None => {
                if !current.is_empty() {
                    out.push(std::mem::take(&mut current));
                }
            }
        }
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

/// Liang-Barsky clipping of segment `p`-`q`: the visible part and whether each end was moved.
fn clip_segment(
    p: (f64, f64),
    q: (f64, f64),
    [x0, x1, y0, y1]: [f64; 4],
) -> Option<((f64, f64), (f64, f64), bool, bool)> {
    let (dx, dy) = (q.0 - p.0, q.1 - p.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (denominator, numerator) in [
        (-dx, p.0 - x0),
        (dx, x1 - p.0),
        (-dy, p.1 - y0),
        (dy, y1 - p.1),
    ] {
        if denominator == 0.0 {
            if numerator < 0.0 {
                return None;
            }
        } else {
            let t = numerator / denominator;
            if denominator < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    if t0 > t1 {
        return None;
    }
    let at = |t: f64| (p.0 + t * dx, p.1 + t * dy);
    Some((at(t0), at(t1), t0 > 0.0, t1 < 1.0))
}

/// Smallest font a long title is shrunk to [px] (below it, it is cut at the edges).
const MIN_TITLE_FONT: f64 = 11.0;

/// Pixel sizes derived from the image size.
#[derive(Debug, Clone, Copy)]
struct Metrics {
    title_font: f64,
    desc_font: f64,
    tick_font: f64,
    legend_font: f64,
    line_width: u32,
    marker_radius: i32,
    margin: i32,
}

impl Metrics {
    fn new(width_px: u32, height_px: u32) -> Self {
        let scale = (f64::from(width_px) * f64::from(height_px) / (1200.0 * 900.0))
            .sqrt()
            .clamp(0.9, 3.0);
        Self {
            title_font: (26.0 * scale).max(22.0),
            desc_font: (20.0 * scale).max(18.0),
            tick_font: (17.0 * scale).max(15.0),
            legend_font: (16.0 * scale).max(14.0),
            line_width: (2.0 * scale).round().max(2.0) as u32,
            marker_radius: (3.5 * scale).round().max(3.0) as i32,
            margin: (12.0 * scale).round() as i32,
        }
    }
}

fn font(size: f64) -> TextStyle<'static> {
    TextStyle::from(FontDesc::new(
        FontFamily::SansSerif,
        size,
        FontStyle::Normal,
    ))
    .color(&BLACK)
}

fn rgb(color: usize) -> RGBColor {
    let (r, g, b) = palette_color(color);
    RGBColor(r, g, b)
}

/// Converts any displayable plotters error into our message string.
fn msg(e: impl std::fmt::Display) -> String {
    e.to_string()
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// Draws a prepared figure into a PNG file.
pub(crate) fn draw_to_file(fig: &Figure, prep: &Prepared, path: &Path) -> Result<(), PlotError> {
    ensure_font()?;
    let wrap = |message| PlotError::Draw {
        path: path.to_path_buf(),
        message,
    };
    let root = BitMapBackend::new(path, (fig.width_px, fig.height_px)).into_drawing_area();
    draw(fig, prep, &root).map_err(wrap)?;
    root.present().map_err(|e| wrap(msg(e)))
}

/// Draws the whole figure on `root`.
fn draw(fig: &Figure, prep: &Prepared, root: &Area) -> Result<(), String> {
    let m = Metrics::new(fig.width_px, fig.height_px);
    root.fill(&WHITE).map_err(msg)?;
    let (w, h) = (fig.width_px as i32, fig.height_px as i32);

    let mut top = m.margin / 2;
    if !fig.title.trim().is_empty() {
        // A title wider than the picture less its margins is drawn smaller, to fit
        // (a dataset's long title and a run's name over a report's Bode plot ran off
        // both sides).
        let room = f64::from((w - 2 * m.margin).max(1));
        let (wide, _) = root
            .estimate_text_size(&fig.title, &font(m.title_font))
            .map_err(msg)?;
        let size = if f64::from(wide) > room {
            (m.title_font * room / f64::from(wide)).max(MIN_TITLE_FONT)
        } else {
            m.title_font
        };
        let style = font(size).pos(Pos::new(HPos::Center, VPos::Top));
        root.draw(&Text::new(fig.title.clone(), (w / 2, top), style))
            .map_err(msg)?;
        top += (m.title_font * 1.5) as i32;
    }

    // Every panel has the same plot height: the bottom one carries the x tick
    // labels and the x title, the others only a small gap.
    let n = fig.panels.len() as i32;
    let panel_top = (m.tick_font * 0.8) as i32;
    let bottom_inner = (m.tick_font * 0.9) as i32;
    let bottom_last = (m.tick_font * 1.6 + m.desc_font * 1.4) as i32 + m.margin;
    let plot_h = (h - top - n * panel_top - (n - 1) * bottom_inner - bottom_last) / n;
    let mut breaks = Vec::new();
    let mut y = top;
    for _ in 0..n - 1 {
        y += panel_top + plot_h + bottom_inner;
        breaks.push(y);
    }
    let body = root.clone().shrink((0, top), (w, h - top));
    let breaks: Vec<i32> = breaks.iter().map(|b| b - top).collect();
    let areas = body.split_by_breakpoints(Vec::<i32>::new(), breaks);

    // One y label area width for all panels keeps the plots aligned.
    let x_labels = ((f64::from(fig.width_px) / (m.tick_font * 5.0)) as usize).max(3);
    let y_labels = ((f64::from(plot_h) / (m.tick_font * 2.8)) as usize).clamp(3, 12);
    let tick_style = font(m.tick_font);
    let mut widest_tick = 0u32;
    for p in &prep.panels {
        for v in p.y.major_ticks(y_labels) {
            let (tw, _) = root
                .estimate_text_size(&p.y.label(v, y_labels), &tick_style)
                .map_err(msg)?;
            widest_tick = widest_tick.max(tw);
        }
    }
    let y_area = widest_tick as i32 + (m.desc_font * 1.5) as i32 + 10;
    let right = (m.tick_font * 2.0) as i32 + m.margin;

    for (i, (area, (panel, dp))) in areas
        .iter()
        .zip(fig.panels.iter().zip(&prep.panels))
        .enumerate()
    {
        let last = i + 1 == fig.panels.len();
        let mut chart = ChartBuilder::on(area)
            .margin_top(panel_top)
            .margin_right(right)
            .margin_left(m.margin / 2)
            .x_label_area_size(if last { bottom_last } else { bottom_inner })
            .y_label_area_size(y_area)
            .build_cartesian_2d(
                LabelledAxis {
                    axis: prep.x,
                    max_labels: x_labels,
                },
                LabelledAxis {
                    axis: dp.y,
                    max_labels: y_labels,
                },
            )
            .map_err(msg)?;

        let no_labels = |_: &f64| String::new();
        let mut mesh = chart.configure_mesh();
        mesh.x_labels(x_labels)
            .y_labels(y_labels)
            .max_light_lines(20)
            .bold_line_style(BLACK.mix(0.22))
            .light_line_style(BLACK.mix(0.07))
            .axis_style(BLACK.mix(0.8))
            .label_style(font(m.tick_font))
            .axis_desc_style(font(m.desc_font))
            .y_desc(panel.y_label.clone());
        if last {
            mesh.x_desc(fig.x_label.clone());
        } else {
            mesh.x_label_formatter(&no_labels);
        }
        mesh.draw().map_err(msg)?;

        for (s, ds) in panel.series.iter().zip(&dp.series) {
            draw_series(&mut chart, s, ds, &m)?;
        }
        draw_legend(&chart, panel, dp, &m)?;
    }
    Ok(())
}

type Chart<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<LabelledAxis, LabelledAxis>>;

fn line_style(color: usize, m: &Metrics) -> ShapeStyle {
    ShapeStyle {
        color: rgb(color).to_rgba(),
        filled: false,
        stroke_width: m.line_width,
    }
}

fn draw_series(chart: &mut Chart, s: &Series, ds: &DrawSeries, m: &Metrics) -> Result<(), String> {
    let color = rgb(s.color);
    let style = line_style(s.color, m);
    let dot = |p: (f64, f64), r: i32| Circle::new(p, r, color.filled());
    if matches!(
        s.style,
        Style::Line | Style::LineMarkers | Style::DashedLine
    ) {
        for piece in &ds.pieces {
            if piece.len() == 1 {
                // An isolated point between gaps: show it rather than drop it.
                chart
                    .draw_series(std::iter::once(dot(piece[0], m.line_width as i32)))
                    .map_err(msg)?;
            } else if s.style == Style::DashedLine {
                let dash = 4 * m.line_width as i32 + 2;
                let gap = 2 * m.line_width as i32 + 2;
                chart
                    .draw_series(DashedLineSeries::new(
                        piece.iter().copied(),
                        dash,
                        gap,
                        style,
                    ))
                    .map_err(msg)?;
            } else {
                chart
                    .draw_series(LineSeries::new(piece.iter().copied(), style))
                    .map_err(msg)?;
            }
        }
    }
    if matches!(s.style, Style::Markers | Style::LineMarkers) {
        chart
            .draw_series(ds.points.iter().map(|&p| dot(p, m.marker_radius)))
            .map_err(msg)?;
    }
    Ok(())
}

/// Legend geometry in pixels, relative to the plot area's top-left corner.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LegendBox {
    x: i32,
    y: i32,
    width: i32,
    height: i32,
}

#[derive(Debug, Clone)]
struct LegendLayout {
    font_px: f64,
    columns: usize,
    rows: usize,
    row_h: i32,
    column_w: i32,
    swatch_w: i32,
    pad: i32,
}

impl LegendLayout {
    fn size(&self) -> (i32, i32) {
        (
            self.columns as i32 * self.column_w + self.pad,
            self.rows as i32 * self.row_h + self.pad,
        )
    }
}

/// Largest font and fewest columns for which the legend fits in about half of
/// the plot height and 60 % of its width; falls back to the most compact one.
fn legend_layout(
    chart: &Chart,
    labels: &[&str],
    m: &Metrics,
    plot: (i32, i32),
) -> Result<LegendLayout, String> {
    let mut fallback = None;
    for shrink in [1.0, 0.9, 0.8, 0.72] {
        let font_px = m.legend_font * shrink;
        let mut widest = 0;
        for l in labels {
            let (tw, _) = chart
                .plotting_area()
                .estimate_text_size(l, &font(font_px))
                .map_err(msg)?;
            widest = widest.max(tw as i32);
        }
        let swatch_w = (font_px * 2.2) as i32;
        let pad = (font_px * 0.5) as i32;
        for columns in 1..=3usize {
            let rows = labels.len().div_ceil(columns);
            let layout = LegendLayout {
                font_px,
                columns,
                rows,
                row_h: (font_px * 1.35) as i32,
                column_w: pad + swatch_w + pad + widest + pad,
                swatch_w,
                pad,
            };
            let (lw, lh) = layout.size();
            if f64::from(lw) > 0.6 * f64::from(plot.0) {
                break;
            }
            if f64::from(lh) <= 0.5 * f64::from(plot.1) {
                return Ok(layout);
            }
            fallback = Some(layout);
        }
    }
    let fallback = fallback.unwrap_or_else(|| {
        let font_px = m.legend_font * 0.72;
        LegendLayout {
            font_px,
            columns: 1,
            rows: labels.len(),
            row_h: (font_px * 1.35) as i32,
            column_w: (0.6 * f64::from(plot.0)) as i32,
            swatch_w: (font_px * 2.2) as i32,
            pad: (font_px * 0.5) as i32,
        }
    });
    Ok(fallback)
}

/// Pixel samples of everything drawn in a panel (relative to the plot area),
/// used to place the legend where it hides the least data.
fn data_samples(chart: &Chart, panel: &Panel, dp: &DrawPanel) -> Vec<(i32, i32)> {
    let base = chart.plotting_area().get_base_pixel();
    let px = |p: &(f64, f64)| {
        let (x, y) = chart.backend_coord(p);
        (x - base.0, y - base.1)
    };
    let mut out = Vec::new();
    for (s, ds) in panel.series.iter().zip(&dp.series) {
        out.extend(ds.points.iter().map(px));
        if s.style == Style::Markers {
            continue;
        }
        for piece in &ds.pieces {
            for w in piece.windows(2) {
                let (a, b) = (px(&w[0]), px(&w[1]));
                let len = (b.0 - a.0).abs().max((b.1 - a.1).abs());
                let steps = (len / 3).max(1);
                for k in 0..steps {
                    out.push((a.0 + (b.0 - a.0) * k / steps, a.1 + (b.1 - a.1) * k / steps));
                }
            }
        }
    }
    out
}

/// Picks the legend position (corners first, then edge middles) covering the fewest samples.
fn place_legend(
    size: (i32, i32),
    plot: (i32, i32),
    samples: &[(i32, i32)],
    inset: i32,
) -> LegendBox {
    let (lw, lh) = size;
    let (pw, ph) = plot;
    let (left, right) = (inset, (pw - lw - inset).max(inset));
    let (top, bottom) = (inset, (ph - lh - inset).max(inset));
    let (center_x, center_y) = (((pw - lw) / 2).max(inset), ((ph - lh) / 2).max(inset));
    let candidates = [
        (right, top),
        (left, top),
        (right, bottom),
        (left, bottom),
        (center_x, top),
        (center_x, bottom),
        (right, center_y),
        (left, center_y),
    ];
    let covered = |&(x, y): &(i32, i32)| {
        samples
            .iter()
            .filter(|&&(sx, sy)| sx >= x - 4 && sx <= x + lw + 4 && sy >= y - 4 && sy <= y + lh + 4)
            .count()
    };
    // min_by_key keeps the first of equal candidates, so corners win ties.
    let (x, y) = candidates
        .iter()
        .copied()
        .min_by_key(covered)
        .unwrap_or((right, top));
    LegendBox {
        x,
        y,
        width: lw,
        height: lh,
    }
}

fn draw_legend(chart: &Chart, panel: &Panel, dp: &DrawPanel, m: &Metrics) -> Result<(), String> {
    let entries: Vec<&Series> = panel
        .series
        .iter()
        .filter(|s| !s.label.is_empty())
        .collect();
    if entries.is_empty() {
        return Ok(());
    }
    let labels: Vec<&str> = entries.iter().map(|s| s.label.as_str()).collect();
    let area = chart.plotting_area().strip_coord_spec();
    let (pw, ph) = area.dim_in_pixel();
    let plot = (pw as i32, ph as i32);
    let layout = legend_layout(chart, &labels, m, plot)?;
    let samples = data_samples(chart, panel, dp);
    let b = place_legend(layout.size(), plot, &samples, m.margin / 2 + 2);

    area.draw(&Rectangle::new(
        [(b.x, b.y), (b.x + b.width, b.y + b.height)],
        WHITE.mix(0.85).filled(),
    ))
    .map_err(msg)?;
    area.draw(&Rectangle::new(
        [(b.x, b.y), (b.x + b.width, b.y + b.height)],
        BLACK.mix(0.45).stroke_width(1),
    ))
    .map_err(msg)?;

    let text_style = font(layout.font_px).pos(Pos::new(HPos::Left, VPos::Center));
    for (k, s) in entries.iter().enumerate() {
        let column = (k / layout.rows) as i32;
        let row = (k % layout.rows) as i32;
        let x = b.x + layout.pad + column * layout.column_w;
        let yc = b.y + layout.pad + row * layout.row_h + layout.row_h / 2;
        let x_end = x + layout.swatch_w;
        let style = line_style(s.color, m);
        match s.style {
            Style::Line | Style::LineMarkers => {
                area.draw(&PathElement::new(vec![(x, yc), (x_end, yc)], style))
                    .map_err(msg)?;
            }
            Style::DashedLine => {
                let dash = layout.swatch_w / 4;
                let mut x0 = x;
                while x0 < x_end {
                    let x1 = (x0 + dash).min(x_end);
                    area.draw(&PathElement::new(vec![(x0, yc), (x1, yc)], style))
                        .map_err(msg)?;
                    x0 += dash + dash / 2 + 1;
                }
            }
            Style::Markers => {}
        }
        if matches!(s.style, Style::Markers | Style::LineMarkers) {
            area.draw(&Circle::new(
                ((x + x_end) / 2, yc),
                m.marker_radius,
                rgb(s.color).filled(),
            ))
            .map_err(msg)?;
        }
        // plotters' ab_glyph text sits about a fifth of the font size above its
        // nominal centre; move it down to line up with the swatch.
        let text_y = yc + (layout.font_px * 0.22) as i32;
        area.draw(&Text::new(
            s.label.clone(),
            (x_end + layout.pad, text_y),
            text_style.clone(),
        ))
        .map_err(msg)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const UNIT: [f64; 4] = [0.0, 1.0, 0.0, 1.0];

    #[test]
    fn clip_segment_cuts_at_the_box_edges() {
        let (a, b, sc, ec) = clip_segment((-1.0, 0.5), (2.0, 0.5), UNIT).unwrap();
        assert_eq!((a, b, sc, ec), ((0.0, 0.5), (1.0, 0.5), true, true));
        // Diagonal from inside to above the box leaves through y = 1 at x = 0.75.
        let (a, b, sc, ec) = clip_segment((0.5, 0.5), (1.0, 1.5), UNIT).unwrap();
        assert_eq!((a, sc, ec), ((0.5, 0.5), false, true));
        assert!((b.0 - 0.75).abs() < 1e-12 && (b.1 - 1.0).abs() < 1e-12);
        assert!(clip_segment((2.0, 2.0), (3.0, 0.5), UNIT).is_none());
    }

    #[test]
    fn clip_polyline_splits_where_the_line_leaves_the_box() {
        let run = [(0.1, 0.5), (0.3, 2.0), (0.5, 0.5), (0.7, 0.5)];
        let pieces = clip_polyline(&run, UNIT);
        assert_eq!(pieces.len(), 2, "{pieces:?}");
        assert_eq!(pieces[0].len(), 2);
        assert_eq!(pieces[1].len(), 3);
        assert_eq!(pieces[1][2], (0.7, 0.5));
    }

    #[test]
    fn gaps_break_lines_and_single_points_survive() {
        let s = Series {
            label: String::new(),
            x: vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            y: vec![0.0, 1.0, f64::NAN, 1.0, f64::INFINITY, 2.0, 3.0],
            style: Style::Line,
            color: 0,
        };
        let x = Axis::new(-1.0, 7.0, false);
        let y = Axis::new(-1.0, 4.0, false);
        let parts = visible_parts(&s, &x, &y);
        let lens: Vec<usize> = parts.pieces.iter().map(Vec::len).collect();
        assert_eq!(lens, [2, 1, 2]);
        assert_eq!(parts.points.len(), 5);
    }

    #[test]
    fn legend_avoids_the_corner_with_data() {
        // Data fills the top-right quarter: the legend goes top-left.
        let samples: Vec<(i32, i32)> = (0..50).map(|i| (300 + i * 4, 10 + i)).collect();
        let b = place_legend((100, 60), (500, 300), &samples, 5);
        assert_eq!((b.x, b.y), (5, 5));
        let empty = place_legend((100, 60), (500, 300), &[], 5);
        assert_eq!((empty.x, empty.y), (395, 5));
    }
}

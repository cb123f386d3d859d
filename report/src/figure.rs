//! One [`Figure`] → one SVG document, drawn with plotters' SVG backend.

use crate::{Figure, FigureKind, ReportError, Series, SeriesStyle, DIMENSIONLESS};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Series colours in order, as `#rrggbb`: the Okabe–Ito colour-blind-safe palette (Okabe & Ito 2008,
/// "Color Universal Design"), with its yellow (#F0E442, unreadable on white) replaced by a dark grey.
/// Series 9 and later reuse the colours from the start.
pub const PALETTE_HEX: [&str; 8] =
    ["#0072b2", "#d55e00", "#009e73", "#cc79a7", "#e69f00", "#56b4e9", "#000000", "#6e6e6e"];

const PALETTE: [RGBColor; 8] = [
    RGBColor(0x00, 0x72, 0xb2),
    RGBColor(0xd5, 0x5e, 0x00),
    RGBColor(0x00, 0x9e, 0x73),
    RGBColor(0xcc, 0x79, 0xa7),
    RGBColor(0xe6, 0x9f, 0x00),
    RGBColor(0x56, 0xb4, 0xe9),
    RGBColor(0x00, 0x00, 0x00),
    RGBColor(0x6e, 0x6e, 0x6e),
];

const FONT: &str = "sans-serif";

/// Draws `fig` as a standalone SVG 1.1 document of `width` × `height` pixels (title, axes with
/// `quantity / unit` titles and tick labels, light grid, one colour per series, legend) and returns
/// its text, starting with `<svg` and ending with `</svg>`.
///
/// Axis ranges: linear axes span [min − 5 % span, max + 5 % span] of all series' values; a constant
/// axis (span 0) is padded by ±10 % of |value| (±1 when the value is 0); bar charts always include
/// y = 0. Logarithmic axes (base 10) are widened to whole decades, [10^⌊log₁₀ min⌋, 10^⌈log₁₀ max⌉]
/// (at least one decade), so there is always a labelled tick. A figure without any data point is
/// drawn as an empty frame with the message "no data". The legend goes to the plot corner that
/// covers the fewest data points.
///
/// Errors (never panics): x/y length mismatch, NaN or infinite values, values ≤ 0 on a log axis,
/// size outside 200 × 150 … 10000 × 10000 px.
pub fn figure_svg(fig: &Figure, width: u32, height: u32) -> Result<String, ReportError> {
    render_svg(fig, width, height, true)
}

/// Formats a tick value compactly: `span` is the axis span (same unit), used to choose the number of
/// decimals as ⌈−log₁₀(span/10)⌉ + 1 (one digit finer than a tenth of the span), trailing zeros
/// removed; magnitudes ≥ 10⁶ or < 10⁻⁴ use scientific notation (`2.5e-5`). For log axes pass
/// `span = 0`, which keeps 6 significant digits.
pub fn format_tick(value: f64, span: f64) -> String {
    if !value.is_finite() {
        return format!("{value}");
    }
    let magnitude: f64 = value.abs();
    if magnitude == 0.0 || (span > 0.0 && magnitude < span * 1e-9) {
        return "0".to_string();
    }
    if !(1e-4..1e6).contains(&magnitude) {
        // Significant digits needed to tell ticks spaced span/10 apart, at least 1, at most 10.
        // index: counts of digits, not indices: each is bounded here by min(10), min(15) or clamp(0, 15) (a NaN
        // casts to 0).
        let digits: usize =
            if span > 0.0 { ((magnitude / (span / 10.0)).log10().ceil().max(0.0) as usize + 1).min(10) } else { 6 };
        let text: String = format!("{:.*e}", digits.saturating_sub(1), value);
        return match text.split_once('e') {
            Some((mantissa, exponent)) => format!("{}e{}", trim_zeros(mantissa), exponent),
            None => text,
        };
    }
    let decimals: usize = if span > 0.0 {
        ((-(span / 10.0).log10()).ceil().max(0.0) as usize + 1).min(15)
    } else {
        // Six significant digits.
        (5.0 - magnitude.log10().floor()).clamp(0.0, 15.0) as usize
    };
    trim_zeros(&format!("{:.*}", decimals, value)).to_string()
}

fn trim_zeros(text: &str) -> &str {
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.')
    } else {
        text
    }
}

/// Validated points of one series.
struct Prepared<'a> {
    series: &'a Series,
    points: Vec<(f64, f64)>,
}

fn validate(fig: &Figure) -> Result<Vec<Prepared<'_>>, ReportError> {
    let mut out: Vec<Prepared<'_>> = Vec::with_capacity(fig.series.len());
    for s in &fig.series {
        if s.x.len() != s.y.len() {
            return Err(ReportError::LengthMismatch {
                figure: fig.title.clone(),
                series: s.label.clone(),
                x_len: s.x.len(),
                y_len: s.y.len(),
            });
        }
        for (axis, values, log) in [("x", &s.x, fig.log_x), ("y", &s.y, fig.log_y)] {
            for (index, &value) in values.iter().enumerate() {
                if !value.is_finite() {
                    return Err(ReportError::NonFinite {
                        figure: fig.title.clone(),
                        series: s.label.clone(),
                        axis,
                        index,
                        value,
                    });
                }
                if log && value <= 0.0 {
                    return Err(ReportError::NonPositiveOnLogAxis {
                        figure: fig.title.clone(),
                        series: s.label.clone(),
                        axis,
                        index,
                        value,
                    });
                }
            }
        }
        out.push(Prepared { series: s, points: s.x.iter().copied().zip(s.y.iter().copied()).collect() });
    }
    Ok(out)
}

/// Axis range from data values (see [`figure_svg`] for the rules).
fn axis_range(values: &[f64], log: bool, include_zero: bool) -> (f64, f64) {
    let mut lo: f64 = f64::INFINITY;
    let mut hi: f64 = f64::NEG_INFINITY;
    for &v in values {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if log {
        if !(lo.is_finite() && hi.is_finite()) {
            return (1.0, 10.0);
        }
        let d_lo: f64 = lo.log10().floor();
        let mut d_hi: f64 = hi.log10().ceil();
        if d_hi <= d_lo {
            d_hi = d_lo + 1.0;
        }
        // The 1e-9 relative margin keeps the end decades inside the range despite rounding in
        // powf/ln, so plotters puts a labelled tick on them.
        return (10f64.powf(d_lo) * (1.0 - 1e-9), 10f64.powf(d_hi) * (1.0 + 1e-9));
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    if include_zero {
        lo = lo.min(0.0);
        hi = hi.max(0.0);
    }
    let span: f64 = hi - lo;
    let pad: f64 = if span <= 1e-12 * hi.abs().max(lo.abs()) {
        if hi == 0.0 {
            1.0
        } else {
            0.1 * hi.abs()
        }
    } else {
        0.05 * span
    };
    let lo_out: f64 = if include_zero && lo == 0.0 && span > 0.0 { 0.0 } else { lo - pad };
    let hi_out: f64 = if include_zero && hi == 0.0 && span > 0.0 { 0.0 } else { hi + pad };
    (lo_out, hi_out)
}

/// Maps a value to the axis' linear drawing space (log10 for log axes) and back.
fn to_axis(v: f64, log: bool) -> f64 {
    if log {
        v.log10()
    } else {
        v
    }
}

fn from_axis(t: f64, log: bool) -> f64 {
    if log {
        10f64.powf(t)
    } else {
        t
    }
}

/// The legend glyph of a drawn series (the same mark as in the plot).
#[derive(Clone, Copy)]
enum Glyph {
    /// A filled square (bar charts).
    Bar,
    /// A short vertical bar (error bars).
    ErrorBar,
    /// A filled circle (points, or a line of one point).
    Dot,
    /// A 2 px line.
    Line,
    /// A 2 px line with a circle (line with markers).
    LineDot,
    /// A thin, half-transparent line.
    Faint,
    /// A thin dashed line.
    Band,
    /// A 2 px dashed line.
    Dashed,
}

/// One bar: (x left, x right, y top) in data units.
type Bar = (f64, f64, f64);

/// Bar geometry: total group width 80 % of the smallest gap between distinct x (in axis space),
/// split evenly between the series that have a bar at that x — a bar alone at its x is centred on it
/// and takes the whole width (a ranking drawn as one series per candidate), bars of k series at the
/// same x stand side by side in series order, each 1/k of the width.
fn bars(prepared: &[Prepared<'_>], log_x: bool) -> Vec<Vec<Bar>> {
    let mut centres: Vec<f64> =
        prepared.iter().flat_map(|p| p.points.iter().map(|&(x, _)| to_axis(x, log_x))).collect();
    centres.sort_by(|a, b| a.total_cmp(b));
    centres.dedup();
    let min_gap: f64 = centres.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min);
    let group: f64 = if min_gap.is_finite() && min_gap > 0.0 {
        0.8 * min_gap
    } else if log_x {
        0.3 // a single x on a log axis: 0.3 decade wide
    } else {
        let c: f64 = centres.first().copied().unwrap_or(0.0).abs();
        if c > 0.0 {
            0.16 * c
        } else {
            0.8
        }
    };
    // Does series `k` have a bar at axis position `c`?
    let has = |k: usize, c: f64| prepared[k].points.iter().any(|&(x, _)| to_axis(x, log_x) == c);
    prepared
        .iter()
        .enumerate()
        .map(|(i, p)| {
            p.points
                .iter()
                .map(|&(x, y)| {
                    let c: f64 = to_axis(x, log_x);
                    // Slot j of n: the series before this one with a bar at the same x, of all such series.
                    let j: f64 = (0..i).filter(|&k| has(k, c)).count() as f64;
                    let n: f64 = (0..prepared.len()).filter(|&k| k == i || has(k, c)).count() as f64;
                    let left: f64 = c - group / 2.0 + group * j / n;
                    (from_axis(left, log_x), from_axis(left + group / n, log_x), y)
                })
                .collect()
        })
        .collect()
}

fn axis_title(label: &str, unit: &str) -> String {
    if unit.trim() == DIMENSIONLESS {
        format!("{label} (dimensionless)")
    } else if unit.trim().is_empty() {
        label.to_string()
    } else {
        format!("{label} / {unit}")
    }
}

pub(crate) fn render_svg(fig: &Figure, width: u32, height: u32, draw_title: bool) -> Result<String, ReportError> {
    if !(200..=10_000).contains(&width) || !(150..=10_000).contains(&height) {
        return Err(ReportError::BadSize { width, height });
    }
    let prepared: Vec<Prepared<'_>> = validate(fig)?;
    let bar_geometry: Option<Vec<Vec<Bar>>> =
        if fig.kind == FigureKind::Bar { Some(bars(&prepared, fig.log_x)) } else { None };

    let xs: Vec<f64> = match &bar_geometry {
        Some(b) => b.iter().flatten().flat_map(|&(l, r, _)| [l, r]).collect(),
        None => prepared.iter().flat_map(|p| p.points.iter().map(|&(x, _)| x)).collect(),
    };
    let ys: Vec<f64> = prepared.iter().flat_map(|p| p.points.iter().map(|&(_, y)| y)).collect();
    let x_range: (f64, f64) = axis_range(&xs, fig.log_x, false);
    let mut y_range: (f64, f64) = axis_range(&ys, fig.log_y, fig.kind == FigureKind::Bar && !fig.log_y);
    // Room for the legend: when every corner of the plot would put data under it, the y axis is raised
    // by the legend's height, so that the upper corners are free of data (not for a legend taller than
    // 40 % of the plot, which would squash the data instead). The plot's size is estimated from the
    // margins `Job::draw` sets (12 + 24 px beside, 78 px of y labels; 12 + 12 px above and below, 52 px of
    // x labels, about 40 px of title), a little smaller than drawn, so that the room is enough.
    let plot_w: i32 = width as i32 - 114 - 10;
    let plot_h: i32 = height as i32 - 76 - if draw_title && !fig.title.is_empty() { 40 } else { 0 } - 10;
    let probe = Job { fig, prepared: &prepared, bars: bar_geometry.as_deref(), x_range, y_range, draw_title };
    let (covered, (_, h_frac)) = (probe.legend_corner(plot_w, plot_h).0, probe.legend_size(plot_w, plot_h));
    if covered > 0 && h_frac <= 0.4 && prepared.iter().any(|p| !p.series.label.is_empty()) {
        let (a, b) = (to_axis(y_range.0, fig.log_y), to_axis(y_range.1, fig.log_y));
        y_range.1 = from_axis(a + (b - a) / (1.0 - h_frac), fig.log_y);
    }

    let plot_error = |e: String| ReportError::Plot { figure: fig.title.clone(), message: e };
    let mut buf: String = String::new();
    {
        let root: DrawingArea<SVGBackend<'_>, Shift> =
            SVGBackend::with_string(&mut buf, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_error(e.to_string()))?;
        let job = Job { fig, prepared: &prepared, bars: bar_geometry.as_deref(), x_range, y_range, draw_title };
        match (fig.log_x, fig.log_y) {
            (false, false) => job.draw(&root, x_range.0..x_range.1, y_range.0..y_range.1),
            (true, false) => job.draw(&root, (x_range.0..x_range.1).log_scale(), y_range.0..y_range.1),
            (false, true) => job.draw(&root, x_range.0..x_range.1, (y_range.0..y_range.1).log_scale()),
            (true, true) => job.draw(&root, (x_range.0..x_range.1).log_scale(), (y_range.0..y_range.1).log_scale()),
        }
        .map_err(plot_error)?;
        root.present().map_err(|e| plot_error(e.to_string()))?;
    }
    Ok(buf)
}

struct Job<'a> {
    fig: &'a Figure,
    prepared: &'a [Prepared<'a>],
    bars: Option<&'a [Vec<Bar>]>,
    x_range: (f64, f64),
    y_range: (f64, f64),
    draw_title: bool,
}

impl Job<'_> {
    fn draw<XR, YR>(&self, root: &DrawingArea<SVGBackend<'_>, Shift>, x_spec: XR, y_spec: YR) -> Result<(), String>
    where
        XR: AsRangedCoord<Value = f64>,
        YR: AsRangedCoord<Value = f64>,
        XR::CoordDescType: ValueFormatter<f64>,
        YR::CoordDescType: ValueFormatter<f64>,
    {
        let fig: &Figure = self.fig;
        let mut builder = ChartBuilder::on(root);
        builder.margin(12).margin_right(24).x_label_area_size(52).y_label_area_size(78);
        if self.draw_title && !fig.title.is_empty() {
            builder.caption(&fig.title, (FONT, 24));
        }
        let mut chart = builder.build_cartesian_2d(x_spec, y_spec).map_err(|e| e.to_string())?;

        let x_span: f64 = if fig.log_x { 0.0 } else { self.x_range.1 - self.x_range.0 };
        let y_span: f64 = if fig.log_y { 0.0 } else { self.y_range.1 - self.y_range.0 };
        // An integer x axis (iterations, ranks, approach directions): every x value a whole number
        // spanning at most 20, on a linear axis. Its ticks are whole numbers only: at most one tick per
        // integer is asked for, and a fractional tick, should one still be chosen, stays unlabelled.
        let xs = || self.prepared.iter().flat_map(|p| p.points.iter().map(|&(x, _)| x));
        let (x_min, x_max) = xs().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
        let integer_x: bool =
            !fig.log_x && xs().next().is_some() && xs().all(|x| x.fract() == 0.0) && x_max - x_min <= 20.0;
        let x_fmt = move |v: &f64| {
            if integer_x && (v - v.round()).abs() > 1e-9 * x_span.max(1.0) {
                String::new()
            } else {
                format_tick(*v, x_span)
            }
        };
        // Bar charts: about one x tick per bar group, so categories 1, 2, 3 are not labelled 1.5, 2.5.
        let x_labels: usize = match (self.bars, integer_x) {
            (Some(_), _) => {
                let mut centres: Vec<f64> = xs().collect();
                centres.sort_by(|a, b| a.total_cmp(b));
                centres.dedup();
                (centres.len() + 1).clamp(2, 9)
            }
            // One tick per integer of the data at most (iterations 0, 1, 2 → three ticks).
            // index: a tick count, not an index: `as usize` saturates (a NaN span gives 0) and clamp(2, 9) bounds it.
            (None, true) => ((x_max - x_min) as usize + 1).clamp(2, 9),
            (None, false) => 9,
        };
        let y_fmt = move |v: &f64| format_tick(*v, y_span);
        chart
            .configure_mesh()
            .x_desc(axis_title(&fig.x_label, &fig.x_unit))
            .y_desc(axis_title(&fig.y_label, &fig.y_unit))
            .x_label_formatter(&x_fmt)
            .y_label_formatter(&y_fmt)
            .x_labels(x_labels)
            .y_labels(8)
            .max_light_lines(if fig.log_x || fig.log_y { 9 } else { 4 })
            .axis_desc_style((FONT, 19))
            .label_style((FONT, 16))
            .bold_line_style(RGBColor(0xd0, 0xd4, 0xda))
            .light_line_style(RGBColor(0xee, 0xf0, 0xf3))
            .axis_style(RGBColor(0x30, 0x30, 0x30))
            .draw()
            .map_err(|e| e.to_string())?;

        let mut labelled: bool = false;
        // Palette index: one colour per main series; Faint/Band/ErrorBars series share the colour of the
        // main series before them.
        let mut main_index: usize = 0;
        for (i, p) in self.prepared.iter().enumerate() {
            let colour_index: usize = match fig.kind {
                FigureKind::Line if !p.series.style.is_main() => main_index.saturating_sub(1),
                FigureKind::Line => {
                    main_index += 1;
                    main_index - 1
                }
                FigureKind::Scatter | FigureKind::Bar => i,
            };
            if p.points.is_empty() {
                continue;
            }
            let colour: RGBColor = PALETTE[colour_index % PALETTE.len()];
            let label: &str = &p.series.label;
            let style: SeriesStyle = match fig.kind {
                FigureKind::Line => p.series.style,
                FigureKind::Scatter => SeriesStyle::Points,
                FigureKind::Bar => SeriesStyle::Line, // unused below
            };
            let points = p.points.iter().copied();
            // Each series is drawn first; its legend entry (glyph and label) is attached only when it
            // has a label: plotters lists every series with a glyph, so an unlabelled series (each run
            // behind an ISO 230-2 mean) would otherwise leave an empty legend row.
            let (anno, glyph) = if let (FigureKind::Bar, Some(bars)) = (fig.kind, self.bars) {
                let base: f64 = if fig.log_y { self.y_range.0 } else { 0.0 };
                let anno = chart
                    .draw_series(
                        bars[i].iter().map(|&(l, r, y)| Rectangle::new([(l, base), (r, y)], colour.mix(0.85).filled())),
                    )
                    .map_err(|e| e.to_string())?;
                (anno, Glyph::Bar)
            } else {
                match style {
                    SeriesStyle::ErrorBars => {
                        let pairs: Vec<(f64, f64, f64)> =
                            p.points.chunks_exact(2).map(|w| (w[0].0, w[0].1, w[1].1)).collect();
                        let anno = chart
                            .draw_series(pairs.into_iter().map(|(x, y1, y2)| {
                                ErrorBar::new_vertical(
                                    x,
                                    y1.min(y2),
                                    (y1 + y2) / 2.0,
                                    y1.max(y2),
                                    colour.stroke_width(1),
                                    8,
                                )
                            }))
                            .map_err(|e| e.to_string())?;
                        (anno, Glyph::ErrorBar)
                    }
                    SeriesStyle::Points => (
                        chart
                            .draw_series(points.map(|pt| Circle::new(pt, 3, colour.filled())))
                            .map_err(|e| e.to_string())?,
                        Glyph::Dot,
                    ),
                    _ if p.points.len() == 1 => (
                        chart
                            .draw_series(points.map(|pt| Circle::new(pt, 3, colour.filled())))
                            .map_err(|e| e.to_string())?,
                        Glyph::Dot,
                    ),
                    SeriesStyle::Line => (
                        chart
                            .draw_series(LineSeries::new(points, colour.stroke_width(2)))
                            .map_err(|e| e.to_string())?,
                        Glyph::Line,
                    ),
                    SeriesStyle::LinePoints => {
                        chart
                            .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
                            .map_err(|e| e.to_string())?;
                        (
                            chart
                                .draw_series(points.map(|pt| Circle::new(pt, 4, colour.filled())))
                                .map_err(|e| e.to_string())?,
                            Glyph::LineDot,
                        )
                    }
                    SeriesStyle::Faint => (
                        chart
                            .draw_series(LineSeries::new(points, colour.mix(0.45).stroke_width(1)))
                            .map_err(|e| e.to_string())?,
                        Glyph::Faint,
                    ),
                    SeriesStyle::Band => (
                        chart
                            .draw_series(DashedLineSeries::new(points, 5, 4, colour.stroke_width(1)))
                            .map_err(|e| e.to_string())?,
                        Glyph::Band,
                    ),
                    SeriesStyle::Dashed => (
                        chart
                            .draw_series(DashedLineSeries::new(points, 8, 5, colour.stroke_width(2)))
                            .map_err(|e| e.to_string())?,
                        Glyph::Dashed,
                    ),
                }
            };
            if !label.is_empty() {
                match glyph {
                    Glyph::Bar => {
                        anno.legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], colour.filled()))
                    }
                    Glyph::ErrorBar => anno.legend(move |(x, y)| {
                        PathElement::new(vec![(x + 9, y - 6), (x + 9, y + 6)], colour.stroke_width(1))
                    }),
                    Glyph::Dot => anno.legend(move |(x, y)| Circle::new((x + 9, y), 3, colour.filled())),
                    Glyph::Line => {
                        anno.legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], colour.stroke_width(2)))
                    }
                    Glyph::LineDot => anno.legend(move |(x, y)| {
                        EmptyElement::at((x, y))
                            + PathElement::new(vec![(0, 0), (22, 0)], colour.stroke_width(2))
                            + Circle::new((11, 0), 4, colour.filled())
                    }),
                    Glyph::Faint => anno.legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 22, y)], colour.mix(0.45).stroke_width(1))
                    }),
                    Glyph::Band => anno.legend(move |(x, y)| {
                        DashedPathElement::new(vec![(x, y), (x + 24, y)], 5, 4, colour.stroke_width(1))
                    }),
                    Glyph::Dashed => anno.legend(move |(x, y)| {
                        DashedPathElement::new(vec![(x, y), (x + 24, y)], 7, 4, colour.stroke_width(2))
                    }),
                }
                .label(label);
                labelled = true;
            }
        }

        let (px0, px1) = chart.plotting_area().get_pixel_range();
        if self.prepared.iter().all(|p| p.points.is_empty()) {
            let centre: (i32, i32) = ((px0.start + px0.end) / 2, (px1.start + px1.end) / 2);
            let style = TextStyle::from((FONT, 20))
                .color(&RGBColor(0x80, 0x80, 0x80))
                .pos(Pos::new(HPos::Center, VPos::Center));
            root.draw(&Text::new("no data", centre, style)).map_err(|e| e.to_string())?;
        }

        if labelled {
            let position: SeriesLabelPosition = self.legend_corner(px0.end - px0.start, px1.end - px1.start).1;
            chart
                .configure_series_labels()
                .position(position)
                .label_font((FONT, 16))
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(0xb0, 0xb0, 0xb0))
                .margin(10)
                .draw()
                .map_err(|e| e.to_string())?;
        }
        Ok(())
    }

    /// The legend's size as fractions (width, height) of a `plot_w` × `plot_h` px plotting area: ~8 px per
    /// character at the 16-unit legend font, sample + margins 50 px wide, 20 px per entry + 20 px high.
    fn legend_size(&self, plot_w: i32, plot_h: i32) -> (f64, f64) {
        let n_labels: usize = self.prepared.iter().filter(|p| !p.series.label.is_empty()).count();
        let max_chars: usize = self.prepared.iter().map(|p| p.series.label.chars().count()).max().unwrap_or(0);
        let w_frac: f64 = ((max_chars as f64 * 8.0 + 50.0) / plot_w.max(1) as f64).min(1.0);
        let h_frac: f64 = ((n_labels as f64 * 20.0 + 20.0) / plot_h.max(1) as f64).min(1.0);
        (w_frac, h_frac)
    }

    /// Corner whose legend-sized box ([`Job::legend_size`]) contains the fewest data points (ties: upper
    /// right first), with that number of points.
    fn legend_corner(&self, plot_w: i32, plot_h: i32) -> (usize, SeriesLabelPosition) {
        let fig: &Figure = self.fig;
        let (w_frac, h_frac) = self.legend_size(plot_w, plot_h);
        let norm = |v: f64, range: (f64, f64), log: bool| -> f64 {
            let (a, b) = (to_axis(range.0, log), to_axis(range.1, log));
            (to_axis(v, log) - a) / (b - a)
        };
        let corners: [(SeriesLabelPosition, bool, bool); 4] = [
            (SeriesLabelPosition::UpperRight, true, true),
            (SeriesLabelPosition::UpperLeft, false, true),
            (SeriesLabelPosition::LowerRight, true, false),
            (SeriesLabelPosition::LowerLeft, false, false),
        ];
        let mut best: (usize, SeriesLabelPosition) = (usize::MAX, SeriesLabelPosition::UpperRight);
        for (position, right, upper) in corners {
            let mut count: usize = 0;
            for p in self.prepared {
                for &(x, y) in &p.points {
                    let u: f64 = norm(x, self.x_range, fig.log_x);
                    let v: f64 = norm(y, self.y_range, fig.log_y);
                    let in_x: bool = if right { u >= 1.0 - w_frac } else { u <= w_frac };
                    let in_y: bool = if upper { v >= 1.0 - h_frac } else { v <= h_frac };
                    if in_x && in_y {
                        count += 1;
                    }
                }
            }
            if count < best.0 {
                best = (count, position);
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_format_hand_worked() {
        // Span 2 → ticks 0.2 apart → ⌈−log10(0.2)⌉ + 1 = 2 decimals, zeros trimmed.
        assert_eq!(format_tick(0.30000000000000004, 2.0), "0.3");
        assert_eq!(format_tick(1.25, 2.0), "1.25");
        assert_eq!(format_tick(-40.0, 100.0), "-40");
        assert_eq!(format_tick(0.0, 1.0), "0");
        // Rounding noise around zero (1e-17 on a span of 1) prints as 0, not 1e-17.
        assert_eq!(format_tick(1e-17, 1.0), "0");
        assert_eq!(format_tick(2.5e-5, 0.0), "2.5e-5");
        assert_eq!(format_tick(3.0000000000000004e-5, 1e-4), "3e-5");
        assert_eq!(format_tick(2.0e7, 0.0), "2e7");
        // Log axis (span 0): 6 significant digits.
        assert_eq!(format_tick(0.0009999999999999998, 0.0), "0.001");
        assert_eq!(format_tick(300.0, 0.0), "300");
    }

    #[test]
    fn ranges_hand_worked() {
        // 5 % padding of span 10.
        assert_eq!(axis_range(&[0.0, 10.0], false, false), (-0.5, 10.5));
        // Constant 5: ±10 % of 5.
        assert_eq!(axis_range(&[5.0, 5.0], false, false), (4.5, 5.5));
        // Constant 0: ±1.
        assert_eq!(axis_range(&[0.0], false, false), (-1.0, 1.0));
        // Bars: zero included, no padding below the baseline.
        assert_eq!(axis_range(&[2.0, 4.0], false, true), (0.0, 4.2));
        // Log: whole decades 0.01 … 1000 (to 1e-9 relative).
        let (lo, hi) = axis_range(&[0.05, 300.0], true, false);
        assert!((lo / 0.01 - 1.0).abs() < 1e-8 && (hi / 1000.0 - 1.0).abs() < 1e-8, "{lo} {hi}");
        // Log, one value: one decade.
        let (lo, hi) = axis_range(&[3.0], true, false);
        assert!((lo - 1.0).abs() < 1e-8 && (hi - 10.0).abs() < 1e-7, "{lo} {hi}");
        // No data.
        assert_eq!(axis_range(&[], false, false), (0.0, 1.0));
    }

    fn series(label: &str, x: &[f64], y: &[f64], style: SeriesStyle) -> Series {
        Series { label: label.into(), x: x.to_vec(), y: y.to_vec(), style }
    }

    fn line_figure(series: Vec<Series>, kind: FigureKind) -> Figure {
        Figure {
            title: "t".into(),
            x_label: "x".into(),
            x_unit: "mm".into(),
            y_label: "y".into(),
            y_unit: "µm".into(),
            series,
            kind,
            log_x: false,
            log_y: false,
        }
    }

    /// Heights of the legend boxes (the rects with the legend's #B0B0B0 border) of an SVG.
    fn legend_heights(svg: &str) -> Vec<String> {
        svg.split("<rect")
            .skip(1)
            .filter(|r| r.split('>').next().is_some_and(|a| a.to_ascii_uppercase().contains("#B0B0B0")))
            .filter_map(|r| r.split("height=\"").nth(1).and_then(|h| h.split('"').next()).map(String::from))
            .collect()
    }

    /// An unlabelled series (each run behind an ISO 230-2 mean) adds no row to the legend: the legend
    /// of a mean with four unlabelled runs is as tall as that of the mean alone (plotters gave each
    /// unlabelled series an empty row with its glyph: eight blank rows in the ISO figure).
    #[test]
    fn unlabelled_series_take_no_legend_row() {
        let x = [0.0, 100.0, 200.0];
        let mean = series("mean", &x, &[1.0, 2.0, 1.5], SeriesStyle::LinePoints);
        let runs: Vec<Series> =
            (0..4).map(|k| series("", &x, &[1.0 + 0.01 * k as f64, 2.0, 1.5], SeriesStyle::Faint)).collect();
        let alone = figure_svg(&line_figure(vec![mean.clone()], FigureKind::Line), 800, 500).unwrap();
        let with_runs =
            figure_svg(&line_figure(std::iter::once(mean).chain(runs).collect(), FigureKind::Line), 800, 500).unwrap();
        let (a, b) = (legend_heights(&alone), legend_heights(&with_runs));
        assert_eq!(a.len(), 1, "one legend box expected: {a:?}");
        assert_eq!(a, b, "the unlabelled runs changed the legend's height");
    }

    /// The box of the legend (x, y, width, height in px) of an SVG: the rect with the legend's border.
    fn legend_box(svg: &str) -> (f64, f64, f64, f64) {
        let rect = svg
            .split("<rect")
            .skip(1)
            .find(|r| r.split('>').next().is_some_and(|a| a.to_ascii_uppercase().contains("#B0B0B0")))
            .expect("a legend box");
        let attr = |name: &str| -> f64 {
            rect.split(&format!(" {name}=\"")).nth(1).and_then(|v| v.split('"').next()).unwrap().parse().unwrap()
        };
        (attr("x"), attr("y"), attr("width"), attr("height"))
    }

    /// A legend covers no data: a zigzag that fills every corner of the plot (each corner would hide
    /// data under the legend) raises the y axis by the legend's height, and no vertex of the line lies
    /// inside the legend's box; the line's top still reaches the upper part of the plot (the room added
    /// is the legend's, not more).
    #[test]
    fn a_legend_covers_no_data() {
        let x: Vec<f64> = (0..200).map(f64::from).collect();
        let y: Vec<f64> = (0..200).map(|i| if i % 2 == 0 { 1.0 } else { -1.0 }).collect();
        let fig =
            line_figure(vec![series("a zigzag that fills every corner", &x, &y, SeriesStyle::Line)], FigureKind::Line);
        let svg = figure_svg(&fig, 860, 480).unwrap();
        let (bx, by, bw, bh) = legend_box(&svg);
        // The series' line: the polyline with the most vertices (grid and axes are 2-point lines).
        let points: Vec<(f64, f64)> = svg
            .split("<polyline")
            .skip(1)
            .filter_map(|l| l.split("points=\"").nth(1).and_then(|p| p.split('"').next()))
            .map(|p| {
                p.split_whitespace()
                    .map(|xy| {
                        let (a, b) = xy.split_once(',').unwrap();
                        (a.parse().unwrap(), b.parse().unwrap())
                    })
                    .collect::<Vec<(f64, f64)>>()
            })
            .max_by_key(Vec::len)
            .expect("the series' line");
        assert_eq!(points.len(), 200);
        let inside = points.iter().filter(|&&(px, py)| px >= bx && px <= bx + bw && py >= by && py <= by + bh).count();
        assert_eq!(inside, 0, "{inside} points under the legend box ({bx}, {by}, {bw} × {bh})");
        // The top of the zigzag lies within a legend's height (plus the 5 % padding) of the top of the box.
        let top = points.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        assert!(top > by + bh && top < by + 2.0 * bh + 40.0, "top of the data at {top} px, legend {by}–{}", by + bh);
    }

    /// A bar alone at its x is centred on it with the whole group width (a ranking, one series per
    /// candidate); two series at the same x stand side by side.
    #[test]
    fn bars_are_grouped_only_where_series_share_an_x() {
        let (a, b, c) = (
            series("a", &[1.0], &[5.0], SeriesStyle::Points),
            series("b", &[2.0], &[3.0], SeriesStyle::Points),
            series("c", &[3.0], &[1.0], SeriesStyle::Points),
        );
        let prepared: Vec<Prepared<'_>> =
            [&a, &b, &c].iter().map(|s| Prepared { series: s, points: vec![(s.x[0], s.y[0])] }).collect();
        for (k, bars) in bars(&prepared, false).iter().enumerate() {
            let (l, r, _) = bars[0];
            assert!(((l + r) / 2.0 - (k + 1) as f64).abs() < 1e-12, "bar {k} centred at {}", (l + r) / 2.0);
            assert!((r - l - 0.8).abs() < 1e-12, "bar {k} width {}", r - l);
        }
        let (d, e) = (
            series("d", &[-1.0, 1.0], &[1.0, 2.0], SeriesStyle::Points),
            series("e", &[-1.0, 1.0], &[3.0, 4.0], SeriesStyle::Points),
        );
        let prepared: Vec<Prepared<'_>> = [&d, &e]
            .iter()
            .map(|s| Prepared { series: s, points: s.x.iter().copied().zip(s.y.iter().copied()).collect() })
            .collect();
        let g = bars(&prepared, false);
        // Gap 2 → group 1.6, two slots of 0.8: d on [−1.8, −1.0], e on [−1.0, −0.2].
        assert!((g[0][0].0 + 1.8).abs() < 1e-12 && (g[0][0].1 + 1.0).abs() < 1e-12, "{:?}", g[0][0]);
        assert!((g[1][0].0 + 1.0).abs() < 1e-12 && (g[1][0].1 + 0.2).abs() < 1e-12, "{:?}", g[1][0]);
    }

    /// Iterations 0, 1, 2 are labelled 0, 1, 2 — never 0.5 or 1.5 (the SVG writes each label on its own
    /// line inside `<text>`).
    #[test]
    fn an_integer_axis_has_integer_ticks_only() {
        let fig = line_figure(
            vec![series("NRMS", &[0.0, 1.0, 2.0], &[40.0, 20.0, 10.0], SeriesStyle::LinePoints)],
            FigureKind::Line,
        );
        let svg = figure_svg(&fig, 800, 500).unwrap();
        for t in ["0", "1", "2"] {
            assert!(svg.contains(&format!(">\n{t}\n</text>")), "tick {t} missing");
        }
        for t in ["0.5", "1.5", "0.2", "0.25"] {
            assert!(!svg.contains(&format!(">\n{t}\n</text>")), "fractional tick {t} on an integer axis");
        }
        // A position axis keeps its fractional ticks.
        let fig = line_figure(
            vec![series("p", &[0.0, 0.5, 1.0], &[40.0, 20.0, 10.0], SeriesStyle::LinePoints)],
            FigureKind::Line,
        );
        let svg = figure_svg(&fig, 800, 500).unwrap();
        assert!(["0.2", "0.25", "0.5"].iter().any(|t| svg.contains(&format!(">\n{t}\n</text>"))), "no fractional tick");
    }
}

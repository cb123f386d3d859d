//! Self-contained HTML reports for `vmt run` (issue 7).
//!
//! A report is described by plain data ([`Report`] → [`Section`] → [`Figure`] / [`Table`]) that can be
//! built by any command and serialised to JSON. [`render_html`] turns it into ONE HTML5 page
//! (WHATWG HTML Living Standard) with inline CSS and every figure inlined as an SVG 1.1 `<svg>` element
//! drawn with `plotters` ([`figure_svg`]): no scripts, no external resources, nothing fetched from a
//! network, so the file can be mailed, archived and printed as it is. [`write_atomic`] writes it so that
//! a reader never sees a half-written file.
//!
//! Units: figures and tables carry numbers exactly as the caller gives them. The caller chooses the
//! display unit (e.g. converts metres to micrometres) and names it in [`Figure::x_unit`] /
//! [`Figure::y_unit`]; axis titles are printed as `quantity / unit` (ISO 80000-1 §7.1, value of a
//! quantity = number × unit).
#![deny(missing_docs)]

mod figure;
mod html;
mod io;
mod lint;

pub use figure::{figure_svg, format_tick, PALETTE_HEX};
pub use html::{escape_html, render_html};
pub use io::write_atomic;
pub use lint::lint;

/// The unit of a dimensionless quantity (ratio, index) in [`Figure::x_unit`] / [`Figure::y_unit`]: ISO
/// 80000-1 writes it as 1; the axis title then reads `quantity (dimensionless)`.
pub const DIMENSIONLESS: &str = "1";

use serde::{Deserialize, Serialize};

/// A whole report: one HTML page with a title, an optional subtitle and numbered sections.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Page title (shown as the `<h1>` and in the browser tab). Plain text; it is HTML-escaped.
    pub title: String,
    /// One line under the title (scenario name, date, version...). Plain text; empty means none.
    #[serde(default)]
    pub subtitle: String,
    /// The sections in reading order; each gets an entry in the table of contents.
    pub sections: Vec<Section>,
}

/// One numbered section: a heading, plain-text paragraphs, then its tables, then its figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Section {
    /// Section heading (plain text, escaped).
    pub heading: String,
    /// Plain-text paragraphs, one entry per paragraph (escaped; no markup is interpreted).
    #[serde(default)]
    pub text: Vec<String>,
    /// Figures, numbered through the whole report ("Figure 1", "Figure 2", ...).
    #[serde(default)]
    pub figures: Vec<Figure>,
    /// Tables, numbered through the whole report ("Table 1", ...).
    #[serde(default)]
    pub tables: Vec<Table>,
}

/// How a figure draws its series.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FigureKind {
    /// Each series is drawn in its own [`SeriesStyle`] (line, points or dashed line).
    Line,
    /// Every series is drawn as points, whatever its style.
    Scatter,
    /// Every series is drawn as bars from the baseline (y = 0, or the bottom of a log axis) to y;
    /// several series are grouped side by side around each x.
    Bar,
}

/// How one series is drawn in a [`FigureKind::Line`] figure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SeriesStyle {
    /// Solid line through the points in the given order (a single point is drawn as a marker).
    Line,
    /// Markers only (filled circles, 3 px radius).
    Points,
    /// Dashed line (8 px dashes, 5 px gaps): use it for a reference such as the injected truth.
    Dashed,
    /// Solid line with a marker at every data point: use it where the points are the data (a study's
    /// values, iterations) and the line only guides the eye.
    LinePoints,
    /// Thin (1 px), half-transparent line in the colour of the nearest preceding series that is not
    /// `Faint`, `Band` or `ErrorBars`: the individual runs behind a mean.
    Faint,
    /// Thin dashed line in the colour of the nearest preceding main series: an envelope such as the
    /// mean ± 2s of ISO 230-2.
    Band,
    /// Vertical error bars in the colour of the nearest preceding main series: each consecutive pair of
    /// points (x, y₁), (x, y₂) is one bar from y₁ to y₂ with 8 px caps, e.g. value ± σ.
    ErrorBars,
}

impl SeriesStyle {
    /// True for styles drawn in their own palette colour; false for those that take the colour of the
    /// preceding main series ([`SeriesStyle::Faint`], [`SeriesStyle::Band`], [`SeriesStyle::ErrorBars`]).
    pub fn is_main(self) -> bool {
        match self {
            SeriesStyle::Line | SeriesStyle::Points | SeriesStyle::Dashed | SeriesStyle::LinePoints => true,
            SeriesStyle::Faint | SeriesStyle::Band | SeriesStyle::ErrorBars => false,
        }
    }
}

/// One data series: matching x and y values with a legend label.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Series {
    /// Legend text (escaped by the SVG backend). An empty label keeps the series out of the legend.
    pub label: String,
    /// Abscissae, in the unit named by [`Figure::x_unit`]. Must be finite; same length as `y`.
    pub x: Vec<f64>,
    /// Ordinates, in the unit named by [`Figure::y_unit`]. Must be finite; same length as `x`.
    pub y: Vec<f64>,
    /// Drawing style (used by [`FigureKind::Line`] figures).
    pub style: SeriesStyle,
}

/// One 2-D plot. Axis ranges are chosen automatically from the data (see [`figure_svg`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Figure {
    /// Figure title (drawn above the plot by [`figure_svg`], used as caption by [`render_html`]).
    pub title: String,
    /// Name of the x quantity, e.g. "position".
    pub x_label: String,
    /// Unit of x, e.g. "mm"; printed as "position / mm". Empty for a dimensionless quantity.
    #[serde(default)]
    pub x_unit: String,
    /// Name of the y quantity, e.g. "EXX".
    pub y_label: String,
    /// Unit of y, e.g. "µm".
    #[serde(default)]
    pub y_unit: String,
    /// The data; colours follow [`PALETTE_HEX`] in order (cycling after 8 series).
    pub series: Vec<Series>,
    /// Line, scatter or bar chart.
    pub kind: FigureKind,
    /// Logarithmic (base 10) x axis; every x value must then be > 0.
    #[serde(default)]
    pub log_x: bool,
    /// Logarithmic (base 10) y axis; every y value must then be > 0.
    #[serde(default)]
    pub log_y: bool,
}

/// Verdict of one table row, shown as the row's background (green pass, red fail).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum RowStatus {
    /// The row's check passed: green background.
    Pass,
    /// The row's check failed: red background.
    Fail,
    /// No verdict: plain row.
    #[default]
    Neutral,
}

/// A table of text cells with an optional pass/fail verdict per row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Table {
    /// Caption printed above the table (escaped).
    pub caption: String,
    /// Column headings. Every row must have exactly this many cells (when the header is not empty).
    pub header: Vec<String>,
    /// Cells as already-formatted text (escaped). Cells that parse as a number are right-aligned.
    pub rows: Vec<Vec<String>>,
    /// One status per row, or empty for all [`RowStatus::Neutral`].
    #[serde(default)]
    pub highlight: Vec<RowStatus>,
}

/// Everything that can go wrong while building a report. Messages say what was expected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReportError {
    /// x and y of a series differ in length.
    #[error(
        "figure \"{figure}\": series \"{series}\" has {x_len} x values but {y_len} y values; they must be equally long"
    )]
    LengthMismatch {
        /// Figure title.
        figure: String,
        /// Series label.
        series: String,
        /// Number of x values.
        x_len: usize,
        /// Number of y values.
        y_len: usize,
    },
    /// A NaN or infinite value.
    #[error(
        "figure \"{figure}\": series \"{series}\" has {axis}[{index}] = {value}; only finite numbers can be plotted"
    )]
    NonFinite {
        /// Figure title.
        figure: String,
        /// Series label.
        series: String,
        /// "x" or "y".
        axis: &'static str,
        /// Index of the offending value.
        index: usize,
        /// The value (NaN or ±inf).
        value: f64,
    },
    /// Zero or a negative value on a logarithmic axis.
    #[error("figure \"{figure}\": the {axis} axis is logarithmic, so every {axis} value must be > 0, but series \"{series}\" has {axis}[{index}] = {value}")]
    NonPositiveOnLogAxis {
        /// Figure title.
        figure: String,
        /// Series label.
        series: String,
        /// "x" or "y".
        axis: &'static str,
        /// Index of the offending value.
        index: usize,
        /// The value (≤ 0).
        value: f64,
    },
    /// Requested SVG size out of the supported range.
    #[error("figure size must be between 200 x 150 and 10000 x 10000 pixels, got {width} x {height}")]
    BadSize {
        /// Requested width in pixels.
        width: u32,
        /// Requested height in pixels.
        height: u32,
    },
    /// A table row with the wrong number of cells.
    #[error("table \"{caption}\": row {row} has {got} cells but the header has {expected} columns")]
    RaggedTable {
        /// Table caption.
        caption: String,
        /// Row index (0-based).
        row: usize,
        /// Cells in that row.
        got: usize,
        /// Header length.
        expected: usize,
    },
    /// `highlight` neither empty nor one entry per row.
    #[error("table \"{caption}\": highlight has {got} entries but the table has {rows} rows; give one status per row or none")]
    HighlightMismatch {
        /// Table caption.
        caption: String,
        /// Number of highlight entries.
        got: usize,
        /// Number of rows.
        rows: usize,
    },
    /// The plotting library reported an error (should not happen with validated data).
    #[error("drawing figure \"{figure}\" failed: {message}")]
    Plot {
        /// Figure title.
        figure: String,
        /// The library's message.
        message: String,
    },
    /// A file-system error while writing the report.
    #[error("could not write {path}: {message}")]
    Io {
        /// Path being written.
        path: String,
        /// The operating system's message.
        message: String,
    },
}

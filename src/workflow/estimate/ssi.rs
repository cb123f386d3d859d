//! Seed 002's stick-slip index (DESIGN.md §7): SSI = (v_max − v_min)/v_mean of the differentiated encoder.
//! The adapter of `vmt run`'s crawl check and the glue `vmt ssi` shares ([`run_ssi`]).

use super::{Check, Quantity, Statistic, TruthView};
use crate::error::VmtError;
use crate::measurement::{uniform_interval, MeasurementSet, RunData, SampleIntervalError};
use std::path::Path;
use vmt_estimators::ssi::{stick_slip_index, SsiError, SsiResult};
use vmt_report::{Figure, FigureKind, Series, SeriesStyle};

/// The stick-slip index of a position record `x` (m) sampled at the time stamps `t` (s, uniform), with
/// the encoder's quantisation step `resolution` (m) for the floor 2q/(Ts·v) where known: returns the
/// sample interval Ts (s) and the result. The one path from a time series to the estimator, for `vmt run`
/// and `vmt ssi`; errors (a non-uniform or too short `t`, a record the index is not defined on) are the
/// caller's to place.
pub fn run_ssi(t: &[f64], x: &[f64], resolution: Option<f64>) -> Result<(f64, SsiResult), RunSsiError> {
    let dt = uniform_interval(t)?;
    let res = stick_slip_index(x, dt, resolution)?;
    Ok((dt, res))
}

/// Why [`run_ssi`] has no index: the time column, or the record itself.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RunSsiError {
    /// `t` is too short or not uniformly sampled.
    #[error(transparent)]
    Interval(#[from] SampleIntervalError),
    /// The index is not defined on the record.
    #[error(transparent)]
    Index(#[from] SsiError),
}

/// The crawl check: the SSI of `sensor` in every run of `procedure` (named `{procedure}_*`, one per feed)
/// against the patent's example values `expected` within `tolerance` (dimensionless), each with a figure
/// of the differentiated velocity against the commanded feed and a zoom — where the axis crawls, on four
/// stick-slip cycles, else on the first samples, where single readings can be told apart.
pub(super) fn ssi_checks(
    source: &Path,
    set: &MeasurementSet,
    truth: &TruthView<'_>,
    procedure: &str,
    sensor: &str,
    expected: &[f64],
    tolerance: &[f64],
) -> Result<Vec<(Check, Figure, Option<Figure>)>, VmtError> {
    let bad = |m: String| VmtError::bad(source, format!("estimators (ssi {procedure})"), m);
    let crawl = truth.runs_of(set, procedure);
    if crawl.len() != expected.len() || expected.len() != tolerance.len() {
        return Err(bad(format!(
            "{} runs but {} expected values and {} tolerances",
            crawl.len(),
            expected.len(),
            tolerance.len()
        )));
    }
    let q = truth.sensor(sensor).map(|s| s.resolution).filter(|&q| q > 0.0);
    let mut out = Vec::new();
    for ((r, e), tol) in crawl.iter().zip(expected).zip(tolerance) {
        let RunData::TimeSeries { t, .. } = &r.data else { return Err(bad("expected time series".into())) };
        let x = r.data.column(sensor).ok_or_else(|| bad(format!("run `{}` has no `{sensor}`", r.name)))?;
        let (dt, res) = run_ssi(t, x, q).map_err(|m| bad(format!("run `{}`: {m}", r.name)))?;
        let feed = r.feed.unwrap_or(0.0) * 60_000.0;
        let v: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]) / dt * 60_000.0).collect();
        let tv = &t[1..];
        let view = |title: String, range: std::ops::Range<usize>| Figure {
            title,
            x_label: "time".into(),
            x_unit: "s".into(),
            y_label: "velocity".into(),
            y_unit: "mm/min".into(),
            series: vec![
                Series {
                    label: format!("{sensor}, differentiated"),
                    x: tv[range.clone()].to_vec(),
                    y: v[range.clone()].to_vec(),
                    style: SeriesStyle::Line,
                },
                Series {
                    label: "commanded feed".into(),
                    x: vec![tv[range.start], tv[range.end - 1]],
                    y: vec![feed, feed],
                    style: SeriesStyle::Dashed,
                },
            ],
            kind: FigureKind::Line,
            log_x: false,
            log_y: false,
        };
        let fig = view(
            format!(
                "crawl at {feed:.0} mm/min: velocity from the differentiated {sensor}; SSI = (v_max − v_min)/v_mean = {:.2}",
                res.ssi
            ),
            0..v.len(),
        );
        // Four stick-slip cycles: from the 2nd to the 6th upward crossing of the mean velocity.
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let up: Vec<usize> = (1..v.len()).filter(|&i| v[i - 1] < mean && v[i] >= mean).collect();
        // A smooth run (no four cycles to show): its first ZOOM_SAMPLES samples, where the individual
        // readings are visible (over the whole record they fill the band between v_min and v_max).
        const ZOOM_SAMPLES: usize = 60;
        let zoom = if res.ssi >= 1.0 && up.len() >= 6 {
            Some(view(
                format!(
                    "crawl at {feed:.0} mm/min, zoom: four stick-slip cycles, {:.3}–{:.3} s of the record's {:.2}–{:.2} s",
                    tv[up[1]],
                    tv[up[5]],
                    tv[0],
                    tv[tv.len() - 1]
                ),
                up[1]..up[5] + 1,
            ))
        } else {
            let n = v.len().min(ZOOM_SAMPLES);
            (n >= 2).then(|| {
                view(
                    format!(
                        "crawl at {feed:.0} mm/min, zoom: the first {n} samples, {:.3}–{:.3} s of the record's \
                         {:.2}–{:.2} s (SSI {:.2} < 1: no stick-slip cycle)",
                        tv[0],
                        tv[n - 1],
                        tv[0],
                        tv[tv.len() - 1],
                        res.ssi
                    ),
                    0..n,
                )
            })
        };
        // The patent's example value is a reference, not an injected truth (the SSI follows from the
        // simulated physics). An interval that reaches 0 is a one-sided limit: say so.
        let id = format!("ssi.{sensor}.{feed:.0}_mm_per_min");
        let label = format!("SSI at {feed:.0} mm/min");
        let check = if e - tol <= 0.0 {
            Check::at_most(id, label, Quantity::Ratio, *e, res.ssi, e + tol)
        } else {
            Check::new(label, Quantity::Ratio, *e, res.ssi, *tol).with_id(id)
        };
        let check = check.with_statistic(Statistic::StickSlipIndex).with_note(format!(
            "`injected` is the patent's example SSI at this feed ({e:.2}); SSI ≥ 1 means crawling (SSI {:.3}: {})",
            res.ssi,
            if res.ssi >= 1.0 { "crawling" } else { "smooth" }
        ));
        out.push((check, fig, zoom));
    }
    Ok(out)
}

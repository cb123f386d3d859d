//! Human-readable output.

use super::*;

// ------------------------------------------------------------------------------------------
// Human-readable output.

/// How a channel's values are shown: (factor from SI, unit) — deviations in µm, forces in N,
/// accelerations in m/s². The one rule for the text reports and the HTML figures.
pub fn display_unit(si_unit: &str) -> (f64, &'static str) {
    match si_unit {
        "N" => (1.0, "N"),
        "m/s²" => (1.0, "m/s²"),
        _ => (1e6, "µm"),
    }
}

/// The text report of a compare.
pub fn compare_text(r: &CompareReport) -> String {
    let mut s = format!("vmt compare: model {} against {}\n", r.model, r.data);
    s += &format!(
        "{:<12} {:<14} {:>12} {:>10} {:>8} {:>12} {:>8}\n",
        "run", "sensor", "rms", "rms/σ", "fit %", "σ", "LB p"
    );
    for c in &r.channels {
        let (k, u) = display_unit(&c.unit);
        s += &format!(
            "{:<12} {:<14} {:>9.4} {u:<2} {:>10.2} {:>8.1} {:>9.4} {u:<2}{} {:>8}\n",
            c.run,
            c.sensor,
            c.rms * k,
            c.normalized_rms,
            c.fit_percent,
            c.sigma * k,
            if c.sigma_estimated { "*" } else { " " },
            c.ljung_box_p.map_or("-".to_string(), |p| format!("{p:.3}"))
        );
        let dir: Vec<String> = c.by_direction.iter().map(|(d, m, _)| format!("{d:+}: {:.3}", m * k)).collect();
        s += &format!("    mean residual by direction ({u}): {}\n", dir.join(", "));
        let pos: Vec<String> =
            c.by_position.iter().map(|(a, b, m, _)| format!("{:.0}–{:.0} mm {:.3}", a * 1e3, b * 1e3, m * k)).collect();
        s += &format!("    by position: {}\n", pos.join("; "));
        if let Some((wl, a)) = c.spectrum_peaks.first() {
            s += &format!("    strongest spatial period: {:.2} mm, amplitude {:.3} {u}\n", wl * 1e3, a * k);
        }
    }
    s += &format!("normalised RMS (all samples): {:.3}   (1.0 = noise level; * σ estimated)\n", r.normalized_rms);
    for (e, p) in &r.fitted {
        let kv: Vec<String> = p.iter().map(|(k, v)| format!("{k} = {}", param_text(e, k, *v))).collect();
        s += &format!("fitted {e}: {}\n", kv.join(", "));
    }
    s += &shapes_text(&r.shapes);
    s += &sigma_text(r.sigma.as_ref());
    for n in &r.notes {
        s += &format!("note: {n}\n");
    }
    if !r.history.is_empty() {
        s += "iterations (normalised RMS):\n";
        let max = r.history.iter().map(|h| h.normalized_rms).fold(0.0, f64::max).max(1e-300);
        for (i, h) in r.history.iter().enumerate() {
            // index: normalized_rms ≤ max, so the bar is ≤ 40 characters.
            let bar = "#".repeat(((h.normalized_rms / max) * 40.0).round() as usize);
            s += &format!("  {i:>2} {:>10.3} {bar} {} {}\n", h.normalized_rms, h.model, h.added);
        }
    }
    s
}

/// The text report of a diagnosis.
pub fn diagnose_text(r: &DiagnoseReport) -> String {
    let mut s = format!("vmt diagnose: normalised RMS {:.3}\n", r.normalized_rms);
    // p: upper bound of the probability that noise alone gives any candidate a reduction this large.
    s += &format!("{:<22} {:>12} {:>9} {:>10} {:<12} params\n", "effect", "ΔBIC", "p", "explained", "verdict");
    for e in &r.ranking {
        let kv: Vec<String> = e.params.iter().map(|(k, v)| format!("{k}={}", param_text(e.effect, k, *v))).collect();
        let v = match e.verdict {
            Verdict::Significant => "significant",
            Verdict::Noise => "noise",
            Verdict::Inseparable => "inseparable",
        };
        let p = e.p_value.map_or("-".to_string(), |p| format!("{p:.1e}"));
        s += &format!(
            "{:<22} {:>12.1} {:>9} {:>10.3} {:<12} {}",
            e.effect,
            e.delta_bic,
            p,
            e.explained,
            v,
            kv.join(" ")
        );
        if !e.confused_with.is_empty() {
            s += &format!("  (confused with {})", effect_list(&e.confused_with));
        }
        s += "\n";
    }
    s += &shapes_text(&r.shapes);
    s += &sigma_text(r.sigma.as_ref());
    s += &format!("advice: {}\n", r.advice);
    for n in &r.notes {
        s += &format!("note: {n}\n");
    }
    s
}

/// Effect names as written in files, separated by commas: `positioning, straightness_y`.
pub(crate) fn effect_list(names: &[EffectName]) -> String {
    names.iter().map(|n| n.as_str()).collect::<Vec<_>>().join(", ")
}

/// One line per fitted error motion: its basis, order and why, e.g. "positioning: Legendre order 11
/// chosen by BIC over 1..20 (model gave none)".
pub(crate) fn shapes_text(shapes: &EffectMap<ShapeReport>) -> String {
    let mut s = String::new();
    for (n, sh) in shapes {
        let why = match (sh.chosen_by.as_str(), sh.bic_order) {
            ("model", Some(b)) => format!("given by the model (BIC would choose {b})"),
            ("model", None) => "given by the model".to_string(),
            (how, _) => format!("chosen by {how} (model gave none)"),
        };
        let series = match sh.basis {
            ShapeBasis::Legendre => format!("Legendre order {}", sh.order),
            ShapeBasis::Cosine => format!("cosine series order {}", sh.order),
            ShapeBasis::Bspline => format!("{} B-splines", sh.order),
            ShapeBasis::Harmonics => format!("{} harmonics", sh.order),
            ShapeBasis::Table => format!("table of {} values", sh.order),
        };
        s += &format!("{n}: {series} {why}\n");
    }
    s
}

/// One line on the noise σ checked against the repeats, e.g. "σ: stated 0.100 µm, from repeats
/// 0.310 µm (1σ of one reading, 80 degrees of freedom), χ² test p = 1.2e-30: ...".
pub(crate) fn sigma_text(sc: Option<&SigmaCheck>) -> String {
    let Some(sc) = sc else { return String::new() };
    let stated = sc.stated.map_or("none".to_string(), |v| format!("{:.4} µm", v * 1e6));
    let p = sc.p_value.map_or(String::new(), |p| format!(", χ² test p = {p:.2e}"));
    let used = match sc.used {
        SigmaUse::Stated => "significance uses the stated σ",
        SigmaUse::Estimated => "significance uses σ estimated from the data",
        SigmaUse::FromRepeats => "stated σ inconsistent with the repeats: significance uses their upper 95 % bound",
    };
    format!(
        "σ (1σ of one reading): stated {stated}, from repeats {:.4} µm ({} degrees of freedom){p}; {used}\n",
        sc.from_repeats * 1e6,
        sc.dof
    )
}

/// A fitted or diagnosed parameter in the unit of the effect catalogue
/// (`vmt_sim::effects::ParamSpec::unit`): `value=25.37 µm`, `period=10.49 mm`; a key the catalogue
/// does not list (a gain per sensor, a shape coefficient) in SI as written to files.
pub(crate) fn param_text(effect: EffectName, key: &str, v: f64) -> String {
    let unit = vmt_sim::effects::param_specs(effect).iter().find(|s| s.key == key).map(|s| s.unit);
    match unit {
        Some(u) => u.display(v),
        None => fmt_num(v),
    }
}

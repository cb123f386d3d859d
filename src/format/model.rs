//! Models and truths in the `vmt-model/1` format (FORMAT.md §2).
//!
//! ```toml
//! format = "vmt-model/1"
//! machine = "slide_column"
//! axis = "x"                 # default axis of the effects below
//! [effects.positioning]      # EXX
//! fit = true
//! basis = "bspline"          # optional, with fit = true: poly | bspline | harmonics | table
//! order = 8                  # optional, with fit = true
//! [effects.backlash]
//! value = 4e-6               # m
//! ```
//!
//! Error motions take a profile: `poly = [c0, c1, ...]` (Σ cᵢ·xⁱ), `harmonics = [{amplitude,
//! wavelength, phase}, ...]`, `random = {rms, correlation_length, seed}`, `table = "file.csv"`
//! (CSV of position,value relative to the model file, units in the header allowed); several are
//! summed. Other effects take the parameters of [`vmt_sim::effects::param_specs`]. With
//! `fit = true` every parameter is optional and the given ones are starting values.
//! vmt extension (additive): an effect on several axes is written as an array of tables,
//! `[[effects.pitch]]` with `axis` in each.

use crate::error::{parse_toml, TomlReader, VmtError};
use crate::measurement::{fmt_toml_f64, read_value_table, toml_str, value_table_text, write_file_atomic};
use crate::units::Dimension;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use vmt_sim::effects::{param_specs, Effect, EffectName, EffectParams, EffectSet, LeadHarmonic, Range};
use vmt_sim::profile::{Harmonic, Profile, RandomProfile, Term};
use vmt_sim::Axis;

/// The `format` value of a model file.
pub const MODEL_FORMAT: &str = "vmt-model/1";

/// The basis an estimator uses for an error motion marked `fit = true`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Basis {
    /// Polynomial in position (`order` = degree).
    Poly,
    /// B-spline (`order` = number of basis functions).
    Bspline,
    /// Harmonics (`order` = number of harmonics).
    Harmonics,
    /// Values at the measured positions, interpolated linearly (`order` = number of points).
    Table,
}

impl Basis {
    /// Every basis.
    pub const ALL: [Basis; 4] = [Basis::Poly, Basis::Bspline, Basis::Harmonics, Basis::Table];

    /// The name as written in files.
    pub fn as_str(self) -> &'static str {
        match self {
            Basis::Poly => "poly",
            Basis::Bspline => "bspline",
            Basis::Harmonics => "harmonics",
            Basis::Table => "table",
        }
    }

    /// Parses a `basis` string.
    pub fn parse(s: &str) -> Option<Basis> {
        Basis::ALL.iter().copied().find(|b| b.as_str() == s)
    }
}

/// One effect of a model: the effect with its (starting) parameters, whether it is fitted, and
/// the basis requested for a fitted error motion.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelEffect {
    /// Name, axis and parameters (SI). For `fit = true`, parameters not in `given` hold the
    /// starting values of [`EffectParams::default_for`].
    pub effect: Effect,
    /// True: unknown, to be fitted (`fit = true`).
    pub fit: bool,
    /// Basis for a fitted error motion, if requested.
    pub basis: Option<Basis>,
    /// Order of that basis, if requested.
    pub order: Option<u32>,
    /// Parameter keys given in the file (starting values of a fit); all set keys when
    /// `fit = false`. For error motions, the profile keys present (poly, harmonics, random,
    /// table).
    pub given: Vec<String>,
}

/// The keys an effect's parameters fill: set scalar keys in [`param_specs`] order, `harmonics`
/// for a cyclic lead with harmonics; for error motions the profile keys of its terms.
pub fn given_keys(effect: &Effect) -> Vec<String> {
    match &effect.params {
        EffectParams::ErrorMotion(p) => {
            let mut keys: Vec<String> = Vec::new();
            for (k, present) in [
                ("poly", p.terms.iter().any(|t| matches!(t, Term::Poly(_)))),
                ("harmonics", p.terms.iter().any(|t| matches!(t, Term::Harmonics(_)))),
                ("random", p.terms.iter().any(|t| matches!(t, Term::Random { .. }))),
                ("table", p.terms.iter().any(|t| matches!(t, Term::Table { .. }))),
            ] {
                if present {
                    keys.push(k.to_string());
                }
            }
            keys
        }
        params => {
            let mut keys: Vec<String> = params.scalars(effect.name).into_iter().map(|(k, _)| k.to_string()).collect();
            if let EffectParams::CyclicLead(c) = params {
                if !c.harmonics.is_empty() {
                    keys.push("harmonics".to_string());
                }
            }
            keys
        }
    }
}

impl ModelEffect {
    /// A model effect with every set parameter counted as given (a known effect, or a fit that
    /// starts from these values, e.g. `vmt add --from-diagnosis`).
    pub fn new(effect: Effect, fit: bool) -> ModelEffect {
        let given = given_keys(&effect);
        ModelEffect { effect, fit, basis: None, order: None, given }
    }
}

/// A model or truth (FORMAT.md §2).
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    /// Bundled machine name or URDF path relative to the model file.
    pub machine: Option<String>,
    /// Default axis of the effects (file key `axis`, default `"x"`).
    pub axis: Axis,
    /// The effects, sorted by catalogue order then axis.
    pub effects: Vec<ModelEffect>,
    /// The file it was read from (the scenario file for an inline `[truth]`).
    pub source: PathBuf,
}

impl Model {
    /// The effects as a simulator's [`EffectSet`] (fit flags dropped; fitted effects carry
    /// their starting values).
    pub fn effect_set(&self) -> EffectSet {
        EffectSet { effects: self.effects.iter().map(|m| m.effect.clone()).collect() }
    }

    /// The effect `name` on `axis`.
    pub fn get(&self, name: EffectName, axis: Axis) -> Option<&ModelEffect> {
        self.effects.iter().find(|m| m.effect.name == name && m.effect.axis == axis)
    }

    /// Adds an effect (replacing and returning one with the same name and axis), keeping the
    /// canonical order. Used by `vmt add`.
    pub fn insert(&mut self, me: ModelEffect) -> Option<ModelEffect> {
        let old = self
            .effects
            .iter()
            .position(|m| m.effect.name == me.effect.name && m.effect.axis == me.effect.axis)
            .map(|i| self.effects.remove(i));
        self.effects.push(me);
        self.sort();
        old
    }

    /// Sorts the effects by catalogue order, then axis.
    pub fn sort(&mut self) {
        self.effects.sort_by_key(|m| (m.effect.name, m.effect.axis));
    }
}

/// The largest error motion a model or truth may state anywhere on the positions it is used at: 1 m
/// (translational) or 0.1 rad (angular). A machine's geometric errors are µm and µrad; a profile that
/// reaches these sizes (e.g. polynomial coefficients of 1e300, which are finite and pass the per-term
/// checks) is a unit mistake, and would otherwise surface as NaN in an output file, or as a message
/// about another file, far from its cause (issue 14).
pub const MAX_ERROR_MOTION: (f64, f64) = (1.0, 0.1);

impl Model {
    /// Evaluates every error motion with a stated profile at 1001 points over `range(axis)` (the
    /// travel of a scenario's truth, the measured positions of a model checked against data; an axis
    /// without a range is skipped): finite and within [`MAX_ERROR_MOTION`], else the key path
    /// (`PREFIX.effects.NAME`, `effects.NAME` for an empty prefix) and a message naming the worst
    /// position and `over` (what the range is).
    pub fn check_error_motion_sizes(
        &self,
        prefix: &str,
        over: &str,
        range: impl Fn(Axis) -> Option<(f64, f64)>,
    ) -> Result<(), (String, String)> {
        for me in &self.effects {
            let Some(profile) = me.effect.params.profile() else { continue };
            let Some((lo, hi)) = range(me.effect.axis) else { continue };
            let (max, unit) =
                if me.effect.name.is_translational() { (MAX_ERROR_MOTION.0, "m") } else { (MAX_ERROR_MOTION.1, "rad") };
            let at = |i: usize| lo + (hi - lo) * i as f64 / 1000.0;
            // Above the bound or NaN.
            let too_large = |x: &f64| {
                let v = profile.value(*x).abs();
                v.is_nan() || v > max
            };
            if let Some(x) = (0..=1000).map(at).find(too_large) {
                let key = if prefix.is_empty() {
                    format!("effects.{}", me.effect.name)
                } else {
                    format!("{prefix}.effects.{}", me.effect.name)
                };
                return Err((
                    key,
                    format!(
                        "the profile (axis {}) reaches {} {unit} at x = {} m ({over} {}..{} m); an error motion \
                         stays within ±{max} {unit}",
                        me.effect.axis,
                        crate::error::fmt_num(profile.value(x)),
                        crate::error::fmt_num(x),
                        crate::error::fmt_num(lo),
                        crate::error::fmt_num(hi)
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// Reads a `vmt-model/1` file. Table profiles are read relative to the file's directory.
pub fn read_model(path: &Path) -> Result<Model, VmtError> {
    let text = std::fs::read_to_string(path).map_err(|e| VmtError::io(path, "reading the model", e))?;
    let table = parse_toml(path, &text)?;
    if !table.contains_key("format") {
        return Err(VmtError::bad(path, "format", format!("missing key: expected format = \"{MODEL_FORMAT}\"")));
    }
    parse_model(&table, path, &parent_of(path), "")
}

fn parent_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Parses a model from an already parsed TOML table: a model file's root, or a scenario's
/// inline `[truth]` (FORMAT.md §3). `file` is named in messages, `base_dir` resolves `table`
/// CSV paths and `prefix` is the key path of the table (`"truth"`, or `""` for a model file),
/// so errors read `scenario.toml: truth.effects.backlash.value: expected ...`.
/// `format` is optional here but must be `vmt-model/1` when present.
pub fn parse_model(table: &toml::Table, file: &Path, base_dir: &Path, prefix: &str) -> Result<Model, VmtError> {
    let r = TomlReader::new(file, prefix, table);
    if let Some(f) = r.opt_str("format", &format!("\"{MODEL_FORMAT}\""))? {
        if f != MODEL_FORMAT {
            return Err(r.bad("format", format!("expected \"{MODEL_FORMAT}\", got {f:?}")));
        }
    }
    let machine = r.opt_str("machine", "a bundled machine name or URDF path")?.map(str::to_string);
    let axis = r.opt_axis("axis")?.unwrap_or(Axis::X);
    let mut effects: Vec<(ModelEffect, String)> = Vec::new();
    if let Some(er) = r.opt_table("effects")? {
        for (key, value) in er.table() {
            er.allow(&[key.as_str()]);
            let name: EffectName = key.parse().map_err(|_| {
                er.bad(key, format!("unknown effect `{key}`; known effects: {}", EffectName::known_list()))
            })?;
            let readers: Vec<TomlReader<'_>> = match value {
                toml::Value::Table(_) => {
                    vec![er.opt_table(key)?.ok_or_else(|| VmtError::Internal("effect table vanished".to_string()))?]
                }
                toml::Value::Array(_) => er.opt_tables(key)?.unwrap_or_default(),
                v => {
                    return Err(er.bad(
                        key,
                        format!("expected a table [effects.{key}], got {}", crate::error::describe_value(v)),
                    ))
                }
            };
            for t in &readers {
                let me = parse_effect(t, name, axis, base_dir)?;
                effects.push((me, t.prefix().to_string()));
            }
        }
        er.deny_unknown()?;
    }
    r.deny_unknown()?;
    effects.sort_by_key(|(m, _)| (m.effect.name, m.effect.axis));
    for w in effects.windows(2) {
        let (a, _) = &w[0];
        let (b, path) = &w[1];
        if a.effect.name == b.effect.name && a.effect.axis == b.effect.axis {
            return Err(VmtError::bad(
                file,
                path.clone(),
                format!("`{}` is given twice for axis {}", b.effect.name, b.effect.axis),
            ));
        }
    }
    Ok(Model { machine, axis, effects: effects.into_iter().map(|(m, _)| m).collect(), source: file.to_path_buf() })
}

/// Parses one `[effects.NAME]` table.
fn parse_effect(
    r: &TomlReader<'_>,
    name: EffectName,
    default_axis: Axis,
    base_dir: &Path,
) -> Result<ModelEffect, VmtError> {
    let axis = r.opt_axis("axis")?.unwrap_or(default_axis);
    let fit = r.opt_bool("fit")?.unwrap_or(false);
    let mut given: Vec<String> = Vec::new();
    let mut basis: Option<Basis> = None;
    let mut order: Option<u32> = None;
    let params = if name.is_error_motion() {
        let quantity = if name.is_translational() { "a length in metres" } else { "an angle in radians" };
        if let Some(b) = r.opt_str("basis", "poly, bspline, harmonics or table")? {
            basis = Some(
                Basis::parse(b)
                    .ok_or_else(|| r.bad("basis", format!("expected poly, bspline, harmonics or table, got {b:?}")))?,
            );
        }
        if let Some(o) = r.opt_u64("order", "a positive integer")? {
            if o < 1 || o > u64::from(u32::MAX) {
                return Err(r.bad("order", format!("expected a positive integer, got {o}")));
            }
            order = Some(o as u32);
        }
        if !fit {
            for k in ["basis", "order"] {
                if r.has(k) {
                    return Err(r.bad(k, format!("`{k}` only applies to a fitted error motion: add fit = true")));
                }
            }
        }
        let mut terms: Vec<Term> = Vec::new();
        if let Some(c) = r.opt_f64_array("poly", "a polynomial coefficient (SI)")? {
            if c.is_empty() {
                return Err(r.bad("poly", "expected at least one coefficient"));
            }
            terms.push(Term::Poly(c));
        }
        if let Some(hs) = r.opt_tables("harmonics")? {
            let mut v: Vec<Harmonic> = Vec::new();
            for h in &hs {
                v.push(Harmonic {
                    amplitude: h.req_f64("amplitude", quantity)?,
                    wavelength: h.req_f64("wavelength", "a wavelength in metres > 0")?,
                    phase: h.opt_f64("phase", "a phase in radians")?.unwrap_or(0.0),
                });
                h.deny_unknown()?;
            }
            if v.is_empty() {
                return Err(r.bad("harmonics", "expected at least one harmonic"));
            }
            terms.push(Term::Harmonics(v));
        }
        if let Some(rr) = r.opt_table("random")? {
            let spec = RandomProfile {
                rms: rr.req_f64("rms", &format!("{quantity} ≥ 0"))?,
                correlation_length: rr.req_f64("correlation_length", "a correlation length in metres > 0")?,
                seed: rr
                    .opt_u64("seed", "a non-negative integer seed")?
                    .ok_or_else(|| rr.bad("seed", "missing key: expected an integer seed"))?,
            };
            rr.deny_unknown()?;
            // Range-check before expanding (the expansion divides by the correlation length).
            if !Range::NonNegative.contains(spec.rms) {
                return Err(rr.bad("rms", format!("expected {quantity} ≥ 0, got {}", crate::error::fmt_num(spec.rms))));
            }
            if !Range::Positive.contains(spec.correlation_length) {
                return Err(rr.bad(
                    "correlation_length",
                    format!(
                        "expected a correlation length in metres > 0, got {}",
                        crate::error::fmt_num(spec.correlation_length)
                    ),
                ));
            }
            terms.push(Term::random(spec));
        }
        if let Some(f) = r.opt_str("table", "a CSV file name (position,value)")? {
            let dim = if name.is_translational() { Dimension::Length } else { Dimension::Angle };
            let (x, y) = read_value_table(&base_dir.join(f), name.as_str(), dim)?;
            terms.push(Term::Table { x, y });
        }
        if terms.is_empty() && !fit {
            return Err(r.bad(
                "",
                "expected a profile: at least one of poly, harmonics, random, table \
                 (or fit = true to estimate it)",
            ));
        }
        EffectParams::ErrorMotion(Profile { terms })
    } else {
        let mut params = EffectParams::default_for(name);
        for s in param_specs(name) {
            match r.opt_f64(s.key, s.quantity)? {
                Some(v) => {
                    params.set(s.key, v);
                    given.push(s.key.to_string());
                }
                None if s.required && !fit => {
                    return Err(r.bad(
                        s.key,
                        format!(
                            "missing key: expected {}{} (or fit = true to estimate it)",
                            s.quantity,
                            s.range.describe()
                        ),
                    ))
                }
                None => {}
            }
        }
        if let EffectParams::CyclicLead(c) = &mut params {
            if let Some(hs) = r.opt_tables("harmonics")? {
                for h in &hs {
                    let order = h
                        .opt_u64("order", "a harmonic number ≥ 2")?
                        .ok_or_else(|| h.bad("order", "missing key: expected a harmonic number ≥ 2"))?;
                    c.harmonics.push(LeadHarmonic {
                        order: u32::try_from(order).unwrap_or(u32::MAX),
                        amplitude: h.req_f64("amplitude", "a length in metres ≥ 0")?,
                        phase: h.opt_f64("phase", "a phase in radians")?.unwrap_or(0.0),
                    });
                    h.deny_unknown()?;
                }
                given.push("harmonics".to_string());
            }
        }
        params
    };
    r.deny_unknown()?;
    let effect = Effect { name, axis, params };
    if let Some(p) = effect.validate().into_iter().next() {
        return Err(r.bad(&p.key, p.message));
    }
    let given = if fit && !name.is_error_motion() { given } else { given_keys(&effect) };
    Ok(ModelEffect { effect, fit, basis, order, given })
}

/// A TOML inline table of (key, float) pairs.
fn inline(pairs: &[(&str, String)]) -> String {
    let items: Vec<String> = pairs.iter().map(|(k, v)| format!("{k} = {v}")).collect();
    format!("{{ {} }}", items.join(", "))
}

/// Writes the profile keys of an error motion; a table term becomes a sidecar CSV
/// `STEM.AXIS.NAME.csv` returned in `sidecars`.
fn profile_lines(
    me: &ModelEffect,
    p: &Profile,
    stem: &str,
    out: &mut String,
    sidecars: &mut Vec<(String, String)>,
) -> Result<(), VmtError> {
    let e = &me.effect;
    let mut poly: Vec<f64> = Vec::new();
    let mut has_poly = false;
    let mut harmonics: Vec<&Harmonic> = Vec::new();
    let mut random: Option<&RandomProfile> = None;
    let mut table: Option<(&[f64], &[f64])> = None;
    for t in &p.terms {
        match t {
            Term::Poly(c) => {
                has_poly = true;
                if poly.len() < c.len() {
                    poly.resize(c.len(), 0.0);
                }
                for (i, ci) in c.iter().enumerate() {
                    poly[i] += ci;
                }
            }
            Term::Harmonics(h) => harmonics.extend(h.iter()),
            Term::Random { spec, .. } => {
                if random.replace(spec).is_some() {
                    return Err(VmtError::Internal(format!(
                        "{} on {}: a model file holds one `random` term per error motion",
                        e.name, e.axis
                    )));
                }
            }
            Term::Table { x, y } => {
                if table.replace((x, y)).is_some() {
                    return Err(VmtError::Internal(format!(
                        "{} on {}: a model file holds one `table` per error motion",
                        e.name, e.axis
                    )));
                }
            }
        }
    }
    if has_poly {
        let items: Vec<String> = poly.iter().map(|c| fmt_toml_f64(*c)).collect();
        out.push_str(&format!("poly = [{}]\n", items.join(", ")));
    }
    if !harmonics.is_empty() {
        let items: Vec<String> = harmonics
            .iter()
            .map(|h| {
                inline(&[
                    ("amplitude", fmt_toml_f64(h.amplitude)),
                    ("wavelength", fmt_toml_f64(h.wavelength)),
                    ("phase", fmt_toml_f64(h.phase)),
                ])
            })
            .collect();
        out.push_str(&format!("harmonics = [{}]\n", items.join(", ")));
    }
    if let Some(s) = random {
        let seed = i64::try_from(s.seed)
            .map_err(|_| VmtError::Internal(format!("random seed {} exceeds a TOML integer", s.seed)))?;
        out.push_str(&format!(
            "random = {}\n",
            inline(&[
                ("rms", fmt_toml_f64(s.rms)),
                ("correlation_length", fmt_toml_f64(s.correlation_length)),
                ("seed", seed.to_string()),
            ])
        ));
    }
    if let Some((x, y)) = table {
        let name = format!("{stem}.{}.{}.csv", e.axis, e.name);
        out.push_str(&format!("table = {}\n", toml_str(&name)));
        sidecars.push((name, value_table_text(x, y)));
    }
    Ok(())
}

/// The TOML text of a model, and the sidecar CSV files (name, text) of its table profiles,
/// named `STEM.AXIS.EFFECT.csv` (to be written beside the model file). Floats are written with
/// the shortest round-trip digits, so reading the text back gives identical numbers.
pub fn model_to_toml(model: &Model, stem: &str) -> Result<(String, Vec<(String, String)>), VmtError> {
    let mut out = String::new();
    let mut sidecars: Vec<(String, String)> = Vec::new();
    out.push_str("# vmt model (vmt-model/1, docs/formats.md §2); SI units: m, rad, s, N, K\n");
    out.push_str(&format!("format = {}\n", toml_str(MODEL_FORMAT)));
    if let Some(m) = &model.machine {
        out.push_str(&format!("machine = {}\n", toml_str(m)));
    }
    out.push_str(&format!("axis = {}\n", toml_str(&model.axis.to_string())));
    let mut effects: Vec<&ModelEffect> = model.effects.iter().collect();
    effects.sort_by_key(|m| (m.effect.name, m.effect.axis));
    for me in effects {
        let e = &me.effect;
        let many = model.effects.iter().filter(|o| o.effect.name == e.name).count() > 1;
        if many {
            out.push_str(&format!("\n[[effects.{}]]\n", e.name));
        } else {
            out.push_str(&format!("\n[effects.{}]\n", e.name));
        }
        if let Some(sym) = e.name.iso230_symbol(e.axis) {
            out.pop();
            out.push_str(&format!("{}# {sym}\n", " ".repeat(2)));
        }
        if many || e.axis != model.axis {
            out.push_str(&format!("axis = {}\n", toml_str(&e.axis.to_string())));
        }
        if me.fit {
            out.push_str("fit = true\n");
        }
        if let Some(b) = me.basis {
            out.push_str(&format!("basis = {}\n", toml_str(b.as_str())));
        }
        if let Some(o) = me.order {
            out.push_str(&format!("order = {o}\n"));
        }
        match &e.params {
            EffectParams::ErrorMotion(p) => profile_lines(me, p, stem, &mut out, &mut sidecars)?,
            params => {
                let write_key = |k: &str| !me.fit || me.given.iter().any(|g| g == k);
                for (k, v) in params.scalars(e.name) {
                    if write_key(k) {
                        out.push_str(&format!("{k} = {}\n", fmt_toml_f64(v)));
                    }
                }
                if let EffectParams::CyclicLead(c) = params {
                    if (!me.fit && !c.harmonics.is_empty()) || (me.fit && write_key("harmonics")) {
                        let items: Vec<String> = c
                            .harmonics
                            .iter()
                            .map(|h| {
                                inline(&[
                                    ("order", h.order.to_string()),
                                    ("amplitude", fmt_toml_f64(h.amplitude)),
                                    ("phase", fmt_toml_f64(h.phase)),
                                ])
                            })
                            .collect();
                        out.push_str(&format!("harmonics = [{}]\n", items.join(", ")));
                    }
                }
            }
        }
    }
    Ok((out, sidecars))
}

/// Writes a model to `path` (atomically, each file via a temporary sibling and a rename), with
/// table profiles as sidecar CSVs beside it; returns the paths written (sidecars first).
/// Reading the result gives back the same model (round trip).
pub fn write_model(model: &Model, path: &Path) -> Result<Vec<PathBuf>, VmtError> {
    let problems = model.effect_set().validate();
    if let Some(p) = problems.first() {
        return Err(VmtError::bad(path, p.key.clone(), p.message.clone()));
    }
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "model".to_string());
    let (text, sidecars) = model_to_toml(model, &stem)?;
    let dir = parent_of(path);
    let mut written: Vec<PathBuf> = Vec::new();
    for (name, csv) in &sidecars {
        let p = dir.join(name);
        write_file_atomic(&p, csv.as_bytes())?;
        written.push(p);
    }
    write_file_atomic(path, text.as_bytes())?;
    written.push(path.to_path_buf());
    Ok(written)
}

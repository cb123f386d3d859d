//! vmt add and the history.

use super::*;

// ------------------------------------------------------------------------------------------
// vmt add and the history.

/// The model with effect `name` (on the model's axis) added, `fit = true`; with `from` (a ranking
/// entry of a diagnosis) its parameters are the starting values: error-motion polynomial
/// coefficients `cK`, or the scalar parameters by key.
pub fn add_effect(model: &Model, name: EffectName, from: Option<&RankedEffect>) -> Result<Model, AddError> {
    if model.get(name, model.axis).is_some() {
        return Err(AddError::AlreadyInModel { name, axis: model.axis });
    }
    let mut effect = Effect { name, axis: model.axis, params: EffectParams::default_for(name) };
    let mut given: Vec<String> = Vec::new();
    if let Some(r) = from {
        if name.is_error_motion() {
            let deg = r.params.keys().filter_map(|k| k.strip_prefix('c')?.parse::<usize>().ok()).max().unwrap_or(0);
            let mut c = vec![0.0; deg + 1];
            for (k, v) in &r.params {
                if let Some(i) = k.strip_prefix('c').and_then(|s| s.parse::<usize>().ok()) {
                    c[i] = *v;
                }
            }
            effect.params = EffectParams::ErrorMotion(Profile { terms: vec![Term::Poly(c)] });
            given.push("poly".into());
        } else {
            for (k, v) in &r.params {
                if effect.params.set(k, *v) {
                    given.push(k.clone());
                }
            }
            // Amplitudes are ≥ 0 by the catalogue's ranges: fold a negative one into the phase.
            if matches!(name, EffectName::Backlash) && effect.params.get("value").is_some_and(|v| v < 0.0) {
                let v = effect.params.get("value").unwrap_or(0.0);
                effect.params.set("value", v.abs());
            }
            if matches!(name, EffectName::ThermalDrift | EffectName::ThermalExpansion) {
                if let Some(t) = effect.params.get("tau") {
                    effect.params.set("tau", t.max(0.0));
                }
            }
        }
    }
    // A diagnosis value outside the catalogue's range (e.g. a negative viscous coefficient fitted
    // while another term's hyper-parameters were held) is only a starting value: the model gets
    // the catalogue's default there and `compare` fits it afresh (not `given`).
    let default = EffectParams::default_for(name);
    for p in effect.validate() {
        if let Some(v) = default.get(&p.key) {
            effect.params.set(&p.key, v);
            given.retain(|g| *g != p.key);
        }
    }
    if let Some(p) = effect.validate().into_iter().next() {
        return Err(AddError::OutOfRange { key: p.key, message: p.message });
    }
    let mut m = model.clone();
    m.insert(ModelEffect { effect, fit: true, basis: None, order: None, given });
    Ok(m)
}

/// Why [`add_effect`] cannot add an effect.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AddError {
    /// The model has the effect on its axis already.
    #[error("the model already has `{name}` on axis {axis}")]
    AlreadyInModel {
        /// The effect.
        name: EffectName,
        /// The model's axis.
        axis: vmt_core::axis::Axis,
    },
    /// A parameter of the effect is outside the catalogue's range even at its default.
    #[error("{key}: {message}")]
    OutOfRange {
        /// The parameter's key.
        key: String,
        /// What the catalogue expects.
        message: String,
    },
}

/// `history.json` beside a model file.
pub fn history_path(model_path: &Path) -> PathBuf {
    model_path.parent().map(|p| p.join("history.json")).unwrap_or_else(|| PathBuf::from("history.json"))
}

/// Reads a history file (an array of [`HistoryEntry`]); None if absent or unreadable.
pub fn read_history(path: &Path) -> Option<Vec<HistoryEntry>> {
    let text = std::fs::read_to_string(path).ok()?;
    serde_json::from_str(&text).ok()
}

/// Appends entries to a history file (written atomically).
pub fn append_history(path: &Path, entries: &[HistoryEntry]) -> Result<(), VmtError> {
    let mut h = read_history(path).unwrap_or_default();
    h.extend(entries.iter().cloned());
    let text = serde_json::to_string_pretty(&h).map_err(|e| VmtError::Internal(e.to_string()))?;
    write_file_atomic(path, text.as_bytes())
}
